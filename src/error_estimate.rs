//! The error estimate of a `simulate` run: a companion run at a coarser
//! resolution (the fixed-step integrators at twice the step, adaptive RK4 at
//! 16 times the tolerance and to every second output time only) goes along
//! with the run, and their difference at the common times, divided by how
//! much more the coarse run errs (Richardson: `2^p - 1` for a method of
//! order `p`), estimates the error of
//! every coordinate and rate. It is reported relative to each quantity's own
//! scale (its largest magnitude in the run), as the largest over the run,
//! with a warning above [`WARN_ABOVE`] and a step (or tolerance) that would
//! bring it near [`AIM`].
//!
//! The estimate holds where both runs are in their asymptotic range; where
//! they are not, the difference is large and the warning is the right
//! answer. A companion step that fails (a step past the stability limit, a
//! diverging iteration) is itself a warning: the run's step is within a
//! factor of two of where the integrator stops working.

use std::cmp::Ordering;

use flexdyn_runtime::Time;

/// Relative error above which the estimate is a warning.
pub const WARN_ABOVE: f64 = 1e-3;

/// The relative error the suggested step or tolerance aims at.
pub const AIM: f64 = 1e-4;

/// What the companion run is, and how to read its difference.
#[derive(Clone, Copy, Debug)]
pub enum Companion {
    /// A fixed-step integrator of order `order` at twice the step `dt`.
    Doubled { order: u32, dt: f64 },
    /// Adaptive RK4 at 16 times the relative tolerance `tolerance`, to
    /// every second output time. Where the tolerance limits the steps, the
    /// error grows as `tolerance^(4/5)` (error per step controlled, locally
    /// fifth order): 16 times the tolerance errs about 9.2 times more. Where
    /// the output times limit them, steps twice as long err about 16 times
    /// more. The estimate divides by the smaller factor.
    Loosened { tolerance: f64 },
}

/// The loosening factor of [`Companion::Loosened`].
pub const LOOSENED: f64 = 16.0;

impl Companion {
    /// How many times more the companion errs than the run, minus one.
    fn divisor(self) -> f64 {
        match self {
            Companion::Doubled { order, .. } => 2f64.powi(order as i32) - 1.0,
            Companion::Loosened { .. } => LOOSENED.powf(0.8) - 1.0,
        }
    }

    /// What the companion is, for the report.
    fn describe(self) -> String {
        match self {
            Companion::Doubled { dt, .. } => format!("at 2 x --dt = {} s", Time(2.0 * dt)),
            Companion::Loosened { tolerance } => format!(
                "at {LOOSENED} x --tolerance = {:e}, every second output",
                LOOSENED * tolerance
            ),
        }
    }

    /// The option and value that would bring a relative error `e` near
    /// [`AIM`].
    fn advice(self, e: f64) -> String {
        match self {
            Companion::Doubled { order, dt } => format!(
                "--dt {} s",
                Time(two_digits(dt * (AIM / e).powf(1.0 / f64::from(order))))
            ),
            Companion::Loosened { tolerance } => {
                format!(
                    "--tolerance {:e}",
                    two_digits(tolerance * (AIM / e).powf(1.25))
                )
            }
        }
    }
}

/// `x` to two significant digits.
fn two_digits(x: f64) -> f64 {
    format!("{x:.1e}").parse().unwrap_or(x)
}

/// The estimate as the run goes.
pub struct ErrorEstimate {
    companion: Companion,
    /// The compared quantities: coordinates, then `<name>_dot`.
    names: Vec<String>,
    /// Largest magnitude of each quantity in the run.
    scale: Vec<f64>,
    /// Largest estimated error of each quantity, and when.
    worst: Vec<(f64, f64)>,
    /// Why the companion stopped, and when.
    failed: Option<(f64, String)>,
    /// Whether any time was compared.
    compared: bool,
}

impl ErrorEstimate {
    /// An estimate of the quantities `names` (coordinates, then rates).
    pub fn new(companion: Companion, names: Vec<String>) -> ErrorEstimate {
        let n = names.len();
        ErrorEstimate {
            companion,
            names,
            scale: vec![0.0; n],
            worst: vec![(0.0, 0.0); n],
            failed: None,
            compared: false,
        }
    }

    /// Takes the run's quantities `y` at a time into their scales.
    pub fn scale(&mut self, y: impl Iterator<Item = f64>) {
        for (s, v) in self.scale.iter_mut().zip(y) {
            *s = s.max(v.abs());
        }
    }

    /// Compares the run's `y` with the companion's `c` at time `t`.
    pub fn compare(&mut self, t: f64, y: impl Iterator<Item = f64>, c: impl Iterator<Item = f64>) {
        let divisor = self.companion.divisor();
        for (w, (a, b)) in self.worst.iter_mut().zip(y.zip(c)) {
            // A non-finite difference is an infinite error.
            let e = match (a - b).abs() / divisor {
                e if e.is_nan() => f64::INFINITY,
                e => e,
            };
            if e > w.0 {
                *w = (e, t);
            }
        }
        self.compared = true;
    }

    /// The companion stopped at `t` for `why`; the estimate keeps what it
    /// compared before.
    pub fn fail(&mut self, t: f64, why: String) {
        self.failed = Some((t, why));
    }

