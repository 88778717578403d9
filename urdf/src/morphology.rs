//! Morphology files: which modules a robot is built from, their roles, how each is mounted on its
//! parent, and the home joint configuration. See `urdf/morphologies/*.toml`.

use std::collections::HashSet;
use std::fmt;

use serde::Deserialize;

use crate::catalog::ModuleLibrary;
use crate::error::{from_toml, ModelError, Problem};
use crate::physics::{PhysicsSettings, RawPhysics};

/// What a module does in a morphology.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// The arm whose end effector the whole-body task is about.
    Manipulator,
    /// An arm that carries the robot (usually ending in a wheel module).
    Leg,
    /// A wheel module.
    Wheel,
    /// A passive body (a hub).
    Body,
}

impl Role {
    pub const ALL: [Role; 4] = [Role::Manipulator, Role::Leg, Role::Wheel, Role::Body];

    pub fn as_str(self) -> &'static str {
        match self {
            Role::Manipulator => "manipulator",
            Role::Leg => "leg",
            Role::Wheel => "wheel",
            Role::Body => "body",
        }
    }

    pub fn parse(s: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.as_str() == s)
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How a module is attached to its parent: the child's connector faces the parent's connector
/// (z axes opposed), turned by `spin` [rad] about the shared axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Mount {
    pub parent: String,
    pub connector: String,
    pub child_connector: String,
    pub spin: f64,
}

/// One module of a morphology, validated against the module library.
#[derive(Debug, Clone, PartialEq)]
pub struct MorphologyModule {
    /// Unique name; the prefix of the module's links and joints (`arm0/joint1`).
    pub name: String,
    pub kind: String,
    pub role: Role,
    /// `None` for the root module (the robot's base).
    pub mount: Option<Mount>,
    /// Home position of each position-controlled joint [rad], in module order.
    pub home: Vec<f64>,
    pub options: Vec<String>,
    /// Factor on every joint's torque limit (URDF `<limit effort>`) of this module: a module
    /// built with a stronger gearbox than its kind's default. 1 unless the file says otherwise.
    pub effort_scale: f64,
    /// A wheel module mounted below a joint that steers it: its wheels roll with that joint
    /// ([`crate::RobotModel::steering_couplings`]) instead of being dragged sideways. False
    /// unless the file says otherwise.
    pub follow_steering: bool,
}

