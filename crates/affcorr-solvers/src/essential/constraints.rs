//! Shared kernels of the essential solvers: the linear systems, their null spaces, and the
//! cubic essential constraints expanded over a linear family of matrices.
//!
//! A 3×3 matrix is stored as its 9 entries row-major, `e[3i + j] = E_ij`, so the epipolar
//! constraint p̂2ᵀ E p̂1 = 0 reads `Σ_ij p̂2_i p̂1_j e[3i + j] = 0`.

use affcorr_geom::{AffineCorrespondence, Vec2};

/// Row of the point constraint p̂2ᵀ E p̂1 = 0 (docs/design.md §2).
#[inline]
pub(crate) fn point_row(x1: &Vec2, x2: &Vec2) -> [f64; 9] {
    let (p1, p2) = ([x1.x, x1.y, 1.0], [x2.x, x2.y, 1.0]);
    let mut r = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            r[3 * i + j] = p2[i] * p1[j];
        }
    }
    r
}

/// The two rows of the affine epipolar constraint Âᵀ (E p̂1)₁:₂ + (Eᵀ p̂2)₁:₂ = 0
/// (docs/design.md §2): row k is Σ_{i<2} â_ik (E p̂1)_i + (Eᵀ p̂2)_k, so the coefficient of E_ij is
/// [i < 2]·â_ik·p̂1_j + [j = k]·p̂2_i.
#[inline]
pub(crate) fn affine_rows(ac: &AffineCorrespondence) -> [[f64; 9]; 2] {
    let (p1, p2) = ([ac.x1.x, ac.x1.y, 1.0], [ac.x2.x, ac.x2.y, 1.0]);
    let mut rows = [[0.0; 9]; 2];
    for (k, row) in rows.iter_mut().enumerate() {
        for i in 0..3 {
            for j in 0..3 {
                let affine = if i < 2 { ac.a[(i, k)] * p1[j] } else { 0.0 };
                let point = if j == k { p2[i] } else { 0.0 };
                row[3 * i + j] = affine + point;
            }
        }
    }
    rows
}

/// Null space of the `rows.len()` × 9 system (`rows.len()` ≤ 8) by Householder QR of its
/// transpose: with Mᵀ = Q R, the last `9 − r` columns of Q are an orthonormal basis of the null
/// space. Writes them to `basis` (length `9 − rows.len()`). Returns `false` when the system is
/// rank deficient (a diagonal entry of R below 1e-10 of the largest row norm) or not finite.
pub(crate) fn null_space(rows: &[[f64; 9]], basis: &mut [[f64; 9]]) -> bool {
    let r = rows.len();
    debug_assert!(r <= 8 && basis.len() == 9 - r);
    // Columns of Mᵀ = rows of M.
    let mut cols = [[0.0; 9]; 8];
    cols[..r].copy_from_slice(rows);
    let scale = rows
        .iter()
        .map(|c| c.iter().map(|v| v * v).sum::<f64>())
        .fold(0.0f64, f64::max)
        .sqrt();
    if !(scale.is_finite() && scale > 0.0) {
        return false;
    }
    let mut vs = [[0.0; 9]; 8];
    for k in 0..r {
        let norm = cols[k][k..].iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(norm > 1e-10 * scale) {
            return false;
        }
        let alpha = if cols[k][k] > 0.0 { -norm } else { norm };
        let mut v = [0.0; 9];
        v[k..].copy_from_slice(&cols[k][k..]);
        v[k] -= alpha;
        let vn = v[k..].iter().map(|x| x * x).sum::<f64>().sqrt();
        for x in &mut v[k..] {
            *x /= vn;
        }
        for col in cols[k + 1..r].iter_mut() {
            let d: f64 = 2.0 * (k..9).map(|i| v[i] * col[i]).sum::<f64>();
            for i in k..9 {
                col[i] -= d * v[i];
            }
        }
        vs[k] = v;
    }
    // Q e_j = H_0 H_1 … H_{r−1} e_j for j ≥ r.
    for (n, b) in basis.iter_mut().enumerate() {
        let mut q = [0.0; 9];
        q[r + n] = 1.0;
        for k in (0..r).rev() {
            let v = &vs[k];
            let d: f64 = 2.0 * (k..9).map(|i| v[i] * q[i]).sum::<f64>();
            for i in k..9 {
                q[i] -= d * v[i];
            }
        }
        *b = q;
    }
    true
}

