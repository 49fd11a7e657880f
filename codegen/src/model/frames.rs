//! Kinematic frames in file order: each placed in its parent (the world by
//! default), or at a station of a flexible link's deformed centre line, by
//! a translation and elementary rotations in turn.

use super::components::station_frame;
use super::context::Context;
use super::Placement;
use crate::error::Error;
use crate::expr::{exact, Id};
use crate::geometry::Frame;
use crate::load::check_ident;
use crate::load::scene::FrameDef;

impl Context<'_> {
    pub(super) fn frames(&mut self, defs: &[FrameDef]) -> Result<(), Error> {
        for f in defs {
            check_ident(self.source, &f.name, "frame")?;
            let ctx = format!("frame `{}`", f.name.get_ref());
            if f.name.get_ref() == "world" || self.frames.contains_key(f.name.get_ref()) {
                return Err(self.err(f.name.span().start, Some(&ctx), "frame is defined twice"));
            }
            let mut parent = match &f.parent {
                Some(p) => self.lookup_frame(p, &ctx)?,
                None => self.graph.world_frame(),
            };
            if let Some(station) = &f.station {
                parent = station_frame(self, f, station, &parent, &ctx)?;
            }
            let translation = match &f.translation {
                Some(t) => self.vector(t, Some(&ctx), false)?,
                None => [self.graph.constant(0.0); 3],
            };
            let mut rotations = Vec::with_capacity(f.rotation.len());
            for r in &f.rotation {
                let axis = self.axis(&r.axis, &ctx)?;
                let angle = self.scalar(&r.angle, Some(&ctx), false)?;
                match rotations.last_mut() {
                    Some((last, before)) if *last == axis && self.merges(*before, angle) => {
                        *before = self.graph.add(*before, angle);
                    }
                    _ => rotations.push((axis, angle)),
                }
            }
            let frame = self.child_frame(&parent, translation, &rotations);
            self.check_overflow(f.name.span().start, Some(&ctx), "the frame")?;
            self.frames.insert(f.name.get_ref().clone(), frame);
        }
        Ok(())
    }

    /// Whether two turns about one axis, in turn, are written as one turn
    /// by their sum: when both are constant, or one is and is no multiple
    /// of a quarter turn (`R(c) R(q) = R(c + q)` costs one addition, where
    /// the constant rotation would mix every vector it turns; a quarter
    /// turn only permutes and negates, for free).
    fn merges(&self, a: Id, b: Id) -> bool {
        let quarter = |x: f64| {
            let (s, c) = exact::sin_cos(x);
            s == 0.0 || c == 0.0
        };
        match (self.graph.as_const(a), self.graph.as_const(b)) {
            (Some(_), Some(_)) => true,
            (Some(x), None) | (None, Some(x)) => !quarter(x),
            (None, None) => false,
        }
    }

    /// The frame placed in `parent` as [`crate::geometry::Graph::child_frame`]
    /// does, added to the kinematic tree.
    pub(super) fn child_frame(
        &mut self,
        parent: &Frame,
        translation: [Id; 3],
        rotations: &[([f64; 3], Id)],
    ) -> Frame {
        let mut frame = self.graph.child_frame(parent, translation, rotations);
        let twist = self.graph.relative_twist(translation, rotations);
        frame.node = Some(self.placements.len());
        self.placements.push(Placement {
            parent: parent.node,
            translation,
            rotations: rotations.to_vec(),
            twist,
            velocity: [frame.velocity, frame.omega]
                .concat()
                .try_into()
                .expect("six"),
        });
        frame
    }
}
