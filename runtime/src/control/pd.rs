//! Joint-space PD control: actuator `j` acts on coordinate `i_j` with
//!
//! ```text
//! u_j = kp_j (r_j(t) - q_{i_j}) + kd_j (rd_j(t) - qd_{i_j})
//! ```
//!
//! (`r`, `rd`: the values and rates of a [`Trajectory`]). On a coordinate
//! that actuator `j` drives alone with unit gain (`B[:, j] = e_{i_j}`) and
//! mass `m`, the error `e = r - q` of a constant reference obeys
//! `m e'' + kd e' + kp e = 0` (plus the model's own forces): natural
//! frequency `sqrt(kp / m)`, damping ratio `kd / (2 sqrt(kp m))`.

use super::{FeedbackLaw, Trajectory};
use crate::error::{check_indices, Error, ErrorKind};
use nalgebra::SVector;

/// PD feedback of `NU` actuators, each on one of `NQ` coordinates, towards
/// the references `R`; a [`FeedbackLaw`] for [`super::Feedback`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointPd<R, const NQ: usize, const NU: usize> {
    joints: [usize; NU],
    kp: [f64; NU],
    kd: [f64; NU],
    reference: R,
}

impl<R, const NQ: usize, const NU: usize> JointPd<R, NQ, NU>
where
    R: Trajectory<NU>,
{
    /// Actuator `j` on coordinate `joints[j]` with gains `kp[j]`, `kd[j]`
    /// towards component `j` of `reference`.
    ///
    /// Errors: [`ErrorKind::InvalidIndex`] if a joint index is not below
    /// `NQ` (several actuators may act on one coordinate); [`ErrorKind::InvalidParameter`] if a gain is negative
    /// or not finite.
    pub fn new(
        joints: [usize; NU],
        kp: [f64; NU],
        kd: [f64; NU],
        reference: R,
    ) -> Result<Self, Error> {
        check_indices("PD joint coordinate", &joints, NQ, false)?;
        for (what, gains) in [
            ("proportional gain kp (finite, >= 0)", &kp),
            ("derivative gain kd (finite, >= 0)", &kd),
        ] {
            if let Some(index) = gains.iter().position(|g| !(g.is_finite() && *g >= 0.0)) {
                return Err(Error::new(
                    ErrorKind::InvalidParameter {
                        what,
                        index,
                        value: gains[index],
                    },
                    0.0,
                ));
            }
        }
        Ok(JointPd {
            joints,
            kp,
            kd,
            reference,
        })
    }

    /// The coordinate each actuator acts on.
    pub fn joints(&self) -> &[usize; NU] {
        &self.joints
    }

    /// Proportional and derivative gains.
    pub fn gains(&self) -> (&[f64; NU], &[f64; NU]) {
        (&self.kp, &self.kd)
    }

    /// The references.
    pub fn reference(&self) -> &R {
        &self.reference
    }
}

impl<R, const NQ: usize, const NU: usize> FeedbackLaw<NQ, NU> for JointPd<R, NQ, NU>
where
    R: Trajectory<NU>,
{
    fn input(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64) -> SVector<f64, NU> {
        let target = self.reference.at(t);
        let mut u = SVector::<f64, NU>::zeros();
        for (j, &i) in self.joints.iter().enumerate() {
            // `new` checked `i < NQ`; `get` keeps this panic-free regardless.
            let (qi, qdi) = match (q.get(i), qd.get(i)) {
                (Some(&qi), Some(&qdi)) => (qi, qdi),
                _ => (f64::NAN, f64::NAN),
            };
            u[j] = self.kp[j] * (target.position[j] - qi) + self.kd[j] * (target.velocity[j] - qdi);
        }
        u
    }
}
