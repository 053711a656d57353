//! The small dense linear algebra of the homography and fundamental-matrix solvers, all of it on
//! the stack: nothing here allocates.
//!

//! - [`gauss_jordan`]: reduction of a wide R×C system to `[I | B]` with complete pivoting, whose
//!   null space is read off directly ([`null_vector`]); the minimal solvers with an exactly
//!   determined null space use it (one O(R²C) pass, far cheaper than an SVD).
//! - [`Lsq9`]: a streaming blocked Householder QR of an N×9 homogeneous system that keeps only
//!   the 9×9 triangular factor R (MᵀM = RᵀR without ever squaring the condition number), then
//!   inverse iteration on R gives the least-squares null vector and a rank test. The
//!   over-determined and non-minimal solvers use it.
//! - [`smallest_singular3`] and [`cofactor`]: the smallest singular vector of a 3×3 matrix by
//!   power iteration on its cofactor matrix, and 3×3 helpers ([`mat3_from_vec9`],
//!   [`unit_frobenius`]).

use affcorr_geom::{Mat3, Vec3};
use nalgebra::SVector;

/// 9-vector (a 3×3 matrix stacked row-major).
pub(crate) type Vec9 = SVector<f64, 9>;

/// Reduces the R×C matrix `m` (R < C) in place by Gauss–Jordan elimination with complete
/// pivoting. On success the first R columns of the column-permuted matrix are the identity and
/// `perm[k]` is the original column of permuted column k; the null space is spanned by
/// [`null_vector`]`(m, perm, k)` for k = R..C. Returns `None` when a pivot falls below
/// `rel_tol` × the first (largest) pivot, i.e. the rank is below R, or when `m` is not finite.
pub(crate) fn gauss_jordan<const R: usize, const C: usize>(
    m: &mut [[f64; C]; R],
    rel_tol: f64,
) -> Option<[usize; C]> {
    let mut perm = [0usize; C];
    for (k, p) in perm.iter_mut().enumerate() {
        *p = k;
    }
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let mut first = 0.0;
    for i in 0..R {
        let (mut br, mut bc, mut best) = (i, i, -1.0);
        for r in i..R {
            for c in i..C {
                let v = m[r][c].abs();
                if v > best {
                    (br, bc, best) = (r, c, v);
                }
            }
        }
        if i == 0 {
            first = best;
        }
        if !(best > rel_tol * first) {
            return None;
        }
        m.swap(i, br);
        if bc != i {
            for row in m.iter_mut() {
                row.swap(i, bc);
            }
            perm.swap(i, bc);
        }
        let inv = 1.0 / m[i][i];
        for c in i..C {
            m[i][c] *= inv;
        }
        let pivot_row = m[i];
        for (r, row) in m.iter_mut().enumerate() {
            if r == i {
                continue;
            }
            let f = row[i];
            if f != 0.0 {
                for c in i..C {
                    row[c] -= f * pivot_row[c];
                }
            }
        }
    }
    Some(perm)
}

/// The null vector of a matrix reduced by [`gauss_jordan`] that belongs to free (permuted)
/// column `k ≥ R`: v[perm[k]] = 1, v[perm[i]] = −m[i][k] for i < R, 0 elsewhere.
pub(crate) fn null_vector<const R: usize, const C: usize>(
    m: &[[f64; C]; R],
    perm: &[usize; C],
    k: usize,
) -> [f64; C] {
    let mut v = [0.0; C];
    v[perm[k]] = 1.0;
    for i in 0..R {
        v[perm[i]] = -m[i][k];
    }
    v
}

