//! The affine correspondence a homography induces (docs/design.md §2).
//!
//! With p2 ~ H p1, x2 = (h₁·p1, h₂·p1) / w and w = h₃·p1, the Jacobian is
//! A = ∂x2/∂x1 = (H\[0:2,0:2\] − x2 · H\[2,0:2\]) / w.

use crate::batch;
use crate::camera::check_len;
use crate::error::{GeomError, Result};
use crate::types::{AcRow, AffineCorrespondence, Mat2, Mat3, Vec2};

/// `|w|` below this (relative to ‖H‖) means the point maps to infinity.
const VANISHING_W: f64 = 1e-12;

/// The AC induced by `h` at `x1`: `(x1, x2, A)`. `index` only labels the error.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, homography::ac_from_homography};
/// // A pure scaling by 2 about the origin: A = 2·I everywhere.
/// let h = Mat3::new(2.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0);
/// let ac = ac_from_homography(&h, &Vec2::new(3.0, 4.0), 0).unwrap();
/// assert_eq!(ac.x2, Vec2::new(6.0, 8.0));
/// assert_eq!(ac.a, nalgebra::Matrix2::new(2.0, 0.0, 0.0, 2.0));
/// ```
#[inline]
pub fn ac_from_homography(h: &Mat3, x1: &Vec2, index: usize) -> Result<AffineCorrespondence> {
    ac_with_tolerance(h, x1, index, VANISHING_W * h.norm())
}

/// [`ac_from_homography`] with the vanishing tolerance on |w| computed once per batch.
#[inline]
fn ac_with_tolerance(
    h: &Mat3,
    x1: &Vec2,
    index: usize,
    tolerance: f64,
) -> Result<AffineCorrespondence> {
    if !x1.x.is_finite() || !x1.y.is_finite() {
        return Err(GeomError::NonFinite { what: "x1", index });
    }
    let w = h[(2, 0)] * x1.x + h[(2, 1)] * x1.y + h[(2, 2)];
    if w.abs() <= tolerance {
        return Err(GeomError::PointAtInfinity { index, w });
    }
    let x2 = Vec2::new(
        (h[(0, 0)] * x1.x + h[(0, 1)] * x1.y + h[(0, 2)]) / w,
        (h[(1, 0)] * x1.x + h[(1, 1)] * x1.y + h[(1, 2)]) / w,
    );
    let a = Mat2::new(
        h[(0, 0)] - x2.x * h[(2, 0)],
        h[(0, 1)] - x2.x * h[(2, 1)],
        h[(1, 0)] - x2.y * h[(2, 0)],
        h[(1, 1)] - x2.y * h[(2, 1)],
    ) / w;
    Ok(AffineCorrespondence { x1: *x1, x2, a })
}

/// Batched [`ac_from_homography`]: `(N, 2)` points to `(N, 8)` ACs.
pub fn correspondences_from_homography(h: &Mat3, x1: &[[f64; 2]], out: &mut [AcRow]) -> Result<()> {
    check_homography(h)?;
    check_len("out", x1.len(), out.len())?;
    let tolerance = VANISHING_W * h.norm();
    batch::try_fill(out, |i| {
        ac_with_tolerance(h, &Vec2::new(x1[i][0], x1[i][1]), i, tolerance).map(|ac| ac.to_row())
    })
}

/// Batched A only: `(N, 2)` points to `(N, 2, 2)` row-major affine maps.
pub fn affine_from_homography(h: &Mat3, x1: &[[f64; 2]], out: &mut [[f64; 4]]) -> Result<()> {
    check_homography(h)?;
    check_len("out", x1.len(), out.len())?;
    let tolerance = VANISHING_W * h.norm();
    batch::try_fill(out, |i| {
        ac_with_tolerance(h, &Vec2::new(x1[i][0], x1[i][1]), i, tolerance)
            .map(|ac| crate::types::mat2_to_row(&ac.a))
    })
}

fn check_homography(h: &Mat3) -> Result<()> {
    if h.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite {
            what: "H",
            index: 0,
        });
    }
    if h.norm() == 0.0 {
        return Err(GeomError::Degenerate {
            what: "H",
            reason: "it is zero",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graffiti_h() -> Mat3 {
        Mat3::new(
            7.6285898e-01,
            -2.9922929e-01,
            2.2567123e+02,
            3.3443473e-01,
            1.0143901e+00,
            -7.6999973e+01,
            3.4663091e-04,
            -1.4364524e-05,
            1.0,
        )
    }

    fn project(h: &Mat3, x: &Vec2) -> Vec2 {
        let p = h * nalgebra::Vector3::new(x.x, x.y, 1.0);
        Vec2::new(p.x / p.z, p.y / p.z)
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let h = graffiti_h();
        for &(x, y) in &[(100.0, 200.0), (700.0, 50.0), (400.0, 600.0)] {
            let x1 = Vec2::new(x, y);
            let ac = ac_from_homography(&h, &x1, 0).unwrap();
            assert!((ac.x2 - project(&h, &x1)).norm() < 1e-10);
            let eps = 1e-4;
            for j in 0..2 {
                let mut dp = x1;
                let mut dm = x1;
                dp[j] += eps;
                dm[j] -= eps;
                let col = (project(&h, &dp) - project(&h, &dm)) / (2.0 * eps);
                assert!((col - ac.a.column(j)).norm() < 1e-8, "column {j}");
            }
        }
    }

    proptest::proptest! {
        /// The AC of a composition is the composition of the ACs (chain rule):
        /// A_{G∘H}(x) = A_G(H(x)) · A_H(x).
        #[test]
        fn acs_compose_like_jacobians(
            h in proptest::array::uniform9(-1.0f64..1.0), g in proptest::array::uniform9(-1.0f64..1.0),
            x in -2.0f64..2.0, y in -2.0f64..2.0,
        ) {
            let h = Mat3::from_row_slice(&h) + Mat3::identity() * 2.0;
            let g = Mat3::from_row_slice(&g) + Mat3::identity() * 2.0;
            let x1 = Vec2::new(x, y);
            let (Ok(first), Ok(comp)) = (ac_from_homography(&h, &x1, 0), ac_from_homography(&(g * h), &x1, 0)) else {
                return Ok(());
            };
            let Ok(second) = ac_from_homography(&g, &first.x2, 0) else { return Ok(()) };
            let w = (g * h * nalgebra::Vector3::new(x, y, 1.0)).z.abs().min((h * nalgebra::Vector3::new(x, y, 1.0)).z.abs());
            proptest::prop_assume!(w > 1e-3);
            let scale = comp.a.norm().max(1.0);
            proptest::prop_assert!((second.x2 - comp.x2).norm() < 1e-8 * comp.x2.norm().max(1.0));
            proptest::prop_assert!((second.a * first.a - comp.a).norm() < 1e-8 * scale);
        }
    }

    #[test]
    fn vanishing_line_and_non_finite_are_errors() {
        let h = Mat3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -2.0);
        assert!(matches!(
            ac_from_homography(&h, &Vec2::new(2.0, 5.0), 7),
            Err(GeomError::PointAtInfinity { index: 7, .. })
        ));
        let mut out = [[0.0; 4]; 2];
        let e = affine_from_homography(&graffiti_h(), &[[0.0, 0.0], [f64::NAN, 1.0]], &mut out);
        assert_eq!(
            e,
            Err(GeomError::NonFinite {
                what: "x1",
                index: 1
            })
        );
        let e = affine_from_homography(&Mat3::zeros(), &[[0.0, 0.0]], &mut out[..1]);
        assert!(matches!(e, Err(GeomError::Degenerate { what: "H", .. })));
    }
}
