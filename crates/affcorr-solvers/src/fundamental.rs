//! Fundamental-matrix solvers, p2ᵀ F p1 = 0 in pixels (docs/design.md §2, §4).
//!
//! | solver | sample | models | method |
//! |---|---|---|---|
//! | [`fundamental_7pt`] | 7 points | ≤ 3 | 2-dim null space + cubic det(F₁ + xF₂) = 0 |
//! | [`fundamental_8pt`] | N ≥ 8 points | ≤ 1 | normalised 8-point, rank 2 enforced |
//! | [`fundamental_8pt_normal_equations`] | N ≥ 8 points, weighted | ≤ 1 | the same from the normal equations, cheaper (local optimisation's fit) |
//! | [`fundamental_3ac`] | 3 ACs | ≤ 3 (1 generically) | 9 linear equations + rank 2 |
//! | [`fundamental_1ac4pt`] | 1 AC + 4 points | ≤ 3 | 7 linear equations, as 7 points |
//! | [`fundamental_ac_lsq`] | N ≥ 3 ACs | ≤ 1 | the 3AC system over N ACs, least squares |
//!
//! All solvers take pixels, apply Hartley's isotropic normalisation internally
//! (`normalization`), and write F with ‖F‖_F = 1 (its sign is arbitrary) into the
//! caller's buffer, returning the number of models. A sample of the wrong length, with a
//! non-finite value, coincident points, an affine map with det A ≤ 0, or a rank-deficient
//! linear system (e.g. all points or all ACs on one plane, which leaves a 3-parameter family of
//! F) gives 0 models. `out` shorter than the solver's `*_MAX_SOLUTIONS` is a caller bug and
//! panics.
//!
//! # Equations (f = F stacked row-major)
//! - Epipolar constraint: p2ᵀ F p1 = Σᵢⱼ p2ᵢ p1ⱼ Fᵢⱼ = 0 (Hartley & Zisserman, *Multiple View
//!   Geometry*, 2nd ed., eq. 11.3).
//! - Affine epipolar constraint (docs/design.md §2; Bentolila & Francos, "Conic epipolar constraints
//!   from affine correspondences", CVIU 2014; Barath et al.), row k ∈ {1, 2}:
//!   r_k = Σ_{i∈{1,2}} a_ik (F p1)ᵢ + (Fᵀ p2)_k = Σ_{i≤2,j} a_ik p1ⱼ Fᵢⱼ + Σᵢ p2ᵢ F_ik = 0.
//!
//! Both are linear in f and keep their form under the normalising similarities
//! (F = T₂ᵀ F̂ T₁, Â = (s₂/s₁)·A). In the AC systems the affine rows are scaled by ρ·s₁ with
//! ρ = 8 px, which makes their residuals commensurate with the point rows' (an error ε in A moves
//! points at distance ρ by ε·ρ); exact data is unaffected, noisy estimates improve about 3×.

use crate::linalg::{
    Gram9, Lsq9, NullSpace, Vec9, cofactor, gauss_jordan, mat3_from_vec9, null_vector,
    smallest_singular3, unit_frobenius,
};
use crate::normalization::{
    AFFINE_ROW_RADIUS_PX, Similarity, hybrid_normalisers, valid_ac, valid_indexed_input,
};
use crate::poly::real_roots;
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2};

/// Most models [`fundamental_7pt`] returns.
pub const FUNDAMENTAL_7PT_MAX_SOLUTIONS: usize = 3;
/// Most models [`fundamental_8pt`] returns.
pub const FUNDAMENTAL_8PT_MAX_SOLUTIONS: usize = 1;
/// Most models [`fundamental_3ac`] returns (3 only in the non-generic case of a 2-dim null
/// space; generically 1).
pub const FUNDAMENTAL_3AC_MAX_SOLUTIONS: usize = 3;
/// Most models [`fundamental_1ac4pt`] returns.
pub const FUNDAMENTAL_1AC4PT_MAX_SOLUTIONS: usize = 3;
/// Most models [`fundamental_ac_lsq`] returns.
pub const FUNDAMENTAL_AC_LSQ_MAX_SOLUTIONS: usize = 1;