/// Streaming least squares for N×9 homogeneous systems M f = 0: rows are buffered and folded, 16
/// at a time, into the upper-triangular R of M = QR by Householder reflections (MᵀM = RᵀR); one
/// square root per column and block instead of one per entry as with Givens rotations.
///
/// [`Lsq9::solve`] then finds the smallest right singular vectors of R without a full SVD:
/// - **Inverse iteration** on RᵀR with two triangular solves per step, x ← R⁻¹R⁻ᵀx (Golub &
///   Van Loan, *Matrix Computations*, 4th ed., §8.2.2). It starts from x = R⁻¹eₚ, p the
///   smallest diagonal entry of R, which is already close to the null vector of a triangular
///   matrix with one tiny pivot, and converges with ratio (σ₉/σ₈)² per step: 1–3 steps with
///   exact or mildly noisy data. Pivots below ε‖R‖ are raised to ε‖R‖, so exactly singular R
///   (exact data) is fine.
/// - **Rank test, fast path**: a certified lower bound σ₈ ≥ 1/‖T⁻¹‖_F, T the triangular factor
///   of R without the column where the null vector is largest (interlacing), settles σ₈ > tol
///   in O(9³/6) flops for all but near-degenerate samples.
/// - **Deflation** otherwise, for σ₈ and the next vectors: with a Householder reflector P
///   whose last column is the vector found, R P without its last column spans the complement;
///   re-triangularised by Householder reflections it is an (n−1)×(n−1) triangular factor with the
///   remaining singular values, and inverse iteration runs again.
///
/// All of it is O(9²) per step on the stack: much faster than nalgebra's 9×9 SVD (timings of
/// both in benches/results/solvers_hf.md), with the
/// same accuracy on the smallest singular vector (backward-stable solves, no squaring of M).
#[derive(Debug, Clone)]
pub(crate) struct Lsq9 {
    r: [[f64; 9]; 9],
    /// Buffered rows, column-major: `block[j][row]`.
    block: [[f64; BLOCK]; 9],
    len: usize,
}

/// The Gram matrix MᵀM of a homogeneous N×9 system, accumulated row by row (45 products per
/// row, the upper triangle); [`Gram9::into_lsq`] turns it into an [`Lsq9`] through its Cholesky
/// factor ([`Lsq9::from_gram`], which squares the condition number). For small normalised
/// systems solved very often, such as the local optimisation's 8-point fits, where folding
/// each row by Householder reflections costs several times more.
#[derive(Debug, Clone)]
pub(crate) struct Gram9 {
    g: [[f64; 9]; 9],
}

impl Gram9 {
    /// An empty system.
    pub fn new() -> Self {
        Self { g: [[0.0; 9]; 9] }
    }

    /// Appends the equation `√w·row · f = 0`.
    #[inline]
    pub fn add_weighted_row(&mut self, row: &[f64; 9], w: f64) {
        for i in 0..9 {
            let wi = w * row[i];
            for j in i..9 {
                self.g[i][j] += wi * row[j];
            }
        }
    }

    /// The system as an [`Lsq9`] to solve; `None` if an entry is not finite.
    pub fn into_lsq(mut self) -> Option<Lsq9> {
        for i in 0..9 {
            for j in 0..i {
                self.g[i][j] = self.g[j][i];
            }
        }
        self.g
            .iter()
            .flatten()
            .all(|v| v.is_finite())
            .then(|| Lsq9::from_gram(&self.g))
    }
}

/// Rows folded per Householder pass.
const BLOCK: usize = 16;

/// The result of [`Lsq9::solve`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct NullSpace {
    /// Right singular vectors of M for σ₉, σ₈ and (only when σ₈ counts as zero) σ₇; unit norm.
    pub v: [Vec9; 3],
    /// σ₉ ≤ σ₈ ≤ σ₇ (σ₇ = ∞ when it was not computed). When the fast rank test settled
    /// σ₈ > tol, `sigma[1]` is only a lower bound of σ₈ and `v[1]`, `v[2]` are zero.
    #[cfg_attr(not(test), allow(dead_code))]
    pub sigma: [f64; 3],
    /// Dimension of the numerical null space, capped at 3 (3 means "3 or more"): the number of
    /// these singular values at most `rel_tol`·‖R‖_F.
    pub dim: usize,
}

/// The largest number of inverse-iteration steps for a vector that is returned (reached only when
/// σ₉ ≈ σ₈).
const MAX_INVERSE_ITERATIONS: usize = 50;
/// Steps for a singular value that only feeds the rank test. The estimate ‖R x‖ never falls
/// below σ_min, and the iteration reaches the span of the singular values ≤ tol fast when they
/// are far below the next one, so 3 steps decide "σ ≤ tol" reliably.
const RANK_TEST_ITERATIONS: usize = 3;

impl Lsq9 {
    /// An empty system.
    pub fn new() -> Self {
        Self {
            r: [[0.0; 9]; 9],
            block: [[0.0; BLOCK]; 9],
            len: 0,
        }
    }

