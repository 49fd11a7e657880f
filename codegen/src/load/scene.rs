//! The scene file format: TOML read with serde into raw, position-carrying
//! structures. Nothing here interprets expressions; see [`crate::model`].
//!
//! Every expression and number keeps its byte span in the file so that later
//! stages can report errors at the right line and column. Unknown fields are
//! rejected.

use std::collections::BTreeMap;
use std::fmt;

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;
use toml::Spanned;

use crate::error::{Error, Source};

/// A number or an expression written as a string.
#[derive(Debug, Clone)]
pub enum Scalar {
    /// A literal number.
    Number(f64),
    /// An expression in the scene grammar.
    Expr(String),
}

/// A scalar with its position in the file.
pub type SScalar = Spanned<Scalar>;

/// A parameter: a plain number (folded into the generated code) or a table.
#[derive(Debug, Clone)]
pub enum ParameterDef {
    /// Folded as a constant at generation time.
    Value(f64),
    /// A table with options.
    Table(ParameterTable),
}

// `Scalar` and `ParameterDef` are deserialized by hand rather than as
// untagged enums, so that a wrong type or an unknown field inside a parameter
// table is reported as such instead of "data did not match any variant".

struct ScalarVisitor;

impl<'de> Visitor<'de> for ScalarVisitor {
    type Value = Scalar;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or an expression string")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Scalar, E> {
        Ok(Scalar::Number(v))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Scalar, E> {
        Ok(Scalar::Number(v as f64))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Scalar, E> {
        Ok(Scalar::Number(v as f64))
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<Scalar, E> {
        Ok(Scalar::Expr(v.to_owned()))
    }

    fn visit_string<E: de::Error>(self, v: String) -> Result<Scalar, E> {
        Ok(Scalar::Expr(v))
    }
}

impl<'de> Deserialize<'de> for Scalar {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Scalar, D::Error> {
        d.deserialize_any(ScalarVisitor)
    }
}

struct ParameterVisitor;

impl<'de> Visitor<'de> for ParameterVisitor {
    type Value = ParameterDef;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or a table `{ value = ..., runtime = ... }`")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<ParameterDef, E> {
        Ok(ParameterDef::Value(v))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<ParameterDef, E> {
        Ok(ParameterDef::Value(v as f64))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<ParameterDef, E> {
        Ok(ParameterDef::Value(v as f64))
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<ParameterDef, A::Error> {
        ParameterTable::deserialize(de::value::MapAccessDeserializer::new(map))
            .map(ParameterDef::Table)
    }
}

impl<'de> Deserialize<'de> for ParameterDef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<ParameterDef, D::Error> {
        d.deserialize_any(ParameterVisitor)
    }
}

/// A parameter with options.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterTable {
    /// Nominal value.
    pub value: f64,
    /// Leave the parameter as a runtime input of the generated model
    /// (a field of the model struct) instead of folding it.
    #[serde(default)]
    pub runtime: bool,
}

/// A generalized coordinate.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoordinateDef {
    /// Name usable in expressions.
    pub name: Spanned<String>,
    /// Range of positions the scene is used in (validation samples from it).
    pub range: Option<Spanned<[f64; 2]>>,
    /// Range of velocities the scene is used in.
    pub velocity_range: Option<Spanned<[f64; 2]>>,
    /// Initial position for simulations (default 0).
    pub initial: Option<Spanned<f64>>,
    /// Initial velocity for simulations (default 0).
    pub initial_velocity: Option<Spanned<f64>>,
}

/// An elementary rotation of a frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RotationDef {
    /// `"x"`, `"y"`, `"z"`, or a direction as three numbers.
    pub axis: Spanned<AxisDef>,
    /// The angle, in radians.
    pub angle: SScalar,
}

/// An axis of rotation.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum AxisDef {
    /// `"x"`, `"y"` or `"z"`.
    Named(String),
    /// A direction (normalised when read).
    Vector([f64; 3]),
}

