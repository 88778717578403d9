//! Malformed morphology files are refused with an error naming the file, the field and the
//! problem. One test per kind of mistake.

use kumi_model::{load_morphology, ModelError, ModuleLibrary, Morphology, Problem};

const FILE: &str = "my_robot.toml";

fn parse(text: &str) -> ModelError {
    Morphology::parse(FILE, text, &ModuleLibrary::shipped())
        .expect_err("this morphology must be refused")
}

/// A valid two-module robot to break in small ways.
const BASE: &str = r#"
name = "test"
[[module]]
name = "w"
kind = "wheel"
role = "wheel"
options = ["skids"]
[[module]]
name = "a"
kind = "arm"
role = "manipulator"
mount = { parent = "w", connector = "top" }
"#;

#[test]
fn the_base_case_is_valid() {
    Morphology::parse(FILE, BASE, &ModuleLibrary::shipped()).unwrap();
}

#[test]
fn unknown_module_kind() {
    let err = parse(&BASE.replace("kind = \"arm\"", "kind = \"tentacle\""));
    assert_eq!(err.field, "module[1].kind");
    assert!(matches!(&err.problem, Problem::UnknownModule { kind, .. } if kind == "tentacle"));
    let msg = err.to_string();
    assert!(
        msg.starts_with("my_robot.toml: module[1].kind: unknown module kind `tentacle`"),
        "{msg}"
    );
    assert!(
        msg.contains("arm, hub, wheel"),
        "lists the known kinds: {msg}"
    );
}

#[test]
fn duplicate_module_name() {
    let err = parse(&BASE.replace("name = \"a\"", "name = \"w\""));
    assert_eq!(err.field, "module[1].name");
    assert_eq!(
        err.to_string(),
        "my_robot.toml: module[1].name: duplicate name `w`"
    );
}

#[test]
fn mount_on_an_unknown_parent() {
    let err = parse(&BASE.replace("parent = \"w\"", "parent = \"ghost\""));
    assert_eq!(err.field, "module[1].mount.parent");
    assert!(
        err.to_string()
            .contains("bad mount: no module named `ghost`"),
        "{err}"
    );
}

#[test]
fn mount_on_an_unknown_connector() {
    let err = parse(&BASE.replace("connector = \"top\"", "connector = \"side\""));
    assert_eq!(err.field, "module[1].mount.connector");
    let msg = err.to_string();
    assert!(
        msg.contains("module `w` (wheel) has no connector `side`"),
        "{msg}"
    );
    assert!(
        msg.contains("connectors: top, front, back"),
        "lists the connectors: {msg}"
    );
}

#[test]
fn two_modules_on_one_connector() {
    let text = format!(
        "{BASE}\n[[module]]\nname = \"b\"\nkind = \"arm\"\nrole = \"leg\"\nmount = {{ parent = \"w\", connector = \"top\" }}\n"
    );
    let err = parse(&text);
    assert_eq!(err.field, "module[2].mount.connector");
    assert!(
        err.to_string()
            .contains("connector `top` of `w` is already in use"),
        "{err}"
    );
}

#[test]
fn mount_by_a_connector_off_the_root_link() {
    // An arm can only be mounted by its base: its tip is on link7, not on its root link.
    let err = parse(&BASE.replace(
        "connector = \"top\" }",
        "connector = \"top\", child_connector = \"tip\" }",
    ));
    assert_eq!(err.field, "module[1].mount.child_connector");
    assert!(
        err.to_string()
            .contains("only be mounted by a connector on its root link `base`"),
        "{err}"
    );
}

#[test]
fn mounting_cycle() {
    let text = r#"
name = "loop"
[[module]]
name = "root"
kind = "hub"
role = "body"
[[module]]
name = "a"
kind = "arm"
role = "leg"
mount = { parent = "b", connector = "tip" }
[[module]]
name = "b"
kind = "arm"
role = "leg"
mount = { parent = "a", connector = "tip" }
"#;
    let err = parse(text);
    assert!(matches!(err.problem, Problem::BadMount(_)), "{err}");
    assert!(err.to_string().contains("mounting cycle"), "{err}");
}

#[test]
fn no_root_or_two_roots() {
    let err = parse(&BASE.replace("mount = { parent = \"w\", connector = \"top\" }", ""));
    assert_eq!(err.field, "module");
    assert!(
        err.to_string()
            .contains("exactly one module must have no `mount`"),
        "{err}"
    );
    assert!(err.to_string().contains("[w, a]"), "{err}");
}

