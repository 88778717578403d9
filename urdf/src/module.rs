//! Module descriptions: a URDF (geometry, inertia, joint limits) plus a TOML file (actuator
//! gains, connectors, contact materials, options). See `urdf/modules/*.toml`.

use nalgebra::Isometry3;
use serde::Deserialize;

use crate::error::{from_toml, ModelError, Problem};
use crate::pose;

/// How a joint is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActuatorMode {
    /// A PD servo on the joint angle; commands are joint position targets [rad].
    Position,
    /// A damper toward a joint velocity; commands are velocity targets [rad/s].
    Velocity,
}

/// One driven joint with every parameter the simulator needs, gathered from the module URDF
/// (limits, damping, friction) and the module TOML (gains, armature).
#[derive(Debug, Clone, PartialEq)]
pub struct Actuator {
    /// The joint's name (prefixed with the module name once assembled: `arm0/joint1`).
    pub joint: String,
    pub mode: ActuatorMode,
    /// Position gain [N m/rad] (0 for velocity actuators).
    pub stiffness: f64,
    /// Velocity gain [N m s/rad].
    pub damping: f64,
    /// Reflected rotor inertia [kg m^2].
    pub armature: f64,
    /// Passive viscous joint damping [N m s/rad] (URDF `<dynamics damping>`).
    pub joint_damping: f64,
    /// Dry joint friction [N m] (URDF `<dynamics friction>`).
    pub joint_friction: f64,
    /// Torque limit [N m] (URDF `<limit effort>`).
    pub effort_limit: f64,
    /// Velocity limit [rad/s] (URDF `<limit velocity>`).
    pub velocity_limit: f64,
    /// Lower position limit [rad]; `-inf` for continuous joints.
    pub lower: f64,
    /// Upper position limit [rad]; `+inf` for continuous joints.
    pub upper: f64,
}

impl Actuator {
    /// Clamps a position target [rad] into the joint's range.
    pub fn clamp_position(&self, q: f64) -> f64 {
        q.clamp(self.lower, self.upper)
    }

    /// The largest joint increment [rad] per control step at `control_hz` [Hz]: what the joint
    /// can move in one step at its velocity limit. The skill's action scale, and the bound the
    /// sim bridge holds increments from the wire to.
    pub fn max_increment(&self, control_hz: f64) -> f64 {
        self.velocity_limit / control_hz
    }

    /// Clamps a velocity target [rad/s] to the velocity limit.
    pub fn clamp_velocity(&self, v: f64) -> f64 {
        v.clamp(-self.velocity_limit, self.velocity_limit)
    }
}

/// A frame where modules meet; its z axis is the outward normal of the face.
#[derive(Debug, Clone, PartialEq)]
pub struct Connector {
    pub name: String,
    /// The link the connector sits on (unprefixed within the module).
    pub link: String,
    /// Pose of the connector in its link's frame.
    pub pose: Isometry3<f64>,
}

/// A friction coefficient for every collider of a given URDF collision name.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactMaterial {
    pub collision: String,
    /// Coulomb friction coefficient (combined with the ground's by taking the product's root).
    pub friction: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ActuatorToml {
    joint: String,
    mode: ActuatorMode,
    #[serde(default)]
    stiffness: f64,
    damping: f64,
    #[serde(default)]
    armature: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConnectorToml {
    name: String,
    link: String,
    xyz: [f64; 3],
    rpy: [f64; 3],
}

/// An extra collider added by a module option: a sphere of `sphere` [m] radius.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptionCollision {
    pub name: String,
    pub link: String,
    pub xyz: [f64; 3],
    pub sphere: f64,
}

/// A named variant of a module that a morphology can switch on.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModuleOption {
    pub name: String,
    pub description: String,
    #[serde(default)]
    pub collision: Vec<OptionCollision>,
    #[serde(default)]
    pub contact: Vec<ContactMaterial>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModuleToml {
    kind: String,
    description: String,
    urdf: String,
    root_link: String,
    #[serde(default)]
    ee_link: Option<String>,
    roles: Vec<String>,
    default_mount: String,
    #[serde(default)]
    actuator: Vec<ActuatorToml>,
    #[serde(default)]
    connector: Vec<ConnectorToml>,
    #[serde(default)]
    contact: Vec<ContactMaterial>,
    #[serde(default)]
    option: Vec<ModuleOption>,
}