/// A kinematic frame: translation and rotation relative to a parent frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameDef {
    /// Name used by components and other frames.
    pub name: Spanned<String>,
    /// Parent frame, the world frame when absent.
    pub parent: Option<Spanned<String>>,
    /// Origin of this frame in the parent frame.
    pub translation: Option<Spanned<Vec<SScalar>>>,
    /// Rotations applied in order (intrinsic), each about an axis of the
    /// frame produced by the previous ones.
    #[serde(default)]
    pub rotation: Vec<RotationDef>,
    /// A point of the flexible link whose reference frame is `parent`:
    /// `"start"`, `"end"`, or the distance from the start (m). The frame
    /// follows the deformed link there; `translation` and `rotation` apply
    /// after it.
    pub station: Option<SScalar>,
}

/// A component of the mechanism. Which fields apply depends on `type`;
/// [`crate::model`] checks that.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComponentDef {
    /// Name for messages and reports.
    pub name: Option<Spanned<String>>,
    /// `energy`, `point_mass`, `rod`, `rigid_body`, `spring`, `damper`,
    /// `flexible_link`, `flexible_joint`.
    #[serde(rename = "type")]
    pub kind: Spanned<String>,
    /// Kinetic energy (`energy`).
    pub kinetic: Option<SScalar>,
    /// Potential energy (`energy`).
    pub potential: Option<SScalar>,
    /// Rayleigh dissipation function (`energy`).
    pub dissipation: Option<SScalar>,
    /// Mass (`point_mass`, `rod`, `rigid_body`).
    pub mass: Option<SScalar>,
    /// Frame the positions are given in (world when absent).
    pub frame: Option<Spanned<String>>,
    /// Position of a point mass, or of a rigid body's centre of mass.
    pub position: Option<Spanned<Vec<SScalar>>>,
    /// First end of a rod.
    pub from: Option<Spanned<Vec<SScalar>>>,
    /// Second end of a rod.
    pub to: Option<Spanned<Vec<SScalar>>>,
    /// Inertia tensor about the centre of mass (`rigid_body`): three rows
    /// of the full 3x3 tensor, or its diagonal `[ixx, iyy, izz]`.
    pub inertia: Option<Spanned<Vec<Spanned<InertiaEntry>>>>,
    /// Orientation `[roll, pitch, yaw]` of the inertia's axes in the frame
    /// (`rigid_body`; URDF convention `R = Rz(yaw) Ry(pitch) Rx(roll)`).
    pub inertia_rpy: Option<Spanned<Vec<SScalar>>>,
    /// Accept a positive semi-definite inertia tensor that breaks the
    /// triangle inequality (`rigid_body`; as some URDF files publish).
    pub allow_unphysical_inertia: Option<Spanned<bool>>,
    /// Stiffness of a spring.
    pub stiffness: Option<SScalar>,
    /// Damping coefficient of a damper.
    pub damping: Option<SScalar>,
    /// The stretch (spring) or the quantity whose rate is damped (damper),
    /// e.g. `q[1] - q[0]` for a torsion spring between two links.
    pub expression: Option<SScalar>,
    /// Rest value of a spring's expression.
    pub rest: Option<SScalar>,
    /// Shaft axis of a flexible joint in its frame: `x`, `y` or `z`.
    pub axis: Option<Spanned<String>>,
    /// Length of a flexible link (m).
    pub length: Option<SScalar>,
    /// Material of a flexible link.
    pub material: Option<Spanned<MaterialDef>>,
    /// Cross-section of a flexible link.
    pub section: Option<Spanned<SectionDef>>,
    /// Number of finite elements of a flexible link (default 20).
    pub elements: Option<SScalar>,
    /// Number of kept modes of a flexible link (default 6).
    pub modes: Option<SScalar>,
    /// Keep the modes below this frequency (Hz) instead of a fixed number.
    pub max_frequency: Option<SScalar>,
    /// Boundary conditions of a flexible link's modes.
    pub boundary: Option<Spanned<String>>,
    /// Rotational end springs `[k_y, k_z]` of `pinned_pinned_elastic`.
    pub end_stiffness: Option<Spanned<EndStiffnessDef>>,
    /// Modal damping ratio: one value for all modes or one per mode.
    pub damping_ratio: Option<Spanned<ScalarList>>,
    /// Centrifugal (geometric) stiffening of a flexible link.
    pub geometric_stiffening: Option<Spanned<bool>>,
    /// First end of a two-ended `spring` or `damper`: a point of a frame.
    pub a: Option<Spanned<ConstraintEnd>>,
    /// Second end (the world's origin when left out).
    pub b: Option<Spanned<ConstraintEnd>>,
}

