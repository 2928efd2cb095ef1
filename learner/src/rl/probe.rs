//! A linear probe: ridge least squares from feature vectors (a frozen
//! representation's z means) to targets (the tip's offset from the hole),
//! the features standardised by the fitting rows' mean and deviation, with
//! a bias. `repr_probe` scores representations with it; the touch search
//! told the hole by a representation ([`super::search::ProbedSearchView`])
//! acts on its predictions.

use serde::{Deserialize, Serialize};

/// A fitted probe.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearProbe {
    /// Mean of each feature over the fitting rows.
    pub mean: Vec<f64>,
    /// Standard deviation of each feature (at least 10⁻¹²).
    pub sd: Vec<f64>,
    /// Weights, row-major: (features + 1) × targets, the bias row last.
    pub weights: Vec<f64>,
    /// Number of targets.
    pub targets: usize,
}

/// Why a probe cannot be fitted.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ProbeError {
    /// No rows, or rows of different lengths.
    #[error("a probe needs rows of one length, at least one: {0}")]
    Shape(String),
    /// A feature or a target is not finite.
    #[error("a probe's data must be finite: row {0} is not")]
    NotFinite(usize),
    /// The ridge is negative or not finite.
    #[error("a probe's ridge must be finite and not negative, not {0}")]
    Ridge(f64),
    /// With no ridge, some features are linear combinations of others.
    #[error("the features are collinear; fit with a positive ridge")]
    Collinear,
    /// A probe read from a file that no fit could have made.
    #[error("not a fitted probe: {0}")]
    Malformed(String),
}

/// Mean and standard deviation (at least 10⁻¹²) of each of the `d`
/// features over `rows`.
pub fn standardiser<'a>(
    rows: impl Iterator<Item = &'a [f64]> + Clone,
    d: usize,
) -> (Vec<f64>, Vec<f64>) {
    let n = rows.clone().count().max(1) as f64;
    let mut mean = vec![0.0; d];
    for r in rows.clone() {
        for (m, v) in mean.iter_mut().zip(r) {
            *m += v / n;
        }
    }
    let mut var = vec![0.0; d];
    for r in rows {
        for ((s, v), m) in var.iter_mut().zip(r).zip(&mean) {
            *s += (v - m).powi(2) / n;
        }
    }
    (mean, var.into_iter().map(|v| v.sqrt().max(1e-12)).collect())
}

impl LinearProbe {
    /// Fits `y` (rows of targets) from `x` (rows of features) with ridge
    /// `ridge` per row (the penalty on the weights, not the bias, is
    /// `ridge · rows`).
    pub fn fit(x: &[Vec<f64>], y: &[Vec<f64>], ridge: f64) -> Result<Self, ProbeError> {
        use faer::Mat;
        use faer::prelude::*;
        if !(ridge.is_finite() && ridge >= 0.0) {
            return Err(ProbeError::Ridge(ridge));
        }
        let n = x.len();
        if n == 0 || n != y.len() {
            return Err(ProbeError::Shape(format!(
                "{n} feature rows, {} target rows",
                y.len()
            )));
        }
        let (d, k) = (x[0].len(), y[0].len());
        if d == 0 || k == 0 {
            return Err(ProbeError::Shape(format!("{d} features, {k} targets")));
        }
        for (i, (a, b)) in x.iter().zip(y).enumerate() {
            if a.len() != d || b.len() != k {
                return Err(ProbeError::Shape(format!(
                    "row {i} has {} features and {} targets, row 0 {d} and {k}",
                    a.len(),
                    b.len()
                )));
            }
            if !a.iter().chain(b).all(|v| v.is_finite()) {
                return Err(ProbeError::NotFinite(i));
            }
        }
        let (mean, sd) = standardiser(x.iter().map(Vec::as_slice), d);
        let mut probe = Self {
            mean,
            sd,
            weights: Vec::new(),
            targets: k,
        };
        let a = Mat::<f64>::from_fn(n, d + 1, |i, c| probe.feature(&x[i], c));
        let b = Mat::<f64>::from_fn(n, k, |i, t| y[i][t]);
        let ata = a.transpose() * &a;
        let m = Mat::<f64>::from_fn(d + 1, d + 1, |i, j| {
            // The bias (last) is not penalised: a strong ridge shrinks
            // towards the mean target, not towards 0.
            ata[(i, j)]
                + if i == j && i < d {
                    ridge * n as f64
                } else {
                    0.0
                }
        });
        let w = match m.llt(faer::Side::Lower) {
            Ok(llt) => llt.solve(a.transpose() * &b),
            // Only a zero ridge on collinear features gets here (the bias
            // column is all ones, never zero).
            Err(_) => return Err(ProbeError::Collinear),
        };
        probe.weights = (0..=d)
            .flat_map(|c| (0..k).map(move |t| (c, t)))
            .map(|(c, t)| w[(c, t)])
            .collect();
        Ok(probe)
    }

