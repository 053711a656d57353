//! Affine synthesis and decomposition (docs/design.md §2, paper eqs. 7–11).
//!
//! - `A = s · R(θ) · A′`, with s = √det A > 0, R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]] and
//!   A′ = [[a, 0], [b, 1/a]], a > 0: lower triangular, positive diagonal, det 1 (AffNet's form).
//!   It exists and is unique exactly when det A > 0.
//! - The residual shape A″ = (x0, x1, x2) parametrises A′ = B / √det B with
//!   B = [[1 + x0, 0], [x1, 1 + x2]]. Synthesis needs 1 + x0 > 0 and 1 + x2 > 0.
//!   A″ ↦ A′ is 3 → 2, so [`decompose_affine`] returns the canonical A″ with det B = 1, i.e.
//!   B = A′ itself: x0 = a − 1, x1 = b, x2 = 1/a − 1.
//! - From two local affine frames L1, L2 (maps from a canonical patch to each image, the same
//!   physical patch): x2 − c2 = L2 u and x1 − c1 = L1 u, so A = L2 · L1⁻¹.
//!
//! **Decomposition.** With M = A / s (det M = 1) and M = R(θ) A′, the second column of A′ is
//! (0, 1/a), so M's second column is (1/a)(−sin θ, cos θ): θ = atan2(−m₁₂, m₂₂),
//! 1/a = ‖m_{:,2}‖, and A′ = R(−θ) M.
//!
//! **kornia LAFs** are `(…, 2, 3)` = `[L | c]` with the same meaning as our frames. kornia's
//! `get_laf_orientation` is atan2(L₀₁, L₀₀) in degrees, because its rotation matrix is
//! [[cos, sin], [−sin, cos]]; for a similarity frame L = s·R(θ) it is −θ in our convention.

use crate::batch;
use crate::camera::check_len;
use crate::error::{GeomError, Result};
use crate::types::{AcRow, Mat2, mat2_from_row, mat2_to_row, max_abs, power_of_two_normalizer};

/// Orientation θ (radians, in (−π, π]), scale s and residual shape A″ of one affine map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineShape {
    /// θ in radians.
    pub orientation: f64,
    /// s = √det A.
    pub scale: f64,
    /// A″ = (x0, x1, x2), canonical (det B = 1) when it comes from [`decompose_affine`].
    pub residual_shape: [f64; 3],
}

/// R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]].
#[inline]
pub fn rotation(theta: f64) -> Mat2 {
    let (s, c) = theta.sin_cos();
    Mat2::new(c, -s, s, c)
}

/// A′(A″) = B / √det B, B = [[1 + x0, 0], [x1, 1 + x2]]; `None` unless both diagonal entries
/// of B are positive.
#[inline]
pub fn residual_shape_matrix(x: &[f64; 3]) -> Option<Mat2> {
    let (d0, d2) = (1.0 + x[0], 1.0 + x[2]);
    if !(d0 > 0.0 && d2 > 0.0 && x[1].is_finite() && d0.is_finite() && d2.is_finite()) {
        return None;
    }
    // det B = d0·d2 may overflow (or underflow) for finite A″: then √d0·√d2 instead, which
    // cannot. The plain product otherwise, so ordinary inputs keep their bits.
    let det = d0 * d2;
    let k = if det.is_normal() {
        1.0 / det.sqrt()
    } else {
        1.0 / (d0.sqrt() * d2.sqrt())
    };
    Some(Mat2::new(d0 * k, 0.0, x[1] * k, d2 * k))
}

/// A = s · R(θ) · A′(A″) for one map (paper eq. 11). `index` only labels errors.
///
/// ```
/// use affcorr_geom::affine::{AffineShape, synthesize};
/// let shape = AffineShape { orientation: std::f64::consts::FRAC_PI_2, scale: 2.0, residual_shape: [0.0; 3] };
/// let a = synthesize(&shape, 0).unwrap();
/// // A quarter turn scaled by 2: x → (−2y, 2x).
/// assert!((a - nalgebra::Matrix2::new(0.0, -2.0, 2.0, 0.0)).norm() < 1e-15);
/// ```
#[inline]
pub fn synthesize(shape: &AffineShape, index: usize) -> Result<Mat2> {
    if !shape.orientation.is_finite() {
        return Err(GeomError::NonFinite {
            what: "orientation",
            index,
        });
    }
    if !shape.scale.is_finite() {
        return Err(GeomError::NonFinite {
            what: "scale",
            index,
        });
    }
    if shape.scale <= 0.0 {
        return Err(GeomError::NotPositive {
            what: "scale",
            index,
            value: shape.scale,
        });
    }
    if shape.residual_shape.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite {
            what: "residual_shape",
            index,
        });
    }
    let a_prime = residual_shape_matrix(&shape.residual_shape).ok_or(GeomError::NotPositive {
        what: "residual_shape (1 + x0 and 1 + x2)",
        index,
        value: (1.0 + shape.residual_shape[0]).min(1.0 + shape.residual_shape[2]),
    })?;
    let a = rotation(shape.orientation) * a_prime * shape.scale;
    if a.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::Overflow {
            what: "A",
            index,
            reason: "scale · A′(residual_shape) is beyond 1.8e308",
        });
    }
    Ok(a)
}