    /// The system whose Gram matrix MᵀM is `gram` (symmetric positive semi-definite): R is its
    /// Cholesky factor (RᵀR = MᵀM). This squares the condition number that the streaming QR
    /// avoids, so it is for well-conditioned (normalised) systems where the cost of folding
    /// every row matters more than the last digits. A pivot that rounding leaves ≤ 0 (a rank-
    /// deficient M, e.g. exact data) becomes a zero row of R, which [`Lsq9::solve`] treats as
    /// a zero singular value.
    pub fn from_gram(gram: &[[f64; 9]; 9]) -> Self {
        let mut r = [[0.0; 9]; 9];
        for i in 0..9 {
            let d = gram[i][i] - (0..i).map(|k| r[k][i] * r[k][i]).sum::<f64>();
            if !(d > 0.0) {
                continue;
            }
            let rii = d.sqrt();
            r[i][i] = rii;
            for j in i + 1..9 {
                let dot: f64 = (0..i).map(|k| r[k][i] * r[k][j]).sum();
                r[i][j] = (gram[i][j] - dot) / rii;
            }
        }
        Self {
            r,
            block: [[0.0; BLOCK]; 9],
            len: 0,
        }
    }

    /// Appends the equation `row · f = 0`.
    #[inline]
    pub fn add_row(&mut self, row: [f64; 9]) {
        for (col, v) in self.block.iter_mut().zip(row) {
            col[self.len] = v;
        }
        self.len += 1;
        if self.len == BLOCK {
            householder_fold(&mut self.r, 9, &mut self.block, BLOCK);
            self.len = 0;
        }
    }

    /// The smallest right singular vectors of M and the dimension of its null space (singular
    /// values ≤ `rel_tol`·‖R‖_F count as zero). `None` when M is not finite or zero.
    pub fn solve(&self, rel_tol: f64) -> Option<NullSpace> {
        let mut r0 = self.r;
        let mut block = self.block;
        householder_fold(&mut r0, 9, &mut block, self.len);
        if r0.iter().flatten().any(|v| !v.is_finite()) {
            return None;
        }
        let norm = frobenius(&r0, 9);
        if !(norm > 0.0) {
            return None;
        }
        let tol = rel_tol * norm;
        let (x9, s9) = smallest_singular::<9>(&r0, MAX_INVERSE_ITERATIONS);
        // Fast path: a certified lower bound σ₈ ≥ β > tol settles the rank test.
        let beta = sigma8_lower_bound(&r0, &x9);
        if beta > tol {
            let sigma = [s9, beta, f64::INFINITY];
            return Some(NullSpace {
                v: [Vec9::from(x9), Vec9::zeros(), Vec9::zeros()],
                sigma,
                dim: usize::from(s9 <= tol),
            });
        }
        let (r1, u1) = deflate(&r0, 9, &x9);
        let (mut y8, mut s8) = smallest_singular::<8>(&r1, RANK_TEST_ITERATIONS);
        let (mut v7, mut s7) = ([0.0; 9], f64::INFINITY);
        if s8 <= tol {
            // A 2-dim null space: v₈ is a solution too, converge it.
            (y8, s8) = smallest_singular::<8>(&r1, MAX_INVERSE_ITERATIONS);
            let (r2, u2) = deflate(&r1, 8, &y8);
            let (y7, s) = smallest_singular::<7>(&r2, RANK_TEST_ITERATIONS);
            v7 = reflect(&u1, 9, &reflect(&u2, 8, &y7));
            s7 = s;
        }
        let v8 = reflect(&u1, 9, &y8);
        let sigma = [s9, s8, s7];
        Some(NullSpace {
            v: [Vec9::from(x9), Vec9::from(v8), Vec9::from(v7)],
            sigma,
            dim: sigma.iter().take_while(|&&s| s <= tol).count(),
        })
    }
}

