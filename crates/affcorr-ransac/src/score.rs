//! Scoring: how good a model is, from the squared residuals of all data.
//!
//! Every score is a sum of per-datum qualities in [0, 1] (higher is better), so the engine can
//! stop scoring a model as soon as even all-perfect remaining data could not beat the best
//! model so far: an exact bail-out that costs no accuracy.
//!
//! - [`Msac`] (Torr & Zisserman 2000): the truncated quadratic. Quality 1 − r²/τ² below the
//!   threshold τ, 0 above. Maximising it is minimising Σ min(r², τ²).
//! - [`MagsacPlusPlus`] (Barath, Noskova, Ivashechkin & Matas, CVPR 2020): the σ-consensus++
//!   loss, marginalised over a uniform noise scale σ ∈ [0, σ_max]. Quality 1 − ρ(r)/ρ(τ) below
//!   τ, 0 above; its IRLS weights also drive local optimisation and the final refinement.
//!   Its loss in closed form and the tables it reads are in [`crate::loss`].

use crate::loss::Loss;
pub use crate::loss::{MAGSAC_DOF, MAGSAC_K_SQ, MagsacTable};

/// A scoring function over squared residuals.
pub trait Scoring: Sync {
    /// Quality of a datum with squared residual `r2`: in [0, 1], 0 for outliers.
    fn quality(&self, r2: f64) -> f64;
    /// Squared residual at and above which a datum is an outlier.
    fn inlier_threshold_sq(&self) -> f64;
    /// Weight of a datum in a weighted least-squares refit (iteratively re-weighted LO), in
    /// [0, 1].
    fn weight(&self, r2: f64) -> f64;
    /// The robust loss of the final refinement: the cost the score measures.
    fn refinement_loss(&self) -> Loss;
    /// The robust loss of local optimisation's refinements at squared threshold
    /// `threshold_sq` (LO widens the threshold in its first steps).
    fn lo_loss(&self, threshold_sq: f64) -> Loss;
}

/// MSAC with threshold τ.
#[derive(Debug, Clone, Copy)]
pub struct Msac {
    threshold_sq: f64,
    inv_threshold_sq: f64,
}

impl Msac {
    /// MSAC with inlier threshold `threshold` (residual units, e.g. pixels).
    pub fn new(threshold: f64) -> Self {
        Self {
            threshold_sq: threshold * threshold,
            inv_threshold_sq: 1.0 / (threshold * threshold),
        }
    }
}

impl Scoring for Msac {
    #[inline]
    fn quality(&self, r2: f64) -> f64 {
        // `max` also maps NaN residuals (degenerate models) to 0.
        (1.0 - r2 * self.inv_threshold_sq).max(0.0)
    }

    #[inline]
    fn inlier_threshold_sq(&self) -> f64 {
        self.threshold_sq
    }

    #[inline]
    fn weight(&self, r2: f64) -> f64 {
        if r2 < self.threshold_sq { 1.0 } else { 0.0 }
    }

    /// MSAC's own cost, the truncated quadratic, restricted to the inliers the final refinement
    /// fits: plain least squares. (Truncated, LM chased the few residuals crossing the
    /// threshold for several extra steps of no gain; the refinement's rounds re-collect the
    /// inliers instead.)
    fn refinement_loss(&self) -> Loss {
        Loss::Squared
    }

    /// The Cauchy loss: smooth, so that data just beyond a wide threshold still pull.
    fn lo_loss(&self, threshold_sq: f64) -> Loss {
        Loss::Cauchy {
            scale_sq: threshold_sq,
        }
    }
}

/// MAGSAC++ with maximal threshold τ (σ_max = τ/k). See [`crate::loss`] for the formulas.
#[derive(Debug, Clone, Copy)]
pub struct MagsacPlusPlus {
    threshold_sq: f64,
    inv_threshold_sq: f64,
    table: &'static MagsacTable,
}

impl MagsacPlusPlus {
    /// MAGSAC++ whose largest inlier residual is `threshold` (residual units, e.g. pixels).
    pub fn new(threshold: f64) -> Self {
        let threshold_sq = threshold * threshold;
        Self {
            threshold_sq,
            inv_threshold_sq: 1.0 / threshold_sq,
            table: MagsacTable::get(),
        }
    }
}

