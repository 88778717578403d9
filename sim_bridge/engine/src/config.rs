//! Simulation settings: timestep, solver iterations and the articulation layout.

use kumi_model::{Layout, RobotModel};

/// Simulation settings. Training, evaluation and the sim bridge take them from
/// [`SimConfig::for_model`]: the defaults, overridden by the morphology's `[physics]` table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Control rate [Hz]: one [`crate::SimWorld::step`] is one control step (paper: 30 Hz).
    pub control_hz: f64,
    /// Physics steps per control step; the physics timestep is `1 / (control_hz * substeps)`.
    pub substeps: u32,
    /// Physics steps per control step in MuJoCo (see [`SimConfig::mujoco_dt`]).
    pub mujoco_substeps: u32,
    /// Solver iterations per physics step (each is a TGS substep in rapier).
    pub solver_iterations: u32,
    pub layout: Layout,
    /// Rapier's velocity-only stabilisation passes after the last solver iteration. Their
    /// velocities are never integrated into positions, and they still carry the servos'
    /// position-error terms, so a braked wheel reports (and the contacts feel) a spin that the
    /// joint never makes: the robot creeps. 0 integrates every solver velocity.
    pub stabilization_iterations: u32,
    /// Friction coefficient of the ground; a contact uses the smaller of the two coefficients.
    pub ground_friction: f64,
    /// Friction coefficient of robot colliders that the module files do not name.
    pub default_friction: f64,
    /// MuJoCo's contact time constant [s] (the first value of every geom's `solref`); none:
    /// twice MuJoCo's timestep. Only training's domain randomisation sets it; rapier has none.
    pub mujoco_contact_time_s: Option<f64>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            control_hz: kumi_model::commands::CONTROL_HZ,
            substeps: 4,
            mujoco_substeps: 4,
            solver_iterations: 4,
            layout: Layout::PerLimb,
            stabilization_iterations: 0,
            ground_friction: 1.0,
            default_friction: 0.8,
            mujoco_contact_time_s: None,
        }
    }
}

impl SimConfig {
    /// The settings a robot is simulated with everywhere: [`SimConfig::default`], overridden by
    /// its morphology file's `[physics]` table.
    pub fn for_model(model: &RobotModel) -> Self {
        let d = Self::default();
        Self {
            layout: model.physics.layout.unwrap_or(d.layout),
            mujoco_substeps: model.physics.mujoco_substeps.unwrap_or(d.mujoco_substeps),
            ..d
        }
    }

    /// Physics timestep [s].
    pub fn dt(&self) -> f64 {
        1.0 / (self.control_hz * f64::from(self.substeps))
    }

    /// MuJoCo's physics timestep [s]. Measured: Minimal rocks on its skids and creeps (0.6 m in
    /// 60 s) at 1/120 s in MuJoCo, and stands (4 mm) at 1/240 s; its morphology file asks for 8.
    pub fn mujoco_dt(&self) -> f64 {
        1.0 / (self.control_hz * f64::from(self.mujoco_substeps))
    }

    /// MuJoCo's contact time constant [s]: [`SimConfig::mujoco_contact_time_s`], else twice
    /// [`SimConfig::mujoco_dt`] (the smallest MuJoCo recommends).
    pub fn mujoco_contact_time_s(&self) -> f64 {
        self.mujoco_contact_time_s.unwrap_or(2.0 * self.mujoco_dt())
    }

    /// The label of this configuration in `engine`: [`SimConfig::label`] for rapier,
    /// `mujoco/<substeps>sub` for MuJoCo (which has no rapier solver settings).
    pub fn label_for(&self, engine: crate::Engine) -> String {
        match engine {
            crate::Engine::Rapier => self.label(),
            crate::Engine::Mujoco => format!("mujoco/{}sub", self.mujoco_substeps),
        }
    }

    /// A short label for reports: `per-limb/4x4/stab0` (layout / substeps x iterations /
    /// stabilisation passes).
    pub fn label(&self) -> String {
        format!(
            "{}/{}x{}/stab{}",
            self.layout.as_str(),
            self.substeps,
            self.solver_iterations,
            self.stabilization_iterations
        )
    }
}