/// A certified lower bound of σ₈(R), cheap: by interlacing, deleting a column c of R can only
/// lower the smallest singular value, σ₈(R) ≥ σ_min(R₋c) (R₋c: 9×8), and for the 8×8 triangular
/// factor T of R₋c, σ_min(T) ≥ 1/‖T⁻¹‖_F. The column deleted is the one where the null vector
/// `x` is largest, so that R₋c is as far from singular as possible. R₋c is upper Hessenberg from
/// column c on; 8 − c Givens rotations make it triangular. Returns 0 when T is singular.
fn sigma8_lower_bound(r: &[[f64; 9]; 9], x: &[f64; 9]) -> f64 {
    let c = (0..9).fold(0, |b, i| if x[i].abs() > x[b].abs() { i } else { b });
    // t = R without column c (9 rows × 8 columns).
    let mut t = [[0.0; 8]; 9];
    for i in 0..9 {
        for j in 0..8 {
            t[i][j] = r[i][if j < c { j } else { j + 1 }];
        }
    }
    // Zero the subdiagonal (i+1, i) for i = c..8 with rotations of rows i and i+1.
    for i in c..8 {
        let (a, b) = (t[i][i], t[i + 1][i]);
        if b == 0.0 {
            continue;
        }
        let h = (a * a + b * b).sqrt();
        let (co, si) = (a / h, b / h);
        for j in i..8 {
            let (u, v) = (t[i][j], t[i + 1][j]);
            t[i][j] = co * u + si * v;
            t[i + 1][j] = co * v - si * u;
        }
    }
    // ‖T⁻¹‖_F² by back substitution on each unit vector.
    let mut sum = 0.0;
    for k in 0..8 {
        let mut y = [0.0; 8];
        for i in (0..=k).rev() {
            let mut s = if i == k { 1.0 } else { 0.0 };
            for j in i + 1..=k {
                s -= t[i][j] * y[j];
            }
            y[i] = s / t[i][i];
        }
        sum += y[..=k].iter().map(|v| v * v).sum::<f64>();
    }
    let beta = 1.0 / sum.sqrt();
    if beta.is_finite() { beta } else { 0.0 }
}

/// Folds the first `k` rows of `block` (stored column-major, `block[j][row]`, first `m` columns)
/// into the m×m upper-triangular `r`: Householder QR of [R; B], exploiting R's zeros below the
/// diagonal. `block` is clobbered. Column-major storage keeps the inner loops contiguous.
#[inline]
pub(crate) fn householder_fold<const K: usize>(
    r: &mut [[f64; 9]; 9],
    m: usize,
    block: &mut [[f64; K]; 9],
    k: usize,
) {
    for i in 0..m {
        let (head, rest) = block.split_at_mut(i + 1);
        let bi = &head[i][..k];
        let tail: f64 = bi.iter().map(|v| v * v).sum();
        if tail == 0.0 {
            continue;
        }
        // The reflector v = (x₀ − α, bᵢ) maps (x₀, bᵢ) to (α, 0), α = −sign(x₀)·‖(x₀, bᵢ)‖.
        let x0 = r[i][i];
        let norm = (x0 * x0 + tail).sqrt();
        let alpha = if x0 >= 0.0 { -norm } else { norm };
        let v0 = x0 - alpha;
        let tau = 2.0 / (v0 * v0 + tail);
        for (jj, bj) in rest[..m - i - 1].iter_mut().enumerate() {
            let j = i + 1 + jj;
            let bj = &mut bj[..k];
            let dot = v0 * r[i][j] + bi.iter().zip(bj.iter()).map(|(a, b)| a * b).sum::<f64>();
            let f = tau * dot;
            r[i][j] -= f * v0;
            for (b, a) in bj.iter_mut().zip(bi) {
                *b -= f * a;
            }
        }
        r[i][i] = alpha;
        head[i][..k].iter_mut().for_each(|v| *v = 0.0);
    }
}

/// ‖R‖_F of the leading n×n block.
fn frobenius(r: &[[f64; 9]; 9], n: usize) -> f64 {
    r[..n]
        .iter()
        .map(|row| row[..n].iter().map(|v| v * v).sum::<f64>())
        .sum::<f64>()
        .sqrt()
}

/// Scales the first `N` entries to unit norm (no-op on zero).
#[inline]
fn normalise<const N: usize>(x: &mut [f64; 9]) {
    let s = x[..N].iter().map(|v| v * v).sum::<f64>().sqrt();
    if s > 0.0 && s.is_finite() {
        let inv = 1.0 / s;
        x[..N].iter_mut().for_each(|v| *v *= inv);
    }
}

/// x ← R⁻¹x (back substitution on the leading N×N block; `inv` holds 1/rᵢᵢ).
#[inline]
fn back_solve<const N: usize>(r: &[[f64; 9]; 9], inv: &[f64; 9], x: &mut [f64; 9]) {
    for i in (0..N).rev() {
        let mut s = x[i];
        for j in i + 1..N {
            s -= r[i][j] * x[j];
        }
        x[i] = s * inv[i];
    }
}

