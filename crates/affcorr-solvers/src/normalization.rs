//! Hartley's isotropic normalisation and the small dense linear algebra shared by the homography
//! and fundamental-matrix solvers. Nothing here allocates.
//!
//! - [`Similarity`]: x̂ = s·(x − c), with c the centroid and s chosen so that the mean distance of
//!   the points from the origin is √2 (Hartley, "In defense of the eight-point algorithm",
//!   PAMI 1997; Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., Alg. 4.2). A similarity
//!   has a scalar linear part, so an affine map transforms as Â = (s₂/s₁)·A and keeps its shape.
//!   In the normalised frames H = T₂⁻¹ Ĥ T₁ and F = T₂ᵀ F̂ T₁.
//! - [`gauss_jordan`]: reduction of a wide R×C system to `[I | B]` with complete pivoting, whose
//!   null space is read off directly ([`null_vector`]); the minimal solvers with an exactly
//!   determined null space use it (one O(R²C) pass, far cheaper than an SVD).
//! - [`Lsq9`]: a streaming Givens QR of an N×9 homogeneous system that keeps only the 9×9
//!   triangular factor R (MᵀM = RᵀR without ever squaring the condition number), then the SVD of
//!   R gives the least-squares null vector. The over-determined and non-minimal solvers use it.

use affcorr_geom::{Mat3, Vec2};
use nalgebra::{SMatrix, SVector};

/// Radius ρ (pixels of image 1) that scales every affine row in the AC systems by ρ·s₁.
///
/// An error ε in A moves the points at distance ρ from an AC's centre by about ε·ρ pixels, so the
/// affine rows scaled by ρ·s₁ have residuals commensurate with the point rows' (normalised pixels):
/// the AC acts like its centre plus points on a circle of radius ρ. Exact data is unaffected; with
/// noise (0.5 px, 2 % affine) it cuts the error of the over-determined AC solvers about 3× against
/// unweighted rows (ρ from 4 to 16 px all do about equally well).
pub(crate) const AFFINE_ROW_RADIUS_PX: f64 = 8.0;

/// 9×9 matrix.
pub(crate) type Mat9 = SMatrix<f64, 9, 9>;
/// 9-vector (a 3×3 matrix stacked row-major).
pub(crate) type Vec9 = SVector<f64, 9>;

/// x̂ = s·(x − c).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Similarity {
    /// Isotropic scale s > 0.
    pub s: f64,
    /// Centroid c.
    pub c: Vec2,
}

impl Similarity {
    /// Hartley's normalisation of `points`: centroid to the origin, mean distance √2. `None` when
    /// a point is not finite or all points coincide (the scale would be infinite).
    pub fn from_points<I>(points: I) -> Option<Self>
    where
        I: Iterator<Item = Vec2> + Clone,
    {
        let (mut n, mut sum) = (0usize, Vec2::zeros());
        for p in points.clone() {
            n += 1;
            sum += p;
        }
        if n == 0 {
            return None;
        }
        let c = sum / n as f64;
        let mean = points.map(|p| (p - c).norm()).sum::<f64>() / n as f64;
        let s = std::f64::consts::SQRT_2 / mean;
        (c.x.is_finite() && c.y.is_finite() && mean > 0.0 && s.is_finite()).then_some(Self { s, c })
    }

    /// x̂ = s·(x − c).
    #[inline]
    pub fn apply(&self, x: &Vec2) -> Vec2 {
        (x - self.c) * self.s
    }

    /// T = [[s, 0, −s·cx], [0, s, −s·cy], [0, 0, 1]].
    #[inline]
    pub fn matrix(&self) -> Mat3 {
        let s = self.s;
        Mat3::new(s, 0.0, -s * self.c.x, 0.0, s, -s * self.c.y, 0.0, 0.0, 1.0)
    }

    /// T⁻¹ = [[1/s, 0, cx], [0, 1/s, cy], [0, 0, 1]].
    #[inline]
    pub fn inverse_matrix(&self) -> Mat3 {
        let r = 1.0 / self.s;
        Mat3::new(r, 0.0, self.c.x, 0.0, r, self.c.y, 0.0, 0.0, 1.0)
    }
}

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

