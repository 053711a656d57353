//! Homography solvers, p2 ~ H p1 in pixels (docs/design.md §2, §4).
//!
//! | solver | sample | models | method |
//! |---|---|---|---|
//! | [`homography_4pt`] | 4 points | ≤ 1 | normalised DLT, null space in closed form |
//! | [`homography_2ac`] | 2 ACs | ≤ 1 | 12 linear equations (2 point + 4 affine per AC), LSQ |
//! | [`homography_1ac2pt`] | 1 AC + 2 points | ≤ 1 | 10 linear equations (2 + 4 + 4) of rank 8, LSQ |
//! | [`homography_1ac_given_f`] | 1 AC + F | ≤ 1 | H = −\[e₂\]×F + e₂vᵀ, 6 linear equations in v |
//! | [`homography_lsq`] | N ≥ 4 points | ≤ 1 | normalised DLT, least squares |
//! | [`homography_lsq_normal_equations`] | N ≥ 4 points, weighted | ≤ 1 | the same from the normal equations, cheaper (local optimisation's fit) |
//! | [`homography_ac_lsq`] | N ≥ 2 ACs | ≤ 1 | the 2AC system over N ACs, least squares |
//!
//! All solvers take pixels, apply Hartley's isotropic normalisation internally
//! (`normalization`), and write H with ‖H‖_F = 1 (its sign is arbitrary) into the
//! caller's buffer, returning the number of models. A sample of the wrong length, with a
//! non-finite value, collinear or coincident points, an affine map with det A ≤ 0, or a
//! rank-deficient linear system gives 0 models. `out` shorter than the solver's
//! `*_MAX_SOLUTIONS` is a caller bug and panics.
//!
//! # Equations
//! With p = (x, y, 1)ᵀ, hₖ the k-th row of H and w = h₃·p1:
//! - point (DLT, Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., eq. 4.3):
//!   h₁·p1 − x2·(h₃·p1) = 0 and h₂·p1 − y2·(h₃·p1) = 0;
//! - affine (from A = (H\[0:2,0:2\] − x2·H\[2,0:2\]) / w, docs/design.md §2; Barath & Hajder, "A theory
//!   of point-wise homography estimation", PRL 2017, eq. 9): for i, j ∈ {1, 2},
//!   a_ij·(h₃·p1) − h_ij + x2_i·h_3j = 0.
//!
//! Both are linear and homogeneous in the 9 entries of H, and invariant in form under the
//! normalising similarities (Â = (s₂/s₁)·A). In the over-determined AC systems the affine rows
//! are scaled by ρ·s₁ with ρ = 8 px, which makes their residuals commensurate with the point
//! rows' (an error ε in A moves points at distance ρ by ε·ρ); exact data is unaffected, noisy
//! estimates improve about 3× against unweighted rows.

use crate::linalg::{Lsq9, householder_fold, mat3_from_vec9, smallest_singular3, unit_frobenius};
use crate::normalization::{
    AFFINE_ROW_RADIUS_PX, Similarity, hybrid_normalisers, valid_ac, valid_indexed_input,
};
use affcorr_geom::{AffineCorrespondence, Mat3, Vec2, Vec3};

/// Most models [`homography_4pt`] returns.
pub const HOMOGRAPHY_4PT_MAX_SOLUTIONS: usize = 1;
/// Most models [`homography_2ac`] returns.
pub const HOMOGRAPHY_2AC_MAX_SOLUTIONS: usize = 1;
/// Most models [`homography_1ac2pt`] returns.
pub const HOMOGRAPHY_1AC2PT_MAX_SOLUTIONS: usize = 1;
/// Most models [`homography_1ac_given_f`] returns.
pub const HOMOGRAPHY_1AC_GIVEN_F_MAX_SOLUTIONS: usize = 1;
/// Most models [`homography_lsq`] returns.
pub const HOMOGRAPHY_LSQ_MAX_SOLUTIONS: usize = 1;
/// Most models [`homography_ac_lsq`] returns.
pub const HOMOGRAPHY_AC_LSQ_MAX_SOLUTIONS: usize = 1;