#[test]
fn missing_field() {
    let err = parse(&BASE.replace("kind = \"arm\"\n", ""));
    assert_eq!(err.field, "module[1].kind");
    assert_eq!(err.problem, Problem::Missing);
    assert_eq!(
        err.to_string(),
        "my_robot.toml: module[1].kind: missing required field"
    );

    let err = parse(&BASE.replace("name = \"test\"\n", ""));
    assert_eq!(
        (err.field.as_str(), &err.problem),
        ("name", &Problem::Missing)
    );

    let err = parse(&BASE.replace("parent = \"w\", ", ""));
    assert_eq!(err.field, "module[1].mount.parent");
}

#[test]
fn unknown_role() {
    let err = parse(&BASE.replace("role = \"manipulator\"", "role = \"gripper\""));
    assert_eq!(err.field, "module[1].role");
    assert_eq!(
        err.to_string(),
        "my_robot.toml: module[1].role: unknown role `gripper` (allowed here: manipulator, leg)"
    );
    // A real role that this kind of module cannot take is refused the same way.
    let err = parse(&BASE.replace("role = \"wheel\"", "role = \"leg\""));
    assert_eq!(err.field, "module[0].role");
    assert!(err.to_string().contains("(allowed here: wheel)"), "{err}");
}

#[test]
fn unknown_field_is_a_typo_not_silence() {
    let err = parse(&BASE.replace(
        "role = \"manipulator\"",
        "role = \"manipulator\"\nhoem = [0.0]",
    ));
    assert_eq!(err.field, "module[1].hoem");
    assert!(matches!(err.problem, Problem::UnknownField { .. }), "{err}");
    assert!(
        err.to_string().contains("home"),
        "lists the known fields: {err}"
    );
}

#[test]
fn home_of_the_wrong_length_or_out_of_range() {
    let err = parse(&BASE.replace(
        "role = \"manipulator\"",
        "role = \"manipulator\"\nhome = [0.0, 0.1]",
    ));
    assert_eq!(err.field, "module[1].home");
    assert!(
        err.to_string()
            .contains("expected 7 joint positions for a `arm` module, got 2"),
        "{err}"
    );

    let err = parse(&BASE.replace(
        "role = \"manipulator\"",
        "role = \"manipulator\"\nhome = [0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]",
    ));
    assert!(
        err.to_string()
            .contains("joint2 = 3 rad is outside its range [-2, 2]"),
        "{err}"
    );
}

#[test]
fn unknown_option() {
    let err = parse(&BASE.replace("options = [\"skids\"]", "options = [\"rockets\"]"));
    assert_eq!(err.field, "module[0].options[0]");
    assert!(
        err.to_string()
            .contains("has no option `rockets` (options: skids)"),
        "{err}"
    );
}

#[test]
fn not_toml_at_all() {
    let err = parse("name = \"x\"\n[[module]\n");
    assert!(matches!(err.problem, Problem::Syntax(_)), "{err}");
    assert!(err.to_string().starts_with("my_robot.toml: "), "{err}");
}

#[test]
fn a_missing_file_names_the_shipped_morphologies() {
    let err = load_morphology("no/such/file.toml", &ModuleLibrary::shipped()).unwrap_err();
    assert_eq!(err.file, "no/such/file.toml");
    assert!(
        err.to_string().contains("arm, minimal, dragon, tricycle"),
        "{err}"
    );
}

#[test]
fn a_user_file_on_disk_is_accepted() {
    let path =
        std::env::temp_dir().join(format!("kumi-user-morphology-{}.toml", std::process::id()));
    std::fs::write(&path, BASE).unwrap();
    let m = load_morphology(path.to_str().unwrap(), &ModuleLibrary::shipped()).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(m.name, "test");
    assert_eq!(m.modules.len(), 2);
}

#[test]
fn unknown_physics_layout() {
    let err = parse(&format!("{BASE}\n[physics]\nlayout = \"jelly\"\n"));
    assert_eq!(err.field, "physics.layout");
    assert!(
        err.to_string()
            .contains("unknown layout `jelly` (known: single-multibody, per-limb, per-module)"),
        "{err}"
    );
    // Step settings are global on purpose (servo response depends on them): refused here.
    let err = parse(&format!("{BASE}\n[physics]\nsubsteps = 2\n"));
    assert!(matches!(err.problem, Problem::UnknownField { .. }), "{err}");
}

#[test]
fn a_physics_layout_is_read() {
    let m = Morphology::parse(
        FILE,
        &format!("{BASE}\n[physics]\nlayout = \"single-multibody\"\n"),
        &ModuleLibrary::shipped(),
    )
    .unwrap();
    assert_eq!(m.physics.layout, Some(kumi_model::Layout::SingleMultibody));
}

#[test]
fn a_mujoco_step_is_read_and_zero_refused() {
    let m = Morphology::parse(
        FILE,
        &format!("{BASE}\n[physics]\nmujoco_substeps = 8\n"),
        &ModuleLibrary::shipped(),
    )
    .unwrap();
    assert_eq!(m.physics.mujoco_substeps, Some(8));
    let err = parse(&format!("{BASE}\n[physics]\nmujoco_substeps = 0\n"));
    assert_eq!(err.field, "physics.mujoco_substeps");
    assert!(err.to_string().contains("at least 1"), "{err}");
}

