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

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write;

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Source};
use crate::expr::exact;
use crate::inertia::inertia_problem;
use crate::load::parse::RESERVED;

/// Options of the import.
#[derive(Debug, Clone, Default)]
pub struct UrdfOptions {
    /// Joints (URDF names) held fixed at zero: their child links are merged
    /// into the parent's body, as with a fixed joint.
    pub fix: Vec<String>,
}

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

/// An `<origin>` as written.
#[derive(Debug, Clone, Copy, Default)]
struct Origin {
    xyz: [f64; 3],
    rpy: [f64; 3],
}

#[derive(Debug, Clone)]
struct Inertial {
    origin: Origin,
    mass: f64,
    /// `[ixx, ixy, ixz, iyy, iyz, izz]`.
    inertia: [f64; 6],
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
    Ok(write_scene(source, robot, &links, &joints, &tree))
}

fn at(source: &Source, node: roxmltree::Node, message: impl Into<String>) -> Error {
    source.error_at(node.range().start, None, message)
}

/// A required attribute.
fn attribute<'a>(
    source: &Source,
    node: roxmltree::Node<'a, '_>,
    name: &str,
) -> Result<&'a str, Error> {
    node.attribute(name).ok_or_else(|| {
        at(
            source,
            node,
            format!("<{}> needs the attribute `{name}`", node.tag_name().name()),
        )
    })
}

/// Numbers separated by white space, `n` of them, finite and at most
/// `ABSURD` in magnitude.
fn numbers<const N: usize>(
    source: &Source,
    node: roxmltree::Node,
    name: &str,
    text: &str,
) -> Result<[f64; N], Error> {
    let bad = |why: &str| {
        at(
            source,
            node,
            format!(
                "<{}> attribute `{name}` = \"{text}\": {why}",
                node.tag_name().name()
            ),
        )
    };
    let values: Vec<f64> = text
        .split_whitespace()
        .map(|w| w.parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad(&format!("expected {N} number(s)")))?;
    let values: [f64; N] = values
        .try_into()
        .map_err(|_| bad(&format!("expected {N} number(s)")))?;
    if values.iter().any(|v| !v.is_finite() || v.abs() > ABSURD) {
        return Err(bad(&format!(
            "numbers must be finite and at most {ABSURD:e} in magnitude"
        )));
    }
    Ok(values)
}

fn number(source: &Source, node: roxmltree::Node, name: &str) -> Result<f64, Error> {
    let text = attribute(source, node, name)?;
    Ok(numbers::<1>(source, node, name, text)?[0])
}

fn optional_number(
    source: &Source,
    node: roxmltree::Node,
    name: &str,
) -> Result<Option<f64>, Error> {
    node.attribute(name)
        .map(|t| numbers::<1>(source, node, name, t).map(|v| v[0]))
        .transpose()
}

fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

fn origin(source: &Source, parent: roxmltree::Node) -> Result<Origin, Error> {
    let Some(o) = child(parent, "origin") else {
        return Ok(Origin::default());
    };
    let read = |name: &str| match o.attribute(name) {
        Some(t) => numbers::<3>(source, o, name, t),
        None => Ok([0.0; 3]),
    };
    Ok(Origin {
        xyz: read("xyz")?,
        rpy: read("rpy")?,
    })
}

