// Temporary probe: stands a robot on an engine, prints drift over time.
use std::sync::Arc;
use kumi_model::{assemble, load_morphology, ModuleLibrary};
use kumi_worlds::{Engine, SimConfig, SimWorld};
fn main() {
    let name = std::env::args().nth(1).unwrap_or("minimal".into());
    let engine: Engine = std::env::args().nth(2).unwrap_or("mujoco".into()).parse().unwrap();
    let library = ModuleLibrary::shipped();
    let model = Arc::new(assemble(&load_morphology(&name, &library).unwrap(), &library));
    let mut config = SimConfig::for_model(&model);
    if let Ok(s) = std::env::var("SUBSTEPS") { config.substeps = s.parse().unwrap(); }
    let mut w = kumi_worlds::build(engine, model.clone(), config).unwrap();
    let start = w.base_pose().translation.vector;
    let t0 = std::time::Instant::now();
    for k in 0..1800 {
        w.step();
        if k % 150 == 0 {
            let d = w.base_pose().translation.vector - start;
            println!("t={:.1} drift=({:.4},{:.4},{:.4}) tilt={:.3}deg contacts={:?} q={:?} cmd={:?}", w.time(), d.x, d.y, d.z, w.base_tilt().to_degrees(), w.ground_contacts(), w.joint_positions().iter().map(|x| (x*1000.0).round()/1000.0).collect::<Vec<_>>(), w.commands());
        }
    }
    println!("{:.0} steps/s", 1800.0 / t0.elapsed().as_secs_f64());
}
