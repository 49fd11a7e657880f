//! Markers: named points of frames (a frame's origin by default), with
//! their world pose and their velocity in world axes, built along the
//! frames in world axes ([`crate::geometry::Frame`]). The derive stage
//! differentiates them into Jacobians and acceleration biases.
//!
//! In two steps: the poses right after the frames (expressions may read the
//! positions), the velocities after everything else, so that a scene's
//! energies and constraints are built on the same graph nodes with or
//! without markers (a marker at a frame's origin adds no node before them).

use super::context::Context;
use super::Marker;
use crate::error::Error;
use crate::expr::Id;
use crate::geometry::Frame;
use crate::load::check_ident;
use crate::load::scene::MarkerDef;

/// A marker placed on its frame, its velocity not yet built.
pub(super) struct Placed {
    pub(super) name: String,
    pub(super) position: [Id; 3],
    frame: Frame,
    /// The point in the frame's axes, and in world axes from its origin.
    local: [Id; 3],
    offset: [Id; 3],
}

impl Context<'_> {
    /// The markers' poses.
    pub(super) fn markers(&mut self, defs: &[MarkerDef]) -> Result<Vec<Placed>, Error> {
        let mut out: Vec<Placed> = Vec::with_capacity(defs.len());
        for m in defs {
            check_ident(self.source, &m.name, "marker")?;
            let ctx = format!("marker `{}`", m.name.get_ref());
            if out.iter().any(|o| &o.name == m.name.get_ref()) {
                return Err(self.err(m.name.span().start, Some(&ctx), "marker is defined twice"));
            }
            let frame = self.lookup_frame(&m.frame, &ctx)?;
            let local = match &m.position {
                Some(p) => {
                    let local = self.vector(p, Some(&ctx), false)?;
                    let at = p.span().start;
                    for &x in &local {
                        self.nominal_value(x, at, &ctx, "a marker's `position`")?;
                    }
                    local
                }
                None => [self.graph.constant(0.0); 3],
            };
            let g = &mut self.graph;
            let offset = g.rotate(&frame.rotation, local);
            let position = std::array::from_fn(|k| g.add(frame.origin[k], offset[k]));
            self.check_overflow(m.name.span().start, Some(&ctx), "the marker")?;
            out.push(Placed {
                name: m.name.get_ref().clone(),
                position,
                frame,
                local,
                offset,
            });
        }
        Ok(out)
    }

    /// The placed markers with their velocities.
    pub(super) fn marker_velocities(&mut self, placed: Vec<Placed>) -> Vec<Marker> {
        placed
            .into_iter()
            .map(|p| {
                let v = self.graph.world_velocities(&p.frame, p.local, p.offset);
                let (w, l) = (v.angular, v.linear);
                Marker {
                    name: p.name,
                    position: p.position,
                    rotation: p.frame.rotation,
                    velocity: [l[0], l[1], l[2], w[0], w[1], w[2]],
                    linear_about_point: v.linear_about_point,
                }
            })
            .collect()
    }
}