/// A validated morphology.
#[derive(Debug, Clone, PartialEq)]
pub struct Morphology {
    pub name: String,
    pub description: String,
    /// The root module is welded to the world (single-module training scenes).
    pub fixed_base: bool,
    /// Modules with every parent before its children; the first is the root.
    pub modules: Vec<MorphologyModule>,
    /// How this robot is best simulated (the `[physics]` table).
    pub physics: PhysicsSettings,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMorphology {
    name: Option<String>,
    description: Option<String>,
    #[serde(default)]
    fixed_base: bool,
    module: Option<Vec<RawModule>>,
    #[serde(default)]
    physics: RawPhysics,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModule {
    name: Option<String>,
    kind: Option<String>,
    role: Option<String>,
    mount: Option<RawMount>,
    home: Option<Vec<f64>>,
    #[serde(default)]
    options: Vec<String>,
    effort_scale: Option<f64>,
    #[serde(default)]
    follow_steering: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMount {
    parent: Option<String>,
    connector: Option<String>,
    child_connector: Option<String>,
    #[serde(default)]
    spin: f64,
}

fn required<T>(value: Option<T>, file: &str, field: &str) -> Result<T, ModelError> {
    value.ok_or_else(|| ModelError::new(file, field, Problem::Missing))
}

impl Morphology {
    /// Parses and validates a morphology. `file` names the file in errors.
    pub fn parse(file: &str, text: &str, library: &ModuleLibrary) -> Result<Self, ModelError> {
        let raw: RawMorphology = toml::from_str(text).map_err(|e| {
            let mut err = from_toml(file, e.clone());
            // Point unknown or missing fields at the module entry they sit in.
            if let (Some(span), false) = (e.span(), matches!(err.problem, Problem::Syntax(_))) {
                if let Some(i) = module_index_at(text, span.start) {
                    err.field = format!("module[{i}].{}", err.field);
                }
            }
            err
        })?;
        let name = required(raw.name, file, "name")?;
        if name.trim().is_empty() || name.contains(['/', ' ']) {
            return Err(ModelError::new(
                file,
                "name",
                Problem::BadValue(format!(
                    "`{name}` is not a valid robot name (non-empty, no `/` or spaces)"
                )),
            ));
        }
        let description = raw.description.unwrap_or_default();
        let physics = raw.physics.validate(file)?;
        let raw_modules = required(raw.module, file, "module")?;
        if raw_modules.is_empty() {
            return Err(ModelError::new(
                file,
                "module",
                Problem::BadValue("a morphology needs at least one module".into()),
            ));
        }

        let mut modules = Vec::with_capacity(raw_modules.len());
        let mut names = HashSet::new();
        for (i, m) in raw_modules.into_iter().enumerate() {
            let at = |f: &str| format!("module[{i}].{f}");
            let mname = required(m.name, file, &at("name"))?;
            if mname.is_empty() || mname.contains(['/', ' ']) {
                return Err(ModelError::new(
                    file,
                    at("name"),
                    Problem::BadValue(format!(
                        "`{mname}` is not a valid module name (non-empty, no `/` or spaces)"
                    )),
                ));
            }
            if !names.insert(mname.clone()) {
                return Err(ModelError::new(
                    file,
                    at("name"),
                    Problem::Duplicate { name: mname },
                ));
            }
            let kind = required(m.kind, file, &at("kind"))?;
            let module = library.get(&kind).ok_or_else(|| {
                ModelError::new(
                    file,
                    at("kind"),
                    Problem::UnknownModule {
                        kind: kind.clone(),
                        known: library.kinds(),
                    },
                )
            })?;
            let role_name = required(m.role, file, &at("role"))?;
            let role = Role::parse(&role_name)
                .filter(|r| module.roles.iter().any(|a| a == r.as_str()))
                .ok_or_else(|| {
                    ModelError::new(
                        file,
                        at("role"),
                        Problem::UnknownRole {
                            role: role_name.clone(),
                            allowed: module.roles.clone(),
                        },
                    )
                })?;
            for (k, opt) in m.options.iter().enumerate() {
                if !module.options.iter().any(|o| &o.name == opt) {
                    let known: Vec<_> = module.options.iter().map(|o| o.name.as_str()).collect();
                    return Err(ModelError::new(
                        file,
                        at(&format!("options[{k}]")),
                        Problem::BadValue(format!(
                            "module kind `{kind}` has no option `{opt}` (options: {})",
                            if known.is_empty() {
                                "none".to_string()
                            } else {
                                known.join(", ")
                            }
                        )),
                    ));
                }
            }
            let dofs = module.position_dofs();
            let home = m.home.unwrap_or_else(|| vec![0.0; dofs]);
            if home.len() != dofs {
                return Err(ModelError::new(
                    file,
                    at("home"),
                    Problem::BadValue(format!(
                        "expected {dofs} joint positions for a `{kind}` module, got {}",
                        home.len()
                    )),
                ));
            }
            let position_actuators = module
                .actuators
                .iter()
                .filter(|a| a.mode == crate::ActuatorMode::Position);
            for (q, a) in home.iter().zip(position_actuators) {
                if !q.is_finite() || *q < a.lower || *q > a.upper {
                    return Err(ModelError::new(
                        file,
                        at("home"),
                        Problem::BadValue(format!(
                            "{} = {q} rad is outside its range [{}, {}]",
                            a.joint, a.lower, a.upper
                        )),
                    ));
                }
            }
            let effort_scale = m.effort_scale.unwrap_or(1.0);
            if !(effort_scale.is_finite() && (0.1..=10.0).contains(&effort_scale)) {
                return Err(ModelError::new(
                    file,
                    at("effort_scale"),
                    Problem::BadValue(format!(
                        "{effort_scale} is not a torque-limit factor in [0.1, 10]"
                    )),
                ));
            }
            let mount = match m.mount {
                None => None,
                Some(raw_mount) => {
                    let parent = required(raw_mount.parent, file, &at("mount.parent"))?;
                    let connector = required(raw_mount.connector, file, &at("mount.connector"))?;
                    let child_connector = raw_mount
                        .child_connector
                        .unwrap_or_else(|| module.default_mount.clone());
                    if module.connector(&child_connector).is_none() {
                        return Err(ModelError::new(
                            file,
                            at("mount.child_connector"),
                            Problem::BadMount(format!(
                                "module kind `{kind}` has no connector `{child_connector}`"
                            )),
                        ));
                    }
                    // A spin is an angle: two turns either way is more than any mount needs, and
                    // 1e308 rad gave NaN poses in the assembled model (found by fuzzing).
                    if raw_mount.spin.is_nan() || raw_mount.spin.abs() > 4.0 * std::f64::consts::PI
                    {
                        return Err(ModelError::new(
                            file,
                            at("mount.spin"),
                            Problem::BadValue(
                                "spin must be a finite angle within +-4 pi [rad]".into(),
                            ),
                        ));
                    }
                    Some(Mount {
                        parent,
                        connector,
                        child_connector,
                        spin: raw_mount.spin,
                    })
                }
            };
            modules.push(MorphologyModule {
                name: mname,
                kind,
                role,
                mount,
                home,
                options: m.options,
                effort_scale,
                follow_steering: m.follow_steering,
            });
        }
        validate_tree(file, &modules, library)?;
        validate_steering(file, &modules, library)?;
        Ok(Self {
            name,
            description,
            fixed_base: raw.fixed_base,
            modules: order_parents_first(modules),
            physics,
        })
    }

    /// The root module (the robot's base).
    pub fn root(&self) -> &MorphologyModule {
        &self.modules[0]
    }
}

/// Checks each module that follows its steering: a mounted module with wheels, hanging from a
/// module with joints to steer it; the gain itself comes from the geometry at assembly.
fn validate_steering(
    file: &str,
    modules: &[MorphologyModule],
    library: &ModuleLibrary,
) -> Result<(), ModelError> {
    for (i, m) in modules
        .iter()
        .enumerate()
        .filter(|(_, m)| m.follow_steering)
    {
        let bad = |message: String| {
            ModelError::new(
                file,
                format!("module[{i}].follow_steering"),
                Problem::BadValue(message),
            )
        };
        let wheels = library.get(&m.kind).is_some_and(|k| {
            k.actuators
                .iter()
                .any(|a| a.mode == crate::ActuatorMode::Velocity)
        });
        let Some(mount) = m.mount.as_ref().filter(|_| wheels) else {
            return Err(bad(format!(
                "only a mounted module with wheels can follow its steering; `{}` is a {} `{}` \
                 module",
                m.name,
                if m.mount.is_none() {
                    "root"
                } else {
                    "wheel-less"
                },
                m.kind
            )));
        };
        let parent = modules
            .iter()
            .find(|p| p.name == mount.parent)
            .and_then(|p| library.get(&p.kind));
        if parent.is_some_and(|p| p.position_dofs() == 0) {
            return Err(bad(format!(
                "`{}` hangs from `{}`, which has no joint to steer it",
                m.name, mount.parent
            )));
        }
    }
    Ok(())
}

/// Checks that mounts form one tree: one root, known parents, free connectors on the parent,
/// a child connector on the child's root link, no cycles.
fn validate_tree(
    file: &str,
    modules: &[MorphologyModule],
    library: &ModuleLibrary,
) -> Result<(), ModelError> {
    let roots: Vec<_> = modules.iter().filter(|m| m.mount.is_none()).collect();
    if roots.len() != 1 {
        let names: Vec<_> = roots.iter().map(|m| m.name.as_str()).collect();
        return Err(ModelError::new(
            file,
            "module",
            Problem::BadMount(format!(
                "exactly one module must have no `mount` (the base); found {}: [{}]",
                roots.len(),
                names.join(", ")
            )),
        ));
    }
    let mut used: HashSet<(String, String)> = HashSet::new();
    for (i, m) in modules.iter().enumerate() {
        let Some(mount) = &m.mount else { continue };
        let at = |f: &str| format!("module[{i}].mount.{f}");
        let parent = modules
            .iter()
            .find(|p| p.name == mount.parent)
            .ok_or_else(|| {
                ModelError::new(
                    file,
                    at("parent"),
                    Problem::BadMount(format!("no module named `{}`", mount.parent)),
                )
            })?;
        if parent.name == m.name {
            return Err(ModelError::new(
                file,
                at("parent"),
                Problem::BadMount("a module cannot be mounted on itself".into()),
            ));
        }
        let parent_module = library.get(&parent.kind).expect("validated above");
        if parent_module.connector(&mount.connector).is_none() {
            let known: Vec<_> = parent_module
                .connectors
                .iter()
                .map(|c| c.name.as_str())
                .collect();
            return Err(ModelError::new(
                file,
                at("connector"),
                Problem::BadMount(format!(
                    "module `{}` ({}) has no connector `{}` (connectors: {})",
                    parent.name,
                    parent.kind,
                    mount.connector,
                    known.join(", ")
                )),
            ));
        }
        let parent_mounted_by = parent.mount.as_ref().map(|pm| pm.child_connector.as_str());
        if parent_mounted_by == Some(mount.connector.as_str())
            || !used.insert((parent.name.clone(), mount.connector.clone()))
        {
            return Err(ModelError::new(
                file,
                at("connector"),
                Problem::BadMount(format!(
                    "connector `{}` of `{}` is already in use",
                    mount.connector, parent.name
                )),
            ));
        }
        let child_module = library.get(&m.kind).expect("validated above");
        let child_conn = child_module
            .connector(&mount.child_connector)
            .expect("validated above");
        if child_conn.link != child_module.root_link {
            return Err(ModelError::new(
                file,
                at("child_connector"),
                Problem::BadMount(format!(
                    "connector `{}` sits on link `{}`, but a module can only be mounted by a connector on its root link `{}`",
                    mount.child_connector, child_conn.link, child_module.root_link
                )),
            ));
        }
    }
    // Every module must reach the root by following parents (no cycles).
    for (i, m) in modules.iter().enumerate() {
        let mut current = m;
        for _ in 0..=modules.len() {
            match &current.mount {
                None => break,
                Some(mount) => {
                    current = modules
                        .iter()
                        .find(|p| p.name == mount.parent)
                        .expect("checked");
                }
            }
        }
        if current.mount.is_some() {
            return Err(ModelError::new(
                file,
                format!("module[{i}].mount.parent"),
                Problem::BadMount(format!("module `{}` is part of a mounting cycle", m.name)),
            ));
        }
    }
    Ok(())
}

/// Sorts modules so that each parent comes before its children (stable otherwise).
fn order_parents_first(mut modules: Vec<MorphologyModule>) -> Vec<MorphologyModule> {
    let mut ordered: Vec<MorphologyModule> = Vec::with_capacity(modules.len());
    while !modules.is_empty() {
        let next = modules
            .iter()
            .position(|m| match &m.mount {
                None => true,
                Some(mount) => ordered.iter().any(|o| o.name == mount.parent),
            })
            .expect("tree validated: some module always has its parent placed");
        ordered.push(modules.remove(next));
    }
    ordered
}

/// The index of the `[[module]]` table that contains byte `offset` of `text`, if any.
fn module_index_at(text: &str, offset: usize) -> Option<usize> {
    let before = &text[..offset.min(text.len())];
    let count = before
        .lines()
        .filter(|l| l.trim_start().starts_with("[[module]]"))
        .count();
    count.checked_sub(1)
}