/// Twice the area of a triangle of normalised points (mean distance √2 from the centroid) below
/// which the triangle counts as collinear.
const COLLINEAR_TOL: f64 = 1e-8;
/// A singular value of a normalised linear system below this × the largest counts as zero.
const RANK_TOL: f64 = 1e-9;
/// The same test on an eliminated 3×3 system S = CᵀC − …, whose singular values are squares
/// of the system's: σ₂(S) ≤ this × σ₁(S) counts as rank-deficient (the system's σ below
/// 1e-6 × its largest; rounding leaves S's zero eigenvalues near 1e-16 × the largest).
const REDUCED_RANK_TOL: f64 = 1e-12;

/// The homography of 4 point correspondences (exactly determined).
///
/// Normalised DLT (Hartley & Zisserman, Alg. 4.2) with the 8×9 null space solved in closed form
/// instead of by an SVD. Stack the normalised points as the rows pᵢᵀ of the 4×3 matrix P and
/// write H = [a b c]ᵀ. The DLT equations are P a = Dₓ P c and P b = D_y P c with
/// Dₓ = diag(x2ᵢ), D_y = diag(y2ᵢ). The left null vector of P is n, nᵢ = (−1)ⁱ det P₋ᵢ (P₋ᵢ: P
/// without row i; |nᵢ| is twice the area of the triangle of the other three points). Multiplying
/// by nᵀ eliminates a and b: (Pᵀ Dₓ n)·c = 0 and (Pᵀ D_y n)·c = 0, so
/// c = (Pᵀ Dₓ n) × (Pᵀ D_y n). Then a and b follow from the three points of the largest
/// triangle: a = P₃⁻¹ (Dₓ P c)₃, b = P₃⁻¹ (D_y P c)₃.
///
/// Returns 0 when `x1`/`x2` do not hold 4 finite points each, or when 3 of the 4 points are
/// collinear (or coincide) in either image.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, Vec3};
/// use affcorr_solvers::homography::{homography_4pt, HOMOGRAPHY_4PT_MAX_SOLUTIONS};
/// let h = Mat3::new(1.1, 0.1, 5.0, -0.05, 0.9, 3.0, 1e-4, 2e-4, 1.0);
/// let x1 = [
///     Vec2::new(0.0, 0.0),
///     Vec2::new(100.0, 0.0),
///     Vec2::new(100.0, 80.0),
///     Vec2::new(10.0, 90.0),
/// ];
/// let x2 = x1.map(|p| (h * Vec3::new(p.x, p.y, 1.0)).xy() / (h * Vec3::new(p.x, p.y, 1.0)).z);
/// let mut out = [Mat3::zeros(); HOMOGRAPHY_4PT_MAX_SOLUTIONS];
/// assert_eq!(homography_4pt(&x1, &x2, &mut out), 1);
/// let (e, g) = (out[0] / out[0][(2, 2)], h / h[(2, 2)]);
/// assert!((e - g).norm() < 1e-10 * g.norm());
/// ```
pub fn homography_4pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Mat3]) -> usize {
    assert!(out.len() >= HOMOGRAPHY_4PT_MAX_SOLUTIONS, "out too short");
    if x1.len() != 4 || x2.len() != 4 {
        return 0;
    }
    let (Some(t1), Some(t2)) = (
        Similarity::from_points(x1.iter().copied()),
        Similarity::from_points(x2.iter().copied()),
    ) else {
        return 0;
    };
    let p: [Vec3; 4] = std::array::from_fn(|i| t1.apply(&x1[i]).push(1.0));
    let q: [Vec2; 4] = std::array::from_fn(|i| t2.apply(&x2[i]));
    // nᵢ = (−1)ⁱ det P₋ᵢ, and the same for image 2 (only to reject collinear triples there).
    let tri = |a: Vec2, b: Vec2, c: Vec2| (b - a).perp(&(c - a));
    let pxy = |i: usize| p[i].xy();
    let n = [
        -tri(pxy(1), pxy(2), pxy(3)),
        tri(pxy(0), pxy(2), pxy(3)),
        -tri(pxy(0), pxy(1), pxy(3)),
        tri(pxy(0), pxy(1), pxy(2)),
    ];
    let m = [
        tri(q[1], q[2], q[3]),
        tri(q[0], q[2], q[3]),
        tri(q[0], q[1], q[3]),
        tri(q[0], q[1], q[2]),
    ];
    // `!(a > b)` also rejects NaN.
    if n.iter().chain(&m).any(|v| !(v.abs() > COLLINEAR_TOL)) {
        return 0;
    }
    let (mut u, mut w) = (Vec3::zeros(), Vec3::zeros());
    for i in 0..4 {
        u += p[i] * (n[i] * q[i].x);
        w += p[i] * (n[i] * q[i].y);
    }
    let c = u.cross(&w);
    // The three points of the largest triangle: all but row `skip`.
    let skip = (0..4).fold(0, |b, i| if n[i].abs() > n[b].abs() { i } else { b });
    let rows: [usize; 3] = match skip {
        0 => [1, 2, 3],
        1 => [0, 2, 3],
        2 => [0, 1, 3],
        _ => [0, 1, 2],
    };
    let p3 = Mat3::from_rows(&[
        p[rows[0]].transpose(),
        p[rows[1]].transpose(),
        p[rows[2]].transpose(),
    ]);
    let Some(p3_inv) = p3.try_inverse() else {
        return 0;
    };
    let wc = Vec3::from_fn(|k, _| c.dot(&p[rows[k]]));
    let a = p3_inv * Vec3::from_fn(|k, _| q[rows[k]].x * wc[k]);
    let b = p3_inv * Vec3::from_fn(|k, _| q[rows[k]].y * wc[k]);
    let h_norm = Mat3::from_rows(&[a.transpose(), b.transpose(), c.transpose()]);
    finish(&h_norm, &t1, &t2, out)
}

