//! Non-minimal essential matrix: linear least squares over N point correspondences (the
//! eight-point algorithm) and optionally AC rows, projected to the essential manifold.
//!
//! H. C. Longuet-Higgins, "A computer algorithm for reconstructing a scene from two
//! projections", Nature 293, 1981; R. Hartley, "In defense of the eight-point algorithm",
//! IEEE TPAMI 19(6), 1997; Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., §9.6, §11.
//!
//! 1. Hartley normalisation: each image's points are translated to their centroid and scaled
//!    to mean distance √2 (x̃ = T x̂). An AC's Â becomes (s2 / s1)·Â.
//! 2. Rows p̃2ᵀ Ẽ p̃1 = 0 for points, plus the two affine rows Ãᵀ (Ẽ p̃1)₁:₂ + (Ẽᵀ p̃2)₁:₂ = 0 for
//!    each AC (docs/design.md §2), accumulated into the 9×9 normal matrix Σ rᵀr; the solution is its
//!    eigenvector of least eigenvalue (no N×9 storage, so no heap allocation).
//! 3. Back to normalised coordinates, E = T2ᵀ Ẽ T1, then the closest essential matrix in
//!    Frobenius norm (H&Z Thm. 9.19 / §11.1.1): E = U diag(1, 1, 0) Vᵀ / √2.
//!
//! The system must have at least eight independent rows: eight points in general position
//! (points on one plane are degenerate), or fewer points with ACs from at least two planes.

use super::constraints::{affine_rows, point_row};
use affcorr_geom::{AffineCorrespondence, Mat3, Vec2};
use nalgebra::SMatrix;

/// Largest number of essential matrices [`essential_8pt`] and [`essential_lsq`] write.
pub const ESSENTIAL_8PT_MAX_SOLUTIONS: usize = 1;

/// The least-squares essential matrix of N ≥ 8 correspondences in normalised coordinates,
/// projected to the essential manifold (unit Frobenius norm, up to sign).
///
/// Writes at most one model into `out` and returns how many. Degenerate inputs (fewer than
/// eight points, mismatched lengths, coplanar or repeated points giving a rank-deficient
/// system, NaN or infinity) give 0 models.
pub fn essential_8pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Mat3]) -> usize {
    essential_lsq(x1, x2, &[], out)
}

/// [`essential_8pt`] with the three equations of each AC (normalised) stacked under the point
/// rows. Needs `x1.len() + 3·acs.len() ≥ 8`; an AC with det Â ≤ 0 or non-finite entries makes
/// the input degenerate (0 models).
pub fn essential_lsq(
    x1: &[Vec2],
    x2: &[Vec2],
    acs: &[AffineCorrespondence],
    out: &mut [Mat3],
) -> usize {
    if x1.len() != x2.len() || x1.len() + 3 * acs.len() < 8 || out.is_empty() {
        return 0;
    }
    if acs.iter().any(|ac| !(ac.a.determinant() > 0.0)) {
        return 0;
    }
    // Hartley normalisation over every point (points and AC centres).
    let n = (x1.len() + acs.len()) as f64;
    let firsts = x1.iter().chain(acs.iter().map(|ac| &ac.x1));
    let seconds = x2.iter().chain(acs.iter().map(|ac| &ac.x2));
    let c1 = firsts.clone().fold(Vec2::zeros(), |a, p| a + p) / n;
    let c2 = seconds.clone().fold(Vec2::zeros(), |a, p| a + p) / n;
    let d1 = firsts.map(|p| (p - c1).norm()).sum::<f64>() / n;
    let d2 = seconds.map(|p| (p - c2).norm()).sum::<f64>() / n;
    if !(d1.is_finite() && d2.is_finite() && d1 > 0.0 && d2 > 0.0) {
        return 0;
    }
    let (s1, s2) = (std::f64::consts::SQRT_2 / d1, std::f64::consts::SQRT_2 / d2);
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    let mut add = |r: &[f64; 9]| {
        let v = nalgebra::SVector::<f64, 9>::from_column_slice(r);
        ata += v * v.transpose();
    };
    for (p, q) in x1.iter().zip(x2) {
        add(&point_row(&((p - c1) * s1), &((q - c2) * s2)));
    }
    for ac in acs {
        let t = AffineCorrespondence {
            x1: (ac.x1 - c1) * s1,
            x2: (ac.x2 - c2) * s2,
            a: ac.a * (s2 / s1),
        };
        add(&point_row(&t.x1, &t.x2));
        for r in affine_rows(&t) {
            add(&r);
        }
    }
    if ata.iter().any(|v| !v.is_finite()) {
        return 0;
    }
    let eig = ata.symmetric_eigen();
    let mut order = [0usize; 9];
    for (i, o) in order.iter_mut().enumerate() {
        *o = i;
    }
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (l0, l1, lmax) = (
        eig.eigenvalues[order[0]],
        eig.eigenvalues[order[1]],
        eig.eigenvalues[order[8]],
    );
    // A second (near-)zero eigenvalue: the null space is not one-dimensional.
    if !(lmax > 0.0) || l1 <= 1e-12 * lmax || l0 > l1 {
        return 0;
    }
    let v = eig.eigenvectors.column(order[0]);
    let e_tilde = Mat3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
    let t1 = Mat3::new(s1, 0.0, -s1 * c1.x, 0.0, s1, -s1 * c1.y, 0.0, 0.0, 1.0);
    let t2 = Mat3::new(s2, 0.0, -s2 * c2.x, 0.0, s2, -s2 * c2.y, 0.0, 0.0, 1.0);
    match project_to_essential(&(t2.transpose() * e_tilde * t1)) {
        Some(e) => {
            out[0] = e;
            1
        }
        None => 0,
    }
}

/// The essential matrix closest to `m` in Frobenius norm, scaled to unit norm:
/// U diag(1, 1, 0) Vᵀ / √2 from the SVD m = U Σ Vᵀ. `None` for a zero or non-finite `m` or
/// one of rank < 2.
pub fn project_to_essential(m: &Mat3) -> Option<Mat3> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    // nalgebra does not sort singular values: drop the smallest.
    let k = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b]))?;
    let keep: Vec2 = match k {
        0 => Vec2::new(s[1], s[2]),
        1 => Vec2::new(s[0], s[2]),
        _ => Vec2::new(s[0], s[1]),
    };
    if !(keep.min() > 1e-12 * keep.max()) {
        return None;
    }
    let mut d = Mat3::identity() * std::f64::consts::FRAC_1_SQRT_2;
    d[(k, k)] = 0.0;
    Some(u * d * v_t)
}
