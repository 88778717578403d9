//! Morphology and module files, fuzzed (issue 10): the shipped files are mutated as text
//! (bytes flipped, lines dropped, duplicated or swapped, numbers replaced by NaN, infinities,
//! huge or negative values, names emptied or made to collide, text cut short) and parsed. No
//! input may panic, and every accepted input must give the same model back:
//! - a morphology: assembled, its robot URDF read back has the model's links, joints and
//!   actuators, and parsing the same text again gives an equal morphology;
//! - a module: its URDF written out and parsed again with the same TOML gives the same module.
//!
//! Seeded: the same cases on every run. Run with `--nocapture` for the counts.

use std::panic::{catch_unwind, AssertUnwindSafe};

use kumi_model::{assemble, Module, ModuleLibrary, Morphology};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const MORPHOLOGY_CASES: usize = 2500;
const MODULE_CASES: usize = 1500;

const MORPHOLOGIES: [(&str, &str); 4] = [
    ("arm", include_str!("../morphologies/arm.toml")),
    ("minimal", include_str!("../morphologies/minimal.toml")),
    ("dragon", include_str!("../morphologies/dragon.toml")),
    ("tricycle", include_str!("../morphologies/tricycle.toml")),
];

const MODULES: [(&str, &str, &str); 3] = [
    (
        "arm",
        include_str!("../modules/arm.toml"),
        include_str!("../modules/arm.urdf"),
    ),
    (
        "wheel",
        include_str!("../modules/wheel.toml"),
        include_str!("../modules/wheel.urdf"),
    ),
    (
        "hub",
        include_str!("../modules/hub.toml"),
        include_str!("../modules/hub.urdf"),
    ),
];

const NUMBERS: [&str; 12] = [
    "NaN", "nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "-0", "1e-320", "1e999", "0x10",
];

