//! Point and affine Sampson distances with analytic gradients (docs/design.md §3).
//!
//! API: scalar forms for hot loops ([`sampson_point`], [`sampson_affine`], the fused
//! [`sampson_point_affine`], and the `_grad` twins returning [`PointSampsonGrad`] /
//! [`AffineSampsonGrad`]; no allocation, no checks), and batched forms over `(N, 4)` / `(N, 8)`
//! rows with one F for all rows or one per row ([`Fundamentals`]), writing into caller-owned
//! slices: `*_batch` (rows of values or gradient structs) and `*_grad_columns` (struct of
//! arrays, the layout of the Python bindings).
//!
//! # Derivation
//!
//! Notation: p = (x, y, 1)ᵀ, l1 = F p1 and l2 = Fᵀ p2 (the epipolar lines of x1 in image 2 and
//! of x2 in image 1). Indices i, j, k run over {0, 1}; m, n over {0, 1, 2} when they index F.
//! `[c]` is 1 when the condition c holds, else 0. F is row-major everywhere (`F[m][n]`), and
//! A = ∂x2/∂x1 is row-major (a₀₀, a₀₁, a₁₀, a₁₁) as in docs/design.md §2.
//!
//! **Point.** SD_P = e² / D with
//!
//! ```text
//! e = p2ᵀ F p1 = p2 · l1 = p1 · l2          D = l1_0² + l1_1² + l2_0² + l2_1²
//! ∂e/∂x1_j = l2_j    ∂e/∂x2_j = l1_j    ∂e/∂F_mn = p2_m p1_n
//! ∂D/∂x1_j = 2 Σ_i l1_i F_ij    ∂D/∂x2_j = 2 Σ_k l2_k F_jk
//! ∂D/∂F_mn = 2 [m<2] l1_m p1_n + 2 [n<2] l2_n p2_m
//! ```
//!
//! **Affine**, per constraint row k (docs/design.md §2): SD_A,k = r_k² / G_k, where G_k is the
//! squared norm of ∂r_k/∂(x1, y1, x2, y2, a_0k, a_1k). With B = Aᵀ F[0:2, 0:2], i.e.
//! B_kj = Σ_i a_ik F_ij:
//!
//! ```text
//! r_k = Σ_i a_ik l1_i + l2_k
//! ∂r_k/∂x1_j = B_kj    ∂r_k/∂x2_j = F_jk    ∂r_k/∂a_ik = l1_i   (0 for column 1−k of A)
//! ∂r_k/∂F_mn = [m<2] a_mk p1_n + [n=k] p2_m
//! G_k = B_k0² + B_k1² + F_0k² + F_1k² + l1_0² + l1_1²
//! ∂G_k/∂x1_j = 2 Σ_i l1_i F_ij    ∂G_k/∂x2_j = 0    ∂G_k/∂a_ik = 2 Σ_j B_kj F_ij
//! ∂G_k/∂F_mn = 2 [m<2] ([n<2] B_kn a_mk + [n=k] F_mk + l1_m p1_n)
//! ```
//!
//! (paper fix: the supplement's printed partials have typos; these are derived from the
//! definitions and checked against central finite differences in the tests.)
//!
//! **Gradients.** For SD = r²/G and s = r/G, ∂SD = 2 s ∂r − s² ∂G, which is what every
//! `*_grad` function evaluates, with the products l1, l2 and B computed once.
//!
//! **Degenerate denominators.** D = 0 (or G_k = 0) happens only for special F (e.g. when
//! l1 and l2 both vanish in their first two coordinates). The distance is then `0.0` when the
//! residual is also exactly 0 (the constraint holds), and `+∞` otherwise (no nearby
//! correspondence explains it); the gradient is reported as all zeros in both cases. So finite
//! inputs never give NaN (barring overflow). The scalar forms do not check their inputs (NaN in,
//! NaN out); the batched forms reject non-finite inputs with [`GeomError::NonFinite`].
//!
//! The distances are invariant to the scale (and sign) of F, so the gradient w.r.t. F is
//! orthogonal to F (Euler's theorem for a function homogeneous of degree 0).
//!
//! **Extreme scales of F.** The batched forms run the kernels on F · r, r the power of two that
//! brings F's largest entry into [1, 2), and scale the F-gradient back by r: exact, so the bits
//! are those of F for ordinary F, and the invariance holds for any finite F (F · 1e±300 gives
//! F's distances instead of NaN or 0; `tests/extreme_magnitudes.rs`). The scalar forms, for hot
//! loops, take F as it is (the estimators' models are normalised already).

use crate::batch;
use crate::camera::check_len;
use crate::error::{GeomError, Result};
use crate::types::{
    AcRow, AffineCorrespondence, CorrespondenceRow, Mat3, PointCorrespondence, mat3_from_row,
    max_abs, power_of_two_normalizer,
};

/// The fundamental matrices of a batch: one for every row, or one per row (row-major).
#[derive(Debug, Clone, Copy)]
pub enum Fundamentals<'a> {
    /// One F for every row.
    Shared(&'a Mat3),
    /// One F per row, row-major `[f00, f01, f02, f10, …, f22]`; training batches mix image pairs.
    PerRow(&'a [[f64; 9]]),
}

impl<'a> From<&'a Mat3> for Fundamentals<'a> {
    fn from(f: &'a Mat3) -> Self {
        Self::Shared(f)
    }
}

impl<'a> From<&'a [[f64; 9]]> for Fundamentals<'a> {
    fn from(f: &'a [[f64; 9]]) -> Self {
        Self::PerRow(f)
    }
}

impl<'a> From<&'a Vec<[f64; 9]>> for Fundamentals<'a> {
    fn from(f: &'a Vec<[f64; 9]>) -> Self {
        Self::PerRow(f)
    }
}

/// SD_P and its gradient. Arrays are in the layouts of docs/design.md §2: `d_f` is row-major.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointSampsonGrad {
    /// SD_P.
    pub value: f64,
    /// ∂SD_P/∂(x1, y1).
    pub d_x1: [f64; 2],
    /// ∂SD_P/∂(x2, y2).
    pub d_x2: [f64; 2],
    /// ∂SD_P/∂F, row-major.
    pub d_f: [f64; 9],
}

impl PointSampsonGrad {
    /// The gradient w.r.t. an `(N, 4)` row `[x1, y1, x2, y2]`.
    #[inline]
    pub fn d_row(&self) -> [f64; 4] {
        [self.d_x1[0], self.d_x1[1], self.d_x2[0], self.d_x2[1]]
    }
}

