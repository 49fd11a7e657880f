//! A tape's machine code as the tape holds it: an entry point, the number
//! of states a call runs, the dimensions it was compiled for, and the
//! memory that holds it (`native` compiles it). Calls check their slices
//! against those dimensions.

use std::any::Any;
use std::sync::Arc;

/// `fn(q, qd, qdd, t, params, out)`: the caller's slices.
pub(super) type Entry =
    unsafe extern "C" fn(*const f64, *const f64, *const f64, *const f64, *const f64, *mut f64);

/// The dimensions code was compiled for.
#[derive(Debug, Clone, Copy)]
pub(super) struct Shape {
    pub(super) nq: usize,
    pub(super) uses_qd: bool,
    pub(super) uses_qdd: bool,
    pub(super) params: usize,
    /// Values written per state.
    pub(super) outputs: usize,
}

/// Machine code for one state a call or several side by side.
#[derive(Clone)]
pub(super) struct Machine {
    entry: Entry,
    lanes: usize,
    shape: Shape,
    /// Owns the code's memory; freed when the last clone goes.
    _owner: Arc<dyn Any + Send + Sync>,
}

impl std::fmt::Debug for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Machine({} states a call, {:?})", self.lanes, self.shape)
    }
}

impl Machine {
    /// # Safety
    ///
    /// `entry`, while `owner` lives, reads `lanes` states of `shape.nq`
    /// values from `q` (and `qd`, `qdd` where `shape` says it uses them),
    /// `lanes` times, `shape.params` parameters, and writes `lanes` times
    /// `shape.outputs` values to `out`, nothing else.
    pub(super) unsafe fn new(
        entry: Entry,
        lanes: usize,
        shape: Shape,
        owner: Arc<dyn Any + Send + Sync>,
    ) -> Machine {
        Machine {
            entry,
            lanes,
            shape,
            _owner: owner,
        }
    }

    /// Runs the code on its number of states (one after the other in the
    /// slices, `t` one time per state).
    ///
    /// # Panics
    ///
    /// When a slice is shorter than the states: `q` and `out` always, `qd`
    /// and `qdd` where the code reads them, `params` and `t`.
    pub(super) fn call(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        t: &[f64],
        params: &[f64],
        out: &mut [f64],
    ) {
        let (n, s) = (self.lanes, self.shape);
        assert!(
            q.len() >= n * s.nq
                && (qd.len() >= n * s.nq || !s.uses_qd)
                && (qdd.len() >= n * s.nq || !s.uses_qdd)
                && t.len() >= n
                && params.len() >= s.params
                && out.len() >= n * s.outputs,
            "arguments shorter than {n} states"
        );
        // SAFETY: the slices are at least as long as the code reads and
        // writes (`Machine::new`'s contract), checked above.
        unsafe {
            (self.entry)(
                q.as_ptr(),
                qd.as_ptr(),
                qdd.as_ptr(),
                t.as_ptr(),
                params.as_ptr(),
                out.as_mut_ptr(),
            )
        }
    }
}
