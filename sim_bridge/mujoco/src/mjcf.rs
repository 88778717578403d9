//! The MuJoCo model of a kumi robot, generated from `kumi-model` (MJCF text): every mass,
//! inertia, joint range, damping, armature, friction and contact rule is read from the model
//! and [`SimConfig`], none is written here a second time.
//!
//! Pure Rust, so it is tested without libmujoco. Choices (measured, see README):
//! - one MuJoCo body per URDF link with mass or collision; frame-only links (tool frames `ee`)
//!   are offsets from their body, like rapier's loader folds them;
//! - the `implicitfast` integrator (Euler is unstable with the servos' damping at 1/120 s) and
//!   sparse Jacobians for large robots ([`jacobian`]);
//! - the physics step [`SimConfig::mujoco_dt`];
//! - contact time constant 2 physics steps (MuJoCo's smallest recommended; the default 0.02 s
//!   lets Minimal rock on its skids);
//! - friction: a contact uses the smaller coefficient, as in rapier (`Min` rule), through
//!   geom priorities: lower friction wins;
//! - links of one rapier multibody never touch ([`contact_groups`]), through `<exclude>` pairs.

use std::collections::BTreeSet;
use std::fmt::Write;

use kumi_engine::{contact_groups, Engine, SimConfig, SimError};
use kumi_model::kinematics::{JointKind, KinematicTree};
use kumi_model::RobotModel;
use nalgebra::{Isometry3, Matrix3, UnitQuaternion};

/// Name of the ground plane geom.
pub const GROUND_GEOM: &str = "ground";

/// Where a URDF link lives in the MuJoCo model.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkPlacement {
    /// The MuJoCo body (by name) that carries the link.
    pub body: String,
    /// The link frame in that body's frame (identity unless the link is frame-only).
    pub offset: Isometry3<f64>,
}

/// A generated model: the MJCF text and how URDF links map onto its bodies.
#[derive(Debug, Clone)]
pub struct Mjcf {
    pub xml: String,
    /// One per URDF link, in `tree.links()` order.
    pub links: Vec<LinkPlacement>,
}

/// The MuJoCo body name of a URDF link (MuJoCo names may hold `/`).
fn body_name(link: &str) -> String {
    link.to_string()
}

fn unsupported(model: &RobotModel, link: &str, reason: String) -> SimError {
    let module = model
        .modules
        .iter()
        .find(|m| m.links.iter().any(|l| l == link))
        .map_or_else(|| "(none)".to_string(), |m| m.name.clone());
    SimError::Unsupported {
        engine: Engine::Mujoco,
        robot: model.name.clone(),
        module,
        reason,
    }
}

fn pos_quat(iso: &Isometry3<f64>) -> String {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    format!(
        "pos=\"{} {} {}\" quat=\"{} {} {} {}\"",
        t.x, t.y, t.z, q.w, q.i, q.j, q.k
    )
}

/// Geom priorities that make MuJoCo use the smaller friction of a contact pair (rapier's `Min`
/// rule): MuJoCo takes the parameters of the geom with the higher priority.
fn priority(frictions: &[f64], friction: f64) -> usize {
    frictions.iter().filter(|&&f| f > friction).count()
}