/// A singular value (or pivot) of a normalised linear system below this × the largest counts
/// as zero.
const RANK_TOL: f64 = 1e-9;

/// The fundamental matrices of 7 point correspondences (Hartley & Zisserman, §11.1.2).
///
/// The 7×9 epipolar system is reduced by Gauss–Jordan elimination with complete pivoting; its
/// 2-dim null space F₁, F₂ is read off directly. Then det(F₁ + xF₂) = c₀ + c₁x + c₂x² + c₃x³
/// with c₀ = det F₁, c₁ = tr(adj(F₁)F₂) = Σ cof(F₁) ⊙ F₂, c₂ = Σ cof(F₂) ⊙ F₁, c₃ = det F₂
/// (cof: the cofactor matrix, rows rⱼ × rₖ of cross products), and each real root x of the
/// cubic ([`real_roots`], Sturm sequences) gives F = F₁ + xF₂. If c₃ vanishes, F₂ itself
/// (x = ∞) is a solution too.
///
/// Returns 0 for a sample of the wrong length, non-finite values, or a system of rank below 7
/// (coincident points, all points on one plane, …).
pub fn fundamental_7pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Mat3]) -> usize {
    assert!(out.len() >= FUNDAMENTAL_7PT_MAX_SOLUTIONS, "out too short");
    if x1.len() != 7 || x2.len() != 7 {
        return 0;
    }
    let Some((t1, t2)) = normalisers(x1.iter().copied(), x2.iter().copied()) else {
        return 0;
    };
    let mut m = [[0.0; 9]; 7];
    for (row, (a, b)) in m.iter_mut().zip(x1.iter().zip(x2)) {
        *row = epipolar_row(&t1.apply(a), &t2.apply(b));
    }
    let Some(perm) = gauss_jordan(&mut m, RANK_TOL) else {
        return 0;
    };
    let f1 = mat3_from_vec9(&null_vector(&m, &perm, 7));
    let f2 = mat3_from_vec9(&null_vector(&m, &perm, 8));
    let mut n = cubic_solutions(&f1, &f2, &t1, &t2, out);
    n = dedup(out, n);
    n
}

/// The fundamental matrices of one AC and 4 point correspondences: the hybrid minimal sample.
///
/// The AC gives its epipolar row and the two affine epipolar rows of the module doc, each point
/// one epipolar row: 7 rows for F's 7 degrees of freedom, solved as [`fundamental_7pt`] solves
/// its 7 (a 2-dim null space, then the cubic det(F₁ + xF₂) = 0; up to 3 models). The affine
/// rows are weighted as in the AC systems (ρ·s₁); in an exactly determined system that changes
/// nothing but the conditioning. Unlike 3 ACs, the sample does not break on ACs of one plane
/// unless the points lie on it too: three of its five correspondences are plain points.
///
/// Returns 0 for `x1`/`x2` not holding 4 points, non-finite values, det A ≤ 0, or a system of
/// rank below 7 (coincident points, all five on one plane, …).
pub fn fundamental_1ac4pt(
    ac: &AffineCorrespondence,
    x1: &[Vec2],
    x2: &[Vec2],
    out: &mut [Mat3],
) -> usize {
    assert!(
        out.len() >= FUNDAMENTAL_1AC4PT_MAX_SOLUTIONS,
        "out too short"
    );
    let Some((t1, t2)) = hybrid_normalisers(ac, x1, x2, 4) else {
        return 0;
    };
    let (p, q) = (t1.apply(&ac.x1), t2.apply(&ac.x2));
    let w = AFFINE_ROW_RADIUS_PX * t1.s;
    let [a1, a2] = affine_rows(&p, &q, &(ac.a * (t2.s / t1.s)));
    let mut m = [[0.0; 9]; 7];
    m[0] = epipolar_row(&p, &q);
    m[1] = a1.map(|v| v * w);
    m[2] = a2.map(|v| v * w);
    for (row, (a, b)) in m[3..].iter_mut().zip(x1.iter().zip(x2)) {
        *row = epipolar_row(&t1.apply(a), &t2.apply(b));
    }
    let Some(perm) = gauss_jordan(&mut m, RANK_TOL) else {
        return 0;
    };
    let f1 = mat3_from_vec9(&null_vector(&m, &perm, 7));
    let f2 = mat3_from_vec9(&null_vector(&m, &perm, 8));
    let n = cubic_solutions(&f1, &f2, &t1, &t2, out);
    dedup(out, n)
}

