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
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OVector, SVector, U1};

/// PD feedback of `U` actuators, each on one of `Q` coordinates (sizes
/// fixed or known at run time; [`JointPd`]: fixed), towards the references
/// `R`; a [`FeedbackLaw`] for [`super::Feedback`].
#[derive(Clone, Debug, PartialEq)]
pub struct JointPdOf<R, Q: Dim, U: Dim>
where
    DefaultAllocator: Allocator<U>,
{
    nq: Q,
    joints: OVector<usize, U>,
    kp: OVector<f64, U>,
    kd: OVector<f64, U>,
    reference: R,
}

/// [`JointPdOf`] of `NU` actuators on `NQ` coordinates (fixed sizes).
pub type JointPd<R, const NQ: usize, const NU: usize> = JointPdOf<R, Const<NQ>, Const<NU>>;

impl<R: Copy, const NQ: usize, const NU: usize> Copy for JointPd<R, NQ, NU> {}

impl<R, const NQ: usize, const NU: usize> JointPd<R, NQ, NU>
where
    R: Trajectory<Const<NU>>,
{
    /// Actuator `j` on coordinate `joints[j]` with gains `kp[j]`, `kd[j]`
    /// towards component `j` of `reference` ([`JointPdOf::of_sizes`]).
    pub fn new(
        joints: [usize; NU],
        kp: [f64; NU],
        kd: [f64; NU],
        reference: R,
    ) -> Result<Self, Error> {
        Self::of_sizes(
            Const,
            SVector::from(joints),
            SVector::from(kp),
            SVector::from(kd),
            reference,
        )
    }
}

impl<R, Q: Dim, U: Dim> JointPdOf<R, Q, U>
where
    R: Trajectory<U>,
    DefaultAllocator: Allocator<U>,
{
    /// Actuator `j` on coordinate `joints[j]` (of `nq`) with gains `kp[j]`,
    /// `kd[j]` towards component `j` of `reference`.
    ///
    /// Errors: [`ErrorKind::InvalidIndex`] if a joint index is not below
    /// `nq` (several actuators may act on one coordinate); [`ErrorKind::InvalidParameter`] if a gain is negative
    /// or not finite.
    pub fn of_sizes(
        nq: Q,
        joints: OVector<usize, U>,
        kp: OVector<f64, U>,
        kd: OVector<f64, U>,
        reference: R,
    ) -> Result<Self, Error> {
        check_indices("PD joint coordinate", joints.as_slice(), nq.value(), false)?;
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
        Ok(JointPdOf {
            nq,
            joints,
            kp,
            kd,
            reference,
        })
    }

    /// The coordinate each actuator acts on.
    pub fn joints(&self) -> &[usize] {
        self.joints.as_slice()
    }

    /// Proportional and derivative gains.
    pub fn gains(&self) -> (&[f64], &[f64]) {
        (self.kp.as_slice(), self.kd.as_slice())
    }

    /// The references.
    pub fn reference(&self) -> &R {
        &self.reference
    }
}

impl<R, Q: Dim, U: Dim> FeedbackLaw<Q, U> for JointPdOf<R, Q, U>
where
    R: Trajectory<U>,
    DefaultAllocator: Allocator<Q> + Allocator<U>,
{
    fn input(&self, q: &OVector<f64, Q>, qd: &OVector<f64, Q>, t: f64) -> OVector<f64, U> {
        let target = self.reference.at(t);
        let mut u = OVector::<f64, U>::zeros_generic(self.joints.shape_generic().0, U1);
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