/// An entry of a rigid body's `inertia`: a row of the full tensor, or one
/// element of the diagonal shorthand.
#[derive(Debug, Clone)]
pub enum InertiaEntry {
    /// A row `[i_k1, i_k2, i_k3]`.
    Row(Vec<SScalar>),
    /// A diagonal element.
    Diagonal(Scalar),
}

struct InertiaEntryVisitor;

impl<'de> Visitor<'de> for InertiaEntryVisitor {
    type Value = InertiaEntry;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a row of three values or a diagonal element")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<InertiaEntry, E> {
        ScalarVisitor.visit_f64(v).map(InertiaEntry::Diagonal)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<InertiaEntry, E> {
        ScalarVisitor.visit_i64(v).map(InertiaEntry::Diagonal)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<InertiaEntry, E> {
        ScalarVisitor.visit_u64(v).map(InertiaEntry::Diagonal)
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<InertiaEntry, E> {
        ScalarVisitor.visit_str(v).map(InertiaEntry::Diagonal)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<InertiaEntry, A::Error> {
        Vec::<SScalar>::deserialize(de::value::SeqAccessDeserializer::new(seq))
            .map(InertiaEntry::Row)
    }
}

impl<'de> Deserialize<'de> for InertiaEntry {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<InertiaEntry, D::Error> {
        d.deserialize_any(InertiaEntryVisitor)
    }
}

/// Material of a flexible link.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialDef {
    /// Young's modulus `E` (Pa).
    pub youngs_modulus: SScalar,
    /// Poisson's ratio (gives `G = E / (2 (1 + nu))`).
    pub poisson: Option<SScalar>,
    /// Shear modulus `G` (Pa), instead of `poisson`.
    pub shear_modulus: Option<SScalar>,
    /// Density (kg/m^3).
    pub density: SScalar,
}

/// Circular cross-section of a flexible link: `radius` (solid), `area`
/// (solid circle of that area) or `outer_radius` with `inner_radius` (tube).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SectionDef {
    /// Radius of a solid circle.
    pub radius: Option<SScalar>,
    /// Area of a solid circle.
    pub area: Option<SScalar>,
    /// Outer radius of a tube.
    pub outer_radius: Option<SScalar>,
    /// Inner radius of a tube.
    pub inner_radius: Option<SScalar>,
}

/// Rotational end springs: `[k_y, k_z]` at both ends, or a table
/// `{ start = [k_y, k_z], end = [k_y, k_z] }` (either may be left out).
#[derive(Debug, Clone)]
pub enum EndStiffnessDef {
    /// The same springs at both ends.
    Both(Vec<SScalar>),
    /// Springs per end.
    PerEnd(EndStiffnessTable),
}

/// Springs per end, see [`EndStiffnessDef`].
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EndStiffnessTable {
    /// Springs `[k_y, k_z]` at `x = 0`.
    pub start: Option<Spanned<Vec<SScalar>>>,
    /// Springs `[k_y, k_z]` at `x = L`.
    pub end: Option<Spanned<Vec<SScalar>>>,
}

struct EndStiffnessVisitor;

impl<'de> Visitor<'de> for EndStiffnessVisitor {
    type Value = EndStiffnessDef;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array `[k_y, k_z]` or a table `{ start = [k_y, k_z], end = [k_y, k_z] }`")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<EndStiffnessDef, A::Error> {
        Vec::<SScalar>::deserialize(de::value::SeqAccessDeserializer::new(seq))
            .map(EndStiffnessDef::Both)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<EndStiffnessDef, A::Error> {
        EndStiffnessTable::deserialize(de::value::MapAccessDeserializer::new(map))
            .map(EndStiffnessDef::PerEnd)
    }
}

impl<'de> Deserialize<'de> for EndStiffnessDef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<EndStiffnessDef, D::Error> {
        d.deserialize_any(EndStiffnessVisitor)
    }
}

/// One scalar or an array of scalars.
#[derive(Debug, Clone)]
pub enum ScalarList {
    /// A single value.
    One(Scalar),
    /// One value per item.
    Many(Vec<SScalar>),
}

struct ScalarListVisitor;

