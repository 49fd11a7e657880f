//! The scene text: identifiers, numbers, frames, coordinates, bodies.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write;

use super::tree::{combine, Tree};
use super::{Inertial, Joint, Kind, Link, Pose};
use crate::error::{Error, Source};
use crate::inertia::{inertia_problem, parallel_axis_scale, Unphysical};
use crate::load::parse::RESERVED;

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
    if RESERVED.contains(&s.as_str())
        || s == "world"
        || crate::load::RUST_KEYWORDS.contains(&s.as_str())
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

impl Names {
    /// The frame a joint below link `l` hangs from (`None`: the world).
    fn parent_frame(&self, tree: &Tree, l: usize) -> Option<String> {
        (l != tree.root).then(|| self.link[l].clone())
    }
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

pub(super) fn write_scene(
    source: &Source,
    robot: roxmltree::Node,
    links: &[Link],
    joints: &[Joint],
    tree: &Tree,
    outputs: &[String],
) -> Result<String, Error> {
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
         for their origin),\n# coordinates and actuators after the URDF joints, a marker at the \
         origin of every link\n# below the root. Gravity is -9.81 along z.",
        quoted(&file),
        quoted(robot_name),
        links.len(),
        joints.len(),
        moving.len()
    );
    let changes: Vec<f64> = joints
        .iter()
        .map(|j| &j.origin)
        .chain(
            links
                .iter()
                .filter_map(|l| l.inertial.as_ref().map(|i| &i.origin)),
        )
        .flat_map(|o| o.snapped)
        .filter(|d| *d != 0.0)
        .collect();
    if !changes.is_empty() {
        let largest = changes.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let _ = writeln!(
            w,
            "# {} rpy angles agreeing with a multiple of pi/12 to their last written digit (or \
             within 1e-12\n# rad) are taken as exact (largest change {largest:.1e} rad; \
             `--keep-angles` keeps them as written).",
            changes.len()
        );
    }
    let zeroed: usize = joints
        .iter()
        .map(|j| j.origin.zeroed + j.axis_zeroed)
        .chain(
            links
                .iter()
                .filter_map(|l| l.inertial.as_ref().map(|i| i.origin.zeroed)),
        )
        .sum();
    if zeroed > 0 {
        let _ = writeln!(
            w,
            "# {zeroed} axis components and origin coordinates within 1e-12 of zero, relative to \
             their vector,\n# are taken as zero (round-off such as `6.12323e-17`; \
             `--keep-angles` keeps them as written)."
        );
    }
    let _ = writeln!(w, "name = {}", quoted(&scene_name));
    let _ = writeln!(
        w,
        "description = {}",
        quoted(&format!(
            "Robot `{robot_name}` imported from the URDF file {file}"
        ))
    );
    let _ = writeln!(w, "gravity = [0, 0, -9.81]");
    if !outputs.is_empty() {
        let list: Vec<String> = outputs.iter().map(|o| quoted(o)).collect();
        let _ = writeln!(w, "outputs = [{}]", list.join(", "));
    }

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
        let parent = names.parent_frame(tree, joint.parent);
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

    write_bodies(w, source, links, joints, tree, &names)?;

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
    // A marker at the origin of every link below the root (the root is the
    // world), named after it.
    for &j in &tree.order {
        let link = quoted(&names.link[joints[j].child]);
        let _ = writeln!(w, "\n[[markers]]");
        let _ = writeln!(w, "name = {link}");
        let _ = writeln!(w, "frame = {link}");
    }
    Ok(s)
}

/// One `rigid_body` per moving body. A link's inertia tensor that is not
/// physical (see [`Inertial::problem`]) is accepted, with a comment, where
/// the link is fixed to the world (it carries no energy), where its body's
/// tensor (the link's own, or combined with the body's other links) is
/// physical, and where that tensor only breaks the triangle inequality
/// (`allow_unphysical_inertia`, as Pinocchio loads it); a body tensor that
/// is not positive semi-definite is an error at the link's `<inertia>`.
fn write_bodies(
    w: &mut String,
    source: &Source,
    links: &[Link],
    joints: &[Joint],
    tree: &Tree,
    names: &Names,
) -> Result<(), Error> {
    let problem = |l: usize| links[l].inertial.as_ref().and_then(|i| i.problem.as_ref());
    let refuse = |l: usize, also: &str| {
        let (at, problem) = problem(l).expect("a link with a problem");
        let link = &links[l].name;
        source.error_at(
            *at,
            None,
            format!("link `{link}`: {}{also}", problem.message()),
        )
    };
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
            None if massive => ignored.push(match problem(l) {
                Some(_) => format!("{} (its inertia tensor is not physical)", names.link[l]),
                None => names.link[l].clone(),
            }),
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
                if let Some((_, Unphysical::Indefinite { .. })) = problem(*l) {
                    return Err(refuse(*l, ""));
                }
                let i = links[*l].inertial.as_ref().expect("filtered above");
                let _ = writeln!(w, "\n[[components]]");
                if let Some((_, p)) = problem(*l) {
                    let _ = writeln!(
                        w,
                        "# link {}: {}; kept as published",
                        quoted(&names.link[*l]),
                        p.message()
                    );
                }
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
                if problem(*l).is_some() {
                    let _ = writeln!(w, "allow_unphysical_inertia = true");
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
                let odd: Vec<usize> = many
                    .iter()
                    .map(|&(_, l)| l)
                    .filter(|&l| problem(l).is_some())
                    .collect();
                let combined = inertia_problem(&b.tensor, parallel_axis_scale(b.mass, &b.com));
                if let Some(p @ Unphysical::Indefinite { .. }) = &combined {
                    let also = format!(
                        ", and so is the body it is merged into ({}): {}",
                        merged.join(", "),
                        p.message()
                    );
                    return Err(match odd.first() {
                        Some(&l) => refuse(l, &also),
                        None => source.error(format!("body {body_name}: {}", p.message())),
                    });
                }
                let _ = writeln!(w, "\n[[components]]");
                for &l in &odd {
                    let _ = writeln!(
                        w,
                        "# link {}'s own inertia tensor is not physical ({})",
                        quoted(&names.link[l]),
                        problem(l).expect("odd").1.message()
                    );
                }
                match &combined {
                    Some(p) => {
                        let _ =
                            writeln!(w, "# the combined one: {}; kept as published", p.message());
                    }
                    None if !odd.is_empty() => {
                        let _ = writeln!(w, "# the combined one is physical");
                    }
                    None => {}
                }
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
                if combined.is_some() {
                    let _ = writeln!(w, "allow_unphysical_inertia = true");
                }
            }
        }
    }
    Ok(())
}