/// Null space of 5 of the 6 rows of a two-AC system, chosen by a pivoted Householder QR of the
/// transpose: rows `fixed` (the point rows) are taken first, then the remaining rows one at a
/// time, each the one with the largest component orthogonal to those taken (rows are scaled to
/// unit norm first). Writes the orthonormal 4-dimensional null space of the five chosen rows to
/// `basis` and returns the index of the dropped row; `None` when the chosen rows are rank
/// deficient or not finite.
pub(crate) fn null_space_of_best_five(
    rows: &[[f64; 9]; 6],
    fixed: [usize; 2],
    basis: &mut [[f64; 9]; 4],
) -> Option<usize> {
    let mut cols = *rows;
    for c in cols.iter_mut() {
        let n = c.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(n.is_finite() && n > 0.0) {
            return None;
        }
        for v in c.iter_mut() {
            *v /= n;
        }
    }
    let mut idx = [0, 1, 2, 3, 4, 5];
    // Fixed rows first.
    for (k, &f) in fixed.iter().enumerate() {
        let pos = idx.iter().position(|&i| i == f)?;
        idx.swap(k, pos);
        cols.swap(k, pos);
    }
    let mut vs = [[0.0; 9]; 5];
    for k in 0..5 {
        if k >= fixed.len() {
            // Pivot: the remaining column with the largest norm below row k.
            let norm_below = |c: &[f64; 9]| c[k..].iter().map(|v| v * v).sum::<f64>();
            let p =
                (k..6).max_by(|&a, &b| norm_below(&cols[a]).total_cmp(&norm_below(&cols[b])))?;
            idx.swap(k, p);
            cols.swap(k, p);
        }
        let norm = cols[k][k..].iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(norm > 1e-10) {
            return None;
        }
        let alpha = if cols[k][k] > 0.0 { -norm } else { norm };
        let mut v = [0.0; 9];
        v[k..].copy_from_slice(&cols[k][k..]);
        v[k] -= alpha;
        let vn = v[k..].iter().map(|x| x * x).sum::<f64>().sqrt();
        for x in &mut v[k..] {
            *x /= vn;
        }
        for col in cols[k + 1..].iter_mut() {
            let d: f64 = 2.0 * (k..9).map(|i| v[i] * col[i]).sum::<f64>();
            for i in k..9 {
                col[i] -= d * v[i];
            }
        }
        vs[k] = v;
    }
    for (n, b) in basis.iter_mut().enumerate() {
        let mut q = [0.0; 9];
        q[5 + n] = 1.0;
        for k in (0..5).rev() {
            let v = &vs[k];
            let d: f64 = 2.0 * (k..9).map(|i| v[i] * q[i]).sum::<f64>();
            for i in k..9 {
                q[i] -= d * v[i];
            }
        }
        *b = q;
    }
    Some(idx[5])
}

// ---------------------------------------------------------------------------------------------
// Polynomials in (x, y, z) of degree ≤ 3, with the entries of E = x·X + y·Y + z·Z + W linear.

type Exp = [u8; 3];

/// Linear monomials: x, y, z, 1.
const LIN: [Exp; 4] = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]];
/// Quadratic monomials (any fixed order).
const QUAD: [Exp; 10] = [
    [2, 0, 0],
    [1, 1, 0],
    [1, 0, 1],
    [1, 0, 0],
    [0, 2, 0],
    [0, 1, 1],
    [0, 1, 0],
    [0, 0, 2],
    [0, 0, 1],
    [0, 0, 0],
];
/// Cubic monomials in Nistér's order (Nistér 2004, §3.2.1): x³, y³, x²y, xy², x²z, x², y²z, y²,
/// xyz, xy | xz², xz, x, yz², yz, y, z³, z², z, 1.
pub(crate) const CUBIC: [Exp; 20] = [
    [3, 0, 0],
    [0, 3, 0],
    [2, 1, 0],
    [1, 2, 0],
    [2, 0, 1],
    [2, 0, 0],
    [0, 2, 1],
    [0, 2, 0],
    [1, 1, 1],
    [1, 1, 0],
    [1, 0, 2],
    [1, 0, 1],
    [1, 0, 0],
    [0, 1, 2],
    [0, 1, 1],
    [0, 1, 0],
    [0, 0, 3],
    [0, 0, 2],
    [0, 0, 1],
    [0, 0, 0],
];