#[test]
fn an_effort_scale_multiplies_that_modules_torque_limits_only() {
    let text = BASE.replace(
        "role = \"manipulator\"",
        "role = \"manipulator\"\neffort_scale = 3.0",
    );
    let library = ModuleLibrary::shipped();
    let scaled = kumi_model::assemble(&Morphology::parse(FILE, &text, &library).unwrap(), &library);
    let plain = kumi_model::assemble(&Morphology::parse(FILE, BASE, &library).unwrap(), &library);
    let arm = |m: &kumi_model::RobotModel| m.module("a").unwrap().actuators.clone();
    for (s, p) in arm(&scaled).iter().zip(arm(&plain).iter()) {
        assert_eq!(s.effort_limit, 3.0 * p.effort_limit, "{}", s.joint);
    }
    let wheel = |m: &kumi_model::RobotModel| m.module("w").unwrap().actuators.clone();
    assert_eq!(wheel(&scaled), wheel(&plain));
    // The URDF says the same, so both engines and the fingerprint see it.
    let urdf_effort = |m: &kumi_model::RobotModel| {
        m.urdf
            .joints
            .iter()
            .find(|j| j.name == "a/joint2")
            .unwrap()
            .limit
            .effort
    };
    assert_eq!(urdf_effort(&scaled), 3.0 * urdf_effort(&plain));

    for bad in ["0.0", "-1.0", "nan", "11.0"] {
        let err = parse(&BASE.replace(
            "role = \"manipulator\"",
            &format!("role = \"manipulator\"\neffort_scale = {bad}"),
        ));
        assert_eq!(err.field, "module[1].effort_scale", "{bad}");
        assert!(err.to_string().contains("torque-limit factor"), "{err}");
    }
}

#[test]
fn follow_steering_is_refused_on_a_module_without_wheels_or_without_a_mount() {
    let err = parse(&BASE.replace(
        "role = \"manipulator\"",
        "role = \"manipulator\"\nfollow_steering = true",
    ));
    assert_eq!(err.field, "module[1].follow_steering");
    assert!(err.to_string().contains("wheel-less `arm` module"), "{err}");
    let err = parse(&BASE.replace(
        "role = \"wheel\"",
        "role = \"wheel\"\nfollow_steering = true",
    ));
    assert_eq!(err.field, "module[0].follow_steering");
    assert!(err.to_string().contains("root `wheel` module"), "{err}");
    let err = parse(&BASE.replace(
        "role = \"wheel\"",
        "role = \"wheel\"\nfollow_steering = \"yes\"",
    ));
    assert!(err.to_string().contains("expected a boolean"), "{err}");
    // A wheel module on a hub has nothing to steer it.
    let err = parse(
        r#"
name = "cart"
[[module]]
name = "hub"
kind = "hub"
role = "body"
[[module]]
name = "w"
kind = "wheel"
role = "wheel"
mount = { parent = "hub", connector = "bottom" }
follow_steering = true
"#,
    );
    assert_eq!(err.field, "module[1].follow_steering");
    assert!(err.to_string().contains("no joint to steer it"), "{err}");
}

#[test]
fn a_wheel_module_on_a_legs_tip_may_follow_its_steering() {
    let text = r#"
name = "cart"
[[module]]
name = "hub"
kind = "hub"
role = "body"
[[module]]
name = "leg"
kind = "arm"
role = "leg"
mount = { parent = "hub", connector = "side0" }
home = [0.0, 0.0, 0.0, 1.5707963267948966, 0.0, 0.0, 0.0]
[[module]]
name = "w"
kind = "wheel"
role = "wheel"
mount = { parent = "leg", connector = "tip" }
follow_steering = true
"#;
    let library = ModuleLibrary::shipped();
    let model = kumi_model::assemble(&Morphology::parse(FILE, text, &library).unwrap(), &library);
    let couplings = model.steering_couplings();
    assert_eq!(couplings.len(), 2, "{couplings:?}");
    assert!(couplings.iter().all(|c| c.steering_joint() == "leg/joint7"));
    // The two wheels roll opposite ways, by half the track over the radius.
    assert!((couplings[0].gain + couplings[1].gain).abs() < 1e-9);
    assert!((couplings[0].gain.abs() - 0.286 / 0.27).abs() < 1e-9);
    // Without the key, the same robot has none.
    let plain = text.replace("follow_steering = true\n", "");
    let model = kumi_model::assemble(
        &Morphology::parse(FILE, &plain, &library).unwrap(),
        &library,
    );
    assert!(model.steering_couplings().is_empty());
}
