//! A load on a link (`SimWorld::set_link_load`) bends a held arm the same way in every
//! engine, a spring holds it, and a load goes away when cleared or reset.

mod common;

use common::{engines, world};
use kumi_worlds::{Load, SimError, SimWorld};
use nalgebra::Vector3;

/// The fixed arm's tool frame.
const TOOL: &str = "arm/ee";

/// The tool's position [m] after holding the arm at home for 2 s.
fn tool_after_2_s(w: &mut dyn SimWorld) -> Vector3<f64> {
    for _ in 0..60 {
        w.step();
    }
    w.link_pose(TOOL).unwrap().translation.vector
}

/// How far [m] a force bends the held arm at its tool, along the force.
fn sag_m(w: &mut dyn SimWorld, force_w: Vector3<f64>) -> f64 {
    let home = w.home_state();
    w.reset(&home);
    let free = tool_after_2_s(w);
    w.reset(&home);
    w.set_link_load(TOOL, &Load::constant(force_w)).unwrap();
    let loaded = tool_after_2_s(w);
    (loaded - free).dot(&force_w.normalize())
}

#[test]
fn a_tool_load_bends_the_arm_alike_in_every_engine() {
    // At home the arm stands straight up: a force along x bends it about joint2 and joint4
    // (about a metre of lever), one along z presses along its length.
    let mut sags = Vec::new();
    for engine in engines() {
        let mut w = world(engine, "arm");
        let across = sag_m(w.as_mut(), Vector3::new(50.0, 0.0, 0.0));
        // 90 N: at 100 N joint2 passes its 136 N m effort limit and the arm folds.
        let double = sag_m(w.as_mut(), Vector3::new(90.0, 0.0, 0.0));
        let along = sag_m(w.as_mut(), Vector3::new(0.0, 0.0, -100.0));
        // The servos (30,000 N m/rad) give millimetres under 50 N across, in proportion to
        // the force, and far less along the arm.
        assert!(
            (0.0005..0.02).contains(&across),
            "{engine}: 50 N across bent the tool {across} m"
        );
        assert!(
            (double / across - 1.8).abs() < 0.2,
            "{engine}: 90 N bent the tool {double} m, 50 N {across} m"
        );
        assert!(
            along.abs() < 0.2 * double,
            "{engine}: 100 N along the arm moved the tool {along} m, 90 N across {double} m"
        );
        sags.push((engine, across));
    }
    // The PD law alone gives 4 mm (50 N over 1.3 m and 0.87 m of lever at joint2 and joint4,
    // 30,000 N m/rad each), which MuJoCo gives; rapier's solver yields about twice as much
    // (docs/simulation.md, "Rapier physics settings": its servos sag more than their law).
    for pair in sags.windows(2) {
        let ((a, da), (b, db)) = (pair[0], pair[1]);
        assert!(
            da.max(db) < 3.0 * da.min(db),
            "under 50 N across, {a} bends {da} m and {b} {db} m"
        );
    }
}

#[test]
fn a_cleared_or_reset_load_is_gone() {
    for engine in engines() {
        let mut w = world(engine, "arm");
        let home = w.home_state();
        w.reset(&home);
        let free = tool_after_2_s(w.as_mut());
        // A zero force takes the load off: the arm comes back to where it holds unloaded.
        w.reset(&home);
        w.set_link_load(TOOL, &Load::constant(Vector3::new(50.0, 0.0, -80.0)))
            .unwrap();
        tool_after_2_s(w.as_mut());
        w.set_link_load(TOOL, &Load::NONE).unwrap();
        let cleared = tool_after_2_s(w.as_mut());
        assert!(
            (cleared - free).norm() < 1e-3,
            "{engine}: the cleared load left the tool {} m off",
            (cleared - free).norm()
        );
        // A reset takes it off too: the same trajectory as never loaded, bit for bit.
        w.reset(&home);
        w.set_link_load(TOOL, &Load::constant(Vector3::new(50.0, 0.0, -80.0)))
            .unwrap();
        w.step();
        w.reset(&home);
        assert_eq!(tool_after_2_s(w.as_mut()), free, "{engine}");
    }
}

#[test]
fn bad_loads_are_refused_and_change_nothing() {
    for engine in engines() {
        let mut w = world(engine, "arm");
        let home = w.home_state();
        w.reset(&home);
        let free = tool_after_2_s(w.as_mut());
        w.reset(&home);
        assert!(matches!(
            w.set_link_load(
                "arm/nowhere",
                &Load::constant(Vector3::new(0.0, 0.0, -10.0))
            ),
            Err(SimError::UnknownLink(_))
        ));
        let err = w
            .set_link_load(TOOL, &Load::constant(Vector3::new(f64::NAN, 0.0, 0.0)))
            .unwrap_err();
        assert!(err.to_string().contains("finite values"), "{err}");
        let negative = Load {
            stiffness_n_m: -1.0,
            ..Load::NONE
        };
        assert!(matches!(
            w.set_link_load(TOOL, &negative),
            Err(SimError::BadLoad { .. })
        ));
        assert_eq!(tool_after_2_s(w.as_mut()), free, "{engine}");
    }
}

#[test]
fn a_spring_holds_the_tool_near_its_anchor() {
    // The tool anchored where it stands by 20,000 N/m, then pushed 50 N across: the spring
    // takes most of the push that bends the unanchored arm (about 4-9 mm, above).
    for engine in engines() {
        let mut w = world(engine, "arm");
        let free = sag_m(w.as_mut(), Vector3::new(50.0, 0.0, 0.0));
        let home = w.home_state();
        w.reset(&home);
        let anchor_w = w.link_pose(TOOL).unwrap().translation.vector;
        let held = Load {
            force_w: Vector3::new(50.0, 0.0, 0.0),
            anchor_w,
            stiffness_n_m: 20_000.0,
        };
        w.set_link_load(TOOL, &held).unwrap();
        let moved = (tool_after_2_s(w.as_mut()) - anchor_w).norm();
        assert!(
            moved < 0.5 * free && moved.is_finite(),
            "{engine}: anchored, the tool moved {moved} m; free, 50 N bent it {free} m"
        );
    }
}