/// x ← R⁻ᵀx (forward substitution with Rᵀ).
#[inline]
fn forward_solve_transposed<const N: usize>(r: &[[f64; 9]; 9], inv: &[f64; 9], x: &mut [f64; 9]) {
    for i in 0..N {
        let mut s = x[i];
        for j in 0..i {
            s -= r[j][i] * x[j];
        }
        x[i] = s * inv[i];
    }
}

/// The smallest right singular vector (unit, first `N` entries) of the upper-triangular leading
/// N×N block of `r`, and its singular value ‖R x‖, by at most `steps` steps of inverse iteration.
fn smallest_singular<const N: usize>(r: &[[f64; 9]; 9], steps: usize) -> ([f64; 9], f64) {
    let floor = f64::EPSILON * frobenius(r, N);
    let mut inv = [0.0; 9];
    let mut p = 0;
    for i in 0..N {
        let d = r[i][i];
        let d = if d.abs() < floor {
            if d < 0.0 { -floor } else { floor }
        } else {
            d
        };
        inv[i] = 1.0 / d;
        if inv[i].abs() > inv[p].abs() {
            p = i;
        }
    }
    let mut x = [0.0; 9];
    if floor > 0.0 {
        x[p] = 1.0;
        back_solve::<N>(r, &inv, &mut x);
        normalise::<N>(&mut x);
        let mut last_change = f64::INFINITY;
        for _ in 0..steps {
            let mut y = x;
            forward_solve_transposed::<N>(r, &inv, &mut y);
            normalise::<N>(&mut y);
            back_solve::<N>(r, &inv, &mut y);
            normalise::<N>(&mut y);
            let d: f64 = (0..N).map(|i| x[i] * y[i]).sum();
            if d < 0.0 {
                y[..N].iter_mut().for_each(|v| *v = -*v);
            }
            let change: f64 = (0..N).map(|i| (x[i] - y[i]).abs()).fold(0.0, f64::max);
            x = y;
            // Converged, or stagnating at the rounding level.
            if !(change > 1e-13) || change >= last_change {
                break;
            }
            last_change = change;
        }
    } else {
        x[0] = 1.0;
    }
    let sigma = (0..N)
        .map(|i| (i..N).map(|j| r[i][j] * x[j]).sum::<f64>().powi(2))
        .sum::<f64>()
        .sqrt();
    (x, sigma)
}

/// The Householder vector u of P = I − 2uuᵀ/uᵀu with P x = α e_{n−1} (unit x), so that P's last
/// column is ±x and its first n−1 columns span x's complement; and the (n−1)×(n−1) triangular
/// factor of R·P without its last column.
fn deflate(r: &[[f64; 9]; 9], n: usize, x: &[f64; 9]) -> ([[f64; 9]; 9], [f64; 9]) {
    let mut u = *x;
    let alpha = if x[n - 1] >= 0.0 { -1.0 } else { 1.0 };
    u[n - 1] -= alpha;
    let uu: f64 = u[..n].iter().map(|v| v * v).sum();
    let mut cols = [[0.0; 9]; 9];
    for i in 0..n {
        // Row i of R P = rᵢ − (2 rᵢ·u / uᵀu) uᵀ; keep its first n−1 entries (column-major).
        let ru: f64 = (i..n).map(|j| r[i][j] * u[j]).sum();
        let f = 2.0 * ru / uu;
        for j in 0..n - 1 {
            cols[j][i] = if j >= i { r[i][j] } else { 0.0 } - f * u[j];
        }
    }
    let mut out = [[0.0; 9]; 9];
    householder_fold(&mut out, n - 1, &mut cols, n);
    (out, u)
}

/// P·[y; 0] for the reflector of [`deflate`] (maps a vector of the deflated n−1 coordinates back
/// to n coordinates).
fn reflect(u: &[f64; 9], n: usize, y: &[f64; 9]) -> [f64; 9] {
    let mut z = [0.0; 9];
    z[..n - 1].copy_from_slice(&y[..n - 1]);
    let uu: f64 = u[..n].iter().map(|v| v * v).sum();
    let f = 2.0 * (0..n).map(|j| u[j] * z[j]).sum::<f64>() / uu;
    for j in 0..n {
        z[j] -= f * u[j];
    }
    z
}