/// The normalised 8-point algorithm on N ≥ 8 point correspondences (Hartley, "In defense of the
/// eight-point algorithm", PAMI 1997; Hartley & Zisserman, Alg. 11.1): the least-squares null
/// vector of the N×9 epipolar system (streaming Householder QR to a 9×9 factor, then inverse
/// iteration), then the closest rank-2 matrix in the Frobenius norm: F(I − v₃v₃ᵀ), v₃ the
/// smallest right singular vector of F (Eckart–Young), found by power iteration on adj(F)adj(F)ᵀ.
/// Allocation-free.
///
/// Returns 0 when `x1.len() != x2.len()`, N < 8, a value is not finite, or the null space is not
/// one-dimensional (e.g. all points on one plane).
pub fn fundamental_8pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Mat3]) -> usize {
    assert!(out.len() >= FUNDAMENTAL_8PT_MAX_SOLUTIONS, "out too short");
    if x1.len() != x2.len() || x1.len() < 8 {
        return 0;
    }
    let Some((t1, t2)) = normalisers(x1.iter().copied(), x2.iter().copied()) else {
        return 0;
    };
    let mut lsq = Lsq9::new();
    for (a, b) in x1.iter().zip(x2) {
        lsq.add_row(epipolar_row(&t1.apply(a), &t2.apply(b)));
    }
    let Some(ns) = lsq.solve(RANK_TOL) else {
        return 0;
    };
    if ns.dim > 1 {
        return 0;
    }
    rank2_solution(&ns.v[0], &t1, &t2, out)
}

/// [`fundamental_8pt`] on the data `indices` of `x1`, `x2`, optionally weighted (row i scaled
/// by √wᵢ), from the normal equations MᵀWM (45 products per datum) instead of a QR of the N×9
/// system (the saving in a RANSAC run: benches/results/ransac.md). The Gram matrix squares the
/// condition number,
/// harmless in Hartley-normalised coordinates; use it where the fit runs often on many points
/// (local optimisation). Weights must be finite and ≥ 0.
///
/// Returns 0 when `x1.len() != x2.len()`, fewer than 8 indices, an index is out of bounds, a
/// value is not finite, or the null space is not one-dimensional.
pub fn fundamental_8pt_normal_equations(
    x1: &[Vec2],
    x2: &[Vec2],
    indices: &[usize],
    weights: Option<&[f64]>,
    out: &mut [Mat3],
) -> usize {
    assert!(out.len() >= FUNDAMENTAL_8PT_MAX_SOLUTIONS, "out too short");
    if !valid_indexed_input(x1.len(), x2.len(), indices, weights, 8) {
        return 0;
    }
    let Some((t1, t2)) = normalisers(
        indices.iter().map(|&i| x1[i]),
        indices.iter().map(|&i| x2[i]),
    ) else {
        return 0;
    };
    let mut gram = Gram9::new();
    for (k, &i) in indices.iter().enumerate() {
        let w = weights.map_or(1.0, |w| w[k]);
        gram.add_weighted_row(&epipolar_row(&t1.apply(&x1[i]), &t2.apply(&x2[i])), w);
    }
    let Some(ns) = gram.into_lsq().and_then(|lsq| lsq.solve(RANK_TOL)) else {
        return 0;
    };
    if ns.dim > 1 {
        return 0;
    }
    rank2_solution(&ns.v[0], &t1, &t2, out)
}

