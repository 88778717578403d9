//! Simulation settings: timestep, solver iterations and the articulation layout.

/// How the robot's joints are split between rapier's multibodies (reduced coordinates, exact
/// joints) and impulse joints (constraints, which flex a little but keep multibodies small).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// The whole robot is one multibody: exact mounts, cost grows with DoF squared.
    SingleMultibody,
    /// Each limb is its own multibody: a module with children starts a new multibody, joined to
    /// its parent by a fixed impulse joint; leaf modules (a wheel module at a leg's tip, a lone
    /// manipulator) stay in their parent's multibody.
    PerLimb,
    /// Each module is its own multibody; every mount is a fixed impulse joint.
    PerModule,
}

impl Layout {
    pub const ALL: [Layout; 3] = [Layout::SingleMultibody, Layout::PerLimb, Layout::PerModule];

    pub fn as_str(self) -> &'static str {
        match self {
            Layout::SingleMultibody => "single-multibody",
            Layout::PerLimb => "per-limb",
            Layout::PerModule => "per-module",
        }
    }

    pub fn parse(s: &str) -> Option<Layout> {
        Layout::ALL.into_iter().find(|l| l.as_str() == s)
    }
}

/// Simulation settings. [`SimConfig::default`] is the configuration that passes the stability
/// tests and the one training, evaluation and the sim bridge use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Control rate [Hz]: one [`crate::World::step`] is one control step (paper: 30 Hz).
    pub control_hz: f64,
    /// Physics steps per control step; the physics timestep is `1 / (control_hz * substeps)`.
    pub substeps: u32,
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
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            control_hz: 30.0,
            substeps: 4,
            solver_iterations: 4,
            layout: Layout::PerLimb,
            stabilization_iterations: 0,
            ground_friction: 1.0,
            default_friction: 0.8,
        }
    }
}

impl SimConfig {
    /// Physics timestep [s].
    pub fn dt(&self) -> f64 {
        1.0 / (self.control_hz * f64::from(self.substeps))
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
