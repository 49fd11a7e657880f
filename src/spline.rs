//! Natural cubic splines: a sampled function of time with continuous first
//! and second derivatives, so that sampled prescriptions (`flexdyn inverse
//! --prescriptions`) have the accelerations inverse dynamics needs.
//!
//! Through samples `(t_k, y_k)`, `k = 0..n`, the spline is a cubic on each
//! interval, twice continuously differentiable, with zero second derivative
//! at both ends. Its second derivatives `m_k` at the samples solve the
//! tridiagonal system (interior `k`, `h_k = t_{k+1} - t_k`)
//!
//! ```text
//! h_{k-1} m_{k-1} + 2 (h_{k-1} + h_k) m_k + h_k m_{k+1}
//!     = 6 ((y_{k+1} - y_k) / h_k - (y_k - y_{k-1}) / h_{k-1}),   m_0 = m_n = 0
//! ```
//!
//! (Thomas algorithm: the matrix is diagonally dominant). On `[t_k,
//! t_{k+1}]`, with `a = (t_{k+1} - t) / h_k` and `b = 1 - a`,
//! `y = a y_k + b y_{k+1} + ((a^3 - a) m_k + (b^3 - b) m_{k+1}) h_k^2 / 6`.
//! Its error on a smooth function is `O(h^4)` in value (`O(h^2)` in the
//! second derivative) when the function's own second derivative vanishes
//! at the ends, `O(h^2)` near the ends otherwise.

use std::cmp::Ordering;

/// A natural cubic spline through samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Spline {
    t: Vec<f64>,
    y: Vec<f64>,
    /// Second derivatives at the samples.
    m: Vec<f64>,
}

impl Spline {
    /// The spline through `(t[k], y[k])`; `t` strictly increasing, at least
    /// two samples, as many values as times (an error otherwise).
    pub fn new(t: Vec<f64>, y: Vec<f64>) -> Result<Spline, String> {
        let n = t.len();
        if n < 2 || y.len() != n {
            return Err(format!(
                "a spline needs at least two samples and one value per time \
                 ({n} times, {} values)",
                y.len()
            ));
        }
        let increasing = |k: usize| t[k].partial_cmp(&t[k - 1]) == Some(Ordering::Greater);
        if let Some(k) = (1..n).find(|&k| !increasing(k)) {
            return Err(format!(
                "spline times must increase: t = {} after {}",
                t[k],
                t[k - 1]
            ));
        }
        let h: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let slope: Vec<f64> = (0..n - 1).map(|k| (y[k + 1] - y[k]) / h[k]).collect();
        let mut m = vec![0.0; n];
        // Forward elimination over the interior unknowns m_1..m_{n-2}.
        let (mut diag, mut rhs) = (vec![0.0; n], vec![0.0; n]);
        for k in 1..n - 1 {
            diag[k] = 2.0 * (h[k - 1] + h[k]);
            rhs[k] = 6.0 * (slope[k] - slope[k - 1]);
            if k > 1 {
                let w = h[k - 1] / diag[k - 1];
                diag[k] -= w * h[k - 1];
                rhs[k] -= w * rhs[k - 1];
            }
        }
        for k in (1..n - 1).rev() {
            m[k] = (rhs[k] - h[k] * m[k + 1]) / diag[k];
        }
        Ok(Spline { t, y, m })
    }

    /// The sampled time span.
    pub fn span(&self) -> (f64, f64) {
        (self.t[0], self.t[self.t.len() - 1])
    }

    /// Value, first and second derivative at `t` (the end cubics extended
    /// outside the span).
    pub fn eval(&self, t: f64) -> [f64; 3] {
        let k = self
            .t
            .partition_point(|&x| x <= t)
            .clamp(1, self.t.len() - 1)
            - 1;
        let h = self.t[k + 1] - self.t[k];
        let a = (self.t[k + 1] - t) / h;
        let b = 1.0 - a;
        let (m0, m1) = (self.m[k], self.m[k + 1]);
        let (y0, y1) = (self.y[k], self.y[k + 1]);
        let value = a * y0 + b * y1 + ((a * a * a - a) * m0 + (b * b * b - b) * m1) * h * h / 6.0;
        let rate =
            (y1 - y0) / h - (3.0 * a * a - 1.0) * h / 6.0 * m0 + (3.0 * b * b - 1.0) * h / 6.0 * m1;
        [value, rate, a * m0 + b * m1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight line is reproduced exactly (zero curvature everywhere).
    #[test]
    fn lines_are_reproduced() {
        let t = vec![0.0, 0.3, 0.5, 1.2, 2.0];
        let s = Spline::new(t.clone(), t.iter().map(|x| 2.0 - 3.0 * x).collect()).unwrap();
        for x in [0.0, 0.1, 0.7, 1.9, 2.0] {
            let [v, d, a] = s.eval(x);
            assert!((v - (2.0 - 3.0 * x)).abs() < 1e-14, "{v}");
            assert!((d + 3.0).abs() < 1e-13 && a.abs() < 1e-12, "{d} {a}");
        }
    }

    /// `sin t` on `[0, pi]` (zero curvature at both ends): the errors of
    /// value, rate and acceleration fall as `h^4`, `h^3`, `h^2`.
    #[test]
    fn smooth_functions_converge_at_the_expected_orders() {
        let errors = |n: usize| {
            let pi = std::f64::consts::PI;
            let t: Vec<f64> = (0..=n).map(|k| pi * k as f64 / n as f64).collect();
            let s = Spline::new(t.clone(), t.iter().map(|x| x.sin()).collect()).unwrap();
            let mut e = [0.0f64; 3];
            for k in 0..=1000 {
                let x = pi * k as f64 / 1000.0;
                let [v, d, a] = s.eval(x);
                e[0] = e[0].max((v - x.sin()).abs());
                e[1] = e[1].max((d - x.cos()).abs());
                e[2] = e[2].max((a + x.sin()).abs());
            }
            e
        };
        let (coarse, fine) = (errors(20), errors(40));
        for (i, order) in [4.0, 3.0, 2.0].iter().enumerate() {
            let observed = (coarse[i] / fine[i]).log2();
            assert!(
                observed > order - 0.3,
                "derivative {i}: order {observed} ({} -> {})",
                coarse[i],
                fine[i]
            );
        }
        assert!(fine[0] < 1e-6 && fine[2] < 1e-2, "{fine:?}");
    }

    #[test]
    fn bad_samples_are_refused() {
        assert!(Spline::new(vec![0.0], vec![1.0]).is_err());
        assert!(Spline::new(vec![0.0, 1.0], vec![1.0]).is_err());
        let e = Spline::new(vec![0.0, 1.0, 1.0], vec![1.0, 2.0, 3.0]).unwrap_err();
        assert!(e.contains("must increase"), "{e}");
    }
}
