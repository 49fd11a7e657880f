//! Progress of a long run on standard error, never with `--quiet`: on a
//! terminal, a bar that appears once the run has taken a second; otherwise
//! (a pipe, a file, a CI log) a plain line every few seconds, e.g.
//! `simulate: t = 1.23 s of 10 s (12 %), 3.4e5 steps, 8 s elapsed`. The
//! environment variable `FLEXDYN_PROGRESS_INTERVAL` sets the seconds between
//! those lines ([`DEFAULT_INTERVAL`] unless it holds a positive number).

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use flexdyn_runtime::Time;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Seconds between the progress lines written when standard error is not a
/// terminal.
pub const DEFAULT_INTERVAL: f64 = 5.0;

/// The environment variable that overrides [`DEFAULT_INTERVAL`].
pub const INTERVAL_VARIABLE: &str = "FLEXDYN_PROGRESS_INTERVAL";

/// How progress shows.
enum Display {
    /// Nothing (`--quiet`).
    Quiet,
    /// A bar on the terminal, hidden until the run has taken a second.
    Bar { bar: ProgressBar, shown: bool },
    /// A line every `interval`, the next at `next` since the start.
    Lines { interval: Duration, next: Duration },
}

/// Progress of a run of `len` steps.
pub struct Progress {
    display: Display,
    message: String,
    start: Instant,
    len: u64,
    position: u64,
    /// The simulated time reached, when known ([`Progress::inc_to`]).
    t: Option<f64>,
    /// The run's start and end times ([`Progress::timed`]).
    span: (f64, f64),
}

impl Progress {
    /// Progress of `len` steps, shown as `message` unless `quiet`.
    pub fn new(len: u64, message: &str, quiet: bool) -> Progress {
        let display = if quiet {
            Display::Quiet
        } else if std::io::stderr().is_terminal() {
            let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
            let style = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta} left)")
                .map(|s| s.progress_chars("=> "))
                .unwrap_or_else(|_| ProgressStyle::default_bar());
            bar.set_style(style);
            bar.set_message(message.to_owned());
            Display::Bar { bar, shown: false }
        } else {
            let interval = std::env::var(INTERVAL_VARIABLE)
                .ok()
                .and_then(|v| v.trim().parse::<f64>().ok())
                .and_then(|s| Duration::try_from_secs_f64(s).ok())
                .filter(|d| !d.is_zero())
                .unwrap_or(Duration::from_secs_f64(DEFAULT_INTERVAL));
            Display::Lines {
                interval,
                next: interval,
            }
        };
        Progress {
            display,
            message: message.to_owned(),
            start: Instant::now(),
            len,
            position: 0,
            t: None,
            span: (0.0, 0.0),
        }
    }

    /// Progress of a run from time `t0` to `end` (with
    /// [`Progress::inc_to`]), shown as the simulated time reached.
    pub fn timed(self, t0: f64, end: f64) -> Progress {
        Progress {
            span: (t0, end),
            ..self
        }
    }

    /// Record one finished step.
    pub fn inc(&mut self) {
        self.position += 1;
        match &mut self.display {
            Display::Quiet => {}
            Display::Bar { bar, shown } => {
                bar.inc(1);
                if !*shown && self.start.elapsed() > Duration::from_secs(1) {
                    bar.set_draw_target(ProgressDrawTarget::stderr());
                    *shown = true;
                }
            }
            Display::Lines { interval, next } => {
                let elapsed = self.start.elapsed();
                if elapsed >= *next {
                    *next = elapsed + *interval;
                    eprintln!("{}", self.line(elapsed));
                }
            }
        }
    }

    /// Record one finished step that reached the simulated time `t` (of
    /// the span given to [`Progress::timed`]).
    pub fn inc_to(&mut self, t: f64) {
        self.t = Some(t);
        self.inc();
    }

    /// The plain progress line.
    fn line(&self, elapsed: Duration) -> String {
        let steps = match self.position {
            n if n < 100_000 => n.to_string(),
            n => format!("{:.1e}", n as f64),
        };
        let elapsed = elapsed.as_secs_f64().round();
        let percent = |done: f64, all: f64| match all > 0.0 {
            true => (100.0 * done / all).floor(),
            false => 100.0,
        };
        match self.t {
            Some(t) => {
                let (t0, end) = self.span;
                format!(
                    "{}: t = {} s of {} s ({} %), {steps} steps, {elapsed} s elapsed",
                    self.message,
                    Time(rounded(t)),
                    Time(end),
                    percent(t - t0, end - t0)
                )
            }
            None => format!(
                "{}: {steps} of {} steps ({} %), {elapsed} s elapsed",
                self.message,
                self.len,
                percent(self.position as f64, self.len as f64)
            ),
        }
    }

    /// Remove the bar.
    pub fn finish(self) {
        if let Display::Bar { bar, .. } = self.display {
            bar.finish_and_clear();
        }
    }
}

/// `x` to four significant digits (a time of the progress line).
fn rounded(x: f64) -> f64 {
    format!("{x:.3e}").parse().unwrap_or(x)
}