/// Byte ranges of the numbers in `text`.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = (b[i].is_ascii_digit() || b[i] == b'-')
            && (i == 0 || !b[i - 1].is_ascii_alphanumeric() && b[i - 1] != b'_');
        if starts {
            let j = (i + 1..b.len())
                .find(|&j| !(b[j].is_ascii_digit() || b"+-.eE".contains(&b[j])))
                .unwrap_or(b.len());
            out.push((i, j));
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// Byte ranges of the contents of double-quoted strings in `text`.
fn strings(text: &str) -> Vec<(usize, usize)> {
    let quotes: Vec<usize> = text.match_indices('"').map(|(i, _)| i).collect();
    quotes.chunks_exact(2).map(|q| (q[0] + 1, q[1])).collect()
}

fn pick<T: Copy>(rng: &mut ChaCha8Rng, items: &[T]) -> Option<T> {
    (!items.is_empty()).then(|| items[rng.random_range(0..items.len())])
}

/// One text mutation.
fn mutate(text: &str, rng: &mut ChaCha8Rng) -> String {
    let mut lines: Vec<&str> = text.lines().collect();
    let line = rng.random_range(0..lines.len().max(1));
    match rng.random_range(0..9) {
        0 => {
            let mut b = text.as_bytes().to_vec();
            let i = rng
                .random_range(0..b.len().max(1))
                .min(b.len().saturating_sub(1));
            if !b.is_empty() {
                b[i] = rng.random_range(0x20..0x7f);
            }
            String::from_utf8_lossy(&b).into_owned()
        }
        1 if !lines.is_empty() => {
            lines.remove(line);
            lines.join("\n")
        }
        2 if !lines.is_empty() => {
            lines.insert(line, lines[line]);
            lines.join("\n")
        }
        3 if lines.len() > 1 => {
            let other = rng.random_range(0..lines.len());
            lines.swap(line, other);
            lines.join("\n")
        }
        4 | 5 => match pick(rng, &numbers(text)) {
            Some((a, b)) => {
                let n = pick(rng, &NUMBERS).unwrap();
                format!("{}{n}{}", &text[..a], &text[b..])
            }
            None => text.to_string(),
        },
        6 => match pick(rng, &strings(text)) {
            Some((a, b)) => {
                let others = strings(text);
                let (c, d) = pick(rng, &others).unwrap();
                let replacement = match rng.random_range(0..4) {
                    0 => String::new(),
                    1 => text[c..d].to_string(),
                    2 => "x".repeat(10_000),
                    _ => "a/../b".to_string(),
                };
                format!("{}{replacement}{}", &text[..a], &text[b..])
            }
            None => text.to_string(),
        },
        7 => {
            let mut cut = rng.random_range(0..text.len().max(1));
            while !text.is_char_boundary(cut) {
                cut -= 1;
            }
            text[..cut].to_string()
        }
        _ => {
            let mut at = rng.random_range(0..text.len().max(1));
            while !text.is_char_boundary(at) {
                at -= 1;
            }
            let junk = pick(
                rng,
                &["[[module]]", "<", ">", "\"", "=", "]]", "\u{0}", "é"],
            )
            .unwrap();
            format!("{}{junk}{}", &text[..at], &text[at..])
        }
    }
}

fn mutated(text: &str, rng: &mut ChaCha8Rng) -> String {
    let mut out = text.to_string();
    for _ in 0..rng.random_range(1..=3) {
        out = mutate(&out, rng);
    }
    out
}

/// Every number of an accepted model is finite, but the range of a continuous joint: checked
/// on its debug text, outside string literals.
fn assert_finite(debug: &str, input: &str) {
    let numbers: String = debug
        .split('"')
        .step_by(2)
        .collect::<Vec<_>>()
        .join("\"\"")
        .replace("lower: -inf, upper: inf", "");
    let b = numbers.as_bytes();
    let bad = numbers
        .match_indices("NaN")
        .chain(numbers.match_indices("inf"))
        .find(|(i, m)| {
            let before = if *i > 0 { b[i - 1] } else { b' ' };
            let after = b.get(i + m.len()).copied().unwrap_or(b' ');
            !before.is_ascii_alphabetic() && !after.is_ascii_alphanumeric()
        });
    if let Some((i, _)) = bad {
        panic!(
            "accepted a number that is not finite: …{}…\nin this input:\n{input}",
            &numbers[i.saturating_sub(80)..(i + 10).min(numbers.len())]
        );
    }
}

/// Runs `f`; a panic fails the test with the input that caused it.
fn no_panic<T>(what: &str, input: &str, f: impl FnOnce() -> T) -> T {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|_| {
        panic!("{what} panicked on this input:\n{input}");
    })
}

#[test]
fn mutated_morphology_files_are_refused_or_give_the_same_model_back() {
    let library = ModuleLibrary::shipped();
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let (mut run, mut accepted) = (0, 0);
    for (name, text) in MORPHOLOGIES {
        for _ in 0..MORPHOLOGY_CASES {
            let input = mutated(text, &mut rng);
            run += 1;
            let parsed = no_panic("Morphology::parse", &input, || {
                Morphology::parse("fuzz.toml", &input, &library)
            });
            let Ok(morphology) = parsed else { continue };
            accepted += 1;
            let again = Morphology::parse("fuzz.toml", &input, &library).unwrap();
            assert_eq!(morphology, again, "{name}: parsing is not deterministic");
            let model = no_panic("assemble", &input, || assemble(&morphology, &library));
            assert_finite(&format!("{model:?}"), &input);
            let xml = no_panic("urdf_xml", &input, || model.urdf_xml());
            let robot = urdf_rs::read_from_string(&xml).unwrap_or_else(|e| {
                panic!("{name}: the robot URDF does not read back ({e}):\n{input}")
            });
            let tree = kumi_model::kinematics::KinematicTree::new(&robot)
                .unwrap_or_else(|e| panic!("{name}: the robot URDF is no tree ({e:?}):\n{input}"));
            assert_eq!(robot.links.len(), model.urdf.links.len(), "{input}");
            assert_eq!(robot.joints.len(), model.urdf.joints.len(), "{input}");
            for actuator in model.actuators() {
                assert!(
                    tree.joint_index(&actuator.joint).is_some(),
                    "{name}: actuator `{}` is not in the URDF read back:\n{input}",
                    actuator.joint
                );
            }
        }
    }
    eprintln!("morphology files: {run} mutated cases, {accepted} accepted");
    assert!(
        accepted > 0 && accepted < run,
        "the mutations must reach both outcomes"
    );
}

