//! Essential and fundamental matrices, and relative pose (docs/design.md §2).
//!
//! - Motion: X2 = R X1 + t. Then E = \[t\]× R and p̂2ᵀ E p̂1 = 0 for normalised points.
//! - F = K2⁻ᵀ E K1⁻¹, so p2ᵀ F p1 = 0 in pixels.
//! - E = U diag(1, 1, 0) Vᵀ has four (R, t) factorisations (Hartley & Zisserman, Result 9.19):
//!   R ∈ {U W Vᵀ, U Wᵀ Vᵀ}, t = ±u₃. Cheirality (points in front of both cameras) picks one.

use crate::camera::Intrinsics;
use crate::error::{GeomError, Result};
use crate::types::{Mat3, Vec2, Vec3, max_abs, power_of_two_normalizer};

/// A relative pose: X2 = R X1 + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation.
    pub r: Mat3,
    /// Translation (unit norm when it comes from an essential matrix).
    pub t: Vec3,
}

impl Pose {
    /// E = \[t\]× R.
    pub fn essential(&self) -> Mat3 {
        essential_from_pose(&self.r, &self.t)
    }
}

/// The cross-product matrix: `skew(t) * v = t × v`.
#[inline]
pub fn skew(t: &Vec3) -> Mat3 {
    Mat3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
}

/// E = \[t\]× R.
#[inline]
pub fn essential_from_pose(r: &Mat3, t: &Vec3) -> Mat3 {
    skew(t) * r
}

/// F = K2⁻ᵀ E K1⁻¹.
pub fn fundamental_from_essential(e: &Mat3, k1: &Intrinsics, k2: &Intrinsics) -> Mat3 {
    k2.inverse().transpose() * e * k1.inverse()
}

/// E = K2ᵀ F K1.
pub fn essential_from_fundamental(f: &Mat3, k1: &Intrinsics, k2: &Intrinsics) -> Mat3 {
    k2.matrix().transpose() * f * k1.matrix()
}

/// The four (R, t) factorisations of `e`, with unit t, in the order
/// (U W Vᵀ, u₃), (U W Vᵀ, −u₃), (U Wᵀ Vᵀ, u₃), (U Wᵀ Vᵀ, −u₃).
///
/// A noisy `e` (rank 3, unequal singular values) is read through its SVD, which amounts to
/// projecting it onto the essential manifold first.
pub fn decompose_essential(e: &Mat3) -> Result<[Pose; 4]> {
    if e.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite {
            what: "E",
            index: 0,
        });
    }
    // R and t do not depend on E's scale: factor E · r (r a power of two, exact) so that the
    // SVD neither overflows for huge E nor loses a tiny one to underflow.
    let e = e * power_of_two_normalizer(max_abs(e.iter()));
    let svd = e.svd(true, true);
    let (mut u, mut v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    // nalgebra's SVD does not sort singular values: bring the smallest to the last column.
    let s = svd.singular_values;
    let k = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap();
    if s.max() == 0.0 {
        return Err(GeomError::Degenerate {
            what: "E",
            reason: "it is zero",
        });
    }
    if k != 2 {
        u.swap_columns(k, 2);
        v_t.swap_rows(k, 2);
    }
    // Proper rotations: flipping the sign of the null vectors changes neither E's null spaces
    // nor the factorisation's validity.
    if u.determinant() < 0.0 {
        u.column_mut(2).neg_mut();
    }
    if v_t.determinant() < 0.0 {
        v_t.row_mut(2).neg_mut();
    }
    let w = Mat3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let r1 = u * w * v_t;
    let r2 = u * w.transpose() * v_t;
    let t: Vec3 = u.column(2).into_owned();
    Ok([
        Pose { r: r1, t },
        Pose { r: r1, t: -t },
        Pose { r: r2, t },
        Pose { r: r2, t: -t },
    ])
}