/// The cofactor matrix: row i is r_{i+1} × r_{i+2}, so adj(A) = cof(A)ᵀ and
/// Σ cof(A) ⊙ B = tr(adj(A) B).
#[inline]
pub(crate) fn cofactor(a: &Mat3) -> Mat3 {
    let r = |i: usize| a.row(i).transpose();
    Mat3::from_rows(&[
        r(1).cross(&r(2)).transpose(),
        r(2).cross(&r(0)).transpose(),
        r(0).cross(&r(1)).transpose(),
    ])
}

/// The smallest right (`left == false`) or left singular vector of a 3×3 matrix of rank ≥ 2,
/// without an SVD: power iteration on adj(A)adj(A)ᵀ = cof(A)ᵀcof(A) ∝ (AᵀA)⁻¹ (or on
/// cof(A)cof(A)ᵀ ∝ (AAᵀ)⁻¹ for the left one), started from the largest row (column) of cof(A).
/// adj(A) of a rank-2 A is the rank-1 σ₁σ₂·v₃u₃ᵀ, so the start is already exact then; otherwise
/// it converges with ratio (σ₃/σ₂)². `None` when σ₂ ≤ `rel_tol`·σ₁ (‖cof A‖ ≈ σ₁σ₂ against
/// ‖A‖² ≈ σ₁²) or A is not finite.
pub(crate) fn smallest_singular3(a: &Mat3, left: bool, rel_tol: f64) -> Option<Vec3> {
    let c = cofactor(a);
    let c = if left { c.transpose() } else { c };
    // Now the wanted vector is the dominant eigenvector of cᵀc; rows of c approximate it.
    let norm = c.norm();
    if !(norm > rel_tol * a.norm_squared()) || !norm.is_finite() {
        return None;
    }
    let mut best = 0;
    for i in 1..3 {
        if c.row(i).norm_squared() > c.row(best).norm_squared() {
            best = i;
        }
    }
    let mut x: Vec3 = c.row(best).transpose().normalize();
    for _ in 0..30 {
        let y = (c.transpose() * (c * x)).normalize();
        let y = if y.dot(&x) < 0.0 { -y } else { y };
        let change = (y - x).amax();
        x = y;
        if !(change > 1e-15) {
            break;
        }
    }
    Some(x)
}

/// A 9-vector (row-major) as a 3×3 matrix.
#[inline]
pub(crate) fn mat3_from_vec9(v: &[f64]) -> Mat3 {
    Mat3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8])
}

