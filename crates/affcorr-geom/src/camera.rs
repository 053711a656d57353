//! Camera intrinsics and normalised coordinates (docs/design.md §2).
//!
//! - A pixel p = (x, y, 1) becomes x̂ = K⁻¹ p.
//! - An AC's A becomes Â = K2\[0:2,0:2\]⁻¹ · A · K1\[0:2,0:2\]: the chain rule through
//!   x̂2 = K2⁻¹ p2 and p1 = K1 x̂1, both affine in the first two coordinates because the
//!   last row of K is (0, 0, 1). GC-RANSAC skips this and is right only when fx = fy.

use crate::batch;
use crate::error::{GeomError, Result};
use crate::types::{AcRow, AffineCorrespondence, Mat2, Mat3, Vec2};

/// Validated intrinsics: upper triangular, positive focal lengths, last row (0, 0, 1).
/// Skew is allowed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    k: Mat3,
    k_inv: Mat3,
}

impl Intrinsics {
    /// Validates `k`; `what` names the argument in the error (`"K1"`, `"K2"`).
    ///
    /// A `K` whose last row is `(0, 0, c)` with `c > 0` is divided by `c`.
    pub fn new(k: Mat3, what: &'static str) -> Result<Self> {
        let invalid = |reason| GeomError::InvalidIntrinsics { what, reason };
        if k.iter().any(|v| !v.is_finite()) {
            return Err(invalid("it contains NaN or infinity"));
        }
        if k[(1, 0)] != 0.0 || k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 {
            return Err(invalid(
                "it must be upper triangular with last row (0, 0, 1)",
            ));
        }
        if k[(2, 2)] <= 0.0 {
            return Err(invalid("K[2,2] must be positive"));
        }
        let k = k / k[(2, 2)];
        if k[(0, 0)] <= 0.0 || k[(1, 1)] <= 0.0 {
            return Err(invalid(
                "the focal lengths K[0,0] and K[1,1] must be positive",
            ));
        }
        // Upper triangular with positive diagonal: the inverse exists and is closed-form.
        let (fx, s, cx, fy, cy) = (k[(0, 0)], k[(0, 1)], k[(0, 2)], k[(1, 1)], k[(1, 2)]);
        let k_inv = Mat3::new(
            1.0 / fx,
            -s / (fx * fy),
            (s * cy - cx * fy) / (fx * fy),
            0.0,
            1.0 / fy,
            -cy / fy,
            0.0,
            0.0,
            1.0,
        );
        // Tiny focal lengths (e.g. 1e-200) pass the sign checks but overflow the inverse.
        if k_inv.iter().any(|v| !v.is_finite()) {
            return Err(invalid("it is numerically singular (K⁻¹ overflows)"));
        }
        Ok(Self { k, k_inv })
    }

    /// From focal lengths and principal point, no skew.
    pub fn from_focal(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<Self> {
        Self::new(Mat3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0), "K")
    }

    /// The matrix K (normalised so that K\[2,2\] = 1).
    pub fn matrix(&self) -> &Mat3 {
        &self.k
    }

    /// K⁻¹.
    pub fn inverse(&self) -> &Mat3 {
        &self.k_inv
    }

