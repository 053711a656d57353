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
//!
//! ## MAGSAC++ in closed form
//!
//! The residual of an inlier at noise scale σ is σ·χ_ν (ν = 4: the data are points in two
//! images), cut at kσ with k² the 0.99 quantile of χ²_ν. With σ uniform on [0, σ_max] and
//! σ_max = τ/k (so that τ, the threshold, is the largest inlier residual), the IRLS weight of a
//! residual r < τ is
//!
//! w(r) ∝ Γ(s, r²/2σ_max²) − Γ(s, k²/2),  s = (ν − 1)/2,
//!
//! (Γ(s, ·) the upper incomplete gamma function), and the loss whose IRLS weight it is,
//! ρ(r) = ∫₀ʳ x w(x) dx, is, with a = r²/2σ_max² and b = k²/2,
//!
//! ρ(r) ∝ γ(s + 1, a) + a·(Γ(s, a) − Γ(s, b)),
//!
//! constant for r ≥ τ. For ν = 4, s = 3/2 and both gamma functions reduce to erfc and exp:
//! Γ(3/2, x) = (√π/2)·erfc(√x) + √x·e⁻ˣ and γ(5/2, x) = (3/2)·γ(3/2, x) − x^{3/2}·e⁻ˣ. The
//! normalised loss ρ̂(u) = ρ/ρ(τ) and its derivative are tabulated once over u = r²/τ² ∈ [0, 1]
//! and interpolated linearly (relative error < 1e-6), so scoring costs a multiply, a load pair
//! and a lerp per datum, as MSAC's does, and is deterministic.

use crate::refine::Loss;
use std::sync::OnceLock;

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

/// MAGSAC++ with maximal threshold τ (σ_max = τ/k). See the module docs for the formulas.
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

/// Intervals of the MAGSAC++ tables over u = r²/τ² ∈ [0, 1].
const TABLE: usize = 2048;

/// Degrees of freedom ν of the residual's noise model (points in two images).
pub const MAGSAC_DOF: f64 = 4.0;
/// k², the 0.99 quantile of χ²₄: σ_max = τ/k.
pub const MAGSAC_K_SQ: f64 = 13.276_704_135_987_6;

/// ρ̂(u) = ρ(r)/ρ(τ) and dρ̂/du at u = i/TABLE.
#[derive(Debug)]
pub struct MagsacTable {
    /// Fixed-length, so that the clamped index needs no bounds check in the hot loops.
    loss: Box<[f64; TABLE + 2]>,
    slope: Box<[f64; TABLE + 2]>,
}

impl MagsacTable {
    /// The tables, computed on first use.
    pub fn get() -> &'static MagsacTable {
        static TABLES: OnceLock<MagsacTable> = OnceLock::new();
        TABLES.get_or_init(|| {
            let b = MAGSAC_K_SQ / 2.0;
            let gb = upper_gamma_3_2(b);
            let f = |a: f64| lower_gamma_5_2(a) + a * (upper_gamma_3_2(a) - gb);
            let fb = f(b);
            let (mut loss, mut slope) = (Vec::with_capacity(TABLE + 2), Vec::new());
            for i in 0..=TABLE + 1 {
                let u = (i as f64 / TABLE as f64).min(1.0);
                loss.push(f(u * b) / fb);
                slope.push(b * (upper_gamma_3_2(u * b) - gb) / fb);
            }
            let fixed = |v: Vec<f64>| -> Box<[f64; TABLE + 2]> {
                v.into_boxed_slice().try_into().expect("TABLE + 2 entries")
            };
            MagsacTable {
                loss: fixed(loss),
                slope: fixed(slope),
            }
        })
    }

    /// The interval of u and the position in it.
    #[inline(always)]
    fn locate(u: f64) -> (usize, f64) {
        let x = u * TABLE as f64;
        let i = (x as usize).min(TABLE);
        (i, x - i as f64)
    }

    #[inline(always)]
    fn lerp(table: &[f64; TABLE + 2], (i, t): (usize, f64)) -> f64 {
        table[i] + t * (table[i + 1] - table[i])
    }

    /// ρ̂(u) for u ∈ [0, 1] (1 beyond).
    #[inline(always)]
    pub fn loss(&self, u: f64) -> f64 {
        if !(u < 1.0) {
            return 1.0;
        }
        Self::lerp(&self.loss, Self::locate(u.max(0.0)))
    }

    /// dρ̂/du for u ∈ [0, 1] (0 beyond).
    #[inline(always)]
    pub fn slope(&self, u: f64) -> f64 {
        if !(u < 1.0) {
            return 0.0;
        }
        Self::lerp(&self.slope, Self::locate(u.max(0.0)))
    }

    /// (ρ̂(u), dρ̂/du) with one table search: (1, 0) beyond u = 1.
    #[inline(always)]
    pub fn loss_and_slope(&self, u: f64) -> (f64, f64) {
        if !(u < 1.0) {
            return (1.0, 0.0);
        }
        let at = Self::locate(u.max(0.0));
        (Self::lerp(&self.loss, at), Self::lerp(&self.slope, at))
    }
}

/// Γ(3/2, x) = (√π/2)·erfc(√x) + √x·e⁻ˣ.
fn upper_gamma_3_2(x: f64) -> f64 {
    let r = x.sqrt();
    0.5 * std::f64::consts::PI.sqrt() * erfc(r) + r * (-x).exp()
}

/// γ(5/2, x) = (3/2)·γ(3/2, x) − x^{3/2}·e⁻ˣ, with γ(3/2, x) = √π/2 − Γ(3/2, x).
fn lower_gamma_5_2(x: f64) -> f64 {
    let lower_3_2 = 0.5 * std::f64::consts::PI.sqrt() - upper_gamma_3_2(x);
    1.5 * lower_3_2 - x * x.sqrt() * (-x).exp()
}

/// erfc(x) for x ≥ 0 to ~1e-15 relative: the Taylor series of erf below 2, Lentz's continued
/// fraction of erfc above (Abramowitz & Stegun 7.1.5 and 7.1.14).
fn erfc(x: f64) -> f64 {
    debug_assert!(x >= 0.0);
    if x < 2.0 {
        // erf(x) = 2/√π Σ (−1)ⁿ x^{2n+1} / (n! (2n + 1))
        let (mut term, mut sum, x2) = (x, x, x * x);
        for n in 1..200 {
            term *= -x2 / n as f64;
            let add = term / (2 * n + 1) as f64;
            sum += add;
            if add.abs() < 1e-17 * sum.abs() {
                break;
            }
        }
        1.0 - 2.0 / std::f64::consts::PI.sqrt() * sum
    } else {
        // erfc(x) = e^{−x²}/√π · 1/(x + (1/2)/(x + 1/(x + (3/2)/(x + 2/(x + ...)))))
        let tiny = 1e-300;
        let mut f = x;
        let (mut c, mut d) = (x, 0.0);
        for n in 1..300 {
            let a = n as f64 / 2.0;
            d = x + a * d;
            d = if d.abs() < tiny { tiny } else { d };
            c = x + a / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            let delta = c * d;
            f *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (-x * x).exp() / (std::f64::consts::PI.sqrt() * f)
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
    fn erfc_matches_known_values() {
        // erfc(0) = 1, erfc(0.5), erfc(1), erfc(2), erfc(3) to 15 digits.
        for (x, v) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_13),
            (2.0, 0.004_677_734_981_047_266),
            (3.0, 2.209_049_699_858_544e-5),
        ] {
            assert!(
                (erfc(x) - v).abs() < 1e-14 * v.max(1e-3),
                "erfc({x}) = {}",
                erfc(x)
            );
        }
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