/// `m / ‖m‖_F`, or `None` when that is not a finite non-zero matrix.
#[inline]
pub(crate) fn unit_frobenius(m: &Mat3) -> Option<Mat3> {
    let n = m.norm();
    (n > 0.0 && n.is_finite()).then(|| m / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_jordan_null_space_and_rank_check() {
        // Two random-ish rows in 4 unknowns: null space of dimension 2.
        let mut m = [[1.0, 2.0, 3.0, 4.0], [2.0, -1.0, 0.5, 3.0]];
        let orig = m;
        let perm = gauss_jordan(&mut m, 1e-12).unwrap();
        for k in 2..4 {
            let v = null_vector(&m, &perm, k);
            for row in &orig {
                let dot: f64 = row.iter().zip(&v).map(|(a, b)| a * b).sum();
                assert!(dot.abs() < 1e-12);
            }
        }
        let mut rank_one = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0]];
        assert!(gauss_jordan(&mut rank_one, 1e-12).is_none());
        let mut nan = [[1.0, f64::NAN, 3.0], [2.0, 4.0, 7.0]];
        assert!(gauss_jordan(&mut nan, 1e-12).is_none());
    }

    #[test]
    fn streaming_qr_matches_the_null_space() {
        // Rows orthogonal to a known f.
        let mut state = 12345u64;
        let mut rand = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let f = Vec9::from_fn(|_, _| rand());
        let mut lsq = Lsq9::new();
        for _ in 0..12 {
            let g = Vec9::from_fn(|_, _| rand());
            let row = g - f * (g.dot(&f) / f.dot(&f));
            lsq.add_row(row.into());
        }
        let ns = lsq.solve(1e-10).unwrap();
        assert_eq!(ns.dim, 1);
        let v = ns.v[0];
        assert!((v.dot(&f).abs() / f.norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn smallest_singular3_matches_svd() {
        let mut state = 5u64;
        let mut rand = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for trial in 0..200 {
            let mut a = Mat3::from_fn(|_, _| rand());
            if trial % 2 == 0 {
                // Exactly rank 2.
                let x = Vec3::new(rand(), rand(), rand());
                a -= (a * x) * x.transpose() / x.norm_squared();
            }
            let svd = a.svd(true, true);
            let k = svd.singular_values.imin();
            let s = &svd.singular_values;
            let mid = (0..3)
                .filter(|&i| i != k)
                .map(|i| s[i])
                .fold(f64::INFINITY, f64::min);
            if mid < 5.0 * s[k] {
                continue; // Nearly equal: the vector is ill-defined.
            }
            let v = svd.v_t.unwrap().row(k).transpose();
            let u = svd.u.unwrap().column(k).into_owned();
            let x = smallest_singular3(&a, false, 1e-9).unwrap();
            let y = smallest_singular3(&a, true, 1e-9).unwrap();
            assert!((x.dot(&v).abs() - 1.0).abs() < 1e-12, "{trial}");
            assert!((y.dot(&u).abs() - 1.0).abs() < 1e-12, "{trial}");
        }
        let rank1 = Vec3::new(1.0, 2.0, 3.0) * Vec3::new(0.5, -1.0, 2.0).transpose();
        assert!(smallest_singular3(&rank1, false, 1e-9).is_none());
        assert!(smallest_singular3(&Mat3::zeros(), true, 1e-9).is_none());
    }

    /// Inverse iteration + deflation agree with nalgebra's SVD on planted null spaces of
    /// dimension 1–3, with and without noise.
    #[test]
    fn null_space_matches_svd() {
        let mut state = 777u64;
        let mut rand = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for trial in 0..300 {
            let dim = 1 + trial % 3;
            let noise = if trial % 2 == 0 { 0.0 } else { 1e-4 };
            let basis: Vec<Vec9> = (0..dim).map(|_| Vec9::from_fn(|_, _| rand())).collect();
            let mut rows = Vec::new();
            let mut lsq = Lsq9::new();
            for _ in 0..15 {
                let mut g = Vec9::from_fn(|_, _| rand());
                // Project out the planted null space (Gram–Schmidt against a QR of the basis).
                let q = nalgebra::DMatrix::from_fn(9, dim, |i, j| basis[j][i])
                    .qr()
                    .q();
                for c in q.column_iter() {
                    let c = Vec9::from_iterator(c.iter().copied());
                    g -= c * c.dot(&g);
                }
                g += Vec9::from_fn(|_, _| rand() * noise);
                lsq.add_row(g.into());
                rows.push(g.transpose());
            }
            let m = nalgebra::DMatrix::from_fn(rows.len(), 9, |i, j| rows[i][j]);
            let svd = m.svd(false, true);
            let mut idx: Vec<usize> = (0..9).collect();
            idx.sort_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]));
            let ns = lsq.solve(1e-9).unwrap();
            let expected = if noise > 0.0 { 0 } else { dim };
            assert_eq!(ns.dim, expected, "trial {trial}");
            // The smallest vector, and the second one when the gap makes it well defined.
            let v_t = svd.v_t.unwrap();
            let s = &svd.singular_values;
            let sv = |i: usize| s[idx[i]];
            let tiny = |i: usize| sv(i) <= 1e-12 * sv(8);
            for k in 0..2 {
                // Compare where the vectors are unique: separated singular values.
                let separated = sv(k + 1) > 10.0 * sv(k) && !tiny(k + 1);
                let below = k == 0 || (sv(k) > 10.0 * sv(k - 1) && !tiny(k));
                let computed = k == 0 || ns.v[1].norm() > 0.0;
                if !computed {
                    // Only a certified lower bound of σ₈.
                    assert!(ns.sigma[1] <= sv(1) * (1.0 + 1e-9), "{trial}");
                }
                if separated && below && computed {
                    let err = (ns.sigma[k] - sv(k)).abs();
                    assert!(err <= 1e-9 * sv(8) + 1e-6 * sv(k), "{trial} {k}");
                    let v = Vec9::from_iterator(v_t.row(idx[k]).iter().copied());
                    assert!((ns.v[k].dot(&v).abs() - 1.0).abs() < 1e-10, "{trial} {k}");
                }
            }
        }
    }
}