/// The homography of 2 ACs: 12 linear equations (per AC, 2 point DLT rows and the 4 affine rows
/// of the module doc) in the 9 entries of H, solved in the least-squares sense in normalised
/// coordinates (an over-determined system: 8 unknowns up to scale). Barath & Hajder, PRL 2017,
/// §3 ("HA" method).
///
/// Returns 0 for a sample of the wrong length, non-finite values, det A ≤ 0, coincident points,
/// or a system whose null space is not one-dimensional.
pub fn homography_2ac(acs: &[AffineCorrespondence], out: &mut [Mat3]) -> usize {
    assert!(out.len() >= HOMOGRAPHY_2AC_MAX_SOLUTIONS, "out too short");
    if acs.len() != 2 {
        return 0;
    }
    ac_least_squares(acs, out)
}

/// The homography of one AC and two point correspondences `x1[k] ↔ x2[k]`: the hybrid
/// sample. One AC fixes H up to a 2-parameter family: with the AC's points at the origins,
/// H = \[\[A, 0\], \[vᵀ, 1\]\] for any v (H(x) = A x / (1 + vᵀx) has the value 0 and the
/// Jacobian A there). A further point x ↦ q fixes only 1 + vᵀx = ‖A x‖/‖q‖, one equation in v
/// (its other equation, q ∥ A x, constrains the data, not H), so one AC and one point leave
/// a 1-parameter family and two points are needed. The AC's 2 point and 4 affine rows and the
/// points' 4 rows (module doc) are 10 equations of rank 8, solved in the least-squares sense
/// (normalised coordinates, affine rows weighted as in the AC systems). Four affine rows
/// instead of the 2-AC sample's eight: less of H rests on the affine maps' error.
///
/// Returns 0 for `x1`/`x2` not holding 2 points, non-finite values, det A ≤ 0, a point
/// coinciding with the AC's, or a system whose null space is not one-dimensional.
pub fn homography_1ac2pt(
    ac: &AffineCorrespondence,
    x1: &[Vec2],
    x2: &[Vec2],
    out: &mut [Mat3],
) -> usize {
    assert!(
        out.len() >= HOMOGRAPHY_1AC2PT_MAX_SOLUTIONS,
        "out too short"
    );
    let Some((t1, t2)) = hybrid_normalisers(ac, x1, x2, 2) else {
        return 0;
    };
    let (p, q) = (t1.apply(&ac.x1), t2.apply(&ac.x2));
    let w = AFFINE_ROW_RADIUS_PX * t1.s;
    let mut lsq = Lsq9::new();
    for r in point_rows(&p, &q) {
        lsq.add_row(r);
    }
    for r in affine_rows(&p, &q, &(ac.a * (t2.s / t1.s))) {
        lsq.add_row(r.map(|v| v * w));
    }
    for (a, b) in x1.iter().zip(x2) {
        for r in point_rows(&t1.apply(a), &t2.apply(b)) {
            lsq.add_row(r);
        }
    }
    solve_lsq(&lsq, &t1, &t2, out)
}

