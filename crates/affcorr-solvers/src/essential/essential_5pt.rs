//! Five-point relative pose: the essential matrices consistent with five calibrated point
//! correspondences.
//!
//! D. Nistér, "An efficient solution to the five-point relative pose problem", IEEE TPAMI 26(6),
//! 2004; H. Stewénius, C. Engels, D. Nistér, "Recent developments on direct relative
//! orientation", ISPRS J. 60, 2006.
//!
//! 1. Each correspondence gives one row of p̂2ᵀ E p̂1 = 0 (Nistér eq. 3); the 5×9 system has a
//!    4-dimensional null space E = x·X + y·Y + z·Z + W (eq. 9), taken orthonormal from a
//!    Householder QR of its transpose.
//! 2. det E = 0 and 2·E Eᵀ E − tr(E Eᵀ)·E = 0 (eqs. 6–7) give ten cubics in (x, y, z): a 10×20
//!    matrix over the monomials x³, y³, x²y, xy², x²z, x², y²z, y², xyz, xy | xz², xz, x, yz²,
//!    yz, y, z³, z², z, 1.
//! 3. Gauss–Jordan elimination (partial pivoting) of its left 10×10 block (§3.2.2). With rows
//!    ⟨e⟩…⟨j⟩ led by x²z, x², y²z, y², xyz, xy, the combinations ⟨k⟩ = ⟨e⟩ − z⟨f⟩,
//!    ⟨l⟩ = ⟨g⟩ − z⟨h⟩, ⟨m⟩ = ⟨i⟩ − z⟨j⟩ are linear in (x, y, 1) with coefficients of degree
//!    3, 3, 4 in z: B(z)·(x, y, 1)ᵀ = 0 (eq. 11–13).
//! 4. det B(z) is the degree-10 polynomial of eq. 14; its real roots come from the shared Sturm
//!    root finder ([`crate::poly::real_roots`]), no eigen-decomposition.
//! 5. For each root, (x, y, 1) spans the null space of B(z): the cross product of the two rows
//!    of B(z) whose cross product is largest (eq. 15).
//! 6. Beyond the paper: every candidate (x, y, z) is polished by Gauss–Newton on all ten cubics
//!    (B(z) can be nearly rank 1 on planar scenes, and the cross product then loses digits):
//!    one step always (as cheap as the residual test it replaced), more only while the step is
//!    above 1e-9 of the variables' scale (1.25 steps per root on average). With the Sturm
//!    refinement fix in [`crate::poly`], this lifts the 1e-8 success rate on planar scenes
//!    from 81% to 99.7% (tests/essential_solvers.rs).
//!
//! No heap allocation: every array lives on the stack.
//!
//! Cost: `benches/results/solvers_essential.md` (callgrind, 64 one-plane samples cycled) breaks
//! the instructions per call down; root isolation and refinement ([`crate::poly::real_roots`])
//! is the largest part, then the ten cubics, the Gauss–Jordan elimination and the polish. The
//! residuals and Jacobian of the polish are evaluated lane-parallel over
//! the ten constraints (coefficients transposed by monomial, derivative zeros skipped), and
//! the elimination updates rows in place, only on the columns still read.

use super::constraints::{CUBIC, combine, cubic_constraints, null_space, point_row, unit};
use crate::poly;
use affcorr_geom::{Mat3, Vec2};

/// Largest number of essential matrices [`essential_5pt`] writes.
pub const ESSENTIAL_5PT_MAX_SOLUTIONS: usize = 10;

