//! The kinematic tree, poses, and the combined inertia of the links joined
//! by fixed joints.

use nalgebra::{Matrix3, Vector3};

use super::{at, Inertial, Joint, Kind, Link, Origin, Pose};
use crate::error::{Error, Source};
use crate::expr::exact;

pub(super) fn tensor(i: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(i[0], i[1], i[2], i[1], i[3], i[4], i[2], i[4], i[5])
}

/// The links' tree: the root, each link's parent joint, and the joints in
/// depth-first order from the root (children in file order).
pub(super) struct Tree {
    pub(super) root: usize,
    parent_joint: Vec<Option<usize>>,
    pub(super) order: Vec<usize>,
}

impl Tree {
    pub(super) fn new(
        source: &Source,
        robot: roxmltree::Node,
        links: &[Link],
        joints: &[Joint],
    ) -> Result<Tree, Error> {
        if links.is_empty() {
            return Err(at(source, robot, "the robot has no <link>"));
        }
        let mut parent_joint: Vec<Option<usize>> = vec![None; links.len()];
        for (j, joint) in joints.iter().enumerate() {
            if let Some(other) = parent_joint[joint.child] {
                return Err(source.error(format!(
                    "link `{}` is the child of two joints, `{}` and `{}` (a URDF is a tree)",
                    links[joint.child].name, joints[other].name, joint.name
                )));
            }
            parent_joint[joint.child] = Some(j);
        }
        let roots: Vec<usize> = (0..links.len())
            .filter(|&l| parent_joint[l].is_none())
            .collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => return Err(source.error("the joints form a cycle: every link has a parent")),
            many => {
                let names: Vec<&str> = many.iter().map(|&l| links[l].name.as_str()).collect();
                return Err(source.error(format!(
                    "the robot has {} root links ({}): links must form one tree",
                    many.len(),
                    names.join(", ")
                )));
            }
        };
        let mut order = Vec::with_capacity(joints.len());
        let mut stack = vec![root];
        while let Some(l) = stack.pop() {
            let children: Vec<usize> = (0..joints.len())
                .filter(|&j| joints[j].parent == l)
                .collect();
            for &j in children.iter().rev() {
                stack.push(joints[j].child);
            }
            if let Some(j) = parent_joint[l] {
                order.push(j);
            }
        }
        if order.len() != joints.len() {
            let stray = joints
                .iter()
                .enumerate()
                .find(|(j, _)| !order.contains(j))
                .map(|(_, joint)| joint.name.as_str())
                .unwrap_or_default();
            return Err(source.error(format!(
                "joint `{stray}` is on a cycle of joints, not connected to the root link `{}`",
                links[root].name
            )));
        }
        Ok(Tree {
            root,
            parent_joint,
            order,
        })
    }

    /// Whether joint `j` moves (not fixed, not held).
    pub(super) fn moves(joints: &[Joint], j: usize) -> bool {
        joints[j].kind != Kind::Fixed && !joints[j].held
    }

    /// The link whose frame is the body frame of link `l`: the child of the
    /// nearest moving joint above it (`None`: the body is the world).
    pub(super) fn body_of(&self, joints: &[Joint], mut l: usize) -> Option<usize> {
        loop {
            let j = self.parent_joint[l]?;
            if Tree::moves(joints, j) {
                return Some(l);
            }
            l = joints[j].parent;
        }
    }
}

/// `R = Rz(yaw) Ry(pitch) Rx(roll)`, sines and cosines folded exactly at
/// multiples of `pi/12` like the scene's rotations.
fn rpy_matrix(rpy: [f64; 3]) -> Matrix3<f64> {
    let (sr, cr) = exact::sin_cos(rpy[0]);
    let (sp, cp) = exact::sin_cos(rpy[1]);
    let (sy, cy) = exact::sin_cos(rpy[2]);
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cr, -sr, 0.0, sr, cr);
    let ry = Matrix3::new(cp, 0.0, sp, 0.0, 1.0, 0.0, -sp, 0.0, cp);
    let rz = Matrix3::new(cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0);
    product(&product(&rz, &ry), &rx)
}

/// `A B` with the cancellation rule of [`exact::cancel`] on every entry.
fn product(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| {
        let terms = (0..3).map(|k| a[(i, k)] * b[(k, j)]);
        exact::cancel(terms.clone().sum(), terms.map(f64::abs).sum())
    })
}

/// `A v` with the cancellation rule.
fn apply(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::from_fn(|i, _| {
        let terms = (0..3).map(|k| a[(i, k)] * v[k]);
        exact::cancel(terms.clone().sum(), terms.map(f64::abs).sum())
    })
}

impl Pose {
    pub(super) fn identity() -> Pose {
        Pose {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    pub(super) fn of(o: &Origin) -> Pose {
        Pose {
            rotation: rpy_matrix(o.rpy),
            translation: Vector3::from(o.xyz),
        }
    }

    /// `self` then `next` (next given in self's axes).
    pub(super) fn then(&self, next: &Pose) -> Pose {
        let moved = apply(&self.rotation, &next.translation);
        Pose {
            rotation: product(&self.rotation, &next.rotation),
            translation: Vector3::from_fn(|i, _| {
                exact::cancel(
                    self.translation[i] + moved[i],
                    self.translation[i].abs() + moved[i].abs(),
                )
            }),
        }
    }
}

/// A body's inertia in its frame: mass, centre of mass, tensor about it.
pub(super) struct BodyInertia {
    pub(super) mass: f64,
    pub(super) com: Vector3<f64>,
    pub(super) tensor: Matrix3<f64>,
}

/// The combined inertia of `parts` (pose of the link in the body frame,
/// the link's inertial).
pub(super) fn combine(parts: &[(Pose, &Inertial)]) -> BodyInertia {
    let mass: f64 = parts.iter().map(|(_, i)| i.mass).sum();
    let placed: Vec<(f64, Vector3<f64>, Matrix3<f64>)> = parts
        .iter()
        .map(|(pose, i)| {
            let frame = pose.then(&Pose::of(&i.origin));
            let r = frame.rotation;
            let t = product(&product(&r, &tensor(&i.inertia)), &r.transpose());
            (i.mass, frame.translation, t)
        })
        .collect();
    let com = if mass > 0.0 {
        placed.iter().map(|(m, c, _)| c * *m).sum::<Vector3<f64>>() / mass
    } else {
        Vector3::zeros()
    };
    let mut tensor = Matrix3::zeros();
    for (m, c, t) in &placed {
        let d = c - com;
        // Parallel axes: I + m (|d|^2 E - d d^T).
        let shift = (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * *m;
        tensor += t + shift;
    }
    let scale = tensor.abs().max();
    let tensor = Matrix3::from_fn(|i, j| {
        // Symmetric by construction; drop round-off of zeros.
        let v = 0.5 * (tensor[(i, j)] + tensor[(j, i)]);
        exact::cancel(v, scale)
    });
    BodyInertia { mass, com, tensor }
}