/// SD_A,k (one row k of the affine constraint) and its gradient.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AffineSampsonGrad {
    /// SD_A,k.
    pub value: f64,
    /// ∂SD_A,k/∂(x1, y1).
    pub d_x1: [f64; 2],
    /// ∂SD_A,k/∂(x2, y2).
    pub d_x2: [f64; 2],
    /// ∂SD_A,k/∂(a11, a12, a21, a22) (only column k of A is non-zero).
    pub d_a: [f64; 4],
    /// ∂SD_A,k/∂F, row-major.
    pub d_f: [f64; 9],
}

impl AffineSampsonGrad {
    /// The gradient w.r.t. an `(N, 8)` row `[x1, y1, x2, y2, a11, a12, a21, a22]`.
    #[inline]
    pub fn d_row(&self) -> [f64; 8] {
        let (a, b, c) = (self.d_x1, self.d_x2, self.d_a);
        [a[0], a[1], b[0], b[1], c[0], c[1], c[2], c[3]]
    }
}

/// F's entries row-major, read once.
#[inline(always)]
fn entries(f: &Mat3) -> [[f64; 3]; 3] {
    [
        [f[(0, 0)], f[(0, 1)], f[(0, 2)]],
        [f[(1, 0)], f[(1, 1)], f[(1, 2)]],
        [f[(2, 0)], f[(2, 1)], f[(2, 2)]],
    ]
}

/// The shared products: l1 = F p1 (all three) and the first two entries of l2 = Fᵀ p2.
#[inline(always)]
fn lines(f: &[[f64; 3]; 3], p1: [f64; 2], p2: [f64; 2]) -> ([f64; 3], [f64; 2]) {
    let l1 = [
        f[0][0] * p1[0] + f[0][1] * p1[1] + f[0][2],
        f[1][0] * p1[0] + f[1][1] * p1[1] + f[1][2],
        f[2][0] * p1[0] + f[2][1] * p1[1] + f[2][2],
    ];
    let l2 = [
        f[0][0] * p2[0] + f[1][0] * p2[1] + f[2][0],
        f[0][1] * p2[0] + f[1][1] * p2[1] + f[2][1],
    ];
    (l1, l2)
}

/// r² / d with the degenerate-denominator rule of the module docs.
#[inline(always)]
fn ratio(r: f64, d: f64) -> f64 {
    if d == 0.0 {
        if r == 0.0 { 0.0 } else { f64::INFINITY }
    } else {
        r * r / d
    }
}

/// The point Sampson distance SD_P = (p2ᵀFp1)² / ((Fp1)₁² + (Fp1)₂² + (Fᵀp2)₁² + (Fᵀp2)₂²), in
/// squared units of the coordinates (pixels² for a pixel F).
///
/// ```
/// use affcorr_geom::{Mat3, PointCorrespondence, Vec2};
/// use affcorr_geom::sampson::sampson_point;
/// // Pure translation along x: F = [t]× with t = (1, 0, 0), epipolar lines are rows y = const.
/// let f = Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
/// let on = PointCorrespondence { x1: Vec2::new(3.0, 2.0), x2: Vec2::new(7.0, 2.0) };
/// let off = PointCorrespondence { x1: Vec2::new(3.0, 2.0), x2: Vec2::new(7.0, 3.0) };
/// assert_eq!(sampson_point(&f, &on), 0.0);
/// // One pixel off the line, shared between the two images: 1² / (1 + 1).
/// assert!((sampson_point(&f, &off) - 0.5).abs() < 1e-15);
/// ```
#[inline(always)]
pub fn sampson_point(f: &Mat3, c: &PointCorrespondence) -> f64 {
    let f = entries(f);
    let (p1, p2) = ([c.x1.x, c.x1.y], [c.x2.x, c.x2.y]);
    let (l1, l2) = lines(&f, p1, p2);
    let e = p2[0] * l1[0] + p2[1] * l1[1] + l1[2];
    ratio(
        e,
        l1[0] * l1[0] + l1[1] * l1[1] + l2[0] * l2[0] + l2[1] * l2[1],
    )
}

/// SD_P and its gradient w.r.t. x1, x2 and F (see the module docs for the partials).
#[inline]
pub fn sampson_point_grad(f: &Mat3, c: &PointCorrespondence) -> PointSampsonGrad {
    let fe = entries(f);
    let (p1, p2) = ([c.x1.x, c.x1.y], [c.x2.x, c.x2.y]);
    let (l1, l2) = lines(&fe, p1, p2);
    let e = p2[0] * l1[0] + p2[1] * l1[1] + l1[2];
    let d = l1[0] * l1[0] + l1[1] * l1[1] + l2[0] * l2[0] + l2[1] * l2[1];
    if d == 0.0 {
        return PointSampsonGrad {
            value: ratio(e, d),
            ..Default::default()
        };
    }
    let s = e / d;
    // ∂SD = 2s ∂e − s² ∂D; both terms carry a factor 2.
    let (a, b) = (2.0 * s, 2.0 * s * s);
    let (q1, q2) = ([p1[0], p1[1], 1.0], [p2[0], p2[1], 1.0]);
    let mut d_f = [0.0; 9];
    for m in 0..3 {
        for n in 0..3 {
            let mut dd = 0.0;
            if m < 2 {
                dd += l1[m] * q1[n];
            }
            if n < 2 {
                dd += l2[n] * q2[m];
            }
            d_f[3 * m + n] = a * q2[m] * q1[n] - b * dd;
        }
    }
    let d_x1 = [
        a * l2[0] - b * (l1[0] * fe[0][0] + l1[1] * fe[1][0]),
        a * l2[1] - b * (l1[0] * fe[0][1] + l1[1] * fe[1][1]),
    ];
    let d_x2 = [
        a * l1[0] - b * (l2[0] * fe[0][0] + l2[1] * fe[0][1]),
        a * l1[1] - b * (l2[0] * fe[1][0] + l2[1] * fe[1][1]),
    ];
    PointSampsonGrad {
        value: ratio(e, d),
        d_x1,
        d_x2,
        d_f,
    }
}

/// The products the affine forms share.
struct AffineTerms {
    f: [[f64; 3]; 3],
    p1: [f64; 3],
    p2: [f64; 3],
    l1: [f64; 3],
    /// The first two entries of l2 = Fᵀ p2.
    l2: [f64; 2],
    /// A row-major.
    a: [[f64; 2]; 2],
    /// B = Aᵀ F[0:2,0:2]: B[k][j] = Σ_i a_ik F_ij.
    b: [[f64; 2]; 2],
    /// r_k.
    r: [f64; 2],
    /// G_k.
    g: [f64; 2],
}