    /// The upper-left 2×2 block of K: ∂p/∂x̂.
    #[inline]
    pub fn linear(&self) -> Mat2 {
        self.k.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// The upper-left 2×2 block of K⁻¹: ∂x̂/∂p.
    #[inline]
    pub fn linear_inverse(&self) -> Mat2 {
        self.k_inv.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// x̂ = K⁻¹ p for a pixel p.
    #[inline]
    pub fn normalize_point(&self, p: &Vec2) -> Vec2 {
        let k = &self.k_inv;
        Vec2::new(
            k[(0, 0)] * p.x + k[(0, 1)] * p.y + k[(0, 2)],
            k[(1, 1)] * p.y + k[(1, 2)],
        )
    }

    /// p = K x̂ for a normalised point x̂.
    #[inline]
    pub fn denormalize_point(&self, x: &Vec2) -> Vec2 {
        let k = &self.k;
        Vec2::new(
            k[(0, 0)] * x.x + k[(0, 1)] * x.y + k[(0, 2)],
            k[(1, 1)] * x.y + k[(1, 2)],
        )
    }
}

/// The AC in normalised coordinates: x̂1 = K1⁻¹p1, x̂2 = K2⁻¹p2, Â = K2⁻¹\[0:2,0:2\]·A·K1\[0:2,0:2\].
///
/// ```
/// use affcorr_geom::{AffineCorrespondence, camera::{Intrinsics, normalize_ac}};
/// let k1 = Intrinsics::from_focal(800.0, 400.0, 320.0, 240.0).unwrap();
/// let ac = AffineCorrespondence::from_row(&[320.0, 240.0, 320.0, 240.0, 1.0, 0.0, 0.0, 1.0]);
/// let n = normalize_ac(&ac, &k1, &k1);
/// assert_eq!(n.x1, nalgebra::Vector2::zeros());
/// // Identity A stays identity with K1 = K2 whatever fx/fy.
/// assert!((n.a - nalgebra::Matrix2::identity()).norm() < 1e-15);
/// ```
#[inline]
pub fn normalize_ac(
    ac: &AffineCorrespondence,
    k1: &Intrinsics,
    k2: &Intrinsics,
) -> AffineCorrespondence {
    AffineCorrespondence {
        x1: k1.normalize_point(&ac.x1),
        x2: k2.normalize_point(&ac.x2),
        a: k2.linear_inverse() * ac.a * k1.linear(),
    }
}

/// Inverse of [`normalize_ac`]: back to pixels.
#[inline]
pub fn denormalize_ac(
    ac: &AffineCorrespondence,
    k1: &Intrinsics,
    k2: &Intrinsics,
) -> AffineCorrespondence {
    AffineCorrespondence {
        x1: k1.denormalize_point(&ac.x1),
        x2: k2.denormalize_point(&ac.x2),
        a: k2.linear() * ac.a * k1.linear_inverse(),
    }
}

/// Batched [`normalize_ac`] over the `(N, 8)` layout; rejects non-finite rows.
pub fn normalize_correspondences(
    corrs: &[AcRow],
    k1: &Intrinsics,
    k2: &Intrinsics,
    out: &mut [AcRow],
) -> Result<()> {
    check_len("out", corrs.len(), out.len())?;
    batch::try_fill(out, |i| {
        let row = &corrs[i];
        if row.iter().any(|v| !v.is_finite()) {
            return Err(GeomError::NonFinite {
                what: "corrs",
                index: i,
            });
        }
        Ok(normalize_ac(&AffineCorrespondence::from_row(row), k1, k2).to_row())
    })
}

/// Errors unless `got == expected`.
pub(crate) fn check_len(what: &'static str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(GeomError::LengthMismatch {
            what,
            expected,
            got,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn anisotropic() -> Intrinsics {
        Intrinsics::new(
            Mat3::new(800.0, 1.5, 320.0, 0.0, 650.0, 240.0, 0.0, 0.0, 1.0),
            "K",
        )
        .unwrap()
    }

    #[test]
    fn inverse_is_exact() {
        let k = anisotropic();
        let prod = k.matrix() * k.inverse();
        assert!((prod - Mat3::identity()).norm() < 1e-15);
    }

    #[test]
    fn normalisation_round_trips() {
        let (k1, k2) = (
            anisotropic(),
            Intrinsics::from_focal(500.0, 700.0, 300.0, 200.0).unwrap(),
        );
        let ac = AffineCorrespondence::from_row(&[10.0, 20.0, 30.0, 40.0, 1.1, 0.2, -0.3, 0.9]);
        let back = denormalize_ac(&normalize_ac(&ac, &k1, &k2), &k1, &k2);
        assert!((back.x1 - ac.x1).norm() < 1e-12 && (back.x2 - ac.x2).norm() < 1e-12);
        assert!((back.a - ac.a).norm() < 1e-14);
    }

    #[test]
    fn rejects_bad_intrinsics_with_the_argument_name() {
        let bad = [
            Mat3::new(0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0),
            Mat3::new(1.0, 0.0, 1.0, 0.0, -1.0, 1.0, 0.0, 0.0, 1.0),
            Mat3::new(1.0, 0.0, 1.0, 0.5, 1.0, 1.0, 0.0, 0.0, 1.0),
            Mat3::new(1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0),
            Mat3::new(f64::NAN, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0),
        ];
        for k in bad {
            let e = Intrinsics::new(k, "K2").unwrap_err();
            assert!(
                e.to_string()
                    .starts_with("K2 is not a valid intrinsic matrix"),
                "{e}"
            );
        }
        // A scaled K is accepted and normalised.
        let k =
            Intrinsics::new(Mat3::new(2.0, 0.0, 2.0, 0.0, 2.0, 2.0, 0.0, 0.0, 2.0), "K").unwrap();
        assert_eq!(k.matrix()[(2, 2)], 1.0);
    }

    proptest::proptest! {
        /// Normalising then denormalising is the identity for any valid K pair, and the
        /// normalised A is the chain rule of the two coordinate changes.
        #[test]
        fn normalisation_is_a_change_of_coordinates(
            fx in 100.0f64..2000.0, ratio in 0.5f64..2.0, skew in -5.0f64..5.0,
            cx in 0.0f64..1000.0, cy in 0.0f64..1000.0,
            row in proptest::array::uniform8(-500.0f64..500.0),
        ) {
            let k1 = Intrinsics::new(Mat3::new(fx, skew, cx, 0.0, fx * ratio, cy, 0.0, 0.0, 1.0), "K1").unwrap();
            let k2 = Intrinsics::from_focal(fx * ratio, fx, cy, cx).unwrap();
            let ac = AffineCorrespondence::from_row(&row);
            let n = normalize_ac(&ac, &k1, &k2);
            let back = denormalize_ac(&n, &k1, &k2);
            proptest::prop_assert!((back.x1 - ac.x1).norm() < 1e-9 * (1.0 + ac.x1.norm()));
            proptest::prop_assert!((back.a - ac.a).norm() < 1e-9 * (1.0 + ac.a.norm()));
            let p = k1.matrix() * nalgebra::Vector3::new(n.x1.x, n.x1.y, 1.0);
            proptest::prop_assert!((p.xy() - ac.x1).norm() < 1e-9 * (1.0 + ac.x1.norm()));
        }
    }

    #[test]
    fn batch_rejects_non_finite_rows_by_index() {
        let k = anisotropic();
        let mut rows = vec![[1.0; 8]; 5];
        rows[3][6] = f64::INFINITY;
        let mut out = vec![[0.0; 8]; 5];
        let e = normalize_correspondences(&rows, &k, &k, &mut out).unwrap_err();
        assert_eq!(
            e,
            GeomError::NonFinite {
                what: "corrs",
                index: 3
            }
        );
    }
}
