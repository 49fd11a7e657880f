//! Markers: named points of frames (a frame's origin by default), with
//! their world pose and their velocity in world axes, built along the
//! frames in world axes ([`crate::geometry::Frame`]). The derive stage differentiates them into
//! Jacobians and acceleration biases.

use super::context::Context;
use super::Marker;
use crate::error::Error;
use crate::load::check_ident;
use crate::load::scene::MarkerDef;

impl Context<'_> {
    pub(super) fn markers(&mut self, defs: &[MarkerDef]) -> Result<Vec<Marker>, Error> {
        let mut out: Vec<Marker> = Vec::with_capacity(defs.len());
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
            let (angular, linear) = g.world_velocities(&frame, local, offset);
            self.check_overflow(m.name.span().start, Some(&ctx), "the marker")?;
            out.push(Marker {
                name: m.name.get_ref().clone(),
                position,
                rotation: frame.rotation,
                velocity: [
                    linear[0], linear[1], linear[2], angular[0], angular[1], angular[2],
                ],
            });
        }
        Ok(out)
    }
}
