//! URDF import: a robot description (XML) read into a scene file's text,
//! which the normal pipeline then loads like any other scene. Nothing of
//! the input becomes code: names are checked and rewritten as identifiers,
//! every number is parsed and written back as a number.
//!
//! The kinematic tree becomes frames named after the links: a link's frame
//! is its parent link's frame moved by the joint's `<origin>` (translation
//! `xyz`, then the rotations `Rz(yaw) Ry(pitch) Rx(roll)` of `rpy`) and by
//! the joint's motion about or along its `<axis>` (a prismatic joint gets a
//! frame of its own, named after the joint, for its origin). Revolute,
//! continuous and prismatic joints become coordinates and actuators named
//! after the joints, with `range` from `<limit lower upper>` (revolute and
//! prismatic), `velocity_range` from `<limit velocity>` and a `damper`
//! from `<dynamics damping>`; `mimic` joints become independent coordinates
//! (as in Pinocchio's URDF parser). A fixed joint (or a joint listed in
//! [`UrdfOptions::fix`], held at zero) makes its child part of its parent's
//! body: each body (the links joined by fixed joints) gets one `rigid_body`,
//! its links' inertias combined exactly (masses and first moments summed,
//! the tensors rotated into the body's frame and moved to the common centre
//! of mass by the parallel-axis rule). A body with a single massive link
//! keeps the link's inertial as written (`inertia_rpy` for its orientation).
//! Links rigidly attached to the root move with the world and carry no
//! energy. Gravity is `[0, 0, -9.81]`. Floating and planar joints are
//! refused.

mod read;
mod tree;
mod write;

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Source};
use crate::inertia::Unphysical;
use read::read_robot;
use tree::Tree;
use write::write_scene;

/// Options of the import.
#[derive(Debug, Clone, Default)]
pub struct UrdfOptions {
    /// Joints (URDF names) held fixed at zero: their child links are merged
    /// into the parent's body, as with a fixed joint.
    pub fix: Vec<String>,
    /// Keep every angle as written: by default an `rpy` angle that agrees
    /// with a multiple of `pi/12` to within one unit of its last written
    /// digit (and at most [`SNAP_LIMIT`] rad), or to within [`SNAP_NOISE`],
    /// is taken to be that multiple, and an axis component or origin
    /// coordinate within [`SNAP_NOISE`] of zero relative to its vector is
    /// zero (`read::snap_noise`); with this set, all are kept as written.
    pub keep_angles: bool,
    /// Optional outputs the scene asks for (its `outputs` list: names of
    /// [`crate::model::OUTPUTS`]).
    pub outputs: Vec<String>,
}

/// The largest change of an angle that snapping makes, rad (about two
/// seconds of arc): an angle written as `1.5708` (3.7e-6 from `pi/2`) is
/// snapped, `1.57` (8e-4) is kept as written.
pub const SNAP_LIMIT: f64 = 1e-5;

/// How close to a multiple of `pi/12` an angle is snapped whatever its
/// written digits, rad: `-1.67685e-15` and `2.78e-29`, rounding noise that
/// CAD exporters write, are zero; `-1.86264e-08` is kept.
pub const SNAP_NOISE: f64 = 1e-12;

/// Largest magnitude accepted for a length, mass, inertia, angle or rate.
const ABSURD: f64 = 1e9;
/// Most links (and joints) of a robot.
const MAX_LINKS: usize = 1000;

/// The joint kinds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
}

/// A pose `x -> R x + p`.
#[derive(Debug, Clone, Copy)]
struct Pose {
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
}

/// An `<origin>` as read: `rpy` after snapping ([`read::snap_angle`]),
/// `snapped` the change of each angle (zero where it was kept); `xyz` with
/// its round-off of zero taken as zero ([`read::snap_noise`]), `zeroed` how
/// many coordinates that was.
#[derive(Debug, Clone, Copy, Default)]
struct Origin {
    xyz: [f64; 3],
    rpy: [f64; 3],
    snapped: [f64; 3],
    zeroed: usize,
}

#[derive(Debug, Clone)]
struct Inertial {
    origin: Origin,
    mass: f64,
    /// `[ixx, ixy, ixz, iyy, iyz, izz]`.
    inertia: [f64; 6],
    /// What is wrong with the tensor, if anything, and where its
    /// `<inertia>` is (a byte offset): an error only where the link's
    /// body carries energy and its inertia (combined with the body's other
    /// links) is not positive semi-definite.
    problem: Option<(usize, Unphysical)>,
}

#[derive(Debug, Clone)]
struct Link {
    name: String,
    inertial: Option<Inertial>,
}

#[derive(Debug, Clone)]
struct Joint {
    name: String,
    kind: Kind,
    parent: usize,
    child: usize,
    origin: Origin,
    axis: [f64; 3],
    /// Components of the written axis taken as zero ([`read::snap_noise`]).
    axis_zeroed: usize,
    limit: Option<[f64; 2]>,
    velocity: Option<f64>,
    damping: f64,
    mimic: Option<String>,
    /// Listed in [`UrdfOptions::fix`].
    held: bool,
}

/// Import the URDF in `source` as the text of a scene file.
pub fn import_urdf(source: &Source, options: &UrdfOptions) -> Result<String, Error> {
    let doc = roxmltree::Document::parse(source.text()).map_err(|e| {
        let pos = e.pos();
        Error {
            file: source.path().to_path_buf(),
            line: pos.row as usize,
            column: pos.col as usize,
            context: None,
            message: format!("malformed XML: {e}"),
        }
    })?;
    let robot = doc.root_element();
    if robot.tag_name().name() != "robot" {
        return Err(at(
            source,
            robot,
            format!(
                "the root element is <{}>, not <robot>",
                robot.tag_name().name()
            ),
        ));
    }
    let (links, joints) = read_robot(source, robot, options)?;
    let tree = Tree::new(source, robot, &links, &joints)?;
    if !tree.order.iter().any(|&j| Tree::moves(&joints, j)) {
        return Err(at(
            source,
            robot,
            "the robot has no moving joint (revolute, continuous or prismatic, not fixed by \
             --fix): a scene needs at least one coordinate",
        ));
    }
    write_scene(source, robot, &links, &joints, &tree, &options.outputs)
}

fn at(source: &Source, node: roxmltree::Node, message: impl Into<String>) -> Error {
    source.error_at(node.range().start, None, message)
}