    /// Feature `c` of row `r`, standardised (`c` = the feature count: the
    /// bias, 1).
    fn feature(&self, r: &[f64], c: usize) -> f64 {
        if c == self.mean.len() {
            1.0
        } else {
            (r[c] - self.mean[c]) / self.sd[c]
        }
    }

    /// Refuses a probe that no fit could have made (one read from a file):
    /// inconsistent lengths, a deviation that is not positive, a value that
    /// is not finite. Prediction assumes this holds.
    pub fn check(&self) -> Result<(), ProbeError> {
        let d = self.mean.len();
        if d == 0 || self.targets == 0 || self.sd.len() != d {
            return Err(ProbeError::Malformed(format!(
                "{d} means, {} deviations, {} targets",
                self.sd.len(),
                self.targets
            )));
        }
        if self.weights.len() != (d + 1) * self.targets {
            return Err(ProbeError::Malformed(format!(
                "{} weights; {d} features and {} targets need {}",
                self.weights.len(),
                self.targets,
                (d + 1) * self.targets
            )));
        }
        if !self.sd.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(ProbeError::Malformed(
                "a deviation is not positive and finite".into(),
            ));
        }
        if !self.mean.iter().chain(&self.weights).all(|v| v.is_finite()) {
            return Err(ProbeError::Malformed("a value is not finite".into()));
        }
        Ok(())
    }

    /// Number of features it takes.
    pub fn features(&self) -> usize {
        self.mean.len()
    }

    /// The predicted targets of one feature row, written into `out`
    /// (`targets` values).
    pub fn predict_into(&self, r: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for c in 0..=self.mean.len() {
            let f = self.feature(r, c);
            let w = &self.weights[c * self.targets..(c + 1) * self.targets];
            for (o, w) in out.iter_mut().zip(w) {
                *o += f * w;
            }
        }
    }

    /// The predicted targets of one feature row.
    pub fn predict(&self, r: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.targets];
        self.predict_into(r, &mut out);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_linear_map_is_recovered_and_bad_rows_are_named() {
        // y = (2 a − b + 3, 0.5 b) on scattered rows; a small ridge.
        let mut rng = stack_common::rng::seeded(5, 0);
        let x: Vec<Vec<f64>> = (0..200)
            .map(|_| {
                vec![
                    stack_common::rng::uniform(&mut rng, -1.0, 1.0),
                    stack_common::rng::uniform(&mut rng, 10.0, 30.0),
                ]
            })
            .collect();
        let y: Vec<Vec<f64>> = x
            .iter()
            .map(|r| vec![2.0 * r[0] - r[1] + 3.0, 0.5 * r[1]])
            .collect();
        let p = LinearProbe::fit(&x, &y, 1e-9).unwrap();
        for (r, t) in x.iter().zip(&y).take(10) {
            let q = p.predict(r);
            assert!((q[0] - t[0]).abs() < 1e-5 && (q[1] - t[1]).abs() < 1e-5);
        }
        // A strong ridge shrinks towards the mean target.
        let shrunk = LinearProbe::fit(&x, &y, 1e3).unwrap();
        let mean0 = y.iter().map(|t| t[0]).sum::<f64>() / y.len() as f64;
        assert!((shrunk.predict(&x[0])[0] - mean0).abs() < 0.1);
        // It survives a round trip through JSON.
        let back: LinearProbe = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
        // Bad rows are named.
        let mut bad = x.clone();
        bad[7][1] = f64::NAN;
        assert_eq!(
            LinearProbe::fit(&bad, &y, 1e-3),
            Err(ProbeError::NotFinite(7))
        );
        let e = LinearProbe::fit(&x[..3], &y[..2], 1e-3).unwrap_err();
        assert!(
            e.to_string().contains("3 feature rows, 2 target rows"),
            "{e}"
        );
        assert!(LinearProbe::fit(&[], &[], 1e-3).is_err());
        assert_eq!(LinearProbe::fit(&x, &y, -1.0), Err(ProbeError::Ridge(-1.0)));
        // A fitted probe passes its check; damaged ones are named.
        p.check().unwrap();
        let mut bad = p.clone();
        bad.weights.pop();
        assert!(bad.check().unwrap_err().to_string().contains("5 weights"));
        let mut bad = p.clone();
        bad.sd[1] = 0.0;
        assert!(bad.check().unwrap_err().to_string().contains("deviation"));
        let mut bad = p.clone();
        bad.mean[0] = f64::INFINITY;
        assert!(bad.check().is_err());
    }
}