/// The unique (θ, s, canonical A″) with A = s · R(θ) · A′(A″); errors when det A ≤ 0.
///
/// ```
/// use affcorr_geom::affine::decompose;
/// let a = nalgebra::Matrix2::new(2.0, 0.0, 1.0, 0.5); // lower triangular: θ = 0
/// let shape = decompose(&a, 0).unwrap();
/// assert!(shape.orientation.abs() < 1e-15 && (shape.scale - 1.0).abs() < 1e-15);
/// assert!(decompose(&nalgebra::Matrix2::new(1.0, 0.0, 0.0, -1.0), 0).is_err()); // reflection
/// ```
#[inline]
pub fn decompose(a: &Mat2, index: usize) -> Result<AffineShape> {
    if a.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite { what: "A", index });
    }
    // A = Â / r with r a power of two: det Â cannot overflow or underflow, and for ordinary A
    // every step below gives the same bits as on A itself (the scale is exact).
    let r = power_of_two_normalizer(max_abs(a.iter()));
    let a_hat = a * r;
    let det_hat = a_hat.determinant();
    if det_hat <= 0.0 {
        return Err(GeomError::NonPositiveDeterminant {
            what: "A",
            index,
            det: det_hat / (r * r),
        });
    }
    let scale_hat = det_hat.sqrt();
    let scale = scale_hat / r;
    let m = a_hat / scale_hat;
    let orientation = (-m[(0, 1)]).atan2(m[(1, 1)]);
    // For a nearly singular A (det Â down to 5e-324), M's entries reach ~1e162: the squares
    // then leave f64's range, and hypot (which cannot) takes over; ordinary A keep their bits.
    let norm_sq = m[(0, 1)] * m[(0, 1)] + m[(1, 1)] * m[(1, 1)];
    let inv_a = if norm_sq.is_normal() {
        norm_sq.sqrt()
    } else {
        m[(0, 1)].hypot(m[(1, 1)])
    };
    // a = 1/‖m_{:,2}‖ exactly; A′'s (0,0) entry recomputed from M would carry rounding.
    let diag0 = 1.0 / inv_a;
    // A′ = R(−θ) M with (−sin θ, cos θ) = m_{:,2} / ‖m_{:,2}‖, so its (1,0) entry is
    // −sin θ·m₁₁ + cos θ·m₂₁ = (m₁₂ m₁₁ + m₂₂ m₂₁) / ‖m_{:,2}‖: no sin/cos of θ needed.
    let mut b = (m[(0, 1)] * m[(0, 0)] + m[(1, 1)] * m[(1, 0)]) * diag0;
    if !b.is_finite() {
        // The products overflowed: the unit vector first (its entries are at most 1).
        b = (m[(0, 1)] / inv_a) * m[(0, 0)] + (m[(1, 1)] / inv_a) * m[(1, 0)];
    }
    let residual_shape = [diag0 - 1.0, b, inv_a - 1.0];
    if !(scale.is_finite() && residual_shape.iter().all(|v| v.is_finite())) {
        return Err(GeomError::Overflow {
            what: "A",
            index,
            reason: "its scale or shape A′ is beyond 1.8e308",
        });
    }
    Ok(AffineShape {
        orientation,
        scale,
        residual_shape,
    })
}

/// Batched [`synthesize`]: `orientation (N)`, `scale (N)`, `residual_shape (N, 3)` to
/// `(N, 2, 2)` row-major maps. The first bad row's error is returned.
pub fn synthesize_affine(
    orientation: &[f64],
    scale: &[f64],
    residual_shape: &[[f64; 3]],
    out: &mut [[f64; 4]],
) -> Result<()> {
    let n = orientation.len();
    check_len("scale", n, scale.len())?;
    check_len("residual_shape", n, residual_shape.len())?;
    check_len("out", n, out.len())?;
    batch::try_fill(out, |i| {
        let shape = AffineShape {
            orientation: orientation[i],
            scale: scale[i],
            residual_shape: residual_shape[i],
        };
        synthesize(&shape, i).map(|a| mat2_to_row(&a))
    })
}

