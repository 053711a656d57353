//! Scoring: how good a model is, from the squared residuals of all data.
//!
//! Every score is a sum of per-datum qualities in [0, 1] (higher is better), so the engine can
//! stop scoring a model as soon as even all-perfect remaining data could not beat the best
//! model so far: an exact bail-out that costs no accuracy.
//!
//! - [`Msac`] (Torr & Zisserman 2000): the truncated quadratic. Quality 1 − r²/τ² below the
//!   threshold τ, 0 above. Maximising it is minimising Σ min(r², τ²).

/// A scoring function over squared residuals.
pub trait Scoring: Sync {
    /// Quality of a datum with squared residual `r2`: in [0, 1], 0 for outliers.
    fn quality(&self, r2: f64) -> f64;
    /// Squared residual at and above which a datum is an outlier.
    fn inlier_threshold_sq(&self) -> f64;
    /// Weight of a datum in a weighted least-squares refit (iteratively re-weighted LO).
    fn weight(&self, r2: f64) -> f64;
}

/// MSAC with threshold τ.
#[derive(Debug, Clone, Copy)]
pub struct Msac {
    threshold_sq: f64,
}

impl Msac {
    /// MSAC with inlier threshold `threshold` (residual units, e.g. pixels).
    pub fn new(threshold: f64) -> Self {
        Self {
            threshold_sq: threshold * threshold,
        }
    }
}

impl Scoring for Msac {
    #[inline]
    fn quality(&self, r2: f64) -> f64 {
        // `max` also maps NaN residuals (degenerate models) to 0.
        (1.0 - r2 / self.threshold_sq).max(0.0)
    }

    #[inline]
    fn inlier_threshold_sq(&self) -> f64 {
        self.threshold_sq
    }

    #[inline]
    fn weight(&self, r2: f64) -> f64 {
        if r2 < self.threshold_sq { 1.0 } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn msac_is_the_truncated_quadratic() {
        let s = Msac::new(2.0);
        assert_eq!(s.quality(0.0), 1.0);
        assert_eq!(s.quality(2.0), 0.5);
        assert_eq!(s.quality(4.0), 0.0);
        assert_eq!(s.quality(100.0), 0.0);
        assert_eq!(s.quality(f64::NAN), 0.0);
        assert_eq!(s.weight(3.9), 1.0);
        assert_eq!(s.weight(4.0), 0.0);
    }
}