impl Scoring for MagsacPlusPlus {
    #[inline]
    fn quality(&self, r2: f64) -> f64 {
        let u = r2 * self.inv_threshold_sq;
        // `!(u < 1)` also maps NaN residuals to 0.
        if !(u < 1.0) {
            return 0.0;
        }
        1.0 - self.table.loss(u)
    }

    #[inline]
    fn inlier_threshold_sq(&self) -> f64 {
        self.threshold_sq
    }

    #[inline]
    fn weight(&self, r2: f64) -> f64 {
        let u = r2 * self.inv_threshold_sq;
        if !(u < 1.0) {
            return 0.0;
        }
        self.table.slope(u) / self.table.slope[0]
    }

    fn refinement_loss(&self) -> Loss {
        Loss::Magsac {
            threshold_sq: self.threshold_sq,
        }
    }

    fn lo_loss(&self, threshold_sq: f64) -> Loss {
        Loss::Magsac { threshold_sq }
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

    #[test]
    fn magsac_weight_is_the_marginal_over_sigma() {
        // w(r) = 1/σ_max ∫_{r/k}^{σ_max} 2C σ^{-ν} r^{ν-1} e^{-r²/2σ²} dσ (ν = 4), integrated
        // numerically, must be proportional to the closed form's slope.
        let s = MagsacPlusPlus::new(1.0);
        let k = MAGSAC_K_SQ.sqrt();
        let sigma_max = 1.0 / k;
        let w = |r: f64| {
            let (lo, n) = (r / k, 20_000);
            let h = (sigma_max - lo) / n as f64;
            (0..n)
                .map(|i| {
                    let sg = lo + (i as f64 + 0.5) * h;
                    sg.powi(-4) * r.powi(3) * (-r * r / (2.0 * sg * sg)).exp() * h
                })
                .sum::<f64>()
        };
        // IRLS: w(r) = ρ′(r)/r, so dρ/d(r²) = w(r)/2 and our weight(r²) is w(r) normalised.
        let (r_ref, r_test) = (0.2, 0.6);
        let ratio_num = w(r_test) / w(r_ref);
        let ratio = s.weight(r_test * r_test) / s.weight(r_ref * r_ref);
        assert!((ratio - ratio_num).abs() < 1e-4, "{ratio} vs {ratio_num}");
    }

    #[test]
    fn magsac_quality_and_loss_are_consistent() {
        let s = MagsacPlusPlus::new(2.0);
        assert_eq!(s.quality(0.0), 1.0);
        assert_eq!(s.quality(4.0), 0.0);
        assert_eq!(s.quality(9.0), 0.0);
        assert_eq!(s.quality(f64::NAN), 0.0);
        assert_eq!(s.weight(0.0), 1.0);
        assert_eq!(s.weight(4.0), 0.0);
        // Monotone: quality falls and the weight falls as the residual grows.
        let mut prev = (2.0, 2.0);
        for i in 0..=400 {
            let r2 = 4.0 * i as f64 / 400.0;
            let (q, w) = (s.quality(r2), s.weight(r2));
            assert!(
                q <= prev.0 && w <= prev.1 && (0.0..=1.0).contains(&q),
                "{r2}: {q} {w}"
            );
            prev = (q, w);
        }
        // Continuous at τ, and the loss's derivative is its weight (the Loss used by LM).
        assert!(s.quality(4.0 * (1.0 - 1e-9)) < 1e-6);
        let loss = s.refinement_loss();
        for r2 in [0.01, 0.5, 1.7, 3.2] {
            let h = 1e-5;
            let fd = (loss.cost(r2 + h) - loss.cost(r2 - h)) / (2.0 * h);
            // (The tables are lerped: the chord's slope is the tangent's to O(1/TABLE).)
            let w = loss.weight(r2);
            assert!((fd - w).abs() < 1e-3 * w, "{r2}: {fd} vs {w}");
            // quality = 1 − cost/τ².
            assert!((s.quality(r2) - (1.0 - loss.cost(r2) / 4.0)).abs() < 1e-12);
        }
        // MAGSAC++ down-weights residuals MSAC still counts fully.
        assert!(s.weight(2.0) < 0.5 && s.quality(2.0) < Msac::new(2.0).quality(2.0));
    }
}