/// Streaming least squares for N×9 homogeneous systems M f = 0: rows are folded one at a time into
/// the upper-triangular R of M = QR by Givens rotations.
#[derive(Debug, Clone)]
pub(crate) struct Lsq9 {
    r: [[f64; 9]; 9],
}

/// The result of [`Lsq9::solve`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct NullSpace {
    /// Right singular vectors of M ordered by increasing singular value (unit norm).
    pub v: [Vec9; 3],
    /// The matching singular values σ₉ ≤ σ₈ ≤ σ₇.
    pub sigma: [f64; 3],
    /// The largest singular value σ₁.
    pub sigma_max: f64,
}

impl NullSpace {
    /// Dimension of the numerical null space among the three smallest singular directions:
    /// singular values at most `rel_tol`·σ₁ count as zero (so 3 means "3 or more").
    pub fn dimension(&self, rel_tol: f64) -> usize {
        self.sigma
            .iter()
            .take_while(|&&s| s <= rel_tol * self.sigma_max)
            .count()
    }
}

impl Lsq9 {
    /// An empty system.
    pub fn new() -> Self {
        Self { r: [[0.0; 9]; 9] }
    }

    /// Appends the equation `row · f = 0`.
    #[inline]
    pub fn add_row(&mut self, mut row: [f64; 9]) {
        for i in 0..9 {
            let b = row[i];
            if b == 0.0 {
                continue;
            }
            let a = self.r[i][i];
            let h = (a * a + b * b).sqrt();
            let (c, s) = (a / h, b / h);
            self.r[i][i] = h;
            for j in i + 1..9 {
                let (rij, vj) = (self.r[i][j], row[j]);
                self.r[i][j] = c * rij + s * vj;
                row[j] = c * vj - s * rij;
            }
        }
    }

    /// The three smallest right singular vectors of M (from the SVD of R). `None` when M is not
    /// finite.
    pub fn solve(&self) -> Option<NullSpace> {
        let r = Mat9::from_fn(|i, j| self.r[i][j]);
        if r.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let svd = r.svd_unordered(false, true);
        let v_t = svd.v_t?;
        let s = svd.singular_values;
        let mut idx = [0usize, 1, 2, 3, 4, 5, 6, 7, 8];
        idx.sort_unstable_by(|&a, &b| s[a].total_cmp(&s[b]));
        let col = |k: usize| -> Vec9 { v_t.row(idx[k]).transpose() };
        Some(NullSpace {
            v: [col(0), col(1), col(2)],
            sigma: [s[idx[0]], s[idx[1]], s[idx[2]]],
            sigma_max: s[idx[8]],
        })
    }
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
    fn hartley_normalisation_centres_and_scales() {
        let pts = [
            Vec2::new(10.0, 20.0),
            Vec2::new(400.0, 30.0),
            Vec2::new(300.0, 200.0),
        ];
        let t = Similarity::from_points(pts.iter().copied()).unwrap();
        let mapped: Vec<Vec2> = pts.iter().map(|p| t.apply(p)).collect();
        let centroid = mapped.iter().sum::<Vec2>() / 3.0;
        assert!(centroid.norm() < 1e-12);
        let mean = mapped.iter().map(|p| p.norm()).sum::<f64>() / 3.0;
        assert!((mean - std::f64::consts::SQRT_2).abs() < 1e-12);
        let p = t.matrix() * nalgebra::Vector3::new(pts[1].x, pts[1].y, 1.0);
        assert!((p.xy() - mapped[1]).norm() < 1e-12);
        assert!((t.matrix() * t.inverse_matrix() - Mat3::identity()).norm() < 1e-12);
        // Coincident or non-finite points have no normalisation.
        assert!(Similarity::from_points([pts[0]; 4].into_iter()).is_none());
        assert!(Similarity::from_points([pts[0], Vec2::new(f64::NAN, 0.0)].into_iter()).is_none());
        assert!(Similarity::from_points(std::iter::empty()).is_none());
    }

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
        let ns = lsq.solve().unwrap();
        assert_eq!(ns.dimension(1e-10), 1);
        let v = ns.v[0];
        assert!((v.dot(&f).abs() / f.norm() - 1.0).abs() < 1e-12);
    }
}