/// The factorisation of an essential matrix `e` that puts every correspondence (normalised
/// coordinates) in front of both cameras, or `None` when none does (or `e` is not finite or has
/// rank below 2). Generic data leave one such factorisation; where degenerate data leave more,
/// which one is returned is unspecified (the signs of u₃ below are not the SVD's).
///
/// Meant for the minimal solvers' E, which are essential up to rounding: instead of an SVD it
/// builds the bases in closed form. E = \[t\]× R has equal singular values σ and left null
/// vector t, which is normal to every column of E: u₃ = t/|t| is the normalised largest cross
/// product of two columns, u₁ the largest column made normal to u₃, u₂ = u₃ × u₁. Then
/// Eᵀu₃ = 0 and E = Σᵢ uᵢ (Eᵀuᵢ)ᵀ = σ (u₁v₁ᵀ + u₂v₂ᵀ) with vᵢ = Eᵀuᵢ/σ, so U = \[u₁ u₂ u₃\] and
/// V = \[v₁ v₂ v₁ × v₂\] are rotations with E = U diag(σ, σ, 0) Vᵀ, the form of Hartley &
/// Zisserman's Result 9.19 that [`decompose_essential`] reads off an SVD. v₂ is made normal to
/// v₁ so that V stays a rotation when `e` is essential only to rounding; for a noisy E (an
/// over-determined fit) [`pose_from_essential`]'s projection by the SVD is the right tool.
///
/// The candidates are tested one by one and a candidate is dropped at its first point behind a
/// camera, so a minimal sample costs about one cheirality test per wrong candidate.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, Vec3, epipolar::{Pose, pose_with_all_in_front}};
/// let truth = Pose { r: Mat3::identity(), t: Vec3::new(1.0, 0.0, 0.0) };
/// // A point at (0, 0, 4) in camera 1 is at (1, 0, 4) in camera 2.
/// let (x1, x2) = ([Vec2::new(0.0, 0.0)], [Vec2::new(0.25, 0.0)]);
/// let pose = pose_with_all_in_front(&truth.essential(), &x1, &x2).unwrap();
/// assert!((pose.r - truth.r).norm() < 1e-12 && (pose.t - truth.t).norm() < 1e-12);
/// // Its mirror image (0, 0, -4), behind both cameras, is in front of both under (R, -t):
/// // no factorisation keeps the two in front.
/// let (y1, y2) = ([x1[0], x1[0]], [x2[0], Vec2::new(-0.25, 0.0)]);
/// assert!(pose_with_all_in_front(&truth.essential(), &y1, &y2).is_none());
/// ```
pub fn pose_with_all_in_front(e: &Mat3, x1: &[Vec2], x2: &[Vec2]) -> Option<Pose> {
    if x1.len() != x2.len() || e.iter().any(|v| !v.is_finite()) {
        return None;
    }
    // As in decompose_essential: an exact power-of-two scale keeps the products in range.
    let e = e * power_of_two_normalizer(max_abs(e.iter()));
    let cols = [e.column(0), e.column(1), e.column(2)];
    let crosses = [
        cols[0].cross(&cols[1]),
        cols[0].cross(&cols[2]),
        cols[1].cross(&cols[2]),
    ];
    let t = crosses
        .iter()
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
    let widest = cols
        .iter()
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
    // Rank 2 or nothing: E = [t]× R has a cross product of norm ≥ σ²/√3 (the columns are
    // t × rᵢ, so their cross products are ±t (t·rₖ)), a rank-1 E only rounding.
    if t.norm() <= 1e-8 * widest.norm_squared() {
        return None;
    }
    let u3 = t.normalize();
    let u1 = (widest - u3 * widest.dot(&u3)).try_normalize(0.0)?;
    let u2 = u3.cross(&u1);
    let v1 = (e.transpose() * u1).try_normalize(0.0)?;
    let v2 = e.transpose() * u2;
    let v2 = (v2 - v1 * v2.dot(&v1)).try_normalize(0.0)?;
    let v3 = v1.cross(&v2);
    let v = Mat3::from_columns(&[v1, v2, v3]);
    // U W and U Wᵀ, W the quarter turn of decompose_essential, U = [u₁ u₂ u₃].
    let (uw, uwt) = (
        Mat3::from_columns(&[u2, -u1, u3]),
        Mat3::from_columns(&[-u2, u1, u3]),
    );
    let (r1, r2) = (uw * v.transpose(), uwt * v.transpose());
    [(r1, u3), (r1, -u3), (r2, u3), (r2, -u3)]
        .into_iter()
        .map(|(r, t)| Pose { r, t })
        .find(|pose| {
            x1.iter()
                .zip(x2)
                .all(|(a, b)| cheirality(pose, a, b) == Cheirality::InFront)
        })
}

