//! Evaluating a tape: the public calls, which check their arguments and
//! run the tape's machine code where it has it (compiled on the first call,
//! `native`), else the interpreter (`tape`).

use super::tape::{Scratch, Tape, LANES};

impl Tape {
    /// Evaluate at `(q, qd, t)` with runtime parameter values `params`
    /// (in the scene's order), writing [`Tape::output_len`] values to `out`.
    /// `qd` may be empty when the function does not read it. `scratch` grows
    /// to the tape's size on first use and is reused after that.
    ///
    /// # Panics
    ///
    /// When a slice's length differs from the scene's dimensions (callers
    /// check states first, as `flexdyn eval` does).
    #[inline]
    pub fn eval(
        &self,
        q: &[f64],
        qd: &[f64],
        t: f64,
        params: &[f64],
        scratch: &mut Scratch,
        out: &mut [f64],
    ) {
        self.eval_with_accelerations(q, qd, &[], t, params, scratch, out);
    }

    /// [`Tape::eval`] with the accelerations `qdd` too (which may be empty
    /// when the function does not read them).
    ///
    /// # Panics
    ///
    /// As [`Tape::eval`].
    #[allow(clippy::too_many_arguments)]
    pub fn eval_with_accelerations(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: f64,
        params: &[f64],
        scratch: &mut Scratch,
        out: &mut [f64],
    ) {
        let nq = self.nq;
        assert_eq!(q.len(), nq, "expected {nq} positions, got {}", q.len());
        assert!(
            qd.len() == nq || (qd.is_empty() && !self.uses_qd),
            "expected {nq} velocities, got {}",
            qd.len()
        );
        assert!(
            qdd.len() == nq || (qdd.is_empty() && !self.uses_qdd),
            "expected {nq} accelerations, got {}",
            qdd.len()
        );
        assert_eq!(
            params.len(),
            self.params,
            "expected {} runtime parameters, got {}",
            self.params,
            params.len()
        );
        let len = self.output_len();
        assert_eq!(out.len(), len, "expected {len} outputs, got {}", out.len());
        #[cfg(feature = "jit")]
        if let Some(native) = self.native(&self.native, 1) {
            native.call(q, qd, qdd, &[t], params, out);
            return;
        }
        self.interpret(q, qd, qdd, t, params, scratch, out);
    }

    /// [`Tape::eval_with_accelerations`] of `n` states at once: `q` (and
    /// `qd`, `qdd` where the function reads them, else empty) hold `n`
    /// states of `nq` values one after the other, `t` one time per state,
    /// and `out` receives `n` times [`Tape::output_len`] values, state after
    /// state. The states run two at a time in machine code where the tape
    /// has it (vectors of two `f64`), else [`LANES`] at a time on the
    /// interpreter, each bitwise as [`Tape::eval`] computes it alone (the
    /// same operations in the same order, lane by lane).
    ///
    /// # Panics
    ///
    /// When a slice's length differs from `n` times the scene's dimensions.
    #[allow(clippy::too_many_arguments)]
    pub fn eval_batch(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: &[f64],
        params: &[f64],
        scratch: &mut Scratch<LANES>,
        out: &mut [f64],
    ) {
        let (nq, n, len) = (self.nq, t.len(), self.output_len());
        assert_eq!(
            q.len(),
            n * nq,
            "expected {n} x {nq} positions, got {}",
            q.len()
        );
        for (uses, x, what) in [
            (self.uses_qd, qd, "velocities"),
            (self.uses_qdd, qdd, "accelerations"),
        ] {
            assert!(
                x.len() == n * nq || (x.is_empty() && !uses),
                "expected {n} x {nq} {what}, got {}",
                x.len()
            );
        }
        assert_eq!(
            params.len(),
            self.params,
            "expected {} runtime parameters",
            self.params
        );
        assert_eq!(
            out.len(),
            n * len,
            "expected {n} x {len} outputs, got {}",
            out.len()
        );
        #[cfg(feature = "jit")]
        if let (Some(one), Some(two)) = (
            self.native(&self.native, 1),
            self.native(&self.native_pairs, 2),
        ) {
            // Machine code, two states a call (and the last one alone).
            fn part(x: &[f64], k: usize, n: usize, w: usize) -> &[f64] {
                x.get(k * w..(k + n) * w).unwrap_or(&[])
            }
            let mut k = 0;
            for o in out.chunks_mut(2 * len.max(1)) {
                let m = (t.len() - k).min(2);
                let native = if m == 2 { two } else { one };
                let (q, qd, qdd) = (part(q, k, m, nq), part(qd, k, m, nq), part(qdd, k, m, nq));
                native.call(q, qd, qdd, &t[k..k + m], params, o);
                k += m;
            }
            return;
        }
        self.interpret_batch(q, qd, qdd, t, params, scratch, out);
    }

    /// The tape's machine code, compiled on the first call; `None` where
    /// the tape is interpreted.
    #[cfg(feature = "jit")]
    fn native<'a>(
        &self,
        cell: &'a std::sync::OnceLock<Option<super::machine::Machine>>,
        lanes: usize,
    ) -> Option<&'a super::machine::Machine> {
        cell.get_or_init(|| super::native::compile(self, lanes))
            .as_ref()
    }
}