/// Builds the MJCF model of `model` with `config`'s timestep.
pub fn build(model: &RobotModel, config: &SimConfig) -> Result<Mjcf, SimError> {
    let tree = KinematicTree::new(&model.urdf).map_err(|source| SimError::Tree {
        robot: model.name.clone(),
        source,
    })?;
    let urdf_links = &model.urdf.links;
    let link_of = |name: &str| {
        urdf_links
            .iter()
            .find(|l| l.name == name)
            .expect("tree links come from the URDF")
    };

    // Every collision's friction, for the priority ranks.
    let friction_of = |c: &urdf_rs::Collision| {
        c.name
            .as_deref()
            .and_then(|n| model.friction_of(n))
            .unwrap_or(config.default_friction)
    };
    let mut frictions: Vec<f64> = urdf_links
        .iter()
        .flat_map(|l| l.collision.iter().map(friction_of))
        .chain([config.ground_friction])
        .collect();
    frictions.sort_by(f64::total_cmp);
    frictions.dedup();

    // Which links become bodies: those with mass or collision, and any with children (they
    // carry the subtree).
    let n = tree.links().len();
    let mut is_body = vec![false; n];
    for (i, name) in tree.links().iter().enumerate() {
        let l = link_of(name);
        is_body[i] = l.inertial.mass.value > 0.0 || !l.collision.is_empty();
    }
    for j in tree.joints() {
        // A moving joint needs a body on its child side, and the parent of any body is one.
        if j.kind != JointKind::Fixed || is_body[j.child_link] {
            is_body[j.child_link] = true;
        }
    }
    // Parents of bodies must be bodies (walk joints children-last, so repeat to a fixed point).
    loop {
        let mut changed = false;
        for j in tree.joints() {
            if is_body[j.child_link] && !is_body[j.parent_link] {
                is_body[j.parent_link] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    is_body[tree.root()] = true;

    let mut links: Vec<Option<LinkPlacement>> = vec![None; n];
    let root_name = &tree.links()[tree.root()];
    links[tree.root()] = Some(LinkPlacement {
        body: body_name(root_name),
        offset: Isometry3::identity(),
    });
    // Children of each link, in joint order.
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (k, j) in tree.joints().iter().enumerate() {
        children[j.parent_link].push(k);
    }

    let mut body_xml = String::new();
    let root_pose = if model.fixed_base {
        String::new()
    } else {
        // Placed by every reset; start clear of the ground.
        " pos=\"0 0 1\"".to_string()
    };
    writeln!(
        body_xml,
        "    <body name=\"{}\"{root_pose}>",
        body_name(root_name)
    )
    .unwrap();
    if !model.fixed_base {
        writeln!(body_xml, "      <freejoint name=\"root\"/>").unwrap();
    }
    let mut ctx = Ctx {
        model,
        config,
        tree: &tree,
        frictions: &frictions,
        is_body: &is_body,
        children: &children,
        links: &mut links,
        out: &mut body_xml,
    };
    ctx.body_contents(tree.root(), 3)?;
    writeln!(body_xml, "    </body>").unwrap();

    let links: Vec<LinkPlacement> = links
        .into_iter()
        .map(|l| l.expect("every link is reached from the root"))
        .collect();

    // Contact exclusion: bodies of one multibody group never touch (rapier's rule).
    let groups = contact_groups(model, config.layout);
    let colliding: Vec<(usize, &str)> = tree
        .links()
        .iter()
        .enumerate()
        .filter(|(i, name)| is_body[*i] && !link_of(name).collision.is_empty())
        .map(|(i, name)| (i, name.as_str()))
        .collect();
    let group_of = |tree_index: usize| {
        let name = &tree.links()[tree_index];
        groups[urdf_links
            .iter()
            .position(|l| &l.name == name)
            .expect("same URDF")]
    };
    let mut excludes = BTreeSet::new();
    for (a, (ia, na)) in colliding.iter().enumerate() {
        for (ib, nb) in &colliding[a + 1..] {
            if group_of(*ia) == group_of(*ib) {
                excludes.insert((na.to_string(), nb.to_string()));
            }
        }
    }
    let mut contact_xml = String::new();
    for (a, b) in &excludes {
        writeln!(contact_xml, "    <exclude body1=\"{a}\" body2=\"{b}\"/>").unwrap();
    }

    let dt = config.mujoco_dt();
    let ground_priority = priority(&frictions, config.ground_friction);
    let xml = format!(
        r#"<mujoco model="{name}">
  <compiler angle="radian" autolimits="true" inertiafromgeom="false"/>
  <option timestep="{dt}" integrator="implicitfast" jacobian="{jacobian}" gravity="0 0 -9.81"/>
  <default>
    <geom condim="3" solref="{solref} 1"/>
  </default>
  <worldbody>
    <geom name="{GROUND_GEOM}" type="plane" size="0 0 1" friction="{gf} 0 0" priority="{ground_priority}"/>
{body_xml}  </worldbody>
  <contact>
{contact_xml}  </contact>
</mujoco>
"#,
        name = model.name,
        solref = config.mujoco_contact_time_s(),
        gf = config.ground_friction,
        jacobian = jacobian(&tree, model.fixed_base),
    );
    Ok(Mjcf { xml, links })
}

/// Dense Jacobians for small robots, sparse for large ones: measured (control steps/s, one
/// thread) arm 45,700 dense against 35,700 sparse, Dragon (24 dofs) even, Tricycle (40 dofs)
/// 3,290 dense against 3,760 sparse.
fn jacobian(tree: &KinematicTree, fixed_base: bool) -> &'static str {
    let moving = tree
        .joints()
        .iter()
        .filter(|j| j.kind != JointKind::Fixed)
        .count();
    let dofs = moving + if fixed_base { 0 } else { 6 };
    if dofs > 30 {
        "sparse"
    } else {
        "dense"
    }
}

struct Ctx<'a> {
    model: &'a RobotModel,
    config: &'a SimConfig,
    tree: &'a KinematicTree,
    frictions: &'a [f64],
    is_body: &'a [bool],
    children: &'a [Vec<usize>],
    links: &'a mut Vec<Option<LinkPlacement>>,
    out: &'a mut String,
}

impl Ctx<'_> {
    /// Writes link `i`'s inertial and geoms into the current body, then its child links:
    /// children that are bodies nest, frame-only children fold into this body.
    fn body_contents(&mut self, i: usize, depth: usize) -> Result<(), SimError> {
        let body = self.links[i].clone().expect("placed before its contents");
        let name = self.tree.links()[i].clone();
        let link = self
            .model
            .urdf
            .links
            .iter()
            .find(|l| l.name == name)
            .expect("same URDF");
        let pad = "  ".repeat(depth);
        if self.is_body[i] {
            self.inertial(link, &pad);
            self.geoms(link, &pad)?;
        }
        for &k in &self.children[i].clone() {
            let j = &self.tree.joints()[k];
            let child = j.child_link;
            if self.is_body[child] {
                let child_name = self.tree.links()[child].clone();
                self.links[child] = Some(LinkPlacement {
                    body: body_name(&child_name),
                    offset: Isometry3::identity(),
                });
                writeln!(
                    self.out,
                    "{pad}<body name=\"{}\" {}>",
                    body_name(&child_name),
                    pos_quat(&(body.offset * j.origin))
                )
                .unwrap();
                self.joint(k, &format!("{pad}  "))?;
                self.body_contents(child, depth + 1)?;
                writeln!(self.out, "{pad}</body>").unwrap();
            } else {
                self.links[child] = Some(LinkPlacement {
                    body: body.body.clone(),
                    offset: body.offset * j.origin,
                });
                self.body_contents(child, depth)?;
            }
        }
        Ok(())
    }

    fn joint(&mut self, k: usize, pad: &str) -> Result<(), SimError> {
        let j = &self.tree.joints()[k];
        let child = &self.tree.links()[j.child_link];
        match j.kind {
            JointKind::Fixed => return Ok(()),
            JointKind::Prismatic => {
                return Err(unsupported(
                    self.model,
                    child,
                    format!("prismatic joint `{}`: only revolute, continuous and fixed joints are supported", j.name),
                ))
            }
            JointKind::Revolute => {}
        }
        let urdf_joint = self
            .model
            .urdf
            .joints
            .iter()
            .find(|u| u.name == j.name)
            .expect("same URDF");
        let actuator = self.model.actuators().find(|a| a.joint == j.name);
        // Servos: the model's damping, friction, armature and range; passive joints: the URDF's.
        let (damping, friction, armature, lower, upper) = match actuator {
            Some(a) => (
                a.joint_damping,
                a.joint_friction,
                a.armature,
                a.lower,
                a.upper,
            ),
            None => {
                let d = urdf_joint.dynamics.clone().unwrap_or_default();
                let limited = urdf_joint.joint_type == urdf_rs::JointType::Revolute;
                let (lo, hi) = if limited {
                    (urdf_joint.limit.lower, urdf_joint.limit.upper)
                } else {
                    (f64::NEG_INFINITY, f64::INFINITY)
                };
                (d.damping, d.friction, 0.0, lo, hi)
            }
        };
        let axis = j.axis;
        let range = if lower.is_finite() && upper.is_finite() {
            format!(" range=\"{lower} {upper}\"")
        } else {
            String::new()
        };
        writeln!(
            self.out,
            "{pad}<joint name=\"{}\" type=\"hinge\" axis=\"{} {} {}\"{range} damping=\"{damping}\" frictionloss=\"{friction}\" armature=\"{armature}\"/>",
            j.name, axis.x, axis.y, axis.z
        )
        .unwrap();
        Ok(())
    }

    fn inertial(&mut self, link: &urdf_rs::Link, pad: &str) {
        let mass = link.inertial.mass.value;
        if mass <= 0.0 {
            return;
        }
        let origin = kumi_model::pose::from_urdf(&link.inertial.origin);
        let i = &link.inertial.inertia;
        let local = Matrix3::new(
            i.ixx, i.ixy, i.ixz, //
            i.ixy, i.iyy, i.iyz, //
            i.ixz, i.iyz, i.izz,
        );
        // The URDF inertia is in the inertial frame; MuJoCo's fullinertia in the body frame.
        let r = origin.rotation.to_rotation_matrix();
        let body = r.matrix() * local * r.matrix().transpose();
        let t = origin.translation.vector;
        writeln!(
            self.out,
            "{pad}<inertial pos=\"{} {} {}\" mass=\"{mass}\" fullinertia=\"{} {} {} {} {} {}\"/>",
            t.x,
            t.y,
            t.z,
            body[(0, 0)],
            body[(1, 1)],
            body[(2, 2)],
            body[(0, 1)],
            body[(0, 2)],
            body[(1, 2)]
        )
        .unwrap();
    }

    fn geoms(&mut self, link: &urdf_rs::Link, pad: &str) -> Result<(), SimError> {
        for c in &link.collision {
            let shape = match &c.geometry {
                urdf_rs::Geometry::Box { size } => format!(
                    "type=\"box\" size=\"{} {} {}\"",
                    size[0] / 2.0,
                    size[1] / 2.0,
                    size[2] / 2.0
                ),
                urdf_rs::Geometry::Cylinder { radius, length } => {
                    format!("type=\"cylinder\" size=\"{radius} {}\"", length / 2.0)
                }
                urdf_rs::Geometry::Sphere { radius } => {
                    format!("type=\"sphere\" size=\"{radius}\"")
                }
                other => {
                    return Err(unsupported(
                        self.model,
                        &link.name,
                        format!(
                            "collision geometry {other:?} of link `{}`: only boxes, cylinders and spheres are supported",
                            link.name
                        ),
                    ))
                }
            };
            let friction = c
                .name
                .as_deref()
                .and_then(|n| self.model.friction_of(n))
                .unwrap_or(self.config.default_friction);
            let origin = kumi_model::pose::from_urdf(&c.origin);
            writeln!(
                self.out,
                "{pad}<geom {shape} {} friction=\"{friction} 0 0\" priority=\"{}\"/>",
                pos_quat(&origin),
                priority(self.frictions, friction)
            )
            .unwrap();
        }
        Ok(())
    }
}

/// Unit quaternion from MuJoCo's `[w, x, y, z]`.
pub fn quat_wxyz(q: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}
