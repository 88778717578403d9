use kumi_model::{assemble, load_morphology, ModuleLibrary};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{self, Goal};
use kumi_policies::skill::ArmSkill;
use kumi_worlds::{home_joint_positions, Engine};
use std::sync::Arc;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let engine: Engine = args[1].parse().unwrap();
    let active: Vec<String> = args[2].split(',').map(String::from).collect();
    let scale: f64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(1.0);
    let library = ModuleLibrary::shipped();
    let morph = std::env::var("MORPH").unwrap_or("tricycle".into());
    let tri = Arc::new(assemble(
        &load_morphology(&morph, &library).unwrap(),
        &library,
    ));
    let sim = kumi_worlds::SimConfig::for_model(&tri);
    let mut world = kumi_worlds::build(engine, tri.clone(), sim).unwrap();
    let st = world.standing_state(0.0, 0.0, 0.0, home_joint_positions(&tri));
    world.reset(&st);
    let skill_bytes = std::fs::read(kumi_runtime::shipped_arm_policy()).unwrap();
    let mut mods = Vec::new();
    for name in &active {
        let m = tri.module(name).unwrap();
        let contract = ArmSkill::new(m, sim.control_hz).unwrap();
        let policy = kumi_runtime::SkillPolicy::from_bytes(
            skill_bytes.clone(),
            "skill",
            &contract,
            kumi_runtime::BackendChoice::Tract,
        )
        .unwrap();
        let home: [f64; 7] = std::array::from_fn(|j| m.home[j]);
        let pose = ToolKinematics::new(&tri, m).unwrap().tool_pose_b(&home);
        let goal = Goal {
            position_b: pose.translation.vector,
            orientation_b: pose.rotation,
        };
        let range = world.module_range(name).unwrap();
        mods.push((name.clone(), contract, policy, goal, range, home));
    }
    for step in 0..360 {
        let (q, qd) = (world.joint_positions(), world.joint_velocities());
        for (name, contract, policy, goal, r, _) in mods.iter_mut() {
            let obs = observation::build(
                &std::array::from_fn(|j| q[r.start + j]),
                &std::array::from_fn(|j| qd[r.start + j]),
                goal,
            );
            let a = policy.act(&obs).unwrap();
            let inc: Vec<f64> = contract.increments(&a).iter().map(|v| v * scale).collect();
            world.apply_increments(name, &inc).unwrap();
        }
        world.step();
        if step % 30 == 0 {
            let q = world.joint_positions();
            let s: Vec<String> = mods
                .iter()
                .map(|(n, _, _, _, r, home)| {
                    let d: Vec<String> = (0..7)
                        .map(|j| format!("{:+.2}", q[r.start + j] - home[j]))
                        .collect();
                    format!("{n}[{}]", d.join(" "))
                })
                .collect();
            println!(
                "t={:.0} tilt={:.3} z={:.3} {}",
                step as f64 / 30.0,
                world.base_tilt(),
                world.base_pose().translation.z,
                s.join(" ")
            );
        }
    }
}