/// The essential matrices E (unit Frobenius norm, up to sign) with x̂2ᵢᵀ E x̂1ᵢ = 0 for five
/// correspondences in normalised coordinates (x̂ = K⁻¹p).
///
/// Writes up to [`ESSENTIAL_5PT_MAX_SOLUTIONS`] models into `out` (which must be at least that
/// long) and returns how many. Degenerate samples (fewer than five points, repeated points, a
/// rank-deficient system, NaN or infinity) give 0 models.
///
/// ```
/// use affcorr_geom::{Vec2, Vec3, Mat3, epipolar::essential_from_pose, synthetic::rotation_about};
/// use affcorr_solvers::essential::{essential_5pt, ESSENTIAL_5PT_MAX_SOLUTIONS};
/// let r = rotation_about(&Vec3::new(0.2, 1.0, 0.1).normalize(), 0.3);
/// let t = Vec3::new(1.0, 0.1, 0.2);
/// let pts = [[0.1, 0.2, 4.0], [-0.5, 0.3, 5.0], [0.7, -0.4, 6.0], [0.2, 0.6, 3.5], [-0.3, -0.8, 4.5]];
/// let (mut x1, mut x2) = (vec![], vec![]);
/// for p in pts {
///     let p1 = Vec3::from(p);
///     let p2 = r * p1 + t;
///     x1.push(Vec2::new(p1.x / p1.z, p1.y / p1.z));
///     x2.push(Vec2::new(p2.x / p2.z, p2.y / p2.z));
/// }
/// let mut out = [Mat3::zeros(); ESSENTIAL_5PT_MAX_SOLUTIONS];
/// let n = essential_5pt(&x1, &x2, &mut out);
/// let truth = essential_from_pose(&r, &t).normalize();
/// assert!(out[..n].iter().any(|e| (e - truth).norm().min((e + truth).norm()) < 1e-9));
/// ```
pub fn essential_5pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Mat3]) -> usize {
    if x1.len() != 5 || x2.len() != 5 || out.len() < ESSENTIAL_5PT_MAX_SOLUTIONS {
        return 0;
    }
    let mut rows = [[0.0; 9]; 5];
    for i in 0..5 {
        rows[i] = point_row(&x1[i], &x2[i]);
    }
    let mut basis = [[0.0; 9]; 4];
    if !null_space(&rows, &mut basis) {
        return 0;
    }
    solve_from_basis(&basis, out)
}

/// Steps 2–5 for a 4-dimensional family `basis = [X, Y, Z, W]`.
pub(crate) fn solve_from_basis(basis: &[[f64; 9]; 4], out: &mut [Mat3]) -> usize {
    let orig = cubic_constraints(basis);
    let mut a = orig;
    if !gauss_jordan(&mut a) {
        return 0;
    }
    // Coefficients of ⟨k⟩, ⟨l⟩, ⟨m⟩ (ascending in z) for x, y and 1 (eq. 12).
    let mut b = [[[0.0; 5]; 3]; 3];
    for (r, row) in b.iter_mut().enumerate() {
        let (e, f) = (&a[4 + 2 * r], &a[5 + 2 * r]);
        for (v, c) in [(0usize, 10usize), (1, 13)] {
            // Columns c, c+1, c+2 hold the coefficients of (x|y)·z², (x|y)·z, (x|y).
            row[v] = [e[c + 2], e[c + 1] - f[c + 2], e[c] - f[c + 1], -f[c], 0.0];
        }
        // Columns 16..19: z³, z², z, 1.
        row[2] = [e[19], e[18] - f[19], e[17] - f[18], e[16] - f[17], -f[16]];
    }
    debug_assert_eq!(CUBIC[10], [1, 0, 2]);
    // det B(z) (eq. 14), by cofactors along the first row.
    let cof = |p: &[f64; 5], q: &[f64; 5], r: &[f64; 5], s: &[f64; 5]| {
        let mut c = [0.0; 9];
        for i in 0..5 {
            for j in 0..5 {
                if i + j < 9 {
                    c[i + j] += p[i] * q[j] - r[i] * s[j];
                }
            }
        }
        c
    };
    let c0 = cof(&b[1][1], &b[2][2], &b[1][2], &b[2][1]);
    let c1 = cof(&b[1][0], &b[2][2], &b[1][2], &b[2][0]);
    let c2 = cof(&b[1][0], &b[2][1], &b[1][1], &b[2][0]);
    let mut det = [0.0; 11];
    for i in 0..5 {
        for j in 0..9 {
            if i + j < 11 {
                det[i + j] += b[0][0][i] * c0[j] - b[0][1][i] * c1[j] + b[0][2][i] * c2[j];
            }
        }
    }
    let mut roots = [0.0; poly::MAX_DEGREE];
    let nroots = poly::real_roots(&det, &mut roots);
    // The constraints by monomial (column-major), for the lane-parallel residuals of `polish`.
    let mut cols = [[0.0; 10]; 20];
    if nroots > 0 {
        for (r, row) in orig.iter().enumerate() {
            for (m, &v) in row.iter().enumerate() {
                cols[m][r] = v;
            }
        }
    }
    let mut n = 0;
    for &z in &roots[..nroots] {
        let mut m = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] = poly::eval(&b[r][c], z);
            }
        }
        // Null vector of B(z): the largest of the three row cross products.
        let cross = |p: &[f64; 3], q: &[f64; 3]| {
            [
                p[1] * q[2] - p[2] * q[1],
                p[2] * q[0] - p[0] * q[2],
                p[0] * q[1] - p[1] * q[0],
            ]
        };
        let mut best = [0.0; 3];
        let mut best_norm = -1.0;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let v = cross(&m[p], &m[q]);
            let norm = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if norm > best_norm {
                best = v;
                best_norm = norm;
            }
        }
        if best[2] == 0.0 || !best_norm.is_finite() {
            continue;
        }
        let (x, y) = (best[0] / best[2], best[1] / best[2]);
        let (x, y, z) = polish(&cols, x, y, z);
        if let Some(e) = unit(combine(basis, &[x, y, z, 1.0])) {
            out[n] = e;
            n += 1;
        }
    }
    n
}

