//! Wheels that follow their steering get the same velocities from the simulator's servos
//! (`kumi_engine::ServoBank`, what training, evaluation and the sim bridge run) and from the
//! whole-body node on hardware (`kumi_whole_body_node::steering::SteeringRates`, which sends
//! them to Motion Stack): for the same steering commands and base turning at the same times,
//! bit for bit.

use kumi_model::{assemble, load_morphology, ActuatorMode, ModuleLibrary};
use kumi_whole_body_node::steering::SteeringRates;
use kumi_worlds::{home_joint_positions, ServoBank};
use nalgebra::Vector3;

#[test]
fn the_servos_and_the_hardware_node_roll_following_wheels_alike() {
    let library = ModuleLibrary::shipped();
    let model = assemble(&load_morphology("tricycle", &library).unwrap(), &library);
    let mut bank = ServoBank::new(&model);
    let mut rates = SteeringRates::new(&model);
    let q = home_joint_positions(&model);
    bank.hold(&q);
    // Times in powers of two, so that wall time and summed physics steps agree exactly.
    let physics_dt = 1.0 / 128.0;
    let per_command = 4;
    let wheel_modules = ["wheel0", "wheel1", "wheel2"];
    let v = [0.7, -0.3, 1.9];
    let mut compared = 0;
    for k in 0..40 {
        let t_s = (k * per_command) as f64 * physics_dt;
        // Every leg's tip roll and joint5 commanded along different waves; the legs stop at
        // k = 30.
        for (n, leg) in ["leg0", "leg1", "leg2"].iter().enumerate() {
            if k >= 30 {
                continue;
            }
            let range = bank.module_range(leg).unwrap();
            let mut targets = q[range.clone()].to_vec();
            let roll = 0.4 * ((k as f64) * 0.3 + n as f64).sin();
            targets[6] += roll;
            targets[4] += 0.2 * ((k as f64) * 0.5 - n as f64).cos();
            bank.set(leg, ActuatorMode::Position, &targets).unwrap();
            for joint in [6, 4] {
                let commanded = bank.commands()[range.start + joint];
                let name = format!("{leg}/joint{}", joint + 1);
                assert!(rates.command(&name, commanded, t_s));
            }
        }
        // The base turns (and rocks) along its own wave, as odometry would report it.
        let w_b = Vector3::new(
            0.1 * (k as f64).cos(),
            -0.05,
            0.8 * ((k as f64) * 0.2).sin(),
        );
        bank.set_base_angular_velocity(w_b);
        assert!(rates.base_turning(w_b, t_s));
        for (module, v) in wheel_modules.iter().zip(v) {
            let sign = bank.drive_sign(module).unwrap();
            bank.set(module, ActuatorMode::Velocity, &[sign * v, sign * v])
                .unwrap();
        }
        // The node sends the wheels once per command, at its time; the servos hold what they
        // track over the physics steps until the next command.
        let sent: Vec<(String, f64)> = wheel_modules
            .iter()
            .zip(v)
            .flat_map(|(m, v)| rates.wheel_velocities(&model, m, v, t_s).unwrap())
            .collect();
        for step in 0..per_command {
            let targets: Vec<_> = (0..q.len())
                .map(|i| bank.advance(i, q[i], physics_dt))
                .collect();
            for (joint, velocity) in &sent {
                let i = bank
                    .actuators()
                    .iter()
                    .position(|a| &a.joint == joint)
                    .unwrap();
                assert_eq!(
                    targets[i].velocity.to_bits(),
                    velocity.to_bits(),
                    "{joint} at command {k}, step {step}: servos {} node {velocity}",
                    targets[i].velocity
                );
                compared += 1;
            }
        }
    }
    assert_eq!(compared, 40 * 4 * 6);
}