const fn find<const N: usize>(list: &[Exp; N], e: Exp) -> usize {
    let mut i = 0;
    while i < N {
        if list[i][0] == e[0] && list[i][1] == e[1] && list[i][2] == e[2] {
            return i;
        }
        i += 1;
    }
    panic!("monomial not in list");
}

const fn add(a: Exp, b: Exp) -> Exp {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `LL[i][j]`: index in QUAD of LIN[i]·LIN[j].
const LL: [[usize; 4]; 4] = {
    let mut t = [[0; 4]; 4];
    let mut i = 0;
    while i < 4 {
        let mut j = 0;
        while j < 4 {
            t[i][j] = find(&QUAD, add(LIN[i], LIN[j]));
            j += 1;
        }
        i += 1;
    }
    t
};

/// `QL[i][j]`: index in CUBIC of QUAD[i]·LIN[j].
const QL: [[usize; 4]; 10] = {
    let mut t = [[0; 4]; 10];
    let mut i = 0;
    while i < 10 {
        let mut j = 0;
        while j < 4 {
            t[i][j] = find(&CUBIC, add(QUAD[i], LIN[j]));
            j += 1;
        }
        i += 1;
    }
    t
};

type Lin = [f64; 4];
type Quad = [f64; 10];
type Cubic = [f64; 20];

#[inline(always)]
fn mul_ll(a: &Lin, b: &Lin, out: &mut Quad) {
    for i in 0..4 {
        for j in 0..4 {
            out[LL[i][j]] += a[i] * b[j];
        }
    }
}

#[inline(always)]
fn mul_ql(a: &Quad, b: &Lin, s: f64, out: &mut Cubic) {
    for i in 0..10 {
        for j in 0..4 {
            out[QL[i][j]] += s * a[i] * b[j];
        }
    }
}

/// The ten cubic constraints on E = x·X + y·Y + z·Z + W (`basis = [X, Y, Z, W]`), as rows of
/// coefficients over [`CUBIC`]:
/// - rows 0–8: the trace constraint 2·E Eᵀ E − tr(E Eᵀ)·E = 0 (Nistér 2004, eq. 7; Demazure),
///   written as D·E with D = 2·E Eᵀ − tr(E Eᵀ)·I;
/// - row 9: det E = 0 (eq. 6), by cofactor expansion along the first row.
pub(crate) fn cubic_constraints(basis: &[[f64; 9]; 4]) -> [Cubic; 10] {
    let mut e = [[0.0; 4]; 9];
    for (k, ek) in e.iter_mut().enumerate() {
        *ek = [basis[0][k], basis[1][k], basis[2][k], basis[3][k]];
    }
    // E Eᵀ (symmetric): (E Eᵀ)_ij = Σ_k E_ik E_jk.
    let mut eet = [[0.0; 10]; 9];
    for i in 0..3 {
        for j in i..3 {
            let mut q = [0.0; 10];
            for k in 0..3 {
                mul_ll(&e[3 * i + k], &e[3 * j + k], &mut q);
            }
            eet[3 * i + j] = q;
            eet[3 * j + i] = q;
        }
    }
    let mut d = eet;
    for v in d.iter_mut().flatten() {
        *v *= 2.0;
    }
    for i in 0..3 {
        for m in 0..10 {
            let tr = eet[0][m] + eet[4][m] + eet[8][m];
            d[4 * i][m] -= tr;
        }
    }
    let mut rows = [[0.0; 20]; 10];
    for i in 0..3 {
        for j in 0..3 {
            let row = &mut rows[3 * i + j];
            for k in 0..3 {
                mul_ql(&d[3 * i + k], &e[3 * k + j], 1.0, row);
            }
        }
    }
    // det E = E00 (E11 E22 − E12 E21) − E01 (E10 E22 − E12 E20) + E02 (E10 E21 − E11 E20).
    let minor = |a: usize, b: usize, c: usize, dd: usize| {
        let mut q = [0.0; 10];
        mul_ll(&e[a], &e[b], &mut q);
        let mut r = [0.0; 10];
        mul_ll(&e[c], &e[dd], &mut r);
        for m in 0..10 {
            q[m] -= r[m];
        }
        q
    };
    let det = &mut rows[9];
    mul_ql(&minor(4, 8, 5, 7), &e[0], 1.0, det);
    mul_ql(&minor(3, 8, 5, 6), &e[1], -1.0, det);
    mul_ql(&minor(3, 7, 4, 6), &e[2], 1.0, det);
    rows
}

/// `[E_00, …, E_22]` of `Σ c_k · basis_k`.
#[inline]
pub(crate) fn combine<const K: usize>(basis: &[[f64; 9]; K], c: &[f64; K]) -> [f64; 9] {
    let mut e = [0.0; 9];
    for k in 0..K {
        for i in 0..9 {
            e[i] += c[k] * basis[k][i];
        }
    }
    e
}

/// Scales `e` to unit Frobenius norm; `None` when it is zero or not finite.
#[inline]
pub(crate) fn unit(e: [f64; 9]) -> Option<affcorr_geom::Mat3> {
    let n = e.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(n.is_finite() && n > 0.0) {
        return None;
    }
    Some(affcorr_geom::Mat3::from_row_slice(&e) / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Evaluates a row over CUBIC at (x, y, z).
    fn eval(row: &Cubic, x: f64, y: f64, z: f64) -> f64 {
        CUBIC
            .iter()
            .zip(row)
            .map(|(e, c)| c * x.powi(e[0] as i32) * y.powi(e[1] as i32) * z.powi(e[2] as i32))
            .sum()
    }

    #[test]
    fn cubic_constraints_match_direct_evaluation() {
        let basis = [
            [0.3, -1.2, 0.5, 0.7, 0.1, -0.4, 0.9, 0.2, -0.6],
            [-0.8, 0.4, 0.3, 0.2, -0.5, 1.1, 0.6, -0.3, 0.2],
            [0.1, 0.9, -0.7, -0.4, 0.8, 0.3, -0.2, 0.5, 1.0],
            [0.6, 0.2, 0.4, -0.9, 0.3, 0.7, 0.5, -1.0, 0.3],
        ];
        let rows = cubic_constraints(&basis);
        let (x, y, z) = (0.7, -1.3, 0.4);
        let e = affcorr_geom::Mat3::from_row_slice(&combine(&basis, &[x, y, z, 1.0]));
        let eet = e * e.transpose();
        let trace = 2.0 * eet * e - eet.trace() * e;
        for i in 0..3 {
            for j in 0..3 {
                let got = eval(&rows[3 * i + j], x, y, z);
                assert!(
                    (got - trace[(i, j)]).abs() < 1e-12,
                    "{got} {}",
                    trace[(i, j)]
                );
            }
        }
        assert!((eval(&rows[9], x, y, z) - e.determinant()).abs() < 1e-12);
    }

    #[test]
    fn null_space_is_orthonormal_and_annihilates_rows() {
        let rows = [
            [0.3, -1.2, 0.5, 0.7, 0.1, -0.4, 0.9, 0.2, -0.6],
            [-0.8, 0.4, 0.3, 0.2, -0.5, 1.1, 0.6, -0.3, 0.2],
            [0.1, 0.9, -0.7, -0.4, 0.8, 0.3, -0.2, 0.5, 1.0],
        ];
        let mut basis = [[0.0; 9]; 6];
        assert!(null_space(&rows, &mut basis));
        for (a, b) in basis.iter().enumerate() {
            for r in &rows {
                assert!(r.iter().zip(b).map(|(p, q)| p * q).sum::<f64>().abs() < 1e-14);
            }
            for (c, d) in basis.iter().enumerate() {
                let dot: f64 = b.iter().zip(d).map(|(p, q)| p * q).sum();
                assert!((dot - if a == c { 1.0 } else { 0.0 }).abs() < 1e-14);
            }
        }
        let dup = [rows[0], rows[0]];
        assert!(!null_space(&dup, &mut [[0.0; 9]; 7]));
    }
}
