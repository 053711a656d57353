//! The robust losses ρ(s) of a squared residual s that local optimisation and the refinements
//! minimise ([`Loss`]), and the tabulated MAGSAC++ loss ([`MagsacTable`]) that both the loss and
//! the MAGSAC++ score ([`crate::score::MagsacPlusPlus`]) read.
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

use std::sync::OnceLock;

/// A robust loss ρ(s) of a squared residual s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Loss {
    /// ρ(s) = s.
    Squared,
    /// ρ(s) = min(s, c²): inliers only (MSAC's cost).
    Truncated {
        /// c².
        threshold_sq: f64,
    },
    /// ρ(s) = c² log(1 + s/c²): smooth, so far-away data still pull, weakly.
    Cauchy {
        /// c².
        scale_sq: f64,
    },
    /// ρ(s) = τ²·ρ̂(s/τ²), MAGSAC++'s σ-consensus++ loss with largest inlier residual τ
    /// ([`crate::score::MagsacPlusPlus`]); constant τ² from τ² on.
    Magsac {
        /// τ².
        threshold_sq: f64,
    },
}

impl Loss {
    /// ρ(s).
    #[inline]
    pub fn cost(&self, s: f64) -> f64 {
        match *self {
            Loss::Squared => s,
            Loss::Truncated { threshold_sq } => s.min(threshold_sq),
            Loss::Cauchy { scale_sq } => scale_sq * (s / scale_sq).ln_1p(),
            Loss::Magsac { threshold_sq } => {
                threshold_sq * MagsacTable::get().loss(s / threshold_sq)
            }
        }
    }

    /// ρ′(s), the IRLS weight.
    #[inline]
    pub fn weight(&self, s: f64) -> f64 {
        match *self {
            Loss::Squared => 1.0,
            Loss::Truncated { threshold_sq } => f64::from(u8::from(s < threshold_sq)),
            Loss::Cauchy { scale_sq } => 1.0 / (1.0 + s / scale_sq),
            Loss::Magsac { threshold_sq } => MagsacTable::get().slope(s / threshold_sq),
        }
    }

    /// (ρ(s), ρ′(s)), what the least-squares kernels need per datum: one table search for
    /// MAGSAC++ instead of two.
    #[inline(always)]
    pub fn cost_and_weight(&self, s: f64) -> (f64, f64) {
        match *self {
            Loss::Magsac { threshold_sq } => {
                let (loss, slope) = MagsacTable::get().loss_and_slope(s / threshold_sq);
                (threshold_sq * loss, slope)
            }
            _ => (self.cost(s), self.weight(s)),
        }
    }

    /// Σₖ ρ(sₖ), the cost of one datum's N residuals (the four of an AC's A). The Cauchy loss
    /// takes one logarithm instead of N: Σₖ log(1 + xₖ) = log Π(1 + xₖ) = log1p(q), with
    /// q = Π(1 + xₖ) − 1 built as q ← q + x + q·x. Every term is ≥ 0, so nothing cancels and
    /// small xₖ keep their precision; a product that overflows falls back to the N logarithms.
    #[inline(always)]
    pub fn total_cost<const N: usize>(&self, s: &[f64; N]) -> f64 {
        match *self {
            Loss::Cauchy { scale_sq } => {
                let mut q = 0.0;
                for &sk in s {
                    let x = sk / scale_sq;
                    q += x + q * x;
                }
                if q.is_finite() {
                    scale_sq * q.ln_1p()
                } else {
                    s.iter().map(|&sk| self.cost(sk)).sum()
                }
            }
            _ => s.iter().map(|&sk| self.cost(sk)).sum(),
        }
    }

    /// (Σₖ ρ(sₖ), ρ′(sₖ) for each k): [`Loss::cost_and_weight`] of one datum's N residuals,
    /// with the Cauchy cost of [`Loss::total_cost`].
    #[inline(always)]
    pub fn total_cost_and_weights<const N: usize>(&self, s: &[f64; N]) -> (f64, [f64; N]) {
        match *self {
            Loss::Cauchy { .. } => (self.total_cost(s), s.map(|sk| self.weight(sk))),
            _ => {
                let mut cost = 0.0;
                let w = s.map(|sk| {
                    let (rho, w) = self.cost_and_weight(sk);
                    cost += rho;
                    w
                });
                (cost, w)
            }
        }
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
    /// dρ̂/du; `slope[0]` normalises the MAGSAC++ weight.
    pub(crate) slope: Box<[f64; TABLE + 2]>,
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
    fn losses_and_weights() {
        let t = Loss::Truncated { threshold_sq: 4.0 };
        assert_eq!(
            (t.cost(1.0), t.cost(9.0), t.weight(1.0), t.weight(9.0)),
            (1.0, 4.0, 1.0, 0.0)
        );
        let c = Loss::Cauchy { scale_sq: 2.0 };
        assert!(
            (c.cost(2.0) - 2.0 * 2f64.ln()).abs() < 1e-15 && (c.weight(2.0) - 0.5).abs() < 1e-15
        );
        // ρ′ is the derivative of ρ.
        let h = 1e-6;
        assert!(((c.cost(1.0 + h) - c.cost(1.0 - h)) / (2.0 * h) - c.weight(1.0)).abs() < 1e-8);
    }

    #[test]
    fn a_datums_total_cost_is_the_sum_of_its_residuals_costs() {
        let losses = [
            Loss::Squared,
            Loss::Truncated { threshold_sq: 4.0 },
            Loss::Cauchy { scale_sq: 2.0 },
            Loss::Cauchy { scale_sq: 1e-9 },
            Loss::Magsac { threshold_sq: 4.0 },
        ];
        // Tiny, ordinary and huge residuals, one that overflows the Cauchy product and a zero.
        let cases = [
            [1e-20, 3e-18, 0.0, 1e-16],
            [0.3, 1.7, 2.9, 12.0],
            [1e150, 2.0, 1e160, 0.5],
            [1e300, 1e300, 1e-3, 0.0],
        ];
        for loss in losses {
            for s in cases {
                let sum: f64 = s.iter().map(|&sk| loss.cost(sk)).sum();
                let total = loss.total_cost(&s);
                assert!(
                    (total - sum).abs() <= 1e-14 * sum.abs() || total == sum,
                    "{loss:?} {s:?}: {total} vs {sum}"
                );
                let (cost, w) = loss.total_cost_and_weights(&s);
                assert_eq!(cost, total);
                assert_eq!(w, s.map(|sk| loss.weight(sk)));
            }
        }
    }

    #[test]
    fn cost_and_weight_is_cost_and_weight() {
        let losses = [
            Loss::Squared,
            Loss::Truncated { threshold_sq: 4.0 },
            Loss::Cauchy { scale_sq: 2.0 },
            Loss::Magsac { threshold_sq: 2.25 },
        ];
        // Inside, at and beyond the threshold, and the residual of a degenerate model.
        for loss in losses {
            for s in [0.0, 1e-9, 0.3, 1.7, 2.25, 4.0, 9.0, 1e300, f64::NAN] {
                let (c, w) = loss.cost_and_weight(s);
                assert!(
                    c.to_bits() == loss.cost(s).to_bits()
                        && w.to_bits() == loss.weight(s).to_bits(),
                    "{loss:?} at {s}: ({c}, {w}) vs ({}, {})",
                    loss.cost(s),
                    loss.weight(s)
                );
            }
        }
    }
}