#[inline(always)]
fn affine_terms(f: &Mat3, ac: &AffineCorrespondence) -> AffineTerms {
    let f = entries(f);
    let (x1, x2) = ([ac.x1.x, ac.x1.y], [ac.x2.x, ac.x2.y]);
    let (l1, l2) = lines(&f, x1, x2);
    let a = [[ac.a[(0, 0)], ac.a[(0, 1)]], [ac.a[(1, 0)], ac.a[(1, 1)]]];
    let mut b = [[0.0; 2]; 2];
    let mut r = [0.0; 2];
    let mut g = [0.0; 2];
    let l1n = l1[0] * l1[0] + l1[1] * l1[1];
    for k in 0..2 {
        for j in 0..2 {
            b[k][j] = a[0][k] * f[0][j] + a[1][k] * f[1][j];
        }
        r[k] = a[0][k] * l1[0] + a[1][k] * l1[1] + l2[k];
        g[k] = b[k][0] * b[k][0] + b[k][1] * b[k][1] + f[0][k] * f[0][k] + f[1][k] * f[1][k] + l1n;
    }
    AffineTerms {
        f,
        p1: [x1[0], x1[1], 1.0],
        p2: [x2[0], x2[1], 1.0],
        l1,
        l2,
        a,
        b,
        r,
        g,
    }
}

/// The affine Sampson distances `[SD_A,0, SD_A,1]`, one per row of the affine epipolar
/// constraint Aᵀ (F p1)₁:₂ + (Fᵀ p2)₁:₂ = 0 (docs/design.md §2–3). SD_A is their sum.
///
/// ```
/// use affcorr_geom::sampson::sampson_affine;
/// use affcorr_geom::synthetic::PlaneScene;
/// use rand::SeedableRng;
///
/// let mut rng = rand::rngs::StdRng::seed_from_u64(1);
/// let scene = PlaneScene::random(&mut rng);
/// let f = scene.fundamental().normalize();
/// // An exact AC (x1, x2, A = ∂x2/∂x1) induced by the plane satisfies both rows.
/// let mut ac = scene.sample(&mut rng, 1)[0];
/// let [d0, d1] = sampson_affine(&f, &ac);
/// assert!(d0 < 1e-12 && d1 < 1e-12);
/// // The transposed map does not: A's direction matters.
/// ac.a = ac.a.transpose();
/// let [t0, t1] = sampson_affine(&f, &ac);
/// assert!(t0 + t1 > 1e6 * (d0 + d1));
/// ```
#[inline]
pub fn sampson_affine(f: &Mat3, ac: &AffineCorrespondence) -> [f64; 2] {
    let t = affine_terms(f, ac);
    [ratio(t.r[0], t.g[0]), ratio(t.r[1], t.g[1])]
}

/// `(SD_P, [SD_A,0, SD_A,1])` of one AC, sharing F p1 and Fᵀ p2: bit-identical to
/// [`sampson_point`] and [`sampson_affine`], for residuals that mix the two (docs/design.md §5).
/// Always inlined: the scoring loops over it vectorise only then.
#[inline(always)]
pub fn sampson_point_affine(f: &Mat3, ac: &AffineCorrespondence) -> (f64, [f64; 2]) {
    let t = affine_terms(f, ac);
    let (l1, l2) = (&t.l1, &t.l2);
    let e = t.p2[0] * l1[0] + t.p2[1] * l1[1] + l1[2];
    let d = l1[0] * l1[0] + l1[1] * l1[1] + l2[0] * l2[0] + l2[1] * l2[1];
    (ratio(e, d), [ratio(t.r[0], t.g[0]), ratio(t.r[1], t.g[1])])
}

/// Both SD_A,k and their gradients w.r.t. x1, x2, A and F (see the module docs).
#[inline]
pub fn sampson_affine_grad(f: &Mat3, ac: &AffineCorrespondence) -> [AffineSampsonGrad; 2] {
    let t = affine_terms(f, ac);
    [affine_row_grad(&t, 0), affine_row_grad(&t, 1)]
}

/// The signed affine Sampson residuals s_k = r_k / √G_k (so s_k² = SD_A,k) and their gradients
/// w.r.t. F (row-major), for least squares over F: ∂s_k = ∂r_k / √G_k − r_k ∂(G_k/2) / G_k^{3/2},
/// with ∂r_k and ∂G_k/2 as in the module docs. A row with G_k = 0 gives (0, zeros).
///
/// Branch-free (the degenerate row is a select), and always inlined, so that the refinements'
/// loops over blocks of ACs vectorise.
#[inline(always)]
pub fn sampson_affine_signed_grad_f(f: &Mat3, ac: &AffineCorrespondence) -> [(f64, [f64; 9]); 2] {
    let t = affine_terms(f, ac);
    std::array::from_fn(|k| {
        let g = t.g[k];
        let usable = g > 0.0;
        let r = if usable { t.r[k] } else { 0.0 };
        let inv = if usable { 1.0 / g.sqrt() } else { 0.0 };
        let c = r * inv * inv * inv; // r / G^{3/2}
        let (fe, l1, b) = (&t.f, &t.l1, &t.b[k]);
        let mut d_f = [0.0; 9];
        for m in 0..3 {
            for n in 0..3 {
                let mut dr = if n == k { t.p2[m] } else { 0.0 };
                let mut dg = 0.0;
                if m < 2 {
                    let amk = t.a[m][k];
                    dr += amk * t.p1[n];
                    dg = l1[m] * t.p1[n];
                    if n < 2 {
                        dg += b[n] * amk;
                    }
                    if n == k {
                        dg += fe[m][k];
                    }
                }
                d_f[3 * m + n] = dr * inv - c * dg;
            }
        }
        (r * inv, d_f)
    })
}