#[test]
fn mutated_module_files_are_refused_or_give_the_same_module_back() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (mut run, mut accepted) = (0, 0);
    for (name, toml_text, urdf_text) in MODULES {
        for case in 0..2 * MODULE_CASES {
            // Half the cases break the URDF, half the TOML.
            let (toml_in, urdf_in) = if case % 2 == 0 {
                (toml_text.to_string(), mutated(urdf_text, &mut rng))
            } else {
                (mutated(toml_text, &mut rng), urdf_text.to_string())
            };
            run += 1;
            let input = format!("{toml_in}\n----\n{urdf_in}");
            let parsed = no_panic("Module::parse", &input, || {
                Module::parse("fuzz.toml", &toml_in, &urdf_in)
            });
            let Ok(module) = parsed else { continue };
            accepted += 1;
            assert_finite(&format!("{module:?}"), &input);
            let written = urdf_rs::write_to_string(&module.urdf)
                .unwrap_or_else(|e| panic!("{name}: URDF not written ({e}):\n{input}"));
            let again = Module::parse("fuzz.toml", &toml_in, &written)
                .unwrap_or_else(|e| panic!("{name}: refused its own URDF ({e}):\n{input}"));
            assert_eq!(
                format!("{module:?}"),
                format!("{again:?}"),
                "{name}: another module after writing its URDF out:\n{input}"
            );
        }
    }
    eprintln!("module files: {run} mutated cases, {accepted} accepted");
    assert!(
        accepted > 0 && accepted < run,
        "the mutations must reach both outcomes"
    );
}

// What the fuzzer found, pinned: numbers that parsed but were not finite, or made NaN poses.

#[test]
fn a_module_urdf_with_a_non_finite_number_is_refused_with_the_place() {
    let (_, toml_text, urdf_text) = MODULES[0];
    let broken = urdf_text.replacen("ixy=\"0", "ixy=\"NaN", 1);
    assert_ne!(broken, urdf_text, "the fixture must change");
    let err = Module::parse("arm.toml", toml_text, &broken).unwrap_err();
    assert_eq!(err.field, "urdf");
    assert!(
        err.to_string().contains("inertia is not a finite number"),
        "{err}"
    );
}

#[test]
fn an_option_sphere_of_infinite_radius_is_refused() {
    let (_, toml_text, urdf_text) = MODULES[1];
    let (a, b) = strings_free_number(toml_text, "sphere = ");
    let broken = format!("{}inf{}", &toml_text[..a], &toml_text[b..]);
    let err = Module::parse("wheel.toml", &broken, urdf_text).unwrap_err();
    assert!(err.field.ends_with(".sphere"), "{err}");
}

#[test]
fn a_mount_spin_of_1e308_is_refused() {
    let text = MORPHOLOGIES[2].1.replace(
        "child_connector = \"front\", spin = 1.5707963267948966",
        "child_connector = \"front\", spin = 1e308",
    );
    assert_ne!(text, MORPHOLOGIES[2].1, "the fixture must change");
    let err = Morphology::parse("dragon.toml", &text, &ModuleLibrary::shipped()).unwrap_err();
    assert!(err.field.ends_with("mount.spin"), "{err}");
}

/// The byte range of the number after the first `key` in `text`.
fn strings_free_number(text: &str, key: &str) -> (usize, usize) {
    let a = text.find(key).expect("the key is in the fixture") + key.len();
    let b = a + text[a..]
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap();
    (a, b)
}
