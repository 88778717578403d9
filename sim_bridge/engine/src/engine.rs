//! The engines kumi can simulate with.

use std::fmt;
use std::str::FromStr;

/// A physics engine behind [`crate::SimWorld`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Engine {
    /// rapier3d: pure Rust, always available; the default everywhere but training.
    Rapier,
    /// MuJoCo 3.17 through `mujoco-rs`: about 10x faster, needs `libmujoco` (PyPI wheel).
    Mujoco,
}

impl Engine {
    pub const ALL: [Engine; 2] = [Engine::Rapier, Engine::Mujoco];

    pub fn as_str(self) -> &'static str {
        match self {
            Engine::Rapier => "rapier",
            Engine::Mujoco => "mujoco",
        }
    }
}

impl fmt::Display for Engine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Engine {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Engine::ALL
            .into_iter()
            .find(|e| e.as_str() == s)
            .ok_or_else(|| format!("unknown engine `{s}`: expected `rapier` or `mujoco`"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for e in Engine::ALL {
            assert_eq!(e.as_str().parse::<Engine>(), Ok(e));
        }
        assert!("bullet".parse::<Engine>().unwrap_err().contains("rapier"));
    }
}