/// A loaded, validated module description.
#[derive(Debug, Clone)]
pub struct Module {
    /// The name morphology files use for this module type (`arm`, `wheel`, `hub`).
    pub kind: String,
    pub description: String,
    /// The module's own URDF, unprefixed.
    pub urdf: urdf_rs::Robot,
    pub root_link: String,
    /// The end-effector (tool) frame link, for arms.
    pub ee_link: Option<String>,
    /// Role names this module can take in a morphology.
    pub roles: Vec<String>,
    pub default_mount: String,
    /// Driven joints, in the module's command order.
    pub actuators: Vec<Actuator>,
    pub connectors: Vec<Connector>,
    pub contacts: Vec<ContactMaterial>,
    pub options: Vec<ModuleOption>,
}

/// The first number of `robot` that is NaN or infinite, named (`joint `j1` origin`).
fn first_non_finite_urdf(robot: &urdf_rs::Robot) -> Option<String> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    let pose = |p: &urdf_rs::Pose| finite(&p.xyz.0) && finite(&p.rpy.0);
    let geometry = |g: &urdf_rs::Geometry| match g {
        urdf_rs::Geometry::Box { size } => finite(&size.0),
        urdf_rs::Geometry::Cylinder { radius, length }
        | urdf_rs::Geometry::Capsule { radius, length } => finite(&[*radius, *length]),
        urdf_rs::Geometry::Sphere { radius } => radius.is_finite(),
        urdf_rs::Geometry::Mesh { scale, .. } => scale.as_ref().is_none_or(|s| finite(&s.0)),
    };
    for link in &robot.links {
        let inertial = &link.inertial;
        let i = &inertial.inertia;
        let checks = [
            ("inertial origin", pose(&inertial.origin)),
            ("mass", inertial.mass.value.is_finite()),
            (
                "inertia",
                finite(&[i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz]),
            ),
            (
                "visual",
                link.visual
                    .iter()
                    .all(|v| pose(&v.origin) && geometry(&v.geometry)),
            ),
            (
                "collision",
                link.collision
                    .iter()
                    .all(|c| pose(&c.origin) && geometry(&c.geometry)),
            ),
        ];
        if let Some((what, _)) = checks.iter().find(|(_, ok)| !ok) {
            return Some(format!("link `{}` {what}", link.name));
        }
    }
    for joint in &robot.joints {
        let l = &joint.limit;
        let d = joint.dynamics.clone().unwrap_or_default();
        let checks = [
            ("origin", pose(&joint.origin)),
            ("axis", finite(&joint.axis.xyz.0)),
            ("limit", finite(&[l.lower, l.upper, l.effort, l.velocity])),
            ("dynamics", finite(&[d.damping, d.friction])),
        ];
        if let Some((what, _)) = checks.iter().find(|(_, ok)| !ok) {
            return Some(format!("joint `{}` {what}", joint.name));
        }
    }
    None
}

/// The first number of a module TOML that is NaN or infinite: (field, what).
fn first_non_finite_toml(raw: &ModuleToml) -> Option<(String, &'static str)> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    for (i, a) in raw.actuator.iter().enumerate() {
        if !finite(&[a.stiffness, a.damping, a.armature]) {
            return Some((format!("actuator[{i}]"), "every gain"));
        }
    }
    for (i, c) in raw.connector.iter().enumerate() {
        if !finite(&c.xyz) || !finite(&c.rpy) {
            return Some((format!("connector[{i}]"), "the pose"));
        }
    }
    for (i, c) in raw.contact.iter().enumerate() {
        if !c.friction.is_finite() {
            return Some((format!("contact[{i}].friction"), "friction"));
        }
    }
    for (i, option) in raw.option.iter().enumerate() {
        for (k, c) in option.contact.iter().enumerate() {
            if !c.friction.is_finite() {
                return Some((format!("option[{i}].contact[{k}].friction"), "friction"));
            }
        }
        for (k, c) in option.collision.iter().enumerate() {
            if !finite(&c.xyz) {
                return Some((format!("option[{i}].collision[{k}].xyz"), "the position"));
            }
        }
    }
    None
}