/// The fundamental matrix of 3 ACs.
///
/// Each AC gives the epipolar equation and the two affine epipolar equations of the module doc,
/// so 3 ACs give a 9×9 homogeneous system M f = 0 for 7 degrees of freedom.
///
/// **Null space.** For ACs in general position (not all induced by one plane) the exact system
/// has rank 8: the true F spans a 1-dim null space, and it is rank 2 already. (Counting: each AC
/// carries 3 independent constraints on F, 9 > 8; checked numerically on random multi-plane
/// scenes in the tests.) The solver therefore takes the right singular vector of the smallest
/// singular value (the least-squares solution with noisy data, where M has full rank) and projects
/// it to rank 2 (closest in the Frobenius norm), returning one model. If the second-smallest
/// singular value vanishes as well (a 2-dim null space, a non-generic configuration), rank 2 is
/// what pins F down: as in the 7-point solver the solutions are the real roots of det(F₁ + xF₂) = 0 over the two null
/// vectors, up to 3 models. A null space of dimension ≥ 3 (all three ACs induced by one plane:
/// any F = \[e₂\]×H fits) gives 0.
///
/// Returns 0 for `acs.len() != 3`, non-finite values, det A ≤ 0, coincident points, or a null
/// space of dimension ≥ 3.
pub fn fundamental_3ac(acs: &[AffineCorrespondence], out: &mut [Mat3]) -> usize {
    assert!(out.len() >= FUNDAMENTAL_3AC_MAX_SOLUTIONS, "out too short");
    if acs.len() != 3 {
        return 0;
    }
    let Some((ns, t1, t2)) = ac_system(acs) else {
        return 0;
    };
    match ns.dim {
        0 | 1 => rank2_solution(&ns.v[0], &t1, &t2, out),
        2 => {
            let f1 = mat3_from_vec9(ns.v[0].as_slice());
            let f2 = mat3_from_vec9(ns.v[1].as_slice());
            let n = cubic_solutions(&f1, &f2, &t1, &t2, out);
            dedup(out, n)
        }
        _ => 0,
    }
}

/// The non-minimal fundamental matrix of N ≥ 3 ACs: the system of [`fundamental_3ac`] over all
/// ACs (3N rows), its least-squares null vector, projected to rank 2. Returns 0 when the null
/// space is not one-dimensional.
pub fn fundamental_ac_lsq(acs: &[AffineCorrespondence], out: &mut [Mat3]) -> usize {
    assert!(
        out.len() >= FUNDAMENTAL_AC_LSQ_MAX_SOLUTIONS,
        "out too short"
    );
    if acs.len() < 3 {
        return 0;
    }
    let Some((ns, t1, t2)) = ac_system(acs) else {
        return 0;
    };
    if ns.dim > 1 {
        return 0;
    }
    rank2_solution(&ns.v[0], &t1, &t2, out)
}

/// Hartley normalisations of both images.
fn normalisers<I, J>(x1: I, x2: J) -> Option<(Similarity, Similarity)>
where
    I: Iterator<Item = Vec2> + Clone,
    J: Iterator<Item = Vec2> + Clone,
{
    Some((Similarity::from_points(x1)?, Similarity::from_points(x2)?))
}

/// The row of p2ᵀ F p1 = 0 (normalised points).
#[inline]
fn epipolar_row(p: &Vec2, q: &Vec2) -> [f64; 9] {
    let (x, y, u, v) = (p.x, p.y, q.x, q.y);
    [u * x, u * y, u, v * x, v * y, v, x, y, 1.0]
}

/// The two rows of the affine epipolar constraint r_k = Σ_{i≤2,j} a_ik p1ⱼ Fᵢⱼ + Σᵢ p2ᵢ F_ik.
#[inline]
fn affine_rows(p: &Vec2, q: &Vec2, a: &Mat2) -> [[f64; 9]; 2] {
    let p1 = [p.x, p.y, 1.0];
    let p2 = [q.x, q.y, 1.0];
    let mut rows = [[0.0; 9]; 2];
    for (k, r) in rows.iter_mut().enumerate() {
        for i in 0..2 {
            for j in 0..3 {
                r[3 * i + j] = a[(i, k)] * p1[j];
            }
        }
        for i in 0..3 {
            r[3 * i + k] += p2[i];
        }
    }
    rows
}