/// The non-minimal homography of N ≥ 2 ACs: the system of [`homography_2ac`] over all ACs,
/// least squares (algebraic error, normalised coordinates).
pub fn homography_ac_lsq(acs: &[AffineCorrespondence], out: &mut [Mat3]) -> usize {
    assert!(
        out.len() >= HOMOGRAPHY_AC_LSQ_MAX_SOLUTIONS,
        "out too short"
    );
    if acs.len() < 2 {
        return 0;
    }
    ac_least_squares(acs, out)
}

/// The non-minimal normalised DLT on N ≥ 4 point correspondences (Hartley & Zisserman,
/// Alg. 4.2): the 2N×9 system folded into a 9×9 triangular factor by blocked Householder QR,
/// then the right singular vector of its smallest singular value by inverse iteration
/// (`normalization`). Allocation-free.
///
/// Returns 0 when `x1.len() != x2.len()`, N < 4, a value is not finite, or the null space is not
/// one-dimensional (e.g. all points collinear).
pub fn homography_lsq(x1: &[Vec2], x2: &[Vec2], out: &mut [Mat3]) -> usize {
    assert!(out.len() >= HOMOGRAPHY_LSQ_MAX_SOLUTIONS, "out too short");
    if x1.len() != x2.len() || x1.len() < 4 {
        return 0;
    }
    let (Some(t1), Some(t2)) = (
        Similarity::from_points(x1.iter().copied()),
        Similarity::from_points(x2.iter().copied()),
    ) else {
        return 0;
    };
    let mut lsq = Lsq9::new();
    for (a, b) in x1.iter().zip(x2) {
        let (p, q) = (t1.apply(a), t2.apply(b));
        let [r1, r2] = point_rows(&p, &q);
        lsq.add_row(r1);
        lsq.add_row(r2);
    }
    solve_lsq(&lsq, &t1, &t2, out)
}

