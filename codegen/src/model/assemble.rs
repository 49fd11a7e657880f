//! The model stage in order: the names, the components that add
//! coordinates, the frames and markers, the energies, the constraints and
//! actuators.

use super::components;
use super::context::Context;
use super::{Component, Model};
use crate::error::Error;
use crate::load::LoadedScene;

/// Build the symbolic model of a loaded scene's full scene (a derived
/// scene's reductions are the next stage's).
pub(crate) fn build(scene: &LoadedScene) -> Result<Model, Error> {
    let def = &scene.def;
    let mut cx = Context::new(&scene.source);
    let mut coordinates = cx.coordinates(def)?;
    let runtime_parameters = cx.parameters(def)?;
    cx.gravity = match &def.gravity {
        Some(v) => {
            let g = cx.vector(v, None, false)?;
            cx.check_overflow(v.span().start, None, "gravity")?;
            g
        }
        None => {
            let zero = cx.graph.constant(0.0);
            let g = cx.graph.constant(-9.81);
            [zero, zero, g]
        }
    };
    // Components that add coordinates first (flexible links: their
    // finite-element models are built numerically and their modal
    // coordinates appended to the declared ones), so that frames
    // (stations), components and constraints below can use them.
    let mut early = Vec::with_capacity(def.components.len());
    for (i, c) in def.components.iter().enumerate() {
        if components::adds_coordinates(c) {
            let mut read = components::read(&cx, i, c)?;
            read.value.prepare(&mut cx, &mut coordinates, &read.ctx)?;
            cx.check_overflow(c.kind.span().start, Some(&read.ctx), "the component")?;
            cx.flexible.extend(read.value.flexible_link().cloned());
            early.push(Some(read));
        } else {
            early.push(None);
        }
    }
    cx.frames(&def.frames)?;
    // Markers next, so that the expressions below may read their positions.
    let markers = cx.markers(&def.markers)?;
    for m in &markers {
        cx.scope.points.insert(m.name.clone(), m.position);
    }
    let mut component_energies = Vec::with_capacity(def.components.len());
    for (i, (c, early)) in def.components.iter().zip(early).enumerate() {
        let read = match early {
            Some(read) => read,
            None => components::read(&cx, i, c)?,
        };
        if component_energies
            .iter()
            .any(|e: &Component| e.name == read.name)
        {
            let at = c
                .name
                .as_ref()
                .map_or(c.kind.span().start, |n| n.span().start);
            return Err(cx.err(
                at,
                Some(&read.ctx),
                "a component of this name is declared above (components are named in \
                 messages, reductions and exports)",
            ));
        }
        let terms = read.value.energies(&mut cx, &read.ctx)?;
        cx.check_overflow(c.kind.span().start, Some(&read.ctx), "the component")?;
        let [kinetic, potential, dissipation] = terms.energies;
        component_energies.push(Component {
            name: read.name,
            kind: read.kind.to_owned(),
            kinetic,
            potential,
            dissipation,
            bodies: terms.bodies,
            weight: terms.weight,
        });
    }
    let mut constraints = Vec::new();
    for (i, c) in def.constraints.iter().enumerate() {
        cx.constraint(i, c, &mut constraints)?;
    }
    let actuators = cx.actuators(def, &coordinates)?;
    component_energies.extend(cx.armatures(def, &actuators)?);
    let outputs = cx.outputs(def)?;
    let precision = cx.precision(def)?;
    let markers = cx.marker_velocities(markers);
    Ok(Model {
        name: def.name.get_ref().clone(),
        graph: cx.graph,
        coordinates,
        runtime_parameters,
        parameters: cx.parameter_values,
        components: component_energies,
        constraints,
        actuators,
        markers,
        placements: cx.placements,
        gravity: cx.gravity,
        outputs,
        precision,
        flexible_links: cx.flexible,
        drop_below: None,
        sources: vec![scene.source.path().to_path_buf()],
        notes: Vec::new(),
    })
}