/// Gauss–Jordan elimination of the left 10×10 block with partial pivoting, leaving it the
/// identity. Returns `false` when a pivot vanishes (a degenerate configuration).
fn gauss_jordan(a: &mut [[f64; 20]; 10]) -> bool {
    // `if v > m` (not f64::max) vectorises; a NaN is caught by the finiteness test below or,
    // failing that, by the pivot test.
    let mut scale = 0.0f64;
    let mut finite = true;
    for row in a.iter() {
        for &v in row {
            let v = v.abs();
            scale = if v > scale { v } else { scale };
            finite &= v.is_finite();
        }
    }
    if !finite {
        return false;
    }
    if !(scale.is_finite() && scale > 0.0) {
        return false;
    }
    for col in 0..10 {
        let mut p = col;
        for r in col + 1..10 {
            if a[r][col].abs() > a[p][col].abs() {
                p = r;
            }
        }
        if !(a[p][col].abs() > 1e-13 * scale) {
            return false;
        }
        a.swap(col, p);
        // Only columns right of `col` are read again (the left block is known to become the
        // identity), so the pivot row is scaled and eliminated from `col + 1` on, in place.
        let (above, rest) = a.split_at_mut(col);
        let (pivot, below) = rest.split_first_mut().expect("col < 10");
        let inv = 1.0 / pivot[col];
        for v in pivot[col + 1..].iter_mut() {
            *v *= inv;
        }
        for row in above.iter_mut() {
            eliminate(row, pivot, col);
        }
        for row in below.iter_mut() {
            eliminate(row, pivot, col);
        }
    }
    true
}

/// `row −= row[col] · pivot` on the columns right of `col`.
#[inline(always)]
fn eliminate(row: &mut [f64; 20], pivot: &[f64; 20], col: usize) {
    let f = row[col];
    for c in col + 1..20 {
        row[c] -= f * pivot[c];
    }
}