#[inline(always)]
fn affine_row_grad(t: &AffineTerms, k: usize) -> AffineSampsonGrad {
    let (r, g) = (t.r[k], t.g[k]);
    if g == 0.0 {
        return AffineSampsonGrad {
            value: ratio(r, g),
            ..Default::default()
        };
    }
    let (f, l1, b) = (&t.f, &t.l1, &t.b[k]);
    let s = r / g;
    let (c, h) = (2.0 * s, 2.0 * s * s);
    let mut d_x1 = [0.0; 2];
    let mut d_x2 = [0.0; 2];
    let mut d_a = [0.0; 4];
    for j in 0..2 {
        d_x1[j] = c * b[j] - h * (l1[0] * f[0][j] + l1[1] * f[1][j]);
        d_x2[j] = c * f[j][k];
        // a_jk: ∂r = l1_j, ∂G/2 = Σ_n B_kn F_jn.
        d_a[2 * j + k] = c * l1[j] - h * (b[0] * f[j][0] + b[1] * f[j][1]);
    }
    let mut d_f = [0.0; 9];
    for m in 0..3 {
        for n in 0..3 {
            let mut dr = if n == k { t.p2[m] } else { 0.0 };
            let mut dg = 0.0;
            if m < 2 {
                let amk = t.a[m][k];
                dr += amk * t.p1[n];
                dg = l1[m] * t.p1[n];
                if n < 2 {
                    dg += b[n] * amk;
                }
                if n == k {
                    dg += f[m][k];
                }
            }
            d_f[3 * m + n] = c * dr - h * dg;
        }
    }
    AffineSampsonGrad {
        value: ratio(r, g),
        d_x1,
        d_x2,
        d_a,
        d_f,
    }
}

fn check_f(f: &Mat3) -> Result<()> {
    if f.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(GeomError::NonFinite {
            what: "F",
            index: 0,
        })
    }
}

fn check_corrs(values: &[f64], index: usize) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(GeomError::NonFinite {
            what: "corrs",
            index,
        })
    }
}

/// F · r with r the power of two that brings its largest entry into [1, 2), and r. The
/// distances are invariant to F's scale and their F-gradient scales as 1/scale, so a kernel run
/// on F · r gives the distance of F and, multiplied by r, its F-gradient: bit for bit the same
/// as on F when F's products neither overflow nor underflow, and finite when they would
/// (F · 1e155, F · 1e-160; docs/reliability.md).
fn normalized(f: &Mat3) -> (Mat3, f64) {
    let r = power_of_two_normalizer(max_abs(f.iter()));
    (f * r, r)
}

/// Runs `kernel(F_i · r_i, r_i, i)` for every row of `out` (see [`normalized`]), checking the
/// lengths and F's entries.
fn run<T, K>(f: Fundamentals<'_>, n: usize, out: &mut [T], kernel: K) -> Result<()>
where
    T: Send,
    K: Fn(&Mat3, f64, usize) -> Result<T> + Sync,
{
    check_len("out", n, out.len())?;
    match f {
        Fundamentals::Shared(f) => {
            check_f(f)?;
            let (f, r) = normalized(f);
            batch::try_fill(out, |i| kernel(&f, r, i))
        }
        Fundamentals::PerRow(fs) => {
            check_len("F", n, fs.len())?;
            batch::try_fill(out, |i| {
                if !fs[i].iter().all(|v| v.is_finite()) {
                    return Err(GeomError::NonFinite {
                        what: "F",
                        index: i,
                    });
                }
                let (f, r) = normalized(&mat3_from_row(&fs[i]));
                kernel(&f, r, i)
            })
        }
    }
}

/// `d_f · r`: the F-gradient of F from that of F · r.
fn scaled<const K: usize>(d_f: [f64; K], r: f64) -> [f64; K] {
    d_f.map(|v| v * r)
}

fn point_of<R: CorrespondenceRow>(corrs: &[R], i: usize) -> Result<PointCorrespondence> {
    let c = corrs[i].points();
    check_corrs(&[c.x1.x, c.x1.y, c.x2.x, c.x2.y], i)?;
    Ok(c)
}

fn ac_of(corrs: &[AcRow], i: usize) -> Result<AffineCorrespondence> {
    check_corrs(&corrs[i], i)?;
    Ok(AffineCorrespondence::from_row(&corrs[i]))
}

/// Batched [`sampson_point`] over `(N, 4)` or `(N, 8)` rows (the A columns are ignored, and
/// only the point columns are checked). `out` has N entries. Errors: length mismatches of `F`
/// (per-row) or `out`, and non-finite `F` or `corrs` (the first bad row).
pub fn sampson_point_batch<'a, R: CorrespondenceRow>(
    f: impl Into<Fundamentals<'a>>,
    corrs: &[R],
    out: &mut [f64],
) -> Result<()> {
    run(f.into(), corrs.len(), out, |f, _, i| {
        Ok(sampson_point(f, &point_of(corrs, i)?))
    })
}

/// Batched [`sampson_affine`] over `(N, 8)` rows into `(N, 2)`; errors as
/// [`sampson_point_batch`].
pub fn sampson_affine_batch<'a>(
    f: impl Into<Fundamentals<'a>>,
    corrs: &[AcRow],
    out: &mut [[f64; 2]],
) -> Result<()> {
    run(f.into(), corrs.len(), out, |f, _, i| {
        Ok(sampson_affine(f, &ac_of(corrs, i)?))
    })
}

/// Batched [`sampson_point_grad`]; errors as [`sampson_point_batch`].
pub fn sampson_point_grad_batch<'a, R: CorrespondenceRow>(
    f: impl Into<Fundamentals<'a>>,
    corrs: &[R],
    out: &mut [PointSampsonGrad],
) -> Result<()> {
    run(f.into(), corrs.len(), out, |f, r, i| {
        let mut g = sampson_point_grad(f, &point_of(corrs, i)?);
        g.d_f = scaled(g.d_f, r);
        Ok(g)
    })
}

/// Batched [`sampson_affine_grad`]; errors as [`sampson_point_batch`].
pub fn sampson_affine_grad_batch<'a>(
    f: impl Into<Fundamentals<'a>>,
    corrs: &[AcRow],
    out: &mut [[AffineSampsonGrad; 2]],
) -> Result<()> {
    run(f.into(), corrs.len(), out, |f, r, i| {
        let mut g = sampson_affine_grad(f, &ac_of(corrs, i)?);
        for g in &mut g {
            g.d_f = scaled(g.d_f, r);
        }
        Ok(g)
    })
}

/// Runs `kernel(F_i · r_i, r_i, i)` into three outputs (as [`run`]), checking the lengths and F's entries.
fn run3<A, B, C, K>(
    f: Fundamentals<'_>,
    n: usize,
    out: (&mut [A], &mut [B], &mut [C]),
    kernel: K,
) -> Result<()>
where
    A: Send,
    B: Send,
    C: Send,
    K: Fn(&Mat3, f64, usize) -> Result<(A, B, C)> + Sync,
{
    let (a, b, c) = out;
    check_len("value", n, a.len())?;
    check_len("d_corrs", n, b.len())?;
    check_len("d_f", n, c.len())?;
    match f {
        Fundamentals::Shared(f) => {
            check_f(f)?;
            let (f, r) = normalized(f);
            batch::try_fill3(a, b, c, |i| kernel(&f, r, i))
        }
        Fundamentals::PerRow(fs) => {
            check_len("F", n, fs.len())?;
            batch::try_fill3(a, b, c, |i| {
                if !fs[i].iter().all(|v| v.is_finite()) {
                    return Err(GeomError::NonFinite {
                        what: "F",
                        index: i,
                    });
                }
                let (f, r) = normalized(&mat3_from_row(&fs[i]));
                kernel(&f, r, i)
            })
        }
    }
}