fn read_robot(
    source: &Source,
    robot: roxmltree::Node,
    options: &UrdfOptions,
) -> Result<(Vec<Link>, Vec<Joint>), Error> {
    let mut links: Vec<Link> = Vec::new();
    let mut link_index: BTreeMap<String, usize> = BTreeMap::new();
    for node in robot.children().filter(|n| n.has_tag_name("link")) {
        let name = attribute(source, node, "name")?.to_owned();
        if link_index.insert(name.clone(), links.len()).is_some() {
            return Err(at(source, node, format!("link `{name}` is defined twice")));
        }
        if links.len() == MAX_LINKS {
            return Err(at(source, node, format!("more than {MAX_LINKS} links")));
        }
        let inertial = child(node, "inertial")
            .map(|i| read_inertial(source, i, &name))
            .transpose()?;
        links.push(Link { name, inertial });
    }
    let mut joints: Vec<Joint> = Vec::new();
    let mut joint_names: BTreeSet<String> = BTreeSet::new();
    for node in robot.children().filter(|n| n.has_tag_name("joint")) {
        let name = attribute(source, node, "name")?.to_owned();
        if !joint_names.insert(name.clone()) {
            return Err(at(source, node, format!("joint `{name}` is defined twice")));
        }
        let ctx = format!("joint `{name}`");
        let kind = match attribute(source, node, "type")? {
            "revolute" => Kind::Revolute,
            "continuous" => Kind::Continuous,
            "prismatic" => Kind::Prismatic,
            "fixed" => Kind::Fixed,
            other @ ("floating" | "planar") => {
                return Err(at(
                    source,
                    node,
                    format!(
                        "{ctx}: {other} joints are not supported (only revolute, continuous, \
                         prismatic and fixed)"
                    ),
                ))
            }
            other => {
                return Err(at(
                    source,
                    node,
                    format!(
                        "{ctx}: unknown joint type `{other}` (known: revolute, continuous, \
                         prismatic, fixed)"
                    ),
                ))
            }
        };
        let end = |tag: &str| -> Result<usize, Error> {
            let e = child(node, tag)
                .ok_or_else(|| at(source, node, format!("{ctx} has no <{tag}>")))?;
            let link = attribute(source, e, "link")?;
            link_index.get(link).copied().ok_or_else(|| {
                at(
                    source,
                    e,
                    format!("{ctx}: {tag} link `{link}` is not defined"),
                )
            })
        };
        let (parent, child_link) = (end("parent")?, end("child")?);
        if parent == child_link {
            return Err(at(
                source,
                node,
                format!("{ctx} joins link `{}` to itself", links[parent].name),
            ));
        }
        // A fixed joint's axis is not used (URDF files leave it zero).
        let axis = match child(node, "axis").filter(|_| kind != Kind::Fixed) {
            Some(a) => {
                let v = numbers::<3>(source, a, "xyz", attribute(source, a, "xyz")?)?;
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                if n < 1e-12 {
                    return Err(at(source, a, format!("{ctx}: the axis is zero")));
                }
                if (n - 1.0).abs() < 1e-15 {
                    v
                } else {
                    v.map(|x| x / n)
                }
            }
            None => [1.0, 0.0, 0.0],
        };
        let (mut limit, mut velocity) = (None, None);
        if let Some(l) = child(node, "limit") {
            let lower = optional_number(source, l, "lower")?;
            let upper = optional_number(source, l, "upper")?;
            if let (Some(lo), Some(hi)) = (lower, upper) {
                if lo > hi {
                    return Err(at(
                        source,
                        l,
                        format!("{ctx}: lower limit {lo} is above the upper limit {hi}"),
                    ));
                }
                limit = (lo < hi).then_some([lo, hi]);
            }
            velocity = optional_number(source, l, "velocity")?.filter(|&v| v > 0.0);
        }
        let damping = match child(node, "dynamics") {
            Some(d) => optional_number(source, d, "damping")?.unwrap_or(0.0),
            None => 0.0,
        };
        if damping < 0.0 {
            return Err(at(
                source,
                node,
                format!("{ctx}: negative damping {damping}"),
            ));
        }
        let mimic = match child(node, "mimic") {
            Some(m) => Some(attribute(source, m, "joint")?.to_owned()),
            None => None,
        };
        joints.push(Joint {
            held: options.fix.contains(&name),
            name,
            kind,
            parent,
            child: child_link,
            origin: origin(source, node)?,
            axis,
            limit,
            velocity,
            damping,
            mimic,
        });
    }
    if let Some(missing) = options.fix.iter().find(|f| !joint_names.contains(*f)) {
        return Err(source.error(format!(
            "joint `{missing}` to hold fixed is not in the URDF"
        )));
    }
    Ok((links, joints))
}

