//! The affine correspondence a homography induces (docs/design.md §2).
//!
//! With p2 ~ H p1, x2 = (h₁·p1, h₂·p1) / w and w = h₃·p1, the Jacobian is
//! A = ∂x2/∂x1 = (H\[0:2,0:2\] − x2 · H\[2,0:2\]) / w.

use crate::batch;
use crate::camera::check_len;
use crate::epipolar::Pose;
use crate::error::{GeomError, Result};
use crate::types::{AcRow, AffineCorrespondence, Mat2, Mat3, Vec2, Vec3};

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

/// One decomposition of a calibrated homography: H ∝ R + (t/d) nᵀ for the camera motion
/// X2 = R X1 + t and the plane nᵀ X1 = d (n a unit normal, d > 0 the plane's distance from
/// camera 1). H fixes t only up to that distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarMotion {
    /// R and t/d (the translation in units of the plane's distance).
    pub pose: Pose,
    /// The plane's unit normal n in camera 1, pointing away from it (nᵀ X1 = d > 0).
    pub normal: Vec3,
}

/// The decompositions of the calibrated homography `h` (x̃2 ∝ H x̃1 in normalised coordinates)
/// that put the plane in front of camera 1 at a share `in_front` of the points `x1` (normalised
/// coordinates of the matches `x1` ↔ `x2`), at most two: the true motion and its twin, which
/// induce the same H and so explain every match equally (Faugeras and Lustman, 1988).
///
/// The method of Ma, Soatto, Košecká and Sastry (An Invitation to 3-D Vision, 2004, §5.3.3):
/// with H scaled so that its middle singular value is 1 and x̃2ᵀ H x̃1 > 0 for most matches
/// (the sign of positive depths), HᵀH = V diag(σ₁², 1, σ₃²) Vᵀ,
/// u₁,₂ = (√(1 − σ₃²) v₁ ± √(σ₁² − 1) v₃) / √(σ₁² − σ₃²), and for each u:
/// U = \[v₂, u, v₂ × u\], W = \[H v₂, H u, H v₂ × H u\], R = W Uᵀ, n = v₂ × u, t = (H − R) n;
/// (R, −t, −n) are the other two. With H = R + t nᵀ and X1 = x̃1 / (nᵀ x̃1), the depths in both
/// cameras are positive exactly when nᵀ x̃1 > 0, which keeps two of the four.
///
/// Empty when H is a rotation (σ₁ ≈ σ₃: no translation, or a plane at infinity) or singular.
pub fn decompose_homography(
    h: &Mat3,
    x1: &[Vec2],
    x2: &[Vec2],
    in_front: f64,
) -> Result<Vec<PlanarMotion>> {
    check_len("x2", x1.len(), x2.len())?;
    // HᵀH's eigenvalues are the squared singular values of H: σ₂² scales H, and the
    // eigenvectors are those of the scaled H's HᵀH (whose sign does not change it).
    let eig = (h.transpose() * h).symmetric_eigen();
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let middle = eig.eigenvalues[order[1]];
    if !(middle > 0.0 && eig.eigenvalues.iter().all(|v| v.is_finite())) {
        return Ok(Vec::new());
    }
    let mut hn = h / middle.sqrt();
    let p = |x: &Vec2| Vec3::new(x.x, x.y, 1.0);
    let positive = x1
        .iter()
        .zip(x2)
        .filter(|(a, b)| p(b).dot(&(hn * p(a))) > 0.0)
        .count();
    if 2 * positive < x1.len() {
        hn = -hn;
    }
    let (s1, s3) = (
        eig.eigenvalues[order[0]] / middle,
        eig.eigenvalues[order[2]] / middle,
    );
    let v = |k: usize| eig.eigenvectors.column(order[k]).into_owned();
    let (v1, v2, v3) = (v(0), v(1), v(2));
    if s1 - s3 < 1e-9 * s1.abs().max(1.0) {
        return Ok(Vec::new());
    }
    let (a, b) = ((1.0 - s3).max(0.0).sqrt(), (s1 - 1.0).max(0.0).sqrt());
    let norm = (s1 - s3).sqrt();
    let mut out = Vec::new();
    for u in [(v1 * a + v3 * b) / norm, (v1 * a - v3 * b) / norm] {
        let big_u = Mat3::from_columns(&[v2, u, v2.cross(&u)]);
        let (hv2, hu) = (hn * v2, hn * u);
        let big_w = Mat3::from_columns(&[hv2, hu, hv2.cross(&hu)]);
        let r = big_w * big_u.transpose();
        let n = v2.cross(&u);
        let t = (hn - r) * n;
        for sign in [1.0, -1.0] {
            let (n, t) = (n * sign, t * sign);
            let front = x1.iter().filter(|x| n.dot(&p(x)) > 0.0).count();
            if front as f64 >= in_front * x1.len() as f64 && !x1.is_empty() {
                out.push(PlanarMotion {
                    pose: Pose { r, t },
                    normal: n,
                });
            }
        }
    }
    Ok(out)
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

    /// A random plane in front of camera 1, a motion that keeps it in front of camera 2, and
    /// matches on it (normalised coordinates).
    fn planar_scene(seed: u64) -> (PlanarMotion, Vec<Vec2>, Vec<Vec2>) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        loop {
            let w = Vec3::new(
                rng.random_range(-0.4..0.4),
                rng.random_range(-0.4..0.4),
                rng.random_range(-0.4..0.4),
            );
            let r = nalgebra::Rotation3::new(w).into_inner();
            let t = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-0.5..0.5),
            );
            let n = Vec3::new(
                rng.random_range(-0.4..0.4),
                rng.random_range(-0.4..0.4),
                1.0,
            )
            .normalize()
                / 5.0;
            let (mut x1, mut x2) = (Vec::new(), Vec::new());
            let mut ok = true;
            for _ in 0..60 {
                let y = Vec3::new(
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.4..0.4),
                    1.0,
                );
                let depth = 1.0 / n.dot(&y);
                let x = r * (y * depth) + t;
                ok &= depth > 0.0 && x.z > 0.0;
                x1.push(y.xy());
                x2.push(x.xy() / x.z);
            }
            if ok {
                return (
                    PlanarMotion {
                        pose: Pose { r, t },
                        normal: n,
                    },
                    x1,
                    x2,
                );
            }
        }
    }

    #[test]
    fn a_homography_decomposes_into_its_motion_and_the_twin_that_induces_it_too() {
        let mut twins = 0;
        for seed in 0..40 {
            let (truth, x1, x2) = planar_scene(seed);
            let h = truth.pose.r + truth.pose.t * truth.normal.transpose();
            // Any scale and sign of H.
            let scale = if seed % 2 == 0 { 3.7 } else { -0.02 };
            let found = decompose_homography(&(h * scale), &x1, &x2, 1.0).unwrap();
            assert!(
                (1..=2).contains(&found.len()),
                "seed {seed}: {}",
                found.len()
            );
            // The truth in the decomposition's units: n unit, t over the plane's distance.
            let d = 1.0 / truth.normal.norm();
            let exact = |m: &PlanarMotion| {
                (m.pose.r - truth.pose.r).norm() < 1e-9
                    && (m.pose.t - truth.pose.t / d).norm() < 1e-9
                    && (m.normal - truth.normal * d).norm() < 1e-9
            };
            assert_eq!(found.iter().filter(|m| exact(m)).count(), 1, "seed {seed}");
            for m in &found {
                // Every decomposition is a motion (R a rotation) that induces the same H and
                // keeps the points in front of both cameras.
                let r = m.pose.r;
                assert!((r.transpose() * r - Mat3::identity()).norm() < 1e-9);
                assert!((r.determinant() - 1.0).abs() < 1e-9);
                assert!((r + m.pose.t * m.normal.transpose() - h).norm() < 1e-9 * h.norm());
                for (a, b) in x1.iter().zip(&x2) {
                    let y = Vec3::new(a.x, a.y, 1.0);
                    let depth = 1.0 / m.normal.dot(&y);
                    let x = r * (y * depth) + m.pose.t;
                    assert!(depth > 0.0 && x.z > 0.0);
                    assert!((x.xy() / x.z - b).norm() < 1e-9);
                }
            }
            twins += usize::from(found.len() == 2);
        }
        // The twin is physically valid in many of these scenes.
        assert!(twins >= 10, "{twins} of 40");
    }

    #[test]
    fn a_rotation_or_a_singular_map_has_no_planar_decomposition() {
        let (truth, x1, x2) = planar_scene(1);
        assert!(
            decompose_homography(&truth.pose.r, &x1, &x2, 0.9)
                .unwrap()
                .is_empty()
        );
        assert!(
            decompose_homography(&Mat3::zeros(), &x1, &x2, 0.9)
                .unwrap()
                .is_empty()
        );
        let e = decompose_homography(&truth.pose.r, &x1, &x2[..3], 0.9);
        assert!(matches!(e, Err(GeomError::LengthMismatch { .. })), "{e:?}");
    }
}
