//! Reading the robot: links and joints from the XML, every number checked.

use std::collections::{BTreeMap, BTreeSet};

use super::tree::tensor;
use super::{at, Inertial, Joint, Kind, Link, Origin, UrdfOptions, ABSURD, MAX_LINKS};
use crate::error::{Error, Source};
use crate::inertia::{inertia_problem, parallel_axis_scale};

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

/// A joint limit, `None` where it is absent or beyond [`ABSURD`] in
/// magnitude (infinite included): files write `1e16` for "no limit".
fn limit_value(source: &Source, node: roxmltree::Node, name: &str) -> Result<Option<f64>, Error> {
    match node.attribute(name) {
        None => Ok(None),
        Some(t) if t.trim().parse::<f64>().is_ok_and(|v| v.abs() > ABSURD) => Ok(None),
        Some(t) => numbers::<1>(source, node, name, t).map(|v| Some(v[0])),
    }
}

fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

fn origin(source: &Source, parent: roxmltree::Node, keep_angles: bool) -> Result<Origin, Error> {
    let Some(o) = child(parent, "origin") else {
        return Ok(Origin::default());
    };
    let read = |name: &str| match o.attribute(name) {
        Some(t) => numbers::<3>(source, o, name, t),
        None => Ok([0.0; 3]),
    };
    let written = read("rpy")?;
    let mut rpy = written;
    if !keep_angles {
        let words = o.attribute("rpy").unwrap_or_default().split_whitespace();
        for (angle, word) in rpy.iter_mut().zip(words) {
            *angle = snap_angle(word, *angle);
        }
    }
    let (xyz, zeroed) = match keep_angles {
        true => (read("xyz")?, 0),
        false => snap_noise(read("xyz")?),
    };
    Ok(Origin {
        xyz,
        rpy,
        snapped: std::array::from_fn(|k| rpy[k] - written[k]),
        zeroed,
    })
}

/// `v` with every component within [`super::SNAP_NOISE`] of zero, relative
/// to its largest component, taken as zero, and how many were: an
/// exporter's round-off of zero (`6.12323e-17`, `cos(pi/2)` in an axis
/// `0 1 6.12323e-17` or in a translation's `-1.36916e-17`), which would
/// otherwise make a joint's turn one about a general axis and keep every
/// product with it in the generated code.
pub(super) fn snap_noise(v: [f64; 3]) -> ([f64; 3], usize) {
    let largest = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let noise = |x: f64| x != 0.0 && x.abs() <= super::SNAP_NOISE * largest;
    (
        v.map(|x| if noise(x) { 0.0 } else { x }),
        v.iter().filter(|&&x| noise(x)).count(),
    )
}

/// The angle `value`, written as `text`, snapped to the multiple of
/// `pi/12` it agrees with to within one unit of its last written digit,
/// when that is at most [`super::SNAP_LIMIT`] away: `1.57079632679`
/// (4.9e-12 from `pi/2`, written to 1e-11), `1.5708` and `3.1415926`
/// (truncated) become `pi/2` and `pi`; `1.570796325` (1.8e-9 away, written to
/// 1e-9), `1.57` and zero's neighbours (`5.5e-5`, `-1.9e-8`, written to finer
/// digits) stay as written. An angle within [`super::SNAP_NOISE`] of such a
/// multiple is snapped however it is written (`-1.67685e-15`: rounding
/// noise of an exporter).
pub(super) fn snap_angle(text: &str, value: f64) -> f64 {
    use std::f64::consts::PI;
    let n = (value * 12.0 / PI).round();
    let exact = n * (PI / 12.0);
    let (mantissa, exponent) = match text.find(['e', 'E']) {
        Some(k) => (&text[..k], text[k + 1..].parse::<i32>().unwrap_or(0)),
        None => (text, 0),
    };
    let decimals = mantissa.find('.').map_or(0, |k| mantissa.len() - k - 1) as i32;
    let unit = 10f64.powi(exponent - decimals);
    match (value - exact).abs() <= unit.clamp(super::SNAP_NOISE, super::SNAP_LIMIT) {
        true => exact,
        false => value,
    }
}

pub(super) fn read_robot(
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
            .map(|i| read_inertial(source, i, &name, options.keep_angles))
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
        let (axis, axis_zeroed) = match child(node, "axis").filter(|_| kind != Kind::Fixed) {
            Some(a) => {
                let v = numbers::<3>(source, a, "xyz", attribute(source, a, "xyz")?)?;
                let (v, zeroed) = match options.keep_angles {
                    true => (v, 0),
                    false => snap_noise(v),
                };
                let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                if n < 1e-12 {
                    return Err(at(source, a, format!("{ctx}: the axis is zero")));
                }
                match (n - 1.0).abs() < 1e-15 {
                    true => (v, zeroed),
                    false => (v.map(|x| x / n), zeroed),
                }
            }
            None => ([1.0, 0.0, 0.0], 0),
        };
        let (mut limit, mut velocity) = (None, None);
        if let Some(l) = child(node, "limit") {
            let lower = limit_value(source, l, "lower")?;
            let upper = limit_value(source, l, "upper")?;
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
            velocity = limit_value(source, l, "velocity")?.filter(|&v| v > 0.0);
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
            origin: origin(source, node, options.keep_angles)?,
            axis,
            axis_zeroed,
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

fn read_inertial(
    source: &Source,
    node: roxmltree::Node,
    link: &str,
    keep_angles: bool,
) -> Result<Inertial, Error> {
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
    let origin = origin(source, node, keep_angles)?;
    let floor = parallel_axis_scale(mass, &origin.xyz.into());
    let problem = inertia_problem(&tensor(&inertia), floor).map(|p| (i.range().start, p));
    Ok(Inertial {
        origin,
        mass,
        inertia,
        problem,
    })
}