fn read_inertial(source: &Source, node: roxmltree::Node, link: &str) -> Result<Inertial, Error> {
    let ctx = format!("link `{link}`");
    let m = child(node, "mass")
        .ok_or_else(|| at(source, node, format!("{ctx}: <inertial> has no <mass>")))?;
    let mass = number(source, m, "value")?;
    if mass < 0.0 {
        return Err(at(source, m, format!("{ctx}: negative mass {mass}")));
    }
    let i = child(node, "inertia")
        .ok_or_else(|| at(source, node, format!("{ctx}: <inertial> has no <inertia>")))?;
    let mut inertia = [0.0; 6];
    for (k, name) in ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]
        .iter()
        .enumerate()
    {
        inertia[k] = number(source, i, name)?;
    }
    if let Some(problem) = inertia_problem(&tensor(&inertia)) {
        return Err(at(source, i, format!("{ctx}: {problem}")));
    }
    Ok(Inertial {
        origin: origin(source, node)?,
        mass,
        inertia,
    })
}

fn tensor(i: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(i[0], i[1], i[2], i[1], i[3], i[4], i[2], i[4], i[5])
}

/// The links' tree: the root, each link's parent joint, and the joints in
/// depth-first order from the root (children in file order).
struct Tree {
    root: usize,
    parent_joint: Vec<Option<usize>>,
    order: Vec<usize>,
}