impl<'de> Visitor<'de> for ScalarListVisitor {
    type Value = ScalarList;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number, an expression string or an array of them")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<ScalarList, E> {
        ScalarVisitor.visit_f64(v).map(ScalarList::One)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<ScalarList, E> {
        ScalarVisitor.visit_i64(v).map(ScalarList::One)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<ScalarList, E> {
        ScalarVisitor.visit_u64(v).map(ScalarList::One)
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<ScalarList, E> {
        ScalarVisitor.visit_str(v).map(ScalarList::One)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<ScalarList, A::Error> {
        Vec::<SScalar>::deserialize(de::value::SeqAccessDeserializer::new(seq))
            .map(ScalarList::Many)
    }
}

impl<'de> Deserialize<'de> for ScalarList {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<ScalarList, D::Error> {
        d.deserialize_any(ScalarListVisitor)
    }
}

/// A holonomic constraint: `expression(q, t) = 0`, or a vector constraint
/// between two frames given by `type` (`coincident`, `perpendicular`) with
/// its ends `a` and `b`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintDef {
    /// Name for messages.
    pub name: Option<Spanned<String>>,
    /// The residual.
    pub expression: Option<SScalar>,
    /// `coincident` or `perpendicular` (absent for `expression` constraints).
    #[serde(rename = "type")]
    pub kind: Option<Spanned<String>>,
    /// First end of a vector constraint.
    pub a: Option<Spanned<ConstraintEnd>>,
    /// Second end of a vector constraint.
    pub b: Option<Spanned<ConstraintEnd>>,
}

/// One end of a vector constraint: a point (`position`) or a direction
/// (`axis`) given in a frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintEnd {
    /// The frame (world when absent).
    pub frame: Option<Spanned<String>>,
    /// A point in the frame (`coincident`, default the origin).
    pub position: Option<Spanned<Vec<SScalar>>>,
    /// A direction in the frame (`perpendicular`).
    pub axis: Option<Spanned<AxisDef>>,
}

/// A marker: a named point of a frame (its origin by default) whose pose,
/// velocity, Jacobian and acceleration bias the generated code computes.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerDef {
    /// Name (an identifier): the index in the generated `MARKERS`, and the
    /// `<name>_x` columns of a simulation.
    pub name: Spanned<String>,
    /// The frame it is fixed in (`world`, or a frame above; a frame at a
    /// flexible link's station follows its deflection).
    pub frame: Spanned<String>,
    /// The point in the frame's axes (default its origin).
    pub position: Option<Spanned<Vec<SScalar>>>,
}

/// An actuator input driving one generalized coordinate.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorDef {
    /// Name of the input.
    pub name: Spanned<String>,
    /// Coordinate whose generalized force the input is.
    pub coordinate: Spanned<String>,
    /// Gain (generalized force per unit input), 1 by default.
    pub gain: Option<Spanned<f64>>,
    /// Rotor (armature) inertia reflected to the coordinate: adds the
    /// kinetic energy `armature qd^2 / 2`.
    pub armature: Option<SScalar>,
}

/// The whole scene file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneDef {
    /// Identifier: module name of the generated code.
    pub name: Spanned<String>,
    /// Free text for people; never copied into generated code (read only
    /// to check that it is a string).
    #[allow(dead_code)]
    pub description: Option<String>,
    /// Gravity vector in world axes (default `[0, 0, -9.81]`).
    pub gravity: Option<Spanned<Vec<SScalar>>>,
    /// Parameters by name.
    #[serde(default)]
    pub parameters: BTreeMap<Spanned<String>, Spanned<ParameterDef>>,
    /// Generalized coordinates in order.
    pub coordinates: Vec<CoordinateDef>,
    /// Kinematic frames.
    #[serde(default)]
    pub frames: Vec<FrameDef>,
    /// Components.
    #[serde(default)]
    pub components: Vec<ComponentDef>,
    /// Constraints.
    #[serde(default)]
    pub constraints: Vec<ConstraintDef>,
    /// Actuators.
    #[serde(default)]
    pub actuators: Vec<ActuatorDef>,
    /// Markers (frame and point kinematics).
    #[serde(default)]
    pub markers: Vec<MarkerDef>,
    /// Optional outputs beyond the runtime's core set: `coriolis_matrix`,
    /// `forces` (Coriolis, potential and damping forces separately).
    #[serde(default)]
    pub outputs: Vec<Spanned<String>>,
    /// Scalar type of the generated code: `f64` (default) or `f32`.
    pub precision: Option<Spanned<String>>,
}