impl Module {
    /// Parses a module from its TOML text and its URDF text. `file` names the TOML file in errors.
    pub fn parse(file: &str, toml_text: &str, urdf_text: &str) -> Result<Self, ModelError> {
        let raw: ModuleToml = toml::from_str(toml_text).map_err(|e| from_toml(file, e))?;
        let urdf = urdf_rs::read_from_string(urdf_text)
            .map_err(|e| ModelError::new(file, "urdf", Problem::BadUrdf(e.to_string())))?;
        let err = |field: String, problem| ModelError::new(file, field, problem);
        if let Some(what) = first_non_finite_urdf(&urdf) {
            return Err(err(
                "urdf".into(),
                Problem::BadUrdf(format!("{what} is not a finite number")),
            ));
        }
        if let Some((field, what)) = first_non_finite_toml(&raw) {
            return Err(err(
                field,
                Problem::BadValue(format!("{what} must be finite")),
            ));
        }
        let has_link = |name: &str| urdf.links.iter().any(|l| l.name == name);

        if !has_link(&raw.root_link) {
            return Err(err(
                "root_link".into(),
                Problem::BadUrdf(format!("no link `{}` in {}", raw.root_link, raw.urdf)),
            ));
        }
        if let Some(ee) = &raw.ee_link {
            if !has_link(ee) {
                return Err(err(
                    "ee_link".into(),
                    Problem::BadUrdf(format!("no link `{ee}` in {}", raw.urdf)),
                ));
            }
        }
        let mut actuators = Vec::with_capacity(raw.actuator.len());
        for (i, a) in raw.actuator.iter().enumerate() {
            let joint = urdf
                .joints
                .iter()
                .find(|j| j.name == a.joint)
                .ok_or_else(|| {
                    err(
                        format!("actuator[{i}].joint"),
                        Problem::BadUrdf(format!("no joint `{}` in {}", a.joint, raw.urdf)),
                    )
                })?;
            let (lower, upper) = match joint.joint_type {
                urdf_rs::JointType::Revolute => (joint.limit.lower, joint.limit.upper),
                urdf_rs::JointType::Continuous => (f64::NEG_INFINITY, f64::INFINITY),
                ref other => {
                    return Err(err(
                        format!("actuator[{i}].joint"),
                        Problem::BadValue(format!(
                            "joint `{}` is {other:?}; only revolute and continuous joints can be driven",
                            a.joint
                        )),
                    ))
                }
            };
            if !(joint.limit.effort > 0.0 && joint.limit.velocity > 0.0) {
                return Err(err(
                    format!("actuator[{i}].joint"),
                    Problem::BadUrdf(format!(
                        "joint `{}` needs positive <limit effort> and <limit velocity>",
                        a.joint
                    )),
                ));
            }
            let dynamics = joint.dynamics.clone().unwrap_or_default();
            actuators.push(Actuator {
                joint: a.joint.clone(),
                mode: a.mode,
                stiffness: a.stiffness,
                damping: a.damping,
                armature: a.armature,
                joint_damping: dynamics.damping,
                joint_friction: dynamics.friction,
                effort_limit: joint.limit.effort,
                velocity_limit: joint.limit.velocity,
                lower,
                upper,
            });
        }
        let mut connectors = Vec::with_capacity(raw.connector.len());
        for (i, c) in raw.connector.iter().enumerate() {
            if !has_link(&c.link) {
                return Err(err(
                    format!("connector[{i}].link"),
                    Problem::BadUrdf(format!("no link `{}` in {}", c.link, raw.urdf)),
                ));
            }
            if connectors.iter().any(|k: &Connector| k.name == c.name) {
                return Err(err(
                    format!("connector[{i}].name"),
                    Problem::Duplicate {
                        name: c.name.clone(),
                    },
                ));
            }
            connectors.push(Connector {
                name: c.name.clone(),
                link: c.link.clone(),
                pose: pose::isometry(c.xyz, c.rpy),
            });
        }
        for (i, option) in raw.option.iter().enumerate() {
            for (k, extra) in option.collision.iter().enumerate() {
                if !has_link(&extra.link) {
                    return Err(err(
                        format!("option[{i}].collision[{k}].link"),
                        Problem::BadUrdf(format!("no link `{}` in {}", extra.link, raw.urdf)),
                    ));
                }
                if !extra.sphere.is_finite() || extra.sphere <= 0.0 {
                    return Err(err(
                        format!("option[{i}].collision[{k}].sphere"),
                        Problem::BadValue("sphere radius must be positive and finite [m]".into()),
                    ));
                }
            }
        }
        if !connectors.iter().any(|c| c.name == raw.default_mount) {
            return Err(err(
                "default_mount".into(),
                Problem::BadMount(format!("no connector `{}`", raw.default_mount)),
            ));
        }
        Ok(Self {
            kind: raw.kind,
            description: raw.description,
            urdf,
            root_link: raw.root_link,
            ee_link: raw.ee_link,
            roles: raw.roles,
            default_mount: raw.default_mount,
            actuators,
            connectors,
            contacts: raw.contact,
            options: raw.option,
        })
    }

    /// The connector of this name, if any.
    pub fn connector(&self, name: &str) -> Option<&Connector> {
        self.connectors.iter().find(|c| c.name == name)
    }

    /// Number of position-controlled joints (the length of a home configuration).
    pub fn position_dofs(&self) -> usize {
        self.actuators
            .iter()
            .filter(|a| a.mode == ActuatorMode::Position)
            .count()
    }
}
