//! The number of steps of a run: `--duration` over `--dt`, checked before
//! the run and refused beyond a limit (`--max-steps`, [`MAX_STEPS`] unless
//! given), so that a mistyped step or duration (`--dt 1e-300`,
//! `--duration 1e12`) is an error naming the values and the limit, not an
//! endless run. The commands stream their rows, so a raised limit costs
//! time, not memory.

use flexdyn_runtime::Time;

/// The default of `--max-steps`: 10^7 steps.
pub const MAX_STEPS: u64 = 10_000_000;

/// How the steps of `dt` meet the end of the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Last {
    /// The last step is shortened to end at the duration (at least one
    /// step; the duration must be positive): `simulate`.
    Shortened,
    /// Outputs at `0, dt, 2 dt, ...` up to the duration (inclusive, to
    /// rounding; a duration of 0 gives none after the first): `inverse`.
    Within,
}

/// The number of steps of `dt` s in `duration` s, ended as `last` says.
/// Errors name `--dt` or `--duration` and the value given, or both values,
/// the step count and the limit `max_steps` (and `--max-steps`, which
/// raises it). Never overflows: a count beyond the limit, however large, is
/// an error.
pub fn count(duration: f64, dt: f64, last: Last, max_steps: u64) -> Result<u64, String> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(format!(
            "--dt: the step must be a positive number of seconds, got {dt}"
        ));
    }
    let least_ok = match last {
        Last::Shortened => duration > 0.0,
        Last::Within => duration >= 0.0,
    };
    if !(duration.is_finite() && least_ok) {
        let least = match last {
            Last::Shortened => "positive",
            Last::Within => "non-negative",
        };
        return Err(format!(
            "--duration: the duration must be a {least} number of seconds, got {duration}"
        ));
    }
    let ratio = duration / dt;
    let steps = match last {
        Last::Shortened => (ratio - 1e-9).ceil().max(1.0),
        Last::Within => (ratio * (1.0 + 1e-12)).floor(),
    };
    // Infinite when `duration / dt` overflows: refused too.
    if steps > max_steps as f64 {
        return Err(format!(
            "--duration {} s at --dt {} s is {steps:.3e} steps; at most {max_steps} are allowed \
             (`--max-steps N` raises the limit)",
            Time(duration),
            Time(dt)
        ));
    }
    Ok(steps as u64)
}

/// How many steps of `step` s (named `step_name`, e.g. `--dt`) make one of
/// `output` s (named `output_name`, e.g. `--output-dt`): a positive whole
/// number, to a relative 1e-9. Errors name both options and values.
pub fn per_output(
    output_name: &str,
    output: f64,
    step_name: &str,
    step: f64,
) -> Result<u64, String> {
    if !(output.is_finite() && output > 0.0) {
        return Err(format!(
            "{output_name}: the step must be a positive number of seconds, got {output}"
        ));
    }
    let ratio = output / step;
    if !((ratio - ratio.round()).abs() <= 1e-9 * ratio && ratio.round() >= 1.0) {
        return Err(format!(
            "{output_name} {} s must be a whole multiple of {step_name} {} s",
            Time(output),
            Time(step)
        ));
    }
    Ok(ratio.round() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_refusals() {
        assert_eq!(count(1.0, 0.01, Last::Within, MAX_STEPS), Ok(100));
        assert_eq!(count(1.0, 0.01, Last::Shortened, MAX_STEPS), Ok(100));
        assert_eq!(count(1.0, 0.3, Last::Within, MAX_STEPS), Ok(3));
        assert_eq!(count(1.0, 0.3, Last::Shortened, MAX_STEPS), Ok(4));
        assert_eq!(count(0.0, 0.1, Last::Within, MAX_STEPS), Ok(0));
        assert_eq!(count(1e5, 0.01, Last::Within, MAX_STEPS), Ok(10_000_000));
        for (duration, dt) in [(1.0, 1e-300), (1e12, 0.01), (1e300, 1e-320), (1e5, 0.0099)] {
            let e = count(duration, dt, Last::Within, MAX_STEPS).unwrap_err();
            assert!(
                e.contains(&format!(
                    "--duration {} s at --dt {} s",
                    Time(duration),
                    Time(dt)
                )) && e.contains("at most 10000000 are allowed")
                    && e.contains("--max-steps"),
                "{e}"
            );
        }
        assert_eq!(
            count(1e7, 0.01, Last::Within, 2_000_000_000),
            Ok(1_000_000_000)
        );
        for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = count(1.0, dt, Last::Shortened, MAX_STEPS).unwrap_err();
            assert!(e.starts_with("--dt: the step must be a positive"), "{e}");
        }
        let e = count(0.0, 0.1, Last::Shortened, MAX_STEPS).unwrap_err();
        assert!(
            e.contains("--duration: the duration must be a positive"),
            "{e}"
        );
        let e = count(f64::NAN, 0.1, Last::Within, MAX_STEPS).unwrap_err();
        assert!(e.contains("must be a non-negative number"), "{e}");
    }

    #[test]
    fn outputs_are_whole_multiples_of_the_step() {
        assert_eq!(per_output("--output-dt", 0.01, "--dt", 0.001), Ok(10));
        assert_eq!(per_output("--output-dt", 0.3, "--dt", 0.1), Ok(3));
        assert_eq!(per_output("--output-dt", 0.001, "--dt", 0.001), Ok(1));
        for (output, step) in [(0.0015, 0.001), (0.0005, 0.001), (1e300, 1e-300)] {
            let e = per_output("--output-dt", output, "--dt", step).unwrap_err();
            assert!(e.contains("must be a whole multiple of --dt"), "{e}");
        }
        for output in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = per_output("--output-dt", output, "--dt", 0.1).unwrap_err();
            assert!(
                e.starts_with("--output-dt: the step must be a positive"),
                "{e}"
            );
        }
    }
}