/// [`sampson_point_grad_batch`] with struct-of-arrays outputs, the layout of the Python
/// bindings: `value (N)`, `d_corrs (N, W)` and `d_f (N, 3, 3)` row-major. `W ≥ 4` is the width
/// of the caller's gradient rows: entries past the fourth (the A columns of an `(N, 8)` layout)
/// are set to zero. Errors as [`sampson_point_batch`], naming the output that has the wrong
/// length.
pub fn sampson_point_grad_columns<'a, R: CorrespondenceRow, const W: usize>(
    f: impl Into<Fundamentals<'a>>,
    corrs: &[R],
    value: &mut [f64],
    d_corrs: &mut [[f64; W]],
    d_f: &mut [[f64; 9]],
) -> Result<()> {
    const { assert!(W >= 4, "gradient rows hold at least x1, y1, x2, y2") };
    run3(f.into(), corrs.len(), (value, d_corrs, d_f), |f, r, i| {
        let g = sampson_point_grad(f, &point_of(corrs, i)?);
        let mut row = [0.0; W];
        row[..4].copy_from_slice(&g.d_row());
        Ok((g.value, row, scaled(g.d_f, r)))
    })
}

/// [`sampson_affine_grad_batch`] with struct-of-arrays outputs, the layout of the Python
/// bindings: `value (N, 2)`, `d_corrs (N, 2, 8)` and `d_f (N, 2, 3, 3)`, indexed by row n and
/// constraint row k. Errors as [`sampson_point_grad_columns`].
pub fn sampson_affine_grad_columns<'a>(
    f: impl Into<Fundamentals<'a>>,
    corrs: &[AcRow],
    value: &mut [[f64; 2]],
    d_corrs: &mut [[[f64; 8]; 2]],
    d_f: &mut [[[f64; 9]; 2]],
) -> Result<()> {
    run3(f.into(), corrs.len(), (value, d_corrs, d_f), |f, r, i| {
        let [g0, g1] = sampson_affine_grad(f, &ac_of(corrs, i)?);
        Ok((
            [g0.value, g1.value],
            [g0.d_row(), g1.d_row()],
            [scaled(g0.d_f, r), scaled(g1.d_f, r)],
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::PlaneScene;
    use crate::types::{Mat2, Vec2, mat3_to_row};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// A random scene's unit-norm F and `n` of its exact ACs.
    fn exact(rng: &mut Pcg64, n: usize) -> (Mat3, Vec<AffineCorrespondence>) {
        let scene = PlaneScene::random(rng);
        (scene.fundamental().normalize(), scene.sample(rng, n))
    }

    /// Exact ACs with ~1 px noise on x2 and ~5% on A: residuals are well away from zero.
    fn perturbed(rng: &mut Pcg64, n: usize) -> (Mat3, Vec<AffineCorrespondence>) {
        let (f, mut acs) = exact(rng, n);
        for ac in &mut acs {
            ac.x2 += Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            ac.a += Mat2::from_fn(|_, _| rng.random_range(-0.05..0.05));
        }
        (f, acs)
    }

    /// Parameters as one vector: x1, y1, x2, y2, A (4), F (9, row-major).
    fn pack(f: &Mat3, ac: &AffineCorrespondence) -> [f64; 17] {
        let mut v = [0.0; 17];
        v[..8].copy_from_slice(&ac.to_row());
        v[8..].copy_from_slice(&mat3_to_row(f));
        v
    }

    fn unpack(v: &[f64; 17]) -> (Mat3, AffineCorrespondence) {
        let row: [f64; 8] = v[..8].try_into().unwrap();
        let fr: [f64; 9] = v[8..].try_into().unwrap();
        (mat3_from_row(&fr), AffineCorrespondence::from_row(&row))
    }

    /// Central differences of `g` at `v`, Richardson-extrapolated (error O(h⁴)), with a step per
    /// parameter that moves the epipolar residual by a similar small fraction: F_mn is weighted
    /// by the coordinates it multiplies, which span five orders of magnitude in pixels. Checks
    /// `analytic` entry by entry (relative to the entry, floored at 1e-3 of the largest entry of
    /// its group) and returns the worst relative error.
    fn check_gradient(
        v: &[f64; 17],
        g: impl Fn(&[f64; 17]) -> f64,
        analytic: &[f64; 17],
        label: &str,
    ) -> f64 {
        let norm_f = v[8..].iter().map(|x| x * x).sum::<f64>().sqrt();
        let (q1, q2) = ([v[0], v[1], 1.0], [v[2], v[3], 1.0]);
        let central = |j: usize, h: f64| {
            let (mut up, mut down) = (*v, *v);
            up[j] += h;
            down[j] -= h;
            (g(&up) - g(&down)) / (2.0 * h)
        };
        let mut worst = 0.0f64;
        // Groups: points, A, F.
        let groups: [std::ops::Range<usize>; 3] = [0..4, 4..8, 8..17];
        for group in groups {
            let gmax = group.clone().fold(0.0f64, |m, j| m.max(analytic[j].abs()));
            for j in group {
                let h = match j {
                    0..4 => 1e-3,
                    4..8 => 1e-4 * v[j].abs().max(0.1),
                    _ => {
                        let (m, n) = ((j - 8) / 3, (j - 8) % 3);
                        1e-4 * norm_f / (q2[m].abs().max(1.0) * q1[n].abs().max(1.0))
                    }
                };
                let fd = (4.0 * central(j, h / 2.0) - central(j, h)) / 3.0;
                let err = (fd - analytic[j]).abs() / (analytic[j].abs() + 1e-3 * gmax).max(1e-300);
                assert!(
                    err < 1e-6,
                    "{label}: parameter {j}: analytic {} vs finite differences {fd}",
                    analytic[j]
                );
                worst = worst.max(err);
            }
        }
        worst
    }

    #[test]
    fn exact_plane_correspondences_have_zero_distances() {
        let mut rng = Pcg64::seed_from_u64(11);
        for _ in 0..50 {
            let (f, acs) = exact(&mut rng, 40);
            for ac in &acs {
                let p = sampson_point(&f, &ac.points());
                let [a0, a1] = sampson_affine(&f, ac);
                assert!(p < 1e-12 && a0 < 1e-12 && a1 < 1e-12, "{p} {a0} {a1}");
            }
        }
    }

    #[test]
    fn point_distance_is_the_first_order_geometric_error() {
        // Translation along x: epipolar lines are horizontal; moving x2 by δ in y gives
        // SD_P = δ² / 2 (the error is shared by both images).
        let f = Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
        for delta in [0.5, 2.0, -3.0] {
            let c = PointCorrespondence {
                x1: Vec2::new(10.0, 4.0),
                x2: Vec2::new(-7.0, 4.0 + delta),
            };
            assert!((sampson_point(&f, &c) - delta * delta / 2.0).abs() < 1e-14);
        }
    }

    #[test]
    fn distances_are_invariant_to_the_scale_of_f() {
        let mut rng = Pcg64::seed_from_u64(12);
        let (f, acs) = perturbed(&mut rng, 30);
        for ac in &acs {
            let p = sampson_point(&f, &ac.points());
            let a = sampson_affine(&f, ac);
            assert!(p > 1e-6);
            // Up to rounding: p2ᵀFp1 sums pixel-sized terms that cancel to ~1 px.
            for lambda in [-3.0, 1e-4, 1e5] {
                let g = f * lambda;
                assert!((sampson_point(&g, &ac.points()) - p).abs() < 1e-10 * p + 1e-14);
                let b = sampson_affine(&g, ac);
                for k in 0..2 {
                    assert!((b[k] - a[k]).abs() < 1e-10 * a[k] + 1e-14);
                }
            }
        }
    }

    #[test]
    fn only_the_right_direction_of_a_satisfies_the_affine_constraint() {
        let mut rng = Pcg64::seed_from_u64(13);
        let mut wrong = Vec::new();
        for _ in 0..20 {
            let (f, acs) = exact(&mut rng, 10);
            for ac in &acs {
                let right = sampson_affine(&f, ac);
                for a in [ac.a.transpose(), ac.a.try_inverse().unwrap()] {
                    let bad = sampson_affine(&f, &AffineCorrespondence { a, ..*ac });
                    assert!(right[0] + right[1] < 1e-12);
                    wrong.push(bad[0] + bad[1]);
                }
            }
        }
        // Typical plane ACs are far from symmetric or involutory: the wrong maps miss by
        // (sub)pixels; a few points may lie where A happens to be nearly symmetric.
        wrong.sort_by(f64::total_cmp);
        assert!(
            wrong[wrong.len() / 2] > 1e-2,
            "median {}",
            wrong[wrong.len() / 2]
        );
        assert!(
            wrong[wrong.len() / 10] > 1e-6,
            "10th percentile {}",
            wrong[wrong.len() / 10]
        );
    }

    #[test]
    fn gradients_match_central_differences() {
        let mut rng = Pcg64::seed_from_u64(14);
        let mut worst = 0.0f64;
        for _ in 0..20 {
            let (f, acs) = perturbed(&mut rng, 10);
            for ac in &acs {
                let v = pack(&f, ac);
                let g = sampson_point_grad(&f, &ac.points());
                assert_eq!(g.value, sampson_point(&f, &ac.points()));
                let mut an = [0.0; 17];
                an[..4].copy_from_slice(&g.d_row());
                an[8..].copy_from_slice(&g.d_f);
                let point = |v: &[f64; 17]| {
                    let (f, ac) = unpack(v);
                    sampson_point(&f, &ac.points())
                };
                worst = worst.max(check_gradient(&v, point, &an, "SD_P"));
                let grads = sampson_affine_grad(&f, ac);
                let values = sampson_affine(&f, ac);
                for (k, gk) in grads.iter().enumerate() {
                    assert_eq!(gk.value, values[k]);
                    // The other column of A does not enter row k.
                    assert_eq!(gk.d_a[1 - k], 0.0);
                    assert_eq!(gk.d_a[3 - k], 0.0);
                    let mut an = [0.0; 17];
                    an[..8].copy_from_slice(&gk.d_row());
                    an[8..].copy_from_slice(&gk.d_f);
                    let row = |v: &[f64; 17]| {
                        let (f, ac) = unpack(v);
                        sampson_affine(&f, &ac)[k]
                    };
                    worst = worst.max(check_gradient(&v, row, &an, "SD_A"));
                }
            }
        }
        eprintln!("worst relative gradient error: {worst:e}");
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn signed_affine_residuals_square_to_sd_a_and_their_f_gradients_match_differences() {
        let mut rng = Pcg64::seed_from_u64(15);
        for _ in 0..20 {
            let (f, acs) = perturbed(&mut rng, 10);
            for ac in &acs {
                let signed = sampson_affine_signed_grad_f(&f, ac);
                let sd = sampson_affine(&f, ac);
                for k in 0..2 {
                    let (s, g) = signed[k];
                    assert!(
                        (s * s - sd[k]).abs() <= 1e-12 * sd[k].max(1e-300),
                        "{s} {sd:?}"
                    );
                    for q in 0..9 {
                        let h = 1e-6 * f[(q / 3, q % 3)].abs().max(1e-4);
                        let (mut fp, mut fm) = (f, f);
                        fp[(q / 3, q % 3)] += h;
                        fm[(q / 3, q % 3)] -= h;
                        let fd = (sampson_affine_signed_grad_f(&fp, ac)[k].0
                            - sampson_affine_signed_grad_f(&fm, ac)[k].0)
                            / (2.0 * h);
                        let scale = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                        assert!(
                            (fd - g[q]).abs() < 1e-6 * scale,
                            "F[{q}] row {k}: {fd} vs {}",
                            g[q]
                        );
                    }
                }
            }
        }
        // A degenerate F (all zeros) gives zeros, not NaN.
        let (_, acs) = exact(&mut rng, 1);
        assert_eq!(
            sampson_affine_signed_grad_f(&Mat3::zeros(), &acs[0]),
            [(0.0, [0.0; 9]); 2]
        );
    }

    #[test]
    fn fused_point_and_affine_equal_the_separate_calls() {
        let mut rng = Pcg64::seed_from_u64(19);
        for _ in 0..10 {
            let (f, acs) = perturbed(&mut rng, 20);
            for ac in &acs {
                let (p, a) = sampson_point_affine(&f, ac);
                assert_eq!(p, sampson_point(&f, &ac.points()));
                assert_eq!(a, sampson_affine(&f, ac));
            }
        }
    }

    #[test]
    fn degenerate_denominators_give_zero_or_infinity_never_nan() {
        let ac = AffineCorrespondence {
            x1: Vec2::new(3.0, 4.0),
            x2: Vec2::new(5.0, -1.0),
            a: Mat2::new(1.0, 0.2, -0.3, 0.9),
        };
        // F = 0: residual and denominator vanish: distance 0.
        let zero = Mat3::zeros();
        assert_eq!(sampson_point(&zero, &ac.points()), 0.0);
        assert_eq!(sampson_affine(&zero, &ac), [0.0, 0.0]);
        // Only F₂₀ ≠ 0: l1 = (0, 0, x1), l2 = (1, 0, 0): D = 1 > 0 for points, but row 0 of the
        // affine constraint has G₀ = 0 with r₀ = F₂₀ = 1: +∞. Row 1 has r₁ = G₁ = 0.
        let f = Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        assert_eq!(sampson_affine(&f, &ac), [f64::INFINITY, 0.0]);
        let g = sampson_affine_grad(&f, &ac);
        assert_eq!(g[0].value, f64::INFINITY);
        assert_eq!(g[1].value, 0.0);
        for gk in &g {
            assert_eq!(gk.d_row(), [0.0; 8]);
            assert_eq!(gk.d_f, [0.0; 9]);
        }
        // Only F₂₂ ≠ 0: l1 = l2 = (0, 0, 1) in the first two entries D = 0 but e = 1: +∞.
        let f = Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        assert_eq!(sampson_point(&f, &ac.points()), f64::INFINITY);
        let g = sampson_point_grad(&f, &ac.points());
        assert_eq!(g.value, f64::INFINITY);
        assert_eq!((g.d_row(), g.d_f), ([0.0; 4], [0.0; 9]));
        // ... while its affine rows have r = G = 0.
        assert_eq!(sampson_affine(&f, &ac), [0.0, 0.0]);
    }

    #[test]
    fn batched_equals_scalar_on_both_sides_of_the_parallel_threshold() {
        let mut rng = Pcg64::seed_from_u64(15);
        for n in [0, 7, batch::PARALLEL_MIN_LEN + 5] {
            let (f, acs) = perturbed(&mut rng, n);
            let rows8: Vec<AcRow> = acs.iter().map(|a| a.to_row()).collect();
            let rows4: Vec<[f64; 4]> = rows8.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
            let mut p8 = vec![0.0; n];
            let mut p4 = vec![0.0; n];
            sampson_point_batch(&f, &rows8, &mut p8).unwrap();
            sampson_point_batch(&f, &rows4, &mut p4).unwrap();
            let mut a = vec![[0.0; 2]; n];
            sampson_affine_batch(&f, &rows8, &mut a).unwrap();
            let mut pg = vec![PointSampsonGrad::default(); n];
            sampson_point_grad_batch(&f, &rows4, &mut pg).unwrap();
            let mut ag = vec![[AffineSampsonGrad::default(); 2]; n];
            sampson_affine_grad_batch(&f, &rows8, &mut ag).unwrap();
            for (i, ac) in acs.iter().enumerate() {
                let p = sampson_point(&f, &ac.points());
                assert_eq!((p8[i], p4[i]), (p, p));
                assert_eq!(a[i], sampson_affine(&f, ac));
                assert_eq!(pg[i], sampson_point_grad(&f, &ac.points()));
                assert_eq!(ag[i], sampson_affine_grad(&f, ac));
            }
        }
    }

    #[test]
    fn column_outputs_equal_the_row_structs() {
        let mut rng = Pcg64::seed_from_u64(18);
        for n in [0, 9, batch::PARALLEL_MIN_LEN + 3] {
            let (f, acs) = perturbed(&mut rng, n);
            let rows: Vec<AcRow> = acs.iter().map(|a| a.to_row()).collect();
            let per_row: Vec<[f64; 9]> = vec![mat3_to_row(&f); n];
            let mut pg = vec![PointSampsonGrad::default(); n];
            sampson_point_grad_batch(&f, &rows, &mut pg).unwrap();
            let (mut v, mut dc, mut df) = (vec![0.0; n], vec![[1.0; 8]; n], vec![[0.0; 9]; n]);
            sampson_point_grad_columns(&per_row, &rows, &mut v, &mut dc, &mut df).unwrap();
            let mut ag = vec![[AffineSampsonGrad::default(); 2]; n];
            sampson_affine_grad_batch(&f, &rows, &mut ag).unwrap();
            let (mut av, mut adc, mut adf) = (
                vec![[0.0; 2]; n],
                vec![[[0.0; 8]; 2]; n],
                vec![[[0.0; 9]; 2]; n],
            );
            sampson_affine_grad_columns(&f, &rows, &mut av, &mut adc, &mut adf).unwrap();
            for i in 0..n {
                assert_eq!(v[i], pg[i].value);
                assert_eq!(dc[i][..4], pg[i].d_row());
                assert_eq!(dc[i][4..], [0.0; 4]);
                assert_eq!(df[i], pg[i].d_f);
                for k in 0..2 {
                    assert_eq!(av[i][k], ag[i][k].value);
                    assert_eq!(adc[i][k], ag[i][k].d_row());
                    assert_eq!(adf[i][k], ag[i][k].d_f);
                }
            }
        }
        // Errors: the first bad row whatever the thread count, and the output's name.
        let n = 3 * batch::PARALLEL_MIN_LEN;
        let mut rows = vec![[1.0, 2.0, 3.0, 4.0]; n];
        rows[n - 5][2] = f64::NAN;
        rows[batch::PARALLEL_MIN_LEN + 7][0] = f64::INFINITY;
        let f = Mat3::identity();
        let (mut v, mut dc, mut df) = (vec![0.0; n], vec![[0.0; 4]; n], vec![[0.0; 9]; n]);
        assert_eq!(
            sampson_point_grad_columns(&f, &rows, &mut v, &mut dc, &mut df),
            Err(GeomError::NonFinite {
                what: "corrs",
                index: batch::PARALLEL_MIN_LEN + 7
            })
        );
        assert_eq!(
            sampson_point_grad_columns(&f, &rows, &mut v, &mut dc[1..], &mut df),
            Err(GeomError::LengthMismatch {
                what: "d_corrs",
                expected: n,
                got: n - 1
            })
        );
    }

    #[test]
    fn per_row_f_equals_shared_f_and_mixes_pairs() {
        let mut rng = Pcg64::seed_from_u64(16);
        let (f1, acs1) = perturbed(&mut rng, 5000);
        let (f2, acs2) = perturbed(&mut rng, 3);
        let rows: Vec<AcRow> = acs1.iter().map(|a| a.to_row()).collect();
        let shared_f = vec![mat3_to_row(&f1); rows.len()];
        let mut shared = vec![[0.0; 2]; rows.len()];
        let mut per_row = vec![[0.0; 2]; rows.len()];
        sampson_affine_batch(&f1, &rows, &mut shared).unwrap();
        sampson_affine_batch(&shared_f, &rows, &mut per_row).unwrap();
        assert_eq!(shared, per_row);
        let mut gs = vec![PointSampsonGrad::default(); rows.len()];
        let mut gp = vec![PointSampsonGrad::default(); rows.len()];
        sampson_point_grad_batch(&f1, &rows, &mut gs).unwrap();
        sampson_point_grad_batch(&shared_f, &rows, &mut gp).unwrap();
        assert_eq!(gs, gp);
        // Two image pairs in one batch.
        let mixed: Vec<AcRow> = acs1[..3].iter().chain(&acs2).map(|a| a.to_row()).collect();
        let fs: Vec<[f64; 9]> = [f1; 3].iter().chain(&[f2; 3]).map(mat3_to_row).collect();
        let mut out = vec![[0.0; 2]; 6];
        sampson_affine_batch(&fs, &mixed, &mut out).unwrap();
        let mut ag = vec![[AffineSampsonGrad::default(); 2]; 6];
        sampson_affine_grad_batch(&fs, &mixed, &mut ag).unwrap();
        for i in 0..6 {
            let f = if i < 3 { f1 } else { f2 };
            let ac = AffineCorrespondence::from_row(&mixed[i]);
            assert_eq!(out[i], sampson_affine(&f, &ac));
            assert_eq!(ag[i], sampson_affine_grad(&f, &ac));
        }
    }

    #[test]
    fn batched_forms_report_bad_inputs_by_name_and_row() {
        let f = Mat3::identity();
        let rows = [[1.0, 2.0, 3.0, 4.0, 1.0, 0.0, 0.0, 1.0]; 3];
        let mut out = [0.0; 3];
        let mut out2 = [[0.0; 2]; 3];
        let mut bad = rows;
        bad[2][6] = f64::NAN;
        // A is ignored (and unchecked) by the point distance, but not by the affine one.
        assert!(sampson_point_batch(&f, &bad, &mut out).is_ok());
        assert_eq!(
            sampson_affine_batch(&f, &bad, &mut out2),
            Err(GeomError::NonFinite {
                what: "corrs",
                index: 2
            })
        );
        bad[1][1] = f64::INFINITY;
        assert_eq!(
            sampson_point_batch(&f, &bad, &mut out),
            Err(GeomError::NonFinite {
                what: "corrs",
                index: 1
            })
        );
        let nan_f = Mat3::from_element(f64::NAN);
        assert_eq!(
            sampson_point_batch(&nan_f, &rows, &mut out),
            Err(GeomError::NonFinite {
                what: "F",
                index: 0
            })
        );
        let mut fs = vec![mat3_to_row(&f); 3];
        fs[1][4] = f64::NEG_INFINITY;
        assert_eq!(
            sampson_affine_batch(&fs, &rows, &mut out2),
            Err(GeomError::NonFinite {
                what: "F",
                index: 1
            })
        );
        assert_eq!(
            sampson_affine_batch(&fs[..2], &rows, &mut out2),
            Err(GeomError::LengthMismatch {
                what: "F",
                expected: 3,
                got: 2
            })
        );
        assert_eq!(
            sampson_point_batch(&f, &rows, &mut out[..2]),
            Err(GeomError::LengthMismatch {
                what: "out",
                expected: 3,
                got: 2
            })
        );
    }

    fn arb_perturbed() -> impl Strategy<Value = (Mat3, AffineCorrespondence)> {
        (any::<u64>(), 0.1f64..3.0).prop_map(|(seed, noise)| {
            let mut rng = Pcg64::seed_from_u64(seed);
            let (f, mut acs) = exact(&mut rng, 1);
            let ac = &mut acs[0];
            ac.x2 += Vec2::new(noise, -0.5 * noise);
            ac.a += Mat2::new(0.02, -0.03, 0.01, 0.04) * noise;
            (f, acs[0])
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Degree-0 homogeneity in F: ⟨F, ∂SD/∂F⟩ = 0, and the value does not move with λ.
        #[test]
        fn gradient_in_f_is_orthogonal_to_f((f, ac) in arb_perturbed(), lambda in -50.0f64..50.0) {
            prop_assume!(lambda.abs() > 1e-3);
            let fr = mat3_to_row(&f);
            let dot = |d: &[f64; 9], scale: f64| {
                d.iter().zip(&fr).map(|(a, b)| a * b).sum::<f64>()
                    / (scale * d.iter().map(|x| x * x).sum::<f64>().sqrt())
            };
            let g = sampson_point_grad(&f, &ac.points());
            prop_assert!(dot(&g.d_f, 1.0).abs() < 1e-9);
            let gl = sampson_point_grad(&(f * lambda), &ac.points());
            // Roundoff: F scaled by λ up to 50 changes the rounding of every product.
            prop_assert!((gl.value - g.value).abs() < 1e-9 * g.value + 1e-12);
            for gk in sampson_affine_grad(&f, &ac) {
                prop_assert!(gk.value > 0.0);
                prop_assert!(dot(&gk.d_f, 1.0).abs() < 1e-9);
            }
        }

        /// Swapping the images (x1 ↔ x2, F ↔ Fᵀ) leaves SD_P unchanged.
        #[test]
        fn swapping_the_images_is_a_symmetry((f, ac) in arb_perturbed()) {
            let swapped = PointCorrespondence { x1: ac.x2, x2: ac.x1 };
            let (p, q) = (sampson_point(&f, &ac.points()), sampson_point(&f.transpose(), &swapped));
            prop_assert!((p - q).abs() < 1e-10 * p.max(q) + 1e-14, "{} {}", p, q);
        }
    }

    #[test]
    fn swapped_exact_correspondences_stay_exact() {
        let mut rng = Pcg64::seed_from_u64(17);
        let (f, acs) = exact(&mut rng, 50);
        for ac in &acs {
            let back = AffineCorrespondence {
                x1: ac.x2,
                x2: ac.x1,
                a: ac.a.try_inverse().unwrap(),
            };
            let [a0, a1] = sampson_affine(&f.transpose(), &back);
            assert!(a0 < 1e-12 && a1 < 1e-12);
        }
    }
}