impl Tree {
    fn new(
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

    /// The frame a joint below link `l` hangs from (`None`: the world).
    fn parent_frame(&self, l: usize, names: &Names) -> Option<String> {
        (l != self.root).then(|| names.link[l].clone())
    }

    /// Whether joint `j` moves (not fixed, not held).
    fn moves(joints: &[Joint], j: usize) -> bool {
        joints[j].kind != Kind::Fixed && !joints[j].held
    }

    /// The link whose frame is the body frame of link `l`: the child of the
    /// nearest moving joint above it (`None`: the body is the world).
    fn body_of(&self, joints: &[Joint], mut l: usize) -> Option<usize> {
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
    fn identity() -> Pose {
        Pose {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
        }
    }

    fn of(o: &Origin) -> Pose {
        Pose {
            rotation: rpy_matrix(o.rpy),
            translation: Vector3::from(o.xyz),
        }
    }

    /// `self` then `next` (next given in self's axes).
    fn then(&self, next: &Pose) -> Pose {
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
struct BodyInertia {
    mass: f64,
    com: Vector3<f64>,
    tensor: Matrix3<f64>,
}

/// The combined inertia of `parts` (pose of the link in the body frame,
/// the link's inertial).
fn combine(parts: &[(Pose, &Inertial)]) -> BodyInertia {
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

/// A scene identifier from a URDF name: letters, digits and `_` (others
/// become `_`), starting with a letter (else `j_`/`l_` is put first), not a
/// reserved word (else `_` is appended), unique (else `_2`, `_3`, ...).
fn identifier(name: &str, prefix: &str, taken: &mut BTreeSet<String>) -> String {
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic()) {
        s = format!("{prefix}_{s}");
    }
    s.truncate(56);
    if RESERVED.contains(&s.as_str()) || s == "world" || super::RUST_KEYWORDS.contains(&s.as_str())
    {
        s.push('_');
    }
    let mut unique = s.clone();
    let mut k = 2;
    while taken.contains(&unique) {
        unique = format!("{s}_{k}");
        k += 1;
    }
    taken.insert(unique.clone());
    unique
}

/// A number as TOML (shortest round-trip form).
fn num(x: f64) -> String {
    let x = if x == 0.0 { 0.0 } else { x };
    format!("{x:?}")
}

fn vector(v: &[f64; 3]) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

/// A TOML basic string (names are identifiers, file names may be anything).
fn quoted(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The rotations of an origin's `rpy`, in scene order (yaw, pitch, roll;
/// zero angles left out).
fn rpy_rotations(rpy: &[f64; 3]) -> Vec<String> {
    [("z", rpy[2]), ("y", rpy[1]), ("x", rpy[0])]
        .iter()
        .filter(|(_, a)| *a != 0.0)
        .map(|(axis, a)| format!("{{ axis = \"{axis}\", angle = {} }}", num(*a)))
        .collect()
}

fn axis_text(a: &[f64; 3]) -> String {
    match a {
        [1.0, 0.0, 0.0] => "\"x\"".into(),
        [0.0, 1.0, 0.0] => "\"y\"".into(),
        [0.0, 0.0, 1.0] => "\"z\"".into(),
        _ => vector(a),
    }
}

/// Scene identifiers of the links (frames) and joints (coordinates).
struct Names {
    link: Vec<String>,
    joint: Vec<String>,
    joint_frame: Vec<String>,
}

fn names(links: &[Link], joints: &[Joint]) -> Names {
    let mut frames = BTreeSet::new();
    let link: Vec<String> = links
        .iter()
        .map(|l| identifier(&l.name, "l", &mut frames))
        .collect();
    let mut coordinates = BTreeSet::new();
    let joint: Vec<String> = joints
        .iter()
        .map(|j| identifier(&j.name, "j", &mut coordinates))
        .collect();
    let joint_frame: Vec<String> = (0..joints.len())
        .map(
            |j| match joints[j].kind == Kind::Prismatic && Tree::moves(joints, j) {
                true => identifier(&joints[j].name, "j", &mut frames),
                false => String::new(),
            },
        )
        .collect();
    Names {
        link,
        joint,
        joint_frame,
    }
}

fn write_scene(
    source: &Source,
    robot: roxmltree::Node,
    links: &[Link],
    joints: &[Joint],
    tree: &Tree,
) -> String {
    let names = names(links, joints);
    let robot_name = robot.attribute("name").unwrap_or("robot");
    let mut taken = BTreeSet::new();
    let mut scene_name = identifier(&robot_name.to_ascii_lowercase(), "robot", &mut taken);
    scene_name.make_ascii_lowercase();
    let file = source
        .path()
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let moving: Vec<usize> = tree
        .order
        .iter()
        .copied()
        .filter(|&j| Tree::moves(joints, j))
        .collect();

    let mut s = String::new();
    let w = &mut s;
    // Names from the input appear in comments only as TOML strings (control
    // characters escaped), so that none can end a comment line.
    let _ = writeln!(
        w,
        "# Imported by `flexdyn import urdf` from {}: robot {}, {} links, {} joints \
         ({} moving).\n# Frames are named after the URDF links (prismatic joints also get a frame \
         for their origin),\n# coordinates and actuators after the URDF joints. Gravity is -9.81 \
         along z.",
        quoted(&file),
        quoted(robot_name),
        links.len(),
        joints.len(),
        moving.len()
    );
    let _ = writeln!(w, "name = {}", quoted(&scene_name));
    let _ = writeln!(
        w,
        "description = {}",
        quoted(&format!(
            "Robot `{robot_name}` imported from the URDF file {file}"
        ))
    );
    let _ = writeln!(w, "gravity = [0, 0, -9.81]");

    for &j in &moving {
        let joint = &joints[j];
        let _ = writeln!(w, "\n[[coordinates]]");
        if joint.name != names.joint[j] {
            let _ = writeln!(w, "# URDF joint {}", quoted(&joint.name));
        }
        if let Some(m) = &joint.mimic {
            let _ = writeln!(
                w,
                "# mimics {} in the URDF: an independent coordinate here",
                quoted(m)
            );
        }
        let _ = writeln!(w, "name = {}", quoted(&names.joint[j]));
        match (joint.kind, joint.limit) {
            (Kind::Continuous, _) | (_, None) => {}
            (_, Some([lo, hi])) => {
                let _ = writeln!(w, "range = [{}, {}]", num(lo), num(hi));
            }
        }
        if let Some(v) = joint.velocity {
            let _ = writeln!(w, "velocity_range = [{}, {}]", num(-v), num(v));
        }
    }

    for &j in &tree.order {
        let joint = &joints[j];
        let parent = tree.parent_frame(joint.parent, &names);
        let o = &joint.origin;
        let mut rotations = rpy_rotations(&o.rpy);
        let q = &names.joint[j];
        let moves = Tree::moves(joints, j);
        let header = |w: &mut String, name: &str, note: &str| {
            let _ = writeln!(w, "\n[[frames]]{note}");
            let _ = writeln!(w, "name = {}", quoted(name));
            if let Some(p) = &parent {
                let _ = writeln!(w, "parent = {}", quoted(p));
            }
        };
        let note = match (joint.kind, moves) {
            (Kind::Fixed, _) => format!("  # fixed joint {}", quoted(&joint.name)),
            (_, false) => format!("  # joint {} held fixed at 0", quoted(&joint.name)),
            _ => String::new(),
        };
        if joint.kind == Kind::Prismatic && moves {
            let origin_frame = &names.joint_frame[j];
            header(w, origin_frame, "  # origin of the prismatic joint");
            if o.xyz != [0.0; 3] {
                let _ = writeln!(w, "translation = {}", vector(&o.xyz));
            }
            if !rotations.is_empty() {
                let _ = writeln!(w, "rotation = [{}]", rotations.join(", "));
            }
            let _ = writeln!(w, "\n[[frames]]");
            let _ = writeln!(w, "name = {}", quoted(&names.link[joint.child]));
            let _ = writeln!(w, "parent = {}", quoted(origin_frame));
            let slide: Vec<String> = joint
                .axis
                .iter()
                .map(|&a| match a {
                    0.0 => "0".into(),
                    1.0 => quoted(q),
                    -1.0 => quoted(&format!("-{q}")),
                    a => quoted(&format!("{}*{q}", num(a))),
                })
                .collect();
            let _ = writeln!(w, "translation = [{}]", slide.join(", "));
            continue;
        }
        header(w, &names.link[joint.child], &note);
        if o.xyz != [0.0; 3] {
            let _ = writeln!(w, "translation = {}", vector(&o.xyz));
        }
        if moves {
            rotations.push(format!(
                "{{ axis = {}, angle = {} }}",
                axis_text(&joint.axis),
                quoted(q)
            ));
        }
        if !rotations.is_empty() {
            let _ = writeln!(w, "rotation = [{}]", rotations.join(", "));
        }
    }

    write_bodies(w, links, joints, tree, &names);

    for &j in &moving {
        if joints[j].damping > 0.0 {
            let _ = writeln!(w, "\n[[components]]");
            let _ = writeln!(
                w,
                "name = {}",
                quoted(&format!("{}_damping", names.joint[j]))
            );
            let _ = writeln!(w, "type = \"damper\"");
            let _ = writeln!(w, "damping = {}", num(joints[j].damping));
            let _ = writeln!(w, "expression = {}", quoted(&names.joint[j]));
        }
    }
    for &j in &moving {
        let _ = writeln!(w, "\n[[actuators]]");
        let _ = writeln!(w, "name = {}", quoted(&names.joint[j]));
        let _ = writeln!(w, "coordinate = {}", quoted(&names.joint[j]));
    }
    s
}

/// One `rigid_body` per moving body.
fn write_bodies(w: &mut String, links: &[Link], joints: &[Joint], tree: &Tree, names: &Names) {
    // Links of each body (by the body's frame link), with their poses in it.
    let mut bodies: BTreeMap<usize, Vec<(Pose, usize)>> = BTreeMap::new();
    let mut pose: Vec<Pose> = vec![Pose::identity(); links.len()];
    let mut ignored = Vec::new();
    for &j in &tree.order {
        let joint = &joints[j];
        if !Tree::moves(joints, j) {
            pose[joint.child] = pose[joint.parent].then(&Pose::of(&joint.origin));
        }
    }
    for &l in std::iter::once(&tree.root).chain(tree.order.iter().map(|&j| &joints[j].child)) {
        let massive = links[l]
            .inertial
            .as_ref()
            .is_some_and(|i| i.mass > 0.0 || i.inertia.iter().any(|&v| v != 0.0));
        match tree.body_of(joints, l) {
            Some(body) => bodies.entry(body).or_default().push((pose[l], l)),
            None if massive => ignored.push(names.link[l].clone()),
            None => {}
        }
    }
    if !ignored.is_empty() {
        let _ = writeln!(
            w,
            "\n# Fixed to the world, no energy: {}",
            ignored.join(", ")
        );
    }
    for (&body, members) in &bodies {
        let parts: Vec<(Pose, usize)> = members
            .iter()
            .copied()
            .filter(|&(_, l)| {
                links[l]
                    .inertial
                    .as_ref()
                    .is_some_and(|i| i.mass > 0.0 || i.inertia.iter().any(|&v| v != 0.0))
            })
            .collect();
        let body_name = &names.link[body];
        match parts.as_slice() {
            [] => {
                let _ = writeln!(w, "\n# Body {} is massless.", quoted(body_name));
            }
            [(_, l)] => {
                let i = links[*l].inertial.as_ref().expect("filtered above");
                let _ = writeln!(w, "\n[[components]]");
                let _ = writeln!(w, "name = {}", quoted(&format!("{}_body", names.link[*l])));
                let _ = writeln!(w, "type = \"rigid_body\"");
                let _ = writeln!(w, "frame = {}", quoted(&names.link[*l]));
                let _ = writeln!(w, "mass = {}", num(i.mass));
                if i.origin.xyz != [0.0; 3] {
                    let _ = writeln!(w, "position = {}", vector(&i.origin.xyz));
                }
                let [xx, xy, xz, yy, yz, zz] = i.inertia;
                if xy == 0.0 && xz == 0.0 && yz == 0.0 {
                    let _ = writeln!(w, "inertia = {}", vector(&[xx, yy, zz]));
                } else {
                    let _ = writeln!(
                        w,
                        "inertia = [{}, {}, {}]",
                        vector(&[xx, xy, xz]),
                        vector(&[xy, yy, yz]),
                        vector(&[xz, yz, zz])
                    );
                }
                if i.origin.rpy != [0.0; 3] {
                    let _ = writeln!(w, "inertia_rpy = {}", vector(&i.origin.rpy));
                }
            }
            many => {
                let merged: Vec<String> =
                    many.iter().map(|&(_, l)| names.link[l].clone()).collect();
                let inertials: Vec<(Pose, &Inertial)> = many
                    .iter()
                    .map(|&(p, l)| (p, links[l].inertial.as_ref().expect("filtered above")))
                    .collect();
                let b = combine(&inertials);
                let _ = writeln!(w, "\n[[components]]");
                let _ = writeln!(
                    w,
                    "# the links {} joined by fixed joints, inertias combined",
                    merged.join(", ")
                );
                let _ = writeln!(w, "name = {}", quoted(&format!("{body_name}_body")));
                let _ = writeln!(w, "type = \"rigid_body\"");
                let _ = writeln!(w, "frame = {}", quoted(body_name));
                let _ = writeln!(w, "mass = {}", num(b.mass));
                let _ = writeln!(w, "position = {}", vector(&[b.com.x, b.com.y, b.com.z]));
                let t = b.tensor;
                let row = |i: usize| vector(&[t[(i, 0)], t[(i, 1)], t[(i, 2)]]);
                let _ = writeln!(w, "inertia = [{}, {}, {}]", row(0), row(1), row(2));
            }
        }
    }
}