/// Gauss–Newton on the ten cubic constraints A·m(x, y, z) = 0: restores full precision where
/// the univariate root or B(z) is ill-conditioned (near-planar scenes, clustered roots).
///
/// One step is always taken (it costs what a residual test would, and on a zero-residual
/// system it squares the relative error); further steps (at most five) only while the last one
/// was not already below 1e-9 of the variables' scale, since the error after a step of size δ
/// is O(δ²). Monomials and their partial derivatives are written out in [`CUBIC`]'s order.
fn polish(cols: &[[f64; 10]; 20], mut x: f64, mut y: f64, mut z: f64) -> (f64, f64, f64) {
    for _ in 0..6 {
        let (x2, y2, z2) = (x * x, y * y, z * z);
        let (xy, xz, yz) = (x * y, x * z, y * z);
        // Residuals and Jacobian columns, all ten constraints at once: a combination of the
        // coefficient columns weighted by the monomials (or their nonzero partial derivatives).
        #[rustfmt::skip]
        let r = combo(cols, cols[19], [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18], [
            x2 * x, y2 * y, x2 * y, x * y2, x2 * z, x2, y2 * z, y2, xy * z, xy,
            x * z2, xz, x, y * z2, yz, y, z2 * z, z2, z,
        ]);
        #[rustfmt::skip]
        let j0 = combo(cols, cols[12], [0, 2, 3, 4, 5, 8, 9, 10, 11], [
            3.0 * x2, 2.0 * xy, y2, 2.0 * xz, 2.0 * x, yz, y, z2, z,
        ]);
        #[rustfmt::skip]
        let j1 = combo(cols, cols[15], [1, 2, 3, 6, 7, 8, 9, 13, 14], [
            3.0 * y2, x2, 2.0 * xy, 2.0 * yz, 2.0 * y, xz, x, z2, z,
        ]);
        #[rustfmt::skip]
        let j2 = combo(cols, cols[18], [4, 6, 8, 10, 11, 13, 14, 16, 17], [
            x2, y2, xy, 2.0 * xz, x, 2.0 * yz, y, 3.0 * z2, 2.0 * z,
        ]);
        // Normal equations JᵀJ s = Jᵀr (upper triangle of JᵀJ).
        let (mut h00, mut h01, mut h02, mut h11, mut h12, mut h22) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut g0, mut g1, mut g2) = (0.0, 0.0, 0.0);
        for k in 0..10 {
            h00 += j0[k] * j0[k];
            h01 += j0[k] * j1[k];
            h02 += j0[k] * j2[k];
            h11 += j1[k] * j1[k];
            h12 += j1[k] * j2[k];
            h22 += j2[k] * j2[k];
            g0 += j0[k] * r[k];
            g1 += j1[k] * r[k];
            g2 += j2[k] * r[k];
        }
        // Solve by the adjugate of the symmetric 3×3 matrix.
        let c00 = h11 * h22 - h12 * h12;
        let c01 = h02 * h12 - h01 * h22;
        let c02 = h01 * h12 - h02 * h11;
        let det = h00 * c00 + h01 * c01 + h02 * c02;
        if !(det > 0.0 && det.is_finite()) {
            break;
        }
        let c11 = h00 * h22 - h02 * h02;
        let c12 = h01 * h02 - h00 * h12;
        let c22 = h00 * h11 - h01 * h01;
        let inv = 1.0 / det;
        let s0 = (c00 * g0 + c01 * g1 + c02 * g2) * inv;
        let s1 = (c01 * g0 + c11 * g1 + c12 * g2) * inv;
        let s2 = (c02 * g0 + c12 * g1 + c22 * g2) * inv;
        if !(s0.is_finite() && s1.is_finite() && s2.is_finite()) {
            break;
        }
        x -= s0;
        y -= s1;
        z -= s2;
        if s0.abs() + s1.abs() + s2.abs() <= 1e-9 * (1.0 + x.abs() + y.abs() + z.abs()) {
            break;
        }
    }
    (x, y, z)
}

/// `init + Σ_t w[t]·cols[idx[t]]`, lane-parallel over the ten constraints.
#[inline(always)]
fn combo<const N: usize>(
    cols: &[[f64; 10]; 20],
    init: [f64; 10],
    idx: [usize; N],
    w: [f64; N],
) -> [f64; 10] {
    let mut acc = init;
    for t in 0..N {
        let c = &cols[idx[t]];
        for k in 0..10 {
            acc[k] += c[k] * w[t];
        }
    }
    acc
}
