//! Every shipped morphology's URDF is accepted by the reference parser `check_urdf`
//! (Debian package `liburdfdom-tools`, installed by `.ci/run`). Never skipped: a machine
//! without it fails with the command to install it.

use std::process::Command;

use kumi_model::{assemble, load_morphology, shipped_morphologies, ModuleLibrary};

fn check_urdf(name: &str, xml: &str) -> String {
    let path = std::env::temp_dir().join(format!("kumi-{name}-{}.urdf", std::process::id()));
    std::fs::write(&path, xml).unwrap();
    let output = Command::new("check_urdf")
        .arg(&path)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run check_urdf ({e}); install it with `apt-get install liburdfdom-tools`"
            )
        });
    std::fs::remove_file(&path).unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "check_urdf rejected {name}:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

#[test]
fn check_urdf_accepts_every_shipped_morphology() {
    let library = ModuleLibrary::shipped();
    for name in shipped_morphologies() {
        let model = assemble(&load_morphology(name, &library).unwrap(), &library);
        let report = check_urdf(name, &model.urdf_xml());
        assert!(
            report.contains(&format!("root Link: {} has", model.base_link)),
            "{name}: check_urdf found another root:\n{report}"
        );
        // Every link appears in check_urdf's tree.
        for link in &model.urdf.links {
            assert!(
                report.contains(&link.name),
                "{name}: {} missing:\n{report}",
                link.name
            );
        }
    }
}

#[test]
fn check_urdf_rejects_a_broken_urdf() {
    // The guard works: a joint naming a missing link must fail.
    let path = std::env::temp_dir().join(format!("kumi-broken-{}.urdf", std::process::id()));
    std::fs::write(
        &path,
        r#"<robot name="b"><link name="a"/><joint name="j" type="fixed"><parent link="a"/><child link="ghost"/></joint></robot>"#,
    )
    .unwrap();
    let status = Command::new("check_urdf")
        .arg(&path)
        .output()
        .unwrap()
        .status;
    std::fs::remove_file(&path).unwrap();
    assert!(!status.success());
}