/// [`homography_lsq`] on the data `indices` of `x1`, `x2`, optionally weighted (row pair i
/// scaled by √wᵢ), from the normal equations instead of a QR of the 2N×9 system.
///
/// With p = (x̂1, ŷ1, 1) and q = x̂2 normalised, the two DLT rows of a pair are [pᵀ, 0, −q_x pᵀ]
/// and [0, pᵀ, −q_y pᵀ], so MᵀWM has four distinct 3×3 blocks, all weighted sums of ppᵀ:
/// S = Σw ppᵀ (twice on the diagonal), −Σw q_x ppᵀ, −Σw q_y ppᵀ and Σw ‖q‖² ppᵀ: 24 sums per
/// pair instead of folding 2 rows of 9 (the saving in a RANSAC run: benches/results/ransac.md).
/// The Gram matrix
/// squares the condition number, harmless in Hartley-normalised coordinates (κ(M) ≲ 10³): use
/// it where the fit runs often on many points (local optimisation), [`homography_lsq`] where
/// the last digits matter. Weights must be finite and ≥ 0.
///
/// Returns 0 when `x1.len() != x2.len()`, fewer than 4 indices, a value is not finite, an index
/// is out of bounds, or the null space is not one-dimensional.
pub fn homography_lsq_normal_equations(
    x1: &[Vec2],
    x2: &[Vec2],
    indices: &[usize],
    weights: Option<&[f64]>,
    out: &mut [Mat3],
) -> usize {
    assert!(out.len() >= HOMOGRAPHY_LSQ_MAX_SOLUTIONS, "out too short");
    if !valid_indexed_input(x1.len(), x2.len(), indices, weights, 4) {
        return 0;
    }
    let (Some(t1), Some(t2)) = (
        Similarity::from_points(indices.iter().map(|&i| x1[i])),
        Similarity::from_points(indices.iter().map(|&i| x2[i])),
    ) else {
        return 0;
    };
    let (mut s, mut su, mut sv, mut suv) = ([0.0; 6], [0.0; 6], [0.0; 6], [0.0; 6]);
    for (k, &i) in indices.iter().enumerate() {
        let w = weights.map_or(1.0, |w| w[k]);
        let (p, q) = (t1.apply(&x1[i]), t2.apply(&x2[i]));
        let pp = [p.x * p.x, p.x * p.y, p.x, p.y * p.y, p.y, 1.0];
        let (wu, wv, wuv) = (w * q.x, w * q.y, w * q.norm_squared());
        for k in 0..6 {
            s[k] += w * pp[k];
            su[k] += wu * pp[k];
            sv[k] += wv * pp[k];
            suv[k] += wuv * pp[k];
        }
    }
    const IDX: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];
    let mut gram = [[0.0; 9]; 9];
    for r in 0..3 {
        for c in 0..3 {
            let k = IDX[r][c];
            gram[r][c] = s[k];
            gram[3 + r][3 + c] = s[k];
            gram[r][6 + c] = -su[k];
            gram[6 + c][r] = -su[k];
            gram[3 + r][6 + c] = -sv[k];
            gram[6 + c][3 + r] = -sv[k];
            gram[6 + r][6 + c] = suv[k];
        }
    }
    if !gram.iter().flatten().all(|v| v.is_finite()) {
        return 0;
    }
    solve_lsq(&Lsq9::from_gram(&gram), &t1, &t2, out)
}

/// The homography of one AC given the fundamental matrix F (p2ᵀ F p1 = 0, pixels).
///
/// Every homography compatible with F is H = −\[e₂\]×F + e₂vᵀ up to scale, with e₂ the epipole in
/// image 2 (Fᵀe₂ = 0, ‖e₂‖ = 1) and v ∈ ℝ³ (Hartley & Zisserman, Result 13.3, using
/// −\[e₂\]×\[e₂\]×F = F for unit e₂). Substituting it into the 2 point and 4 affine equations of
/// the module doc, each linear in H, gives 6 linear equations in v,
/// Σₖ (Σᵢ rᵢₖ e₂ᵢ) vₖ = r · vec(\[e₂\]×F) for each equation row r (r as a 3×3 matrix). With exact
/// data their rank is 3 (one point and two affine equations are implied by the epipolar and
/// affine epipolar constraints), so v is their least-squares solution. This is the HAF method of
/// Barath & Hajder, "A theory of point-wise homography estimation", PRL 2017, §4; the whole
/// computation runs in Hartley-normalised coordinates, F̂ = T₂⁻ᵀ F T₁⁻¹.
///
/// Returns 0 for `acs.len() != 1`, non-finite values, det A ≤ 0, F of rank below 2, or an
/// ill-conditioned system (e.g. x2 at the epipole).
pub fn homography_1ac_given_f(acs: &[AffineCorrespondence], f: &Mat3, out: &mut [Mat3]) -> usize {
    assert!(
        out.len() >= HOMOGRAPHY_1AC_GIVEN_F_MAX_SOLUTIONS,
        "out too short"
    );
    let [ac] = acs else {
        return 0;
    };
    if !valid_ac(ac) || f.iter().any(|v| !v.is_finite()) {
        return 0;
    }
    // A single point has no spread: translate it to the origin and scale by 1/max(‖x‖, 1), the
    // order of the image size for pixel coordinates.
    let t1 = Similarity {
        s: 1.0 / ac.x1.norm().max(1.0),
        c: ac.x1,
    };
    let t2 = Similarity {
        s: 1.0 / ac.x2.norm().max(1.0),
        c: ac.x2,
    };
    let f_hat = t2.inverse_matrix().transpose() * f * t1.inverse_matrix();
    // e₂: the left null vector of F̂ (its smallest left singular vector); rank(F) ≥ 2.
    let Some(e2) = smallest_singular3(&f_hat, true, RANK_TOL) else {
        return 0;
    };
    let base = -e2.cross_matrix() * f_hat;
    let (p, q) = (t1.apply(&ac.x1), t2.apply(&ac.x2));
    let a_hat = ac.a * (t2.s / t1.s);
    let [r1, r2] = point_rows(&p, &q);
    let [r3, r4, r5, r6] = affine_rows(&p, &q, &a_hat);
    // Least squares M v = b by Householder QR of [M | b] (6×4): R₃ v = (Qᵀb)₁:₃.
    let mut cols = [[0.0; 6]; 9];
    for (i, r) in [r1, r2, r3, r4, r5, r6].iter().enumerate() {
        for k in 0..3 {
            cols[k][i] = (0..3).map(|j| r[3 * j + k] * e2[j]).sum();
        }
        cols[3][i] = -(0..9).map(|j| r[j] * base[(j / 3, j % 3)]).sum::<f64>();
    }
    let mut qr = [[0.0; 9]; 9];
    householder_fold(&mut qr, 4, &mut cols, 6);
    let d = [qr[0][0].abs(), qr[1][1].abs(), qr[2][2].abs()];
    if !(d[0].min(d[1]).min(d[2]) > RANK_TOL * d[0].max(d[1]).max(d[2])) {
        return 0;
    }
    let mut v = Vec3::zeros();
    for i in (0..3).rev() {
        let s: f64 = (i + 1..3).map(|j| qr[i][j] * v[j]).sum();
        v[i] = (qr[i][3] - s) / qr[i][i];
    }
    let h_norm = base + e2 * v.transpose();
    finish(&h_norm, &t1, &t2, out)
}