    /// The largest relative error, its quantity and time.
    fn largest(&self) -> Option<(f64, &str, f64)> {
        // A quantity that stays at zero is measured against its kind's
        // largest scale (1e-6 of it), not against zero.
        let n = self.names.len() / 2;
        let floor = |k: usize| {
            let kind = if k < n { 0..n } else { n..2 * n };
            1e-6 * self.scale[kind].iter().fold(0.0f64, |a, &b| a.max(b))
        };
        (0..self.names.len())
            .map(|k| {
                let scale = self.scale[k].max(floor(k)).max(f64::MIN_POSITIVE);
                (
                    self.worst[k].0 / scale,
                    self.names[k].as_str(),
                    self.worst[k].1,
                )
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
    }

    /// What to print at the end of the run: notes (printed unless quiet)
    /// and warnings.
    pub fn report(&self) -> (Vec<String>, Vec<String>) {
        let (mut notes, mut warnings) = (Vec::new(), Vec::new());
        let what = self.companion.describe();
        if let Some((t, why)) = &self.failed {
            warnings.push(format!(
                "warning: the error estimate's companion run ({what}) failed at t = {} s: {why}; \
                 this run's step is within a factor of two of where the integrator stops \
                 working, so its answer is not to be trusted far beyond that time",
                Time(*t)
            ));
        }
        if !self.compared {
            return (notes, warnings);
        }
        let Some((e, name, t)) = self.largest() else {
            return (notes, warnings);
        };
        let until = match &self.failed {
            Some((at, _)) => format!(" (until t = {} s)", Time(*at)),
            None => String::new(),
        };
        let figure = match e.is_finite() {
            true => format!("{e:.1e}"),
            false => "unbounded".into(),
        };
        notes.push(format!(
            "error estimate (companion run {what}){until}: largest {figure} of its scale, \
             `{name}` at t = {} s",
            Time(t)
        ));
        // Above, or not a number.
        if !matches!(
            e.partial_cmp(&WARN_ABOVE),
            Some(Ordering::Less | Ordering::Equal)
        ) {
            let advice = match e.is_finite() {
                true => format!("; {} would bring it near {AIM:e}", self.companion.advice(e)),
                false => String::new(),
            };
            warnings.push(format!(
                "warning: the estimated error of `{name}` reaches {figure} of its scale \
                 (at t = {} s; more than {WARN_ABOVE:e}): this run is not to be trusted{advice}",
                Time(t)
            ));
        }
        (notes, warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        ["x", "y", "x_dot", "y_dot"].map(String::from).to_vec()
    }

    #[test]
    fn richardson_divisor_and_scales() {
        let mut e = ErrorEstimate::new(Companion::Doubled { order: 4, dt: 0.01 }, names());
        e.scale([2.0, 0.0, 1.0, 0.0].into_iter());
        // x errs by 15e-6 / 15 = 1e-6, which is 5e-7 of its scale 2; y
        // stays at zero, measured against 1e-6 of x's scale.
        e.compare(
            0.5,
            [2.0, 0.0, 1.0, 0.0].into_iter(),
            [2.0 + 15e-6, 0.0, 1.0, 0.0].into_iter(),
        );
        let (e, name, t) = e.largest().unwrap();
        assert_eq!((name, t), ("x", 0.5));
        // (2 + 15e-6) - 2 keeps 15e-6 to about 1e-11 relative.
        assert!((e - 5e-7).abs() < 1e-10 * 5e-7, "{e}");
    }

    #[test]
    fn warns_above_the_limit_and_advises_a_step() {
        let mut e = ErrorEstimate::new(Companion::Doubled { order: 2, dt: 0.01 }, names());
        e.scale([1.0, 1.0, 1.0, 1.0].into_iter());
        e.compare(1.0, [1.0; 4].into_iter(), [1.0, 1.0, 1.0, 1.03].into_iter());
        let (notes, warnings) = e.report();
        assert!(
            notes[0].contains("largest 1.0e-2 of its scale, `y_dot` at t = 1 s"),
            "{notes:?}"
        );
        // 1e-2 at order 2: a step 10 times smaller gives 1e-4.
        assert!(
            warnings[0].contains("--dt 0.001 s would bring it near 1e-4"),
            "{warnings:?}"
        );
        let mut quiet = ErrorEstimate::new(Companion::Loosened { tolerance: 1e-8 }, names());
        quiet.scale([1.0; 4].into_iter());
        quiet.compare(1.0, [1.0; 4].into_iter(), [1.0 + 1e-9; 4].into_iter());
        assert!(quiet.report().1.is_empty());
    }

    #[test]
    fn a_failed_companion_is_a_warning() {
        let mut e = ErrorEstimate::new(Companion::Doubled { order: 4, dt: 0.01 }, names());
        e.fail(0.25, "step too large".into());
        let (notes, warnings) = e.report();
        assert!(notes.is_empty());
        assert!(
            warnings[0].contains("failed at t = 0.25 s: step too large"),
            "{warnings:?}"
        );
        let mut nan = ErrorEstimate::new(Companion::Doubled { order: 4, dt: 0.01 }, names());
        nan.compare(0.1, [1.0; 4].into_iter(), [f64::NAN; 4].into_iter());
        assert!(nan.report().1[0].contains("reaches unbounded"));
    }
}
