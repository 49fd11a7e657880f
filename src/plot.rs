//! Line plots as PNG or SVG (chosen by the file extension), with an embedded
//! font so that they render the same on any machine.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

/// One curve: a label and its points.
pub struct Series<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
}

/// The most rows of a run a plot keeps ([`Decimated`]).
pub const PLOT_ROWS: usize = 4096;

/// A bounded, evenly spaced copy of a run's rows for its plot: every row
/// while there are at most `capacity`, then every second one, every fourth,
/// ... (each time the copy is full, every other row is dropped and the
/// stride doubles), plus the last row. Its memory does not grow with the
/// number of rows.
pub struct Decimated {
    rows: Vec<Vec<f64>>,
    capacity: usize,
    stride: u64,
    seen: u64,
    last: Vec<f64>,
}

impl Decimated {
    /// An empty copy of at most `capacity` rows (even, at least 2) and the
    /// last one.
    pub fn new(capacity: usize) -> Decimated {
        Decimated {
            rows: Vec::new(),
            capacity: capacity.max(2) & !1,
            stride: 1,
            seen: 0,
            last: Vec::new(),
        }
    }

    /// Offer the next row of the run.
    pub fn push(&mut self, row: &[f64]) {
        if self.seen.is_multiple_of(self.stride) {
            if self.rows.len() == self.capacity {
                // Rows 0, s, 2s, ... become 0, 2s, 4s, ...; `seen`, at
                // `capacity * s`, is a multiple of the new stride.
                let mut k = 0;
                self.rows.retain(|_| {
                    k += 1;
                    k % 2 == 1
                });
                self.stride *= 2;
            }
            self.rows.push(row.to_vec());
        }
        self.seen += 1;
        self.last.clear();
        self.last.extend_from_slice(row);
    }

    /// The rows kept, the last row of the run included.
    pub fn rows(mut self) -> Vec<Vec<f64>> {
        if self
            .seen
            .checked_sub(1)
            .is_some_and(|k| !k.is_multiple_of(self.stride))
        {
            self.rows.push(self.last);
        }
        self.rows
    }
}

/// Axis texts of a plot.
pub struct Labels<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// Horizontal axis.
    pub x: &'a str,
    /// Vertical axis.
    pub y: &'a str,
}

static FONT: Once = Once::new();