/// Batched [`decompose`]: `(N, 2, 2)` row-major maps to shapes.
pub fn decompose_affine(a: &[[f64; 4]], out: &mut [AffineShape]) -> Result<()> {
    check_len("out", a.len(), out.len())?;
    batch::try_fill(out, |i| decompose(&mat2_from_row(&a[i]), i))
}

/// A = L2 · L1⁻¹ from two local affine frames of the same patch; `L1` must be invertible.
#[inline]
pub fn affine_from_frames(l1: &Mat2, l2: &Mat2, index: usize) -> Result<Mat2> {
    if l1.iter().chain(l2.iter()).any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite { what: "laf", index });
    }
    let inv = l1.try_inverse().filter(|_| l1.determinant() != 0.0);
    inv.map(|inv| l2 * inv)
        .ok_or(GeomError::NonPositiveDeterminant {
            what: "laf1",
            index,
            det: l1.determinant(),
        })
}

/// kornia LAF pairs `(N, 2, 3)` (flattened to 6, row-major) to `(N, 8)` ACs:
/// x1, x2 are the frame centres and A = L2 · L1⁻¹.
pub fn laf_to_affine(laf1: &[[f64; 6]], laf2: &[[f64; 6]], out: &mut [AcRow]) -> Result<()> {
    check_len("laf2", laf1.len(), laf2.len())?;
    check_len("out", laf1.len(), out.len())?;
    batch::try_fill(out, |i| {
        let (p, q) = (&laf1[i], &laf2[i]);
        // The centres too: affine_from_frames only sees the 2×2 parts.
        for (what, laf) in [("laf1", p), ("laf2", q)] {
            if laf.iter().any(|v| !v.is_finite()) {
                return Err(GeomError::NonFinite { what, index: i });
            }
        }
        let l1 = Mat2::new(p[0], p[1], p[3], p[4]);
        let l2 = Mat2::new(q[0], q[1], q[3], q[4]);
        let a = affine_from_frames(&l1, &l2, i)?;
        Ok([
            p[2],
            p[5],
            q[2],
            q[5],
            a[(0, 0)],
            a[(0, 1)],
            a[(1, 0)],
            a[(1, 1)],
        ])
    })
}