/// The 3N×9 AC system in normalised coordinates, folded into its 9×9 factor, and its null space.
fn ac_system(acs: &[AffineCorrespondence]) -> Option<(NullSpace, Similarity, Similarity)> {
    if !acs.iter().all(valid_ac) {
        return None;
    }
    let (t1, t2) = normalisers(acs.iter().map(|ac| ac.x1), acs.iter().map(|ac| ac.x2))?;
    let scale = t2.s / t1.s;
    let w = AFFINE_ROW_RADIUS_PX * t1.s;
    let mut lsq = Lsq9::new();
    for ac in acs {
        let (p, q) = (t1.apply(&ac.x1), t2.apply(&ac.x2));
        lsq.add_row(epipolar_row(&p, &q));
        for r in affine_rows(&p, &q, &(ac.a * scale)) {
            lsq.add_row(r.map(|v| v * w));
        }
    }
    Some((lsq.solve(RANK_TOL)?, t1, t2))
}

/// Writes F = denormalised F₁ + xF₂ for every real root x of det(F₁ + xF₂) = 0 (and F₂ itself when
/// the cubic's leading coefficient vanishes); returns the count.
fn cubic_solutions(
    f1: &Mat3,
    f2: &Mat3,
    t1: &Similarity,
    t2: &Similarity,
    out: &mut [Mat3],
) -> usize {
    // Scale both to unit norm so that the coefficients are comparable.
    let (Some(f1), Some(f2)) = (unit_frobenius(f1), unit_frobenius(f2)) else {
        return 0;
    };
    let c = [
        f1.determinant(),
        cofactor(&f1).component_mul(&f2).sum(),
        cofactor(&f2).component_mul(&f1).sum(),
        f2.determinant(),
    ];
    let mut roots = [0.0; 3];
    let k = real_roots(&c, &mut roots);
    let mut n = 0;
    for &x in &roots[..k] {
        n += write_denormalised(&(f1 + f2 * x), t1, t2, &mut out[n..]);
    }
    let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // With three roots found, the one near x = ∞ already is (a multiple of) F₂ + F₁/x: a fourth
    // model would break FUNDAMENTAL_7PT_MAX_SOLUTIONS (found by fuzzing).
    if c[3].abs() <= 1e-12 * scale && k < 3 && n < out.len() {
        n += write_denormalised(&f2, t1, t2, &mut out[n..]);
    }
    n
}

/// Projects the null vector to rank 2 (smallest singular value zeroed), denormalises, writes.
fn rank2_solution(v: &Vec9, t1: &Similarity, t2: &Similarity, out: &mut [Mat3]) -> usize {
    let f = mat3_from_vec9(v.as_slice());
    // F − σ₃u₃v₃ᵀ = F(I − v₃v₃ᵀ): the closest rank-2 matrix (Eckart–Young). A rank-1 F is
    // degenerate.
    let Some(v3) = smallest_singular3(&f, false, RANK_TOL) else {
        return 0;
    };
    write_denormalised(&(f - (f * v3) * v3.transpose()), t1, t2, out)
}

/// F = T₂ᵀ F̂ T₁, unit Frobenius norm; 0 if not finite or zero.
#[inline]
fn write_denormalised(f_hat: &Mat3, t1: &Similarity, t2: &Similarity, out: &mut [Mat3]) -> usize {
    match unit_frobenius(&(t2.matrix().transpose() * f_hat * t1.matrix())) {
        Some(f) if !out.is_empty() => {
            out[0] = f;
            1
        }
        _ => 0,
    }
}

/// Drops candidates equal (up to sign) to an earlier one (double roots); returns the new count.
fn dedup(out: &mut [Mat3], n: usize) -> usize {
    let mut k = 0;
    for i in 0..n {
        let f = out[i];
        let dup = out[..k]
            .iter()
            .any(|g| (g - f).norm().min((g + f).norm()) < 1e-12);
        if !dup {
            out[k] = f;
            k += 1;
        }
    }
    k
}