fn register() {
    FONT.call_once(|| {
        // The font is a static byte slice of the `dejavu` crate; registering
        // it cannot fail for a valid font.
        let _ = register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Draw `series` against a common horizontal axis into `path` (`.png` or `.svg`).
pub fn line_plot(path: &Path, labels: &Labels, series: &[Series]) -> Result<(), String> {
    register();
    let size = (960, 540);
    match format(path)? {
        Format::Png => draw(
            BitMapBackend::new(path, size).into_drawing_area(),
            labels,
            series,
        ),
        Format::Svg => draw(
            SVGBackend::new(path, size).into_drawing_area(),
            labels,
            series,
        ),
    }
}

/// Image formats, chosen by the file extension.
enum Format {
    Png,
    Svg,
}

fn format(path: &Path) -> Result<Format, String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    match ext.as_str() {
        "png" => Ok(Format::Png),
        "svg" => Ok(Format::Svg),
        _ => Err(format!(
            "cannot plot to {}: the file name must end in .png or .svg",
            path.display()
        )),
    }
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    labels: &Labels,
    series: &[Series],
) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| format!("plotting failed: {e}");
    let all = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return Err("nothing to plot: no finite points".into());
    }
    if x1 - x0 < 1e-300 {
        x1 = x0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.05).max(1e-12);
    let (y0, y1) = (y0 - pad, y1 + pad);
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(labels.title, ("sans-serif", 24))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(labels.x)
        .y_desc(labels.y)
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    for (k, s) in series.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                s.points.iter().copied(),
                color.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(s.label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// Draw groups of points on log-log axes into `path` (`.png` or `.svg`), each
/// group in its own colour and marker, with `front` (for example a Pareto
/// front) as a black line. Points that are not positive are left out.
pub fn scatter_plot(
    path: &Path,
    labels: &Labels,
    groups: &[(String, Vec<(f64, f64)>)],
    front: &[(f64, f64)],
) -> Result<(), String> {
    register();
    let all: Vec<(f64, f64)> = groups
        .iter()
        .flat_map(|(_, p)| p.iter().copied())
        .filter(on_log_axes)
        .collect();
    if all.is_empty() {
        return Err("nothing to plot: no positive finite points".into());
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let widen = |a: f64, b: f64| (a / 1.5, b * 1.5);
    let ((x0, x1), (y0, y1)) = (widen(x0, x1), widen(y0, y1));
    let size = (1000, 640);
    let bounds = ((x0, x1), (y0, y1));
    match format(path)? {
        Format::Png => draw_scatter(
            BitMapBackend::new(path, size).into_drawing_area(),
            labels,
            groups,
            front,
            bounds,
        ),
        Format::Svg => draw_scatter(
            SVGBackend::new(path, size).into_drawing_area(),
            labels,
            groups,
            front,
            bounds,
        ),
    }
}

type Bounds = ((f64, f64), (f64, f64));

/// Whether a point can be drawn on log-log axes.
fn on_log_axes(&(x, y): &(f64, f64)) -> bool {
    x.is_finite() && y.is_finite() && x > 0.0 && y > 0.0
}

fn draw_scatter<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    labels: &Labels,
    groups: &[(String, Vec<(f64, f64)>)],
    front: &[(f64, f64)],
    ((x0, x1), (y0, y1)): Bounds,
) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| format!("plotting failed: {e}");
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(labels.title, ("sans-serif", 24))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(80)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(labels.x)
        .y_desc(labels.y)
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    for (k, (label, pts)) in groups.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let pts: Vec<(f64, f64)> = pts.iter().copied().filter(on_log_axes).collect();
        let style = color.filled();
        let anno = match k / COLORS.len() {
            0 => chart.draw_series(pts.iter().map(|&p| Circle::new(p, 5, style).into_dyn())),
            1 => chart.draw_series(
                pts.iter()
                    .map(|&p| TriangleMarker::new(p, 6, style).into_dyn()),
            ),
            _ => chart.draw_series(
                pts.iter()
                    .map(|&p| Cross::new(p, 5, color.stroke_width(2)).into_dyn()),
            ),
        }
        .map_err(|e| err(&e))?;
        let shape = k / COLORS.len();
        anno.label(label.as_str())
            .legend(move |(x, y)| match shape {
                0 => Circle::new((x + 10, y), 5, style).into_dyn(),
                1 => TriangleMarker::new((x + 10, y), 6, style).into_dyn(),
                _ => Cross::new((x + 10, y), 5, color.stroke_width(2)).into_dyn(),
            });
    }
    let line: Vec<(f64, f64)> = front.iter().copied().filter(on_log_axes).collect();
    chart
        .draw_series(LineSeries::new(line, BLACK.stroke_width(1)))
        .map_err(|e| err(&e))?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimated_rows_are_bounded_evenly_spaced_and_end_at_the_last() {
        for n in [0u64, 1, 7, 8, 9, 100, 1001] {
            let mut d = Decimated::new(8);
            for k in 0..n {
                d.push(&[k as f64]);
            }
            let kept: Vec<u64> = d.rows().iter().map(|r| r[0] as u64).collect();
            assert!(kept.len() <= 9, "{n}: {kept:?}");
            if n == 0 {
                assert!(kept.is_empty());
                continue;
            }
            assert_eq!(kept.last(), Some(&(n - 1)), "{n}: {kept:?}");
            // Every kept row but the last at a multiple of one stride.
            let body = &kept[..kept.len() - usize::from(kept.len() > 1)];
            let stride = body.get(1).map_or(1, |s| *s);
            assert!(body
                .iter()
                .enumerate()
                .all(|(i, k)| *k == i as u64 * stride));
            assert!(n <= 8 || kept.len() >= 5, "{n}: {kept:?}");
        }
    }
}