/// `(N, 8)` ACs to kornia LAF pairs of radius `radius` pixels in image 1: L1 = r·I at x1 and
/// L2 = r·A at x2, so that [`laf_to_affine`] gives the ACs back.
pub fn affine_to_laf(
    corrs: &[AcRow],
    radius: f64,
    laf1: &mut [[f64; 6]],
    laf2: &mut [[f64; 6]],
) -> Result<()> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(GeomError::NotPositive {
            what: "radius",
            index: 0,
            value: radius,
        });
    }
    check_len("laf1", corrs.len(), laf1.len())?;
    check_len("laf2", corrs.len(), laf2.len())?;
    let check = |i: usize| -> Result<&AcRow> {
        let r = &corrs[i];
        if r.iter().any(|v| !v.is_finite()) {
            return Err(GeomError::NonFinite {
                what: "corrs",
                index: i,
            });
        }
        Ok(r)
    };
    batch::try_fill(laf1, |i| {
        check(i).map(|r| [radius, 0.0, r[0], 0.0, radius, r[1]])
    })?;
    batch::try_fill(laf2, |i| {
        check(i).map(|r| {
            [
                radius * r[4],
                radius * r[5],
                r[2],
                radius * r[6],
                radius * r[7],
                r[3],
            ]
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;

    proptest! {
        #[test]
        fn synthesize_then_decompose_recovers_the_parameters(
            theta in -3.1f64..3.1, log_s in -3.0f64..3.0,
            x0 in -0.8f64..3.0, x1 in -3.0f64..3.0, x2 in -0.8f64..3.0,
        ) {
            let shape = AffineShape { orientation: theta, scale: log_s.exp(), residual_shape: [x0, x1, x2] };
            let a = synthesize(&shape, 0).unwrap();
            let back = decompose(&a, 0).unwrap();
            prop_assert!((back.orientation - theta).abs() < 1e-12);
            prop_assert!((back.scale / shape.scale - 1.0).abs() < 1e-12);
            // A″ is canonicalised, but it maps to the same A′, hence the same A.
            let again = synthesize(&back, 0).unwrap();
            prop_assert!((again - a).norm() < 1e-12 * a.norm());
            let b = residual_shape_matrix(&back.residual_shape).unwrap();
            prop_assert!((b.determinant() - 1.0).abs() < 1e-12);
        }

        #[test]
        fn decompose_then_synthesize_is_identity(
            a11 in -5.0f64..5.0, a12 in -5.0f64..5.0, a21 in -5.0f64..5.0, a22 in -5.0f64..5.0,
        ) {
            let a = Mat2::new(a11, a12, a21, a22);
            prop_assume!(a.determinant() > 1e-3);
            let shape = decompose(&a, 0).unwrap();
            let a_prime = residual_shape_matrix(&shape.residual_shape).unwrap();
            prop_assert!(a_prime[(0, 1)] == 0.0 && a_prime[(0, 0)] > 0.0 && a_prime[(1, 1)] > 0.0);
            let back = synthesize(&shape, 0).unwrap();
            prop_assert!((back - a).norm() < 1e-12 * a.norm().max(1.0));
        }
    }

    #[test]
    fn pure_rotation_and_scale_decompose_exactly() {
        let a = rotation(PI / 3.0) * 2.5;
        let s = decompose(&a, 0).unwrap();
        assert!((s.orientation - PI / 3.0).abs() < 1e-15);
        assert!((s.scale - 2.5).abs() < 1e-15);
        assert!(s.residual_shape.iter().all(|v| v.abs() < 1e-15));
    }

    #[test]
    fn bad_inputs_give_named_errors() {
        let reflection = Mat2::new(1.0, 0.0, 0.0, -1.0);
        assert!(matches!(
            decompose(&reflection, 4),
            Err(GeomError::NonPositiveDeterminant { index: 4, .. })
        ));
        assert!(matches!(
            decompose(&Mat2::zeros(), 0),
            Err(GeomError::NonPositiveDeterminant { .. })
        ));
        let shape = |o, s, x: [f64; 3]| AffineShape {
            orientation: o,
            scale: s,
            residual_shape: x,
        };
        assert!(matches!(
            synthesize(&shape(0.0, 0.0, [0.0; 3]), 2),
            Err(GeomError::NotPositive {
                what: "scale",
                index: 2,
                ..
            })
        ));
        assert!(matches!(
            synthesize(&shape(f64::NAN, 1.0, [0.0; 3]), 0),
            Err(GeomError::NonFinite {
                what: "orientation",
                ..
            })
        ));
        assert!(synthesize(&shape(0.0, 1.0, [-1.0, 0.0, 0.0]), 0).is_err());
        assert!(synthesize(&shape(0.0, 1.0, [-2.0, 0.0, -2.0]), 0).is_err());
        let mut out = [[0.0; 4]; 2];
        let e = synthesize_affine(&[0.0, 0.0], &[1.0], &[[0.0; 3]; 2], &mut out).unwrap_err();
        assert_eq!(
            e,
            GeomError::LengthMismatch {
                what: "scale",
                expected: 2,
                got: 1
            }
        );
    }

    #[test]
    fn frames_and_lafs_round_trip() {
        let a = Mat2::new(1.2, 0.3, -0.4, 0.8);
        let row = [
            10.0,
            20.0,
            30.0,
            40.0,
            a[(0, 0)],
            a[(0, 1)],
            a[(1, 0)],
            a[(1, 1)],
        ];
        let (mut l1, mut l2) = ([[0.0; 6]; 1], [[0.0; 6]; 1]);
        affine_to_laf(&[row], 6.0, &mut l1, &mut l2).unwrap();
        assert_eq!(l1[0], [6.0, 0.0, 10.0, 0.0, 6.0, 20.0]);
        let mut back = [[0.0; 8]; 1];
        laf_to_affine(&l1, &l2, &mut back).unwrap();
        for k in 0..8 {
            assert!((back[0][k] - row[k]).abs() < 1e-15);
        }
        // Frames of the same patch at different scales and rotations: A = L2 L1⁻¹.
        let l1 = rotation(0.3) * 4.0;
        let l2 = a * l1;
        assert!((affine_from_frames(&l1, &l2, 0).unwrap() - a).norm() < 1e-14);
        assert!(affine_from_frames(&Mat2::zeros(), &l2, 0).is_err());
        assert!(affine_to_laf(&[row], 0.0, &mut [[0.0; 6]], &mut [[0.0; 6]]).is_err());
    }
}