/// Depths (λ1, λ2) of the point seen at normalised x1, x2 under `pose`, from the least-squares
/// solution of λ2·x̂2 = λ1·R·x̂1 + t (the midpoint form, exact for noise-free data).
/// Returns `None` when the rays are parallel.
#[inline]
pub fn triangulate_depths(pose: &Pose, x1: &Vec2, x2: &Vec2) -> Option<(f64, f64)> {
    let a = pose.r * Vec3::new(x1.x, x1.y, 1.0);
    let b = Vec3::new(x2.x, x2.y, 1.0);
    // Normal equations of min ‖λ1 a − λ2 b + t‖².
    let (aa, ab, bb) = (a.dot(&a), a.dot(&b), b.dot(&b));
    let (at, bt) = (a.dot(&pose.t), b.dot(&pose.t));
    let det = aa * bb - ab * ab;
    if det <= 1e-14 * aa * bb {
        return None;
    }
    let l1 = (ab * bt - bb * at) / det;
    let l2 = (aa * bt - ab * at) / det;
    Some((l1, l2))
}

/// Where the point seen at normalised x1, x2 lies under a pose ([`cheirality`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cheirality {
    /// In front of both cameras: both depths of [`triangulate_depths`] positive.
    InFront,
    /// Behind either camera.
    Behind,
    /// The rays are parallel (a point at infinity): [`triangulate_depths`] gives `None`.
    Parallel,
}

/// The signs of [`triangulate_depths`]' depths without its divisions: they share the positive
/// determinant of the normal equations, so each depth has its numerator's sign. Without
/// divisions, and its three outcomes are selects, so that loops over many correspondences
/// vectorise.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, Vec3, epipolar::{Cheirality, Pose, cheirality}};
/// let pose = Pose { r: Mat3::identity(), t: Vec3::new(1.0, 0.0, 0.0) };
/// // A point at (0, 0, 4) in camera 1 is at (1, 0, 4) in camera 2; at (0, 0, -4), behind.
/// assert_eq!(cheirality(&pose, &Vec2::zeros(), &Vec2::new(0.25, 0.0)), Cheirality::InFront);
/// assert_eq!(cheirality(&pose, &Vec2::zeros(), &Vec2::new(-0.25, 0.0)), Cheirality::Behind);
/// assert_eq!(cheirality(&pose, &Vec2::zeros(), &Vec2::zeros()), Cheirality::Parallel);
/// ```
#[inline(always)]
pub fn cheirality(pose: &Pose, x1: &Vec2, x2: &Vec2) -> Cheirality {
    let a = pose.r * Vec3::new(x1.x, x1.y, 1.0);
    let b = Vec3::new(x2.x, x2.y, 1.0);
    let (aa, ab, bb) = (a.dot(&a), a.dot(&b), b.dot(&b));
    let (at, bt) = (a.dot(&pose.t), b.dot(&pose.t));
    let det = aa * bb - ab * ab;
    let (n1, n2) = (ab * bt - bb * at, aa * bt - ab * at);
    if det <= 1e-14 * aa * bb {
        Cheirality::Parallel
    } else if n1 > 0.0 && n2 > 0.0 {
        Cheirality::InFront
    } else {
        Cheirality::Behind
    }
}