/// The two DLT rows of a normalised point pair.
#[inline]
fn point_rows(p: &Vec2, q: &Vec2) -> [[f64; 9]; 2] {
    let (x, y) = (p.x, p.y);
    [
        [x, y, 1.0, 0.0, 0.0, 0.0, -q.x * x, -q.x * y, -q.x],
        [0.0, 0.0, 0.0, x, y, 1.0, -q.y * x, -q.y * y, -q.y],
    ]
}

/// The four affine rows a_ij·(h₃·p) − h_ij + q_i·h_3j = 0 of a normalised AC.
#[inline]
fn affine_rows(p: &Vec2, q: &Vec2, a: &affcorr_geom::Mat2) -> [[f64; 9]; 4] {
    let mut rows = [[0.0; 9]; 4];
    for i in 0..2 {
        for j in 0..2 {
            let r = &mut rows[2 * i + j];
            let aij = a[(i, j)];
            r[6] = aij * p.x;
            r[7] = aij * p.y;
            r[8] = aij;
            r[3 * i + j] = -1.0;
            r[6 + j] += q[i];
        }
    }
    rows
}

/// The shared AC least-squares path of [`homography_2ac`] and [`homography_ac_lsq`], with the
/// first two rows of Ĥ eliminated.
///
/// Every equation of the AC system (module docs, affine rows weighted by r = ρ·s₁) involves one
/// of the rows h₁, h₂ of Ĥ = [h₁ᵀ; h₂ᵀ; h₃ᵀ] and h₃: b·hᵢ + c·h₃ = 0 with
/// (b, c) = (p, −qᵢ·p) for the point row of coordinate i and (−r·eⱼ, r·(âᵢⱼ·p + qᵢ·eⱼ)) for the
/// affine row (i, j). Stacked, B hᵢ + Cᵢ h₃ = 0 with the same B for i = 1, 2, so for a given h₃
/// the least-squares rows are hᵢ = −M⁻¹Nᵢ h₃ with M = BᵀB = Σ p pᵀ + n·r²·diag(1, 1, 0)
/// (positive definite: its (3, 3) entry is n) and Nᵢ = BᵀCᵢ, and h₃ minimises h₃ᵀ S h₃ with
/// S = Σᵢ (CᵢᵀCᵢ − NᵢᵀM⁻¹Nᵢ): the smallest eigenvector of the 3×3 S (variable projection).
/// This is the least-squares solution under ‖h₃‖ = 1 instead of ‖h‖ = 1, the same for exact
/// data; h₃ = 0 would put every point on the line at infinity. 3×3 algebra instead of a 9×9
/// null space: the 2-AC sample is solved once per RANSAC iteration, and the 9×9 inverse
/// iteration was a large share of a homography run (benches/results/ransac.md).
///
/// The null space of the system is one-dimensional exactly when S has rank 2, which
/// `smallest_singular3` tests (σ₂(S) > [`REDUCED_RANK_TOL`]·σ₁(S)).
fn ac_least_squares(acs: &[AffineCorrespondence], out: &mut [Mat3]) -> usize {
    if !acs.iter().all(valid_ac) {
        return 0;
    }
    let (Some(t1), Some(t2)) = (
        Similarity::from_points(acs.iter().map(|ac| ac.x1)),
        Similarity::from_points(acs.iter().map(|ac| ac.x2)),
    ) else {
        return 0;
    };
    let scale = t2.s / t1.s;
    let r = AFFINE_ROW_RADIUS_PX * t1.s;
    let r2 = r * r;
    let mut m = Mat3::zeros();
    let mut nn = [Mat3::zeros(); 2];
    let mut ctc = Mat3::zeros();
    for ac in acs {
        let (p, q) = (t1.apply(&ac.x1), t2.apply(&ac.x2));
        let p = Vec3::new(p.x, p.y, 1.0);
        let a = ac.a * scale;
        let ppt = p * p.transpose();
        m += ppt;
        for i in 0..2 {
            // The point row: b = p, c = −qᵢ·p.
            nn[i] -= ppt * q[i];
            ctc += ppt * (q[i] * q[i]);
            // The affine rows (i, j): b = −r·eⱼ, c = r·(âᵢⱼ·p + qᵢ·eⱼ).
            for j in 0..2 {
                let mut c = p * a[(i, j)];
                c[j] += q[i];
                let mut row = nn[i].row_mut(j);
                row -= c.transpose() * r2;
                ctc += c * c.transpose() * r2;
            }
        }
    }
    m[(0, 0)] += acs.len() as f64 * r2;
    m[(1, 1)] += acs.len() as f64 * r2;
    let Some(m_inv) = m.try_inverse() else {
        return 0;
    };
    let k = [m_inv * nn[0], m_inv * nn[1]];
    let s = ctc - nn[0].transpose() * k[0] - nn[1].transpose() * k[1];
    let Some(h3) = smallest_singular3(&s, false, REDUCED_RANK_TOL) else {
        return 0;
    };
    let (h1, h2) = (-(k[0] * h3), -(k[1] * h3));
    let h_norm = Mat3::from_rows(&[h1.transpose(), h2.transpose(), h3.transpose()]);
    finish(&h_norm, &t1, &t2, out)
}

/// The least-squares null vector as H, if the null space is one-dimensional.
fn solve_lsq(lsq: &Lsq9, t1: &Similarity, t2: &Similarity, out: &mut [Mat3]) -> usize {
    let Some(ns) = lsq.solve(RANK_TOL) else {
        return 0;
    };
    if ns.dim > 1 {
        return 0;
    }
    finish(&mat3_from_vec9(ns.v[0].as_slice()), t1, t2, out)
}

/// Denormalises Ĥ (H = T₂⁻¹ Ĥ T₁), rejects singular or non-finite results, writes H/‖H‖_F.
fn finish(h_norm: &Mat3, t1: &Similarity, t2: &Similarity, out: &mut [Mat3]) -> usize {
    let Some(hn) = unit_frobenius(h_norm) else {
        return 0;
    };
    // A homography between two views of a plane is invertible; ‖Ĥ‖ = 1 here.
    if !(hn.determinant().abs() > 1e-12) {
        return 0;
    }
    match unit_frobenius(&(t2.inverse_matrix() * hn * t1.matrix())) {
        Some(h) => {
            out[0] = h;
            1
        }
        None => 0,
    }
}