/// A scene derived from another scene file by a reduction: "model only what
/// the scene needs" (see [`crate::reduce`]).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DerivedSceneDef {
    /// Identifier: module name of the generated code.
    pub name: Spanned<String>,
    /// Free text for people; never copied into generated code (read only
    /// to check that it is a string).
    #[allow(dead_code)]
    pub description: Option<String>,
    /// The scene it reduces: a file name in the same directory.
    pub base: Spanned<String>,
    /// What to leave out.
    pub reduce: Spanned<ReduceDef>,
}

/// The reductions a derived scene applies to its base.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReduceDef {
    /// Keep only the lowest `modes` modes of every flexible link.
    pub modes: Option<Spanned<i64>>,
    /// Keep only the modes below this frequency (Hz) of every flexible link.
    pub max_frequency: Option<Spanned<f64>>,
    /// Coordinates held at zero (for example the twists of flexible joints,
    /// which makes those joints rigid).
    #[serde(default)]
    pub freeze: Vec<Spanned<String>>,
    /// Drop the terms of the mass matrix and the bias forces whose
    /// contribution over the declared coordinate and velocity ranges stays
    /// below this fraction of the term's scale.
    pub drop_below: Option<Spanned<f64>>,
}

/// A scene file: a full scene, or a reduction of another.
#[derive(Debug, Clone)]
pub enum SceneFile {
    /// A scene written out in full.
    Full(SceneDef),
    /// A scene derived from another file (it has a top-level `base`).
    Derived(DerivedSceneDef),
}

/// Largest scene file accepted, in bytes.
pub const MAX_SCENE_BYTES: usize = 4 << 20;

/// Parse a scene file's text, full or derived (one with a top-level `base`).
pub fn parse_scene_file(source: &Source) -> Result<SceneFile, Error> {
    check_size(source)?;
    let derived =
        toml::from_str::<toml::Table>(source.text()).is_ok_and(|t| t.contains_key("base"));
    if derived {
        from_toml(source).map(SceneFile::Derived)
    } else {
        from_toml(source).map(SceneFile::Full)
    }
}

fn check_size(source: &Source) -> Result<(), Error> {
    if source.text().len() > MAX_SCENE_BYTES {
        return Err(source.error(format!("scene file is larger than {MAX_SCENE_BYTES} bytes")));
    }
    Ok(())
}

fn from_toml<T: serde::de::DeserializeOwned>(source: &Source) -> Result<T, Error> {
    toml::from_str::<T>(source.text()).map_err(|e| {
        let offset = e.span().map_or(0, |s| s.start);
        let mut message = e.message().trim().to_owned();
        if message.is_empty() {
            // toml says nothing about, e.g., a control character in a comment.
            message = match source.text().get(offset..).and_then(|r| r.chars().next()) {
                Some(c) => format!("unexpected character {c:?}"),
                None => "invalid TOML".into(),
            };
        }
        source.error_at(offset, None, message)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn parse(text: &str) -> Result<SceneDef, Error> {
        match parse_scene_file(&Source::new(Path::new("s.toml"), text.into()))? {
            SceneFile::Full(def) => Ok(def),
            SceneFile::Derived(_) => panic!("a full scene was expected"),
        }
    }

    #[test]
    fn minimal_scene_parses() {
        let s = parse(
            "name = \"p\"\n[parameters]\nm = 1.0\nl = { value = 2.0, runtime = true }\n\
             [[coordinates]]\nname = \"x\"\n[[components]]\ntype = \"point_mass\"\nmass = \"m\"\n\
             position = [\"x\", 0, 0]\n",
        )
        .unwrap();
        assert_eq!(s.name.get_ref(), "p");
        assert_eq!(s.parameters.len(), 2);
        assert_eq!(s.components.len(), 1);
    }

    #[test]
    fn unknown_field_is_located() {
        let e = parse("name = \"p\"\ncoordinates = []\nbogus = 1\n").unwrap_err();
        assert_eq!(e.line, 3, "{e}");
        assert!(e.message.contains("bogus"), "{e}");
    }
}