/// Number of correspondences (normalised coordinates) in front of both cameras under `pose`.
pub fn count_in_front(pose: &Pose, x1: &[Vec2], x2: &[Vec2]) -> usize {
    x1.iter()
        .zip(x2)
        .map(|(a, b)| usize::from(cheirality(pose, a, b) == Cheirality::InFront))
        .sum()
}

/// The factorisation of `e` that puts the most correspondences in front of both cameras.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, Vec3, epipolar::{Pose, pose_from_essential}};
/// let truth = Pose { r: Mat3::identity(), t: Vec3::new(1.0, 0.0, 0.0) };
/// // A point at (0, 0, 4) in camera 1 is at (1, 0, 4) in camera 2.
/// let (x1, x2) = (vec![Vec2::new(0.0, 0.0)], vec![Vec2::new(0.25, 0.0)]);
/// let (pose, n) = pose_from_essential(&truth.essential(), &x1, &x2).unwrap();
/// assert_eq!(n, 1);
/// assert!((pose.r - truth.r).norm() < 1e-12 && (pose.t - truth.t).norm() < 1e-12);
/// ```
/// Returns the pose and that count. Ties go to the first candidate in
/// [`decompose_essential`]'s order.
pub fn pose_from_essential(e: &Mat3, x1: &[Vec2], x2: &[Vec2]) -> Result<(Pose, usize)> {
    if x1.len() != x2.len() {
        return Err(GeomError::LengthMismatch {
            what: "x2",
            expected: x1.len(),
            got: x2.len(),
        });
    }
    // A NaN point is never "in front", so it would silently lower the counts.
    for (what, pts) in [("x1", x1), ("x2", x2)] {
        if let Some(index) = pts
            .iter()
            .position(|p| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(GeomError::NonFinite { what, index });
        }
    }
    let candidates = decompose_essential(e)?;
    let mut best = (candidates[0], 0);
    for pose in candidates {
        let n = count_in_front(&pose, x1, x2);
        if n > best.1 {
            best = (pose, n);
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{general_points, random_pose, random_rotation};
    use rand::{Rng, SeedableRng};

    #[test]
    fn decomposition_contains_the_true_pose_and_cheirality_finds_it() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        for _ in 0..200 {
            let truth = random_pose(&mut rng);
            let e = truth.essential();
            let cands = decompose_essential(&e).unwrap();
            let t_unit = truth.t.normalize();
            let hits = cands
                .iter()
                .filter(|p| (p.r - truth.r).norm() < 1e-10 && (p.t - t_unit).norm() < 1e-10)
                .count();
            assert_eq!(hits, 1);
            for p in &cands {
                assert!((p.r.determinant() - 1.0).abs() < 1e-12);
                // Every candidate reproduces E up to sign and scale.
                let ep = p.essential();
                let s = e.norm() / ep.norm();
                assert!((ep * s - e).norm().min((ep * s + e).norm()) < 1e-10 * e.norm());
            }
            // Points in front of camera 1 at depths 2..6.
            let mut x1 = Vec::new();
            let mut x2 = Vec::new();
            for i in 0..10 {
                let xw = Vec3::new(
                    0.1 * i as f64 - 0.5,
                    0.05 * i as f64 - 0.2,
                    2.0 + 0.4 * i as f64,
                );
                let xc2 = truth.r * xw + truth.t;
                if xc2.z > 0.0 {
                    x1.push(Vec2::new(xw.x / xw.z, xw.y / xw.z));
                    x2.push(Vec2::new(xc2.x / xc2.z, xc2.y / xc2.z));
                }
            }
            let (pose, n) = pose_from_essential(&e, &x1, &x2).unwrap();
            assert_eq!(n, x1.len());
            assert!((pose.r - truth.r).norm() < 1e-10 && (pose.t - t_unit).norm() < 1e-10);
        }
        let _ = random_rotation(&mut rng);
    }

    #[test]
    fn fundamental_and_essential_convert_both_ways() {
        let k1 = Intrinsics::from_focal(800.0, 700.0, 320.0, 240.0).unwrap();
        let k2 = Intrinsics::from_focal(600.0, 650.0, 300.0, 200.0).unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
        let e = random_pose(&mut rng).essential();
        let f = fundamental_from_essential(&e, &k1, &k2);
        assert!((essential_from_fundamental(&f, &k1, &k2) - e).norm() < 1e-12);
    }

    #[test]
    fn closed_form_factorisation_agrees_with_the_svd() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        for trial in 0..2000 {
            let truth = random_pose(&mut rng);
            let n = 1 + trial % 6;
            let (x1, x2) = general_points(&mut rng, &truth, n);
            // Any scale and sign, and the rounding of a minimal solver's E.
            let scale = 10f64.powi(rng.random_range(-150..150)) * [1.0, -1.0][trial % 2];
            let jitter = Mat3::from_fn(|_, _| rng.random_range(-1e-13..1e-13));
            let e = (truth.essential() / truth.t.norm() + jitter) * scale;
            let fast = pose_with_all_in_front(&e, &x1, &x2).expect("the truth is a candidate");
            let (svd, count) = pose_from_essential(&e, &x1, &x2).unwrap();
            assert_eq!(count, n);
            assert!((fast.r - svd.r).norm() < 1e-10, "trial {trial}");
            assert!((fast.t - svd.t).norm() < 1e-10, "trial {trial}");
            assert!((fast.r.transpose() * fast.r - Mat3::identity()).norm() < 1e-14);
            assert!((fast.r.determinant() - 1.0).abs() < 1e-14);
            assert!(
                (fast.t - truth.t.normalize()).norm() < 1e-9,
                "trial {trial}"
            );
            assert!((fast.r - truth.r).norm() < 1e-9, "trial {trial}");
        }
    }

    #[test]
    fn closed_form_factorisation_rejects_what_it_cannot_factor() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
        let truth = random_pose(&mut rng);
        let (x1, x2) = general_points(&mut rng, &truth, 5);
        let e = truth.essential();
        assert!(pose_with_all_in_front(&e, &x1, &x2).is_some());
        // A point behind both cameras is in front of both under (R, −t), the others only under
        // (R, t): no factorisation keeps them all in front.
        let behind = loop {
            let xw = Vec3::new(
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
                -4.0,
            );
            let xc2 = truth.r * xw + truth.t;
            if xc2.z < -0.1 {
                break (
                    Vec2::new(xw.x / xw.z, xw.y / xw.z),
                    Vec2::new(xc2.x / xc2.z, xc2.y / xc2.z),
                );
            }
        };
        let (mut y1, mut y2) = (x1.clone(), x2.clone());
        y1.push(behind.0);
        y2.push(behind.1);
        assert!(pose_from_essential(&e, &y1, &y2).unwrap().1 < y1.len());
        assert!(pose_with_all_in_front(&e, &y1, &y2).is_none());
        let alone = pose_with_all_in_front(&e, &y1[5..], &y2[5..]).unwrap();
        assert!((alone.t + truth.t.normalize()).norm() < 1e-9);
        assert!(pose_with_all_in_front(&Mat3::zeros(), &x1, &x2).is_none());
        assert!(pose_with_all_in_front(&Mat3::from_element(f64::NAN), &x1, &x2).is_none());
        let rank_one = e.column(0) * e.row(0);
        assert!(pose_with_all_in_front(&rank_one, &x1, &x2).is_none());
        assert!(pose_with_all_in_front(&e, &x1, &x2[..4]).is_none());
    }

    #[test]
    fn degenerate_essential_is_an_error() {
        assert!(decompose_essential(&Mat3::zeros()).is_err());
        assert!(decompose_essential(&Mat3::from_element(f64::NAN)).is_err());
    }
}
