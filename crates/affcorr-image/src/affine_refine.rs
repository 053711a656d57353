//! Photometric refinement of affine correspondences: affine Lucas–Kanade, coarse to fine.
//!
//! The shape network's A is a good start but a coarse one (its orientation and scale come from
//! bins, and one 32×32 patch per image). Given the two images, the local affine map can be
//! measured directly: the window of image A around x1 is matched to image B around x2 under the
//! affine warp W(d) = x2 + t + A d, d ∈ {−R, …, R}² pixels of image A, with a gain α and a bias
//! β between the images (Lucas & Kanade 1981):
//!
//! ```text
//! min over (t, A, α, β) of  Σ_d w(d) [I_B(x2 + t + A d) − α T(d) − β]²,   T(d) = I_A(x1 + d),
//! ```
//!
//! `w` a Gaussian of σ = R/2 that fades the window's edge.
//!
//! # Inverse compositional, gain and bias projected out
//!
//! Baker & Matthews ("Lucas-Kanade 20 years on", IJCV 2004, and its part 3 on linear
//! appearance variation): the step Δp = (Δt, ΔA) is taken on the template side,
//! T(W₀(d; Δp)) with W₀(d) = d + Δt + ΔA d, so the Jacobian, the steepest-descent images
//!
//! ```text
//! SD(d) = ∇T(d)ᵀ ∂W₀/∂Δp = [Tₓ, T_y, Tₓ dₓ, Tₓ d_y, T_y dₓ, T_y d_y]     (A row-major)
//! ```
//!
//! and the 6×6 Gauss–Newton matrix are fixed per level. Gain and bias are removed by
//! projecting the SD images onto the w-orthogonal complement of span{1, T} (SD⊥). With
//! g(d) = I_B(W(d)) and α = ⟨g, T − T̄⟩_w / ‖T − T̄‖²_w (the regression of g on T), each
//! iteration is one sample of image B per pixel and
//!
//! ```text
//! Δp = H⁻¹ Σ_d w SD⊥(d) g(d)/α,   H = Σ_d w SD⊥ SD⊥ᵀ,
//! ```
//!
//! (the T and constant parts of g/α − T drop out against SD⊥), then the composition
//! W ← W ∘ W₀⁻¹: with M = (I + ΔA)⁻¹, A ← A M and t ← t − A M Δt.
//!
//! The iterations run on Gaussian-blurred copies of both images, the most blurred first,
//! which widens the basin of convergence (an error ε in A moves the window's edge by ε·R px);
//! levels blurred by σ ≥ 0.7 px use every other grid pixel. Each step is capped so that the
//! window's edge moves by at most R/4, and a step that lowers the ZNCC is halved from the best
//! warp so far (up to 4 times).
//!
//! A result is kept only when it is plausible: finite, det A > 0, α > 0, the translation t
//! within R/2, its weighted zero-mean normalised cross-correlation (ZNCC) at the finest
//! level both higher than the input's and at least [`AffineRefineOptions::min_zncc`], and t
//! well determined: the worst-direction standard deviation of t from σ² H⁻¹ at the finest level
//! (`Window::uncertainty`) at most [`AffineRefineOptions::max_shift_std`], which refuses windows
//! on a lone edge, where a shift along it fits as well (the aperture problem). Otherwise the
//! input AC comes back unchanged (textureless or occluded windows, repetitive texture), with a
//! [`RefineStatus`] that says which check failed, and a low `affine_confidence`: a returned
//! input is never passed off as a refined AC ([`crate::confidence`]).
//!
//! Known limit: a window can fit a quite different (t, A) about as well as the true one, and
//! then the fit is well determined around the wrong optimum; no check here sees it
//! (docs/shape_network.md, "Known limit").

use nalgebra::{Matrix2, SMatrix, SVector};
use rayon::prelude::*;
use std::f64::consts::{PI, TAU};

use crate::error::{ImageError, Result};
use crate::gray::GrayImage;

type Mat6 = SMatrix<f64, 6, 6>;
type Vec6 = SVector<f64, 6>;

/// Options of [`refine_affine`].
#[derive(Debug, Clone, PartialEq)]
pub struct AffineRefineOptions {
    /// Half-width R of the square window in image A, pixels. Default 16 (a 33×33 window):
    /// on graffiti 1→3 the median ‖A − A_gt‖_F at SIFT's matches is 0.045 at R = 12 and 0.027
    /// at R = 16 (benches/results/shape_accuracy.md).
    pub radius: usize,
    /// Gaussian blur σ of each level, pixels, coarse to fine (0 = the image as it is). Default
    /// [3, 1.5, 0.75].
    pub blur_sigmas: Vec<f64>,
    /// Most Gauss–Newton iterations per level. Default 6.
    pub iterations: usize,
    /// Least ZNCC of an accepted result, in [−1, 1]. Default 0.8.
    pub min_zncc: f64,
    /// Whether x2 moves to x2 + t as well. Default true: A and t are fitted together, and the
    /// refined x2 is the one the refined A belongs to (with x2 held fixed, a match a pixel
    /// off cannot be fitted: on graffiti with 2 px noise 33% of the ACs pass instead of 81%).
    pub move_points: bool,
    /// Whether to start from A = I instead of the input's A where the identity matches better
    /// at the coarsest level (one extra correlation per AC). Default true: most image pairs
    /// are roughly upright, and there the identity is often the better start: on a 10 px grid
    /// of graffiti 1→3 with 2 px keypoint noise it raises the share of refined ACs from 67%
    /// to 78% (docs/shape_network.md).
    pub try_identity: bool,
    /// Whether to start from the similarity that the AC's nearest ACs' displacements agree on
    /// ([`neighbourhood_similarities`]) where it matches better at the coarsest level than the
    /// input's A and the identity (one extra correlation per AC). Default true: the shape
    /// network's scale is poor beyond about 1.5× zoom (its median error is 0.37 octave), and
    /// from a start that far off the refinement converges for only some of the ACs; the
    /// points' displacements say the scale and rotation of a neighbourhood whatever the zoom.
    pub try_neighbours: bool,
    /// Largest accepted standard deviation of the fitted translation, pixels of image B (the
    /// worst direction of its covariance, see the module docs). Default 0.5. Along a lone edge
    /// the window matches about equally well anywhere (the aperture problem); this check
    /// refuses such fits.
    pub max_shift_std: f64,
}

impl Default for AffineRefineOptions {
    fn default() -> Self {
        Self {
            radius: 16,
            blur_sigmas: vec![3.0, 1.5, 0.75],
            iterations: 6,
            min_zncc: 0.8,
            move_points: true,
            try_identity: true,
            try_neighbours: true,
            max_shift_std: 0.5,
        }
    }
}

impl AffineRefineOptions {
    fn validate(&self) -> Result<()> {
        if !(1..=64).contains(&self.radius) {
            return Err(ImageError::invalid(
                "radius",
                format!("must be in 1..=64 pixels, got {}", self.radius),
            ));
        }
        if self.blur_sigmas.is_empty()
            || self
                .blur_sigmas
                .iter()
                .any(|s| !(s.is_finite() && (0.0..=16.0).contains(s)))
        {
            return Err(ImageError::invalid(
                "blur_sigmas",
                format!(
                    "must be a non-empty list of σ in [0, 16] pixels, got {:?}",
                    self.blur_sigmas
                ),
            ));
        }
        if self.iterations == 0 {
            return Err(ImageError::invalid("iterations", "must be at least 1"));
        }
        if !(self.max_shift_std > 0.0) {
            return Err(ImageError::invalid(
                "max_shift_std",
                format!("must be positive pixels, got {}", self.max_shift_std),
            ));
        }
        if !(-1.0..=1.0).contains(&self.min_zncc) {
            return Err(ImageError::invalid(
                "min_zncc",
                format!("must be in [-1, 1], got {}", self.min_zncc),
            ));
        }
        Ok(())
    }
}

/// What became of one AC in [`refine_affine`]: refined, or why the input came back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum RefineStatus {
    /// The fit converged and passed every check of the module docs: the row is the result.
    #[default]
    Refined,
    /// The window of image A is flat at the finest level (no texture to fit).
    Flat,
    /// The fit left the plausible set: not finite, det A ≤ 0, or the shift over R/2.
    Diverged,
    /// The fit's ZNCC is below [`AffineRefineOptions::min_zncc`].
    LowZncc,
    /// The fit's ZNCC does not beat the input's.
    NotImproved,
    /// The shift is ill-determined (over [`AffineRefineOptions::max_shift_std`]): a lone edge.
    Aperture,
}

impl RefineStatus {
    /// Every status, in the order of [`RefineStatus::code`].
    pub const ALL: [RefineStatus; 6] = [
        Self::Refined,
        Self::Flat,
        Self::Diverged,
        Self::LowZncc,
        Self::NotImproved,
        Self::Aperture,
    ];

    /// A stable small integer (0 = refined), the index in [`RefineStatus::ALL`].
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The name used by the Python API: `"refined"`, `"flat"`, `"diverged"`, `"low_zncc"`,
    /// `"not_improved"`, `"aperture"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Refined => "refined",
            Self::Flat => "flat",
            Self::Diverged => "diverged",
            Self::LowZncc => "low_zncc",
            Self::NotImproved => "not_improved",
            Self::Aperture => "aperture",
        }
    }
}

/// The result of [`refine_affine`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AffineRefinement {
    /// `[x1, y1, x2, y2, a11, a12, a21, a22]` per AC: refined where `refined[i]`, else the input.
    pub corrs: Vec<[f64; 8]>,
    /// Whether AC i was refined (its result passed the checks of the module docs):
    /// `status[i] == RefineStatus::Refined`.
    pub refined: Vec<bool>,
    /// What became of each AC; a rejected one says why.
    pub status: Vec<RefineStatus>,
    /// The weighted ZNCC of each returned AC at the finest level (NaN for a flat window).
    pub zncc: Vec<f64>,
    /// The standard deviation of the returned AC's translation from the Gauss–Newton
    /// covariance σ² H⁻¹ at the finest level, pixels of image B, worst direction (+∞ for a
    /// flat window or a ZNCC ≤ 0).
    pub shift_std: Vec<f64>,
    /// The expected ‖δA‖_F of the returned AC's A from the same covariance (its 4×4 affine
    /// block, mapped through A; +∞ where `shift_std` is).
    pub affine_std: Vec<f64>,
    /// The calibrated probability that each returned A is good (cosine with the true A ≥ 0.9;
    /// [`crate::confidence`]), from the refinement's outcome and the neighbouring ACs.
    pub affine_confidence: Vec<f64>,
    /// `affine_confidence ≥` the calibrated threshold ([`crate::confidence`]).
    pub reliable: Vec<bool>,
}

/// Refines the affine maps (and, with `move_points`, x2) of `corrs` against the images; see
/// the module docs.
///
/// Errors: a non-finite row (naming it), an A with det ≤ 0, or bad options (naming the option).
pub fn refine_affine(
    image_a: &GrayImage,
    image_b: &GrayImage,
    corrs: &[[f64; 8]],
    options: &AffineRefineOptions,
) -> Result<AffineRefinement> {
    options.validate()?;
    if let Some(row) = corrs.iter().position(|c| c.iter().any(|v| !v.is_finite())) {
        return Err(ImageError::NonFinite { what: "corrs", row });
    }
    if let Some(row) = corrs.iter().position(|c| c[4] * c[7] - c[5] * c[6] <= 0.0) {
        return Err(ImageError::invalid(
            "corrs",
            format!("row {row}: the affine map has det A <= 0"),
        ));
    }
    let levels: Vec<Level> = options
        .blur_sigmas
        .iter()
        .map(|&sigma| Level::new(image_a, image_b, sigma, options.radius))
        .collect();
    let starts = if options.try_neighbours {
        neighbourhood_similarities(corrs)
    } else {
        vec![None; corrs.len()]
    };
    let results: Vec<OneResult> = corrs
        .par_iter()
        .zip(&starts)
        .with_min_len(16)
        .map_init(Window::default, |window, (c, start)| {
            refine_one(c, start.as_ref(), &levels, options, window)
        })
        .collect();
    let mut out = AffineRefinement::default();
    for r in results {
        out.refined.push(r.status == RefineStatus::Refined);
        out.status.push(r.status);
        out.corrs.push(r.corr);
        out.zncc.push(r.zncc);
        out.shift_std.push(r.shift_std);
        out.affine_std.push(r.affine_std);
    }
    let conf = crate::confidence::affine_confidence(&out.corrs, None, Some(&out))?;
    out.affine_confidence = conf.confidence;
    out.reliable = conf.reliable;
    Ok(out)
}

/// The nearest ACs (in image A) whose displacements give an AC's neighbourhood start.
const START_NEIGHBOURS: usize = 8;

/// Per AC, the similarity s·R(θ) (row-major) that its neighbourhood's displacements agree on,
/// or `None`: over the 8 nearest ACs in image A that lie 2 px or more away,
/// s is the median of |x2_j − x2_i| / |x1_j − x1_i| and θ the circular median of the angle
/// from x1_j − x1_i to x2_j − x2_i; `None` with fewer than 3 such neighbours. Medians, so that
/// wrong matches among fewer than half of the neighbours do not move it. On a plane seen
/// under an affine map D every displacement is D (x1_j − x1_i): s and θ are D's scale and
/// rotation up to its anisotropy, which the refinement then fits.
pub fn neighbourhood_similarities(corrs: &[[f64; 8]]) -> Vec<Option<[f64; 4]>> {
    let points: Vec<[f64; 2]> = corrs.iter().map(|c| [c[0], c[1]]).collect();
    let knn = crate::confidence::nearest_neighbours(&points, START_NEIGHBOURS);
    corrs
        .iter()
        .zip(&knn)
        .map(|(c, nb)| {
            let (mut log_scale, mut angle) = (Vec::new(), Vec::new());
            for &j in nb {
                let d1 = [corrs[j][0] - c[0], corrs[j][1] - c[1]];
                let d2 = [corrs[j][2] - c[2], corrs[j][3] - c[3]];
                let (n1, n2) = (d1[0].hypot(d1[1]), d2[0].hypot(d2[1]));
                if n1 < 2.0 || n2 <= 0.0 {
                    continue;
                }
                log_scale.push((n2 / n1).ln());
                angle.push((d1[0] * d2[1] - d1[1] * d2[0]).atan2(d1[0] * d2[0] + d1[1] * d2[1]));
            }
            if log_scale.len() < 3 {
                return None;
            }
            log_scale.sort_by(f64::total_cmp);
            let s = log_scale[log_scale.len() / 2].exp();
            // The angle with the least summed distance to the others (wrapped to ±π).
            let spread = |a: f64| {
                angle
                    .iter()
                    .map(|b| (a - b + PI).rem_euclid(TAU) - PI)
                    .map(f64::abs)
                    .sum::<f64>()
            };
            let theta = angle
                .iter()
                .copied()
                .min_by(|a, b| spread(*a).total_cmp(&spread(*b)))?;
            let (sin, cos) = theta.sin_cos();
            Some([s * cos, -s * sin, s * sin, s * cos])
        })
        .collect()
}

/// One AC's outcome in [`refine_one`].
struct OneResult {
    status: RefineStatus,
    corr: [f64; 8],
    zncc: f64,
    shift_std: f64,
    affine_std: f64,
}

/// A blurred image, optionally interleaved with its gradient.
struct Plane<const C: usize> {
    /// `[I, ∂I/∂x, ∂I/∂y]` (C = 3) or `[I]` (C = 1) per pixel.
    data: Vec<[f32; C]>,
    width: usize,
    height: usize,
}

impl<const C: usize> Plane<C> {
    fn new(image: &GrayImage, sigma: f64) -> Self {
        let (w, h) = (image.width(), image.height());
        let blurred = gaussian_blur(image, sigma);
        let mut data = vec![[0.0f32; C]; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
            let row = &blurred[y * w..][..w];
            if C == 1 {
                out.iter_mut().zip(row).for_each(|(o, &v)| o[0] = v);
                return;
            }
            // Central differences, one-sided at the border: (next − previous) / their distance.
            // The interior and the two end columns apart, so that the inner loop has no
            // clamping (the same values as the clamped formula everywhere).
            let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let (up, down) = (&blurred[yu * w..][..w], &blurred[yd * w..][..w]);
            let dy = (yd - yu).max(1) as f32;
            for (((o, &v), &u), &d) in out.iter_mut().zip(row).zip(up).zip(down) {
                o[0] = v;
                o[2] = (d - u) / dy;
            }
            if w == 1 {
                out[0][1] = 0.0;
                return;
            }
            let inner = out[1..w - 1].iter_mut().zip(&row[..w - 2]).zip(&row[2..]);
            for ((o, &left), &right) in inner {
                o[1] = (right - left) / 2.0;
            }
            out[0][1] = row[1] - row[0];
            out[w - 1][1] = row[w - 1] - row[w - 2];
        });
        Self {
            data,
            width: w,
            height: h,
        }
    }

    /// Bilinear read at (x, y), border replicated.
    #[inline(always)]
    fn sample(&self, x: f64, y: f64) -> [f64; C] {
        let (x0, x1, fx) = axis(x, self.width);
        let (y0, y1, fy) = axis(y, self.height);
        let w = self.width;
        let (p00, p01) = (self.data[y0 * w + x0], self.data[y0 * w + x1]);
        let (p10, p11) = (self.data[y1 * w + x0], self.data[y1 * w + x1]);
        std::array::from_fn(|k| {
            let top = (1.0 - fx) * p00[k] as f64 + fx * p01[k] as f64;
            let bottom = (1.0 - fx) * p10[k] as f64 + fx * p11[k] as f64;
            (1.0 - fy) * top + fy * bottom
        })
    }

    /// [`Plane::sample`] for a point known to lie in [0, W − 2] × [0, H − 2], where no read
    /// needs clamping (the same arithmetic, so the same values).
    #[inline(always)]
    fn sample_inside(&self, x: f64, y: f64) -> [f64; C] {
        // x, y ≥ 0 here, so truncation is the floor. `f64::floor` is a libm call on baseline
        // x86-64 (no SSE4.1 `roundsd`) and a saturating cast to usize is a branchy sequence:
        // together they were 30% of the refinement's instructions (callgrind, graffiti 1→3).
        let (xi, yi) = (x as i32, y as i32);
        let (fx, fy) = (x - f64::from(xi), y - f64::from(yi));
        let i = yi as usize * self.width + xi as usize;
        let (top, bottom) = (&self.data[i..i + 2], &self.data[i + self.width..][..2]);
        let (p00, p01, p10, p11) = (top[0], top[1], bottom[0], bottom[1]);
        std::array::from_fn(|k| {
            let top = (1.0 - fx) * p00[k] as f64 + fx * p01[k] as f64;
            let bottom = (1.0 - fx) * p10[k] as f64 + fx * p11[k] as f64;
            (1.0 - fy) * top + fy * bottom
        })
    }

    /// Whether the window `origin + A·[−r, r]²` lies inside [0, W − 2] × [0, H − 2].
    fn contains(&self, origin: [f64; 2], a: &[f64; 4], r: f64) -> bool {
        let (ex, ey) = ((a[0].abs() + a[1].abs()) * r, (a[2].abs() + a[3].abs()) * r);
        origin[0] - ex >= 0.0
            && origin[1] - ey >= 0.0
            && origin[0] + ex <= (self.width as f64 - 2.0)
            && origin[1] + ey <= (self.height as f64 - 2.0)
    }
}

/// One level of the pyramid: image A with its gradient (the template side), image B.
struct Level {
    a: Plane<3>,
    b: Plane<1>,
    /// R: the grid's offsets lie in [−R, R]².
    radius: f64,
    /// The window's offsets and weights at this level's stride.
    grid: Vec<([f64; 2], f64)>,
}

impl Level {
    fn new(image_a: &GrayImage, image_b: &GrayImage, sigma: f64, radius: usize) -> Self {
        // After a blur of σ ≥ 0.7 px neighbouring pixels say nearly the same: on graffiti 1→3
        // every pixel at σ = 0.75 refined as many ACs as every other one (69%), as accurately,
        // at twice the cost.
        let stride = if sigma >= 0.7 { 2 } else { 1 };
        let r = radius as i64;
        let spread = 2.0 * (radius as f64 / 2.0).powi(2);
        let grid = (-r..=r)
            .step_by(stride)
            .flat_map(|dy| {
                (-r..=r)
                    .step_by(stride)
                    .map(move |dx| (dx as f64, dy as f64))
            })
            .map(|(dx, dy)| ([dx, dy], (-(dx * dx + dy * dy) / spread).exp()))
            .collect();
        Self {
            a: Plane::new(image_a, sigma),
            b: Plane::new(image_b, sigma),
            radius: radius as f64,
            grid,
        }
    }
}

/// Per-AC buffers of one level, reused across ACs (one per rayon job).
#[derive(Default)]
struct Window {
    /// w·(T − T̄) per grid pixel.
    centred: Vec<f64>,
    /// w·SD⊥ per grid pixel.
    sd: Vec<[f64; 6]>,
    /// ‖T − T̄‖²_w.
    norm_sq: f64,
    /// Σ w.
    weight: f64,
}

impl Window {
    /// The template of `level` at `x1`: its centred values and projected SD images; the
    /// Cholesky factor of H, or `None` for a flat window.
    fn prepare(
        &mut self,
        level: &Level,
        x1: [f64; 2],
    ) -> Option<nalgebra::Cholesky<f64, nalgebra::U6>> {
        let n = level.grid.len();
        self.centred.clear();
        self.sd.clear();
        let (mut sw, mut st) = (0.0, 0.0);
        let inside = level.a.contains(x1, &[1.0, 0.0, 0.0, 1.0], level.radius);
        for (d, w) in &level.grid {
            let (x, y) = (x1[0] + d[0], x1[1] + d[1]);
            let [t, tx, ty] = if inside {
                level.a.sample_inside(x, y)
            } else {
                level.a.sample(x, y)
            };
            sw += w;
            st += w * t;
            self.centred.push(t);
            self.sd
                .push([tx, ty, tx * d[0], tx * d[1], ty * d[0], ty * d[1]]);
        }
        let mean = st / sw;
        let mut norm_sq = 0.0;
        for (c, (_, w)) in self.centred.iter_mut().zip(&level.grid) {
            *c -= mean;
            norm_sq += w * *c * *c;
        }
        if !(norm_sq > 1e-12 * sw) {
            return None;
        }
        // Project out span{1, T − T̄} (w-orthogonal to each other).
        let (mut m1, mut mt) = ([0.0; 6], [0.0; 6]);
        for ((sd, c), (_, w)) in self.sd.iter().zip(&self.centred).zip(&level.grid) {
            for k in 0..6 {
                m1[k] += w * sd[k];
                mt[k] += w * sd[k] * c;
            }
        }
        let mut h = Mat6::zeros();
        for ((sd, c), (_, w)) in self.sd.iter_mut().zip(&self.centred).zip(&level.grid) {
            for k in 0..6 {
                sd[k] -= m1[k] / sw + mt[k] / norm_sq * c;
            }
            for p in 0..6 {
                for q in p..6 {
                    h[(p, q)] += w * sd[p] * sd[q];
                }
            }
            for v in sd.iter_mut() {
                *v *= w;
            }
        }
        for (c, (_, w)) in self.centred.iter_mut().zip(&level.grid) {
            *c *= w;
        }
        debug_assert_eq!(self.sd.len(), n);
        self.norm_sq = norm_sq;
        self.weight = sw;
        h.fill_lower_triangle_with_upper_triangle();
        h.cholesky()
    }

    /// Samples image B under (origin, A) and returns (Σ w SD⊥ g, ⟨g, T − T̄⟩_w, Σ w g, Σ w g²).
    fn correlate(
        &self,
        level: &Level,
        origin: [f64; 2],
        a: &[f64; 4],
    ) -> ([f64; 6], f64, f64, f64) {
        // The loop twice, so that the common case (the window inside image B) reads without
        // clamping.
        if level.b.contains(origin, a, level.radius) {
            self.accumulate(level, origin, a, |u, v| level.b.sample_inside(u, v)[0])
        } else {
            self.accumulate(level, origin, a, |u, v| level.b.sample(u, v)[0])
        }
    }

    #[inline(always)]
    fn accumulate(
        &self,
        level: &Level,
        origin: [f64; 2],
        a: &[f64; 4],
        sample: impl Fn(f64, f64) -> f64,
    ) -> ([f64; 6], f64, f64, f64) {
        let (mut sdg, mut tg, mut sg, mut gg) = ([0.0; 6], 0.0, 0.0, 0.0);
        for (((d, w), sd), c) in level.grid.iter().zip(&self.sd).zip(&self.centred) {
            let (u, v) = warp(origin, a, d);
            let g = sample(u, v);
            for k in 0..6 {
                sdg[k] += sd[k] * g;
            }
            tg += c * g;
            sg += w * g;
            gg += w * g * g;
        }
        (sdg, tg, sg, gg)
    }

    /// The standard deviation (pixels of image B, worst direction) of the translation fitted
    /// with this template's Gauss–Newton matrix `h` at the warp's linear part `a` and ZNCC `z`,
    /// and the expected ‖δA‖_F of its linear part.
    ///
    /// Cov(Δp) ≈ σ² H⁻¹, with σ² the weighted mean squared residual in template units: the
    /// regression of g on T leaves ‖g − ḡ‖²_w (1 − z²), and α = z ‖g − ḡ‖_w / ‖T − T̄‖_w, so
    /// ‖T − T̄‖²_w (1 − z²) / z² after the division by α; floored at (1/256)², an 8-bit image's
    /// quantisation, so that a noiseless edge is still found ill-posed. The translation block
    /// of H⁻¹ is the marginal covariance of Δt given the shape; image B's translation is A Δt.
    /// The linear part composes as A (I + ΔA)⁻¹ ≈ A − A ΔA, so E‖δA‖²_F = E‖A ΔA‖²_F, taken
    /// as ‖A‖²_F / 2 · tr Cov(ΔA) (exact when A is a similarity).
    fn uncertainty(
        &self,
        h: &nalgebra::Cholesky<f64, nalgebra::U6>,
        a: &Matrix2<f64>,
        z: f64,
    ) -> (f64, f64) {
        if !(z > 0.0) {
            return (f64::INFINITY, f64::INFINITY);
        }
        let residual = self.norm_sq * (1.0 - z * z).max(0.0) / (z * z) / self.weight;
        let sigma_sq = residual.max(1.0 / (256.0 * 256.0));
        let inv = h.inverse();
        let c = inv.fixed_view::<2, 2>(0, 0) * sigma_sq;
        let cov = a * c * a.transpose();
        // Largest eigenvalue of the symmetric 2×2 matrix.
        let (p, q, r) = (cov[(0, 0)], cov[(0, 1)], cov[(1, 1)]);
        let lambda = 0.5 * (p + r) + (0.25 * (p - r) * (p - r) + q * q).sqrt();
        let trace_a = (2..6).map(|k| inv[(k, k)]).sum::<f64>() * sigma_sq;
        let affine = (a.norm_squared() / 2.0 * trace_a.max(0.0)).sqrt();
        (lambda.max(0.0).sqrt(), affine)
    }

    /// The weighted ZNCC from [`Window::correlate`]'s sums.
    fn zncc(&self, tg: f64, sg: f64, gg: f64) -> f64 {
        let var_g = gg - sg * sg / self.weight;
        tg / (self.norm_sq * var_g).sqrt()
    }
}

#[inline(always)]
fn warp(origin: [f64; 2], a: &[f64; 4], d: &[f64; 2]) -> (f64, f64) {
    (
        origin[0] + a[0] * d[0] + a[1] * d[1],
        origin[1] + a[2] * d[0] + a[3] * d[1],
    )
}

/// The two neighbours along an axis of `len` pixels and the weight of the second, for `u`
/// clamped to [0, len − 1].
#[inline(always)]
fn axis(u: f64, len: usize) -> (usize, usize, f64) {
    let max = (len - 1) as f64;
    let u = u.clamp(0.0, max);
    // u ≥ 0: truncation is the floor (see `Plane::sample_inside`).
    let f = f64::from(u as i32);
    let i0 = f as usize;
    let i1 = if f < max { i0 + 1 } else { i0 };
    (i0, i1, u - f)
}

/// A 2×2 matrix as `[a11, a12, a21, a22]`.
fn row_major(a: &Matrix2<f64>) -> [f64; 4] {
    [a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]]
}

/// The warp (A, t) composed with the inverse of the step W₀(d) = d + Δt + ΔA d (module docs);
/// `None` when I + ΔA is singular.
fn compose(a: &Matrix2<f64>, t: &[f64; 2], dp: &Vec6) -> Option<(Matrix2<f64>, [f64; 2])> {
    let m = Matrix2::new(1.0 + dp[2], dp[3], dp[4], 1.0 + dp[5]).try_inverse()?;
    let a = a * m;
    let dt = a * nalgebra::Vector2::new(dp[0], dp[1]);
    Some((a, [t[0] - dt[0], t[1] - dt[1]]))
}

/// The iterations on one AC over all levels, then the acceptance checks.
fn refine_one(
    c: &[f64; 8],
    neighbourhood: Option<&[f64; 4]>,
    levels: &[Level],
    options: &AffineRefineOptions,
    window: &mut Window,
) -> OneResult {
    let x1 = [c[0], c[1]];
    let x2 = [c[2], c[3]];
    let a0 = [c[4], c[5], c[6], c[7]];
    let (mut a, mut t) = (Matrix2::new(a0[0], a0[1], a0[2], a0[3]), [0.0, 0.0]);
    let radius = options.radius as f64;
    // The finest level's Gauss–Newton matrix; `None` when that window is flat.
    let mut h_finest = None;
    for (l, level) in levels.iter().enumerate() {
        let Some(h) = window.prepare(level, x1) else {
            continue;
        };
        if l + 1 == levels.len() {
            h_finest = Some(h);
        }
        if l == 0 {
            // Start from A = I or the neighbourhood's similarity instead when it matches better
            // at the coarsest level.
            let z = |m: &[f64; 4]| {
                let (_, tg, sg, gg) = window.correlate(level, x2, m);
                window.zncc(tg, sg, gg)
            };
            let identity = [1.0, 0.0, 0.0, 1.0];
            let others = [options.try_identity.then_some(&identity), neighbourhood];
            let mut best = z(&a0);
            for m in others.into_iter().flatten() {
                let zm = z(m);
                if zm > best {
                    (best, a) = (zm, Matrix2::new(m[0], m[1], m[2], m[3]));
                }
            }
        }
        // The best-matching warp of this level so far, its ZNCC and the step planned from it.
        let mut best: Option<(Matrix2<f64>, [f64; 2], f64, Vec6)> = None;
        let (mut a_try, mut t_try, mut scale) = (a, t, 1.0);
        // `iterations` steps, and one more evaluation to judge the last.
        for _ in 0..=options.iterations {
            let origin = [x2[0] + t_try[0], x2[1] + t_try[1]];
            let (sdg, tg, sg, gg) = window.correlate(level, origin, &row_major(&a_try));
            let z = window.zncc(tg, sg, gg);
            if best.as_ref().is_none_or(|b| z > b.2) {
                let alpha = tg / window.norm_sq;
                if !(alpha > 0.0) {
                    break;
                }
                let mut dp = h.solve(&Vec6::from_column_slice(&sdg)) / alpha;
                // How far the step moves the window's edge, capped at R/4 (a trust region:
                // far from the optimum the linearisation overshoots).
                let shape = (2..6).map(|k| dp[k].abs()).fold(0.0, f64::max);
                let reach = dp[0].abs().max(dp[1].abs()).max(shape * radius);
                if reach > radius / 4.0 {
                    dp *= radius / 4.0 / reach;
                }
                best = Some((a_try, t_try, z, dp));
                scale = 1.0;
                // Converged: the edge moves by less than 0.01 px.
                if reach < 0.01 {
                    break;
                }
            } else {
                // The step made the match worse: half of it, from the best warp.
                scale *= 0.5;
                if scale < 1.0 / 16.0 {
                    break;
                }
            }
            let (a_best, t_best, _, dp) = best.as_ref().expect("set above");
            let Some((a_next, t_next)) = compose(a_best, t_best, &(dp * scale)) else {
                break;
            };
            (a_try, t_try) = (a_next, t_next);
        }
        if let Some((a_best, t_best, _, _)) = best {
            (a, t) = (a_best, t_best);
        }
    }
    // Judged at the finest level, which the window still holds from the last pass of the
    // loop: the input, then the result.
    let Some(h) = h_finest else {
        return OneResult {
            status: RefineStatus::Flat,
            corr: *c,
            zncc: f64::NAN,
            shift_std: f64::INFINITY,
            affine_std: f64::INFINITY,
        };
    };
    let finest = levels.last().expect("at least one level");
    let (_, tg, sg, gg) = window.correlate(finest, x2, &a0);
    let z_in = window.zncc(tg, sg, gg);
    let a_out = row_major(&a);
    let x2_out = if options.move_points {
        [x2[0] + t[0], x2[1] + t[1]]
    } else {
        x2
    };
    let plausible = a_out.iter().chain(&t).all(|v| v.is_finite())
        && a.determinant() > 0.0
        && t[0].abs().max(t[1].abs()) < radius / 2.0;
    let rejected = |status| {
        let a_in = Matrix2::new(a0[0], a0[1], a0[2], a0[3]);
        let (shift_std, affine_std) = window.uncertainty(&h, &a_in, z_in);
        OneResult {
            status,
            corr: *c,
            zncc: z_in,
            shift_std,
            affine_std,
        }
    };
    if !plausible {
        return rejected(RefineStatus::Diverged);
    }
    // The ZNCC of what is returned: with fixed points, A is judged at x2.
    let (_, tg, sg, gg) = window.correlate(finest, x2_out, &a_out);
    let z_out = window.zncc(tg, sg, gg);
    let (shift_std, affine_std) = window.uncertainty(&h, &a, z_out);
    let status = if !(z_out >= options.min_zncc) {
        RefineStatus::LowZncc
    } else if !(z_out > z_in) {
        RefineStatus::NotImproved
    } else if !(shift_std <= options.max_shift_std) {
        RefineStatus::Aperture
    } else {
        let [p, q] = x2_out;
        let [a11, a12, a21, a22] = a_out;
        return OneResult {
            status: RefineStatus::Refined,
            corr: [x1[0], x1[1], p, q, a11, a12, a21, a22],
            zncc: z_out,
            shift_std,
            affine_std,
        };
    };
    rejected(status)
}

/// The image convolved with a Gaussian of σ pixels (kernel radius ⌈3σ⌉, border replicated),
/// rows then columns; σ = 0 copies it.
pub(crate) fn gaussian_blur(image: &GrayImage, sigma: f64) -> Vec<f32> {
    let (w, h) = (image.width(), image.height());
    if sigma <= 0.0 {
        return image.data().to_vec();
    }
    let r = (3.0 * sigma).ceil() as i64;
    let mut kernel: Vec<f32> = (-r..=r)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);
    let clamp = |i: i64, n: usize| i.clamp(0, n as i64 - 1) as usize;
    let ru = r as usize;
    let mut rows = vec![0.0f32; w * h];
    rows.par_chunks_mut(w)
        .zip(image.data().par_chunks(w))
        .for_each(|(out, src)| {
            // Interior: one axpy per tap over the row, which vectorises; the ends clamp.
            let start = ru.min(w);
            let interior = start..w.saturating_sub(ru).max(start);
            let n = interior.len();
            for (k, kv) in kernel.iter().enumerate().filter(|_| n > 0) {
                for (o, s) in out[interior.clone()].iter_mut().zip(&src[k..k + n]) {
                    *o += kv * s;
                }
            }
            for x in (0..interior.start).chain(interior.end..w) {
                out[x] = kernel
                    .iter()
                    .enumerate()
                    .map(|(k, kv)| kv * src[clamp(x as i64 + k as i64 - r, w)])
                    .sum();
            }
        });
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        for (k, kv) in kernel.iter().enumerate() {
            let src = &rows[clamp(y as i64 + k as i64 - r, h) * w..][..w];
            for (ov, sv) in o.iter_mut().zip(src) {
                *ov += kv * sv;
            }
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth random texture: a sum of sinusoids, so that bilinear sampling is accurate.
    fn texture(w: usize, h: usize, seed: u64) -> GrayImage {
        let mut waves = Vec::new();
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..24 {
            let (f, th, ph) = (
                0.05 + 0.25 * next(),
                std::f64::consts::TAU * next(),
                6.3 * next(),
            );
            waves.push((f * th.cos(), f * th.sin(), ph));
        }
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let v: f64 = waves
                    .iter()
                    .map(|(fx, fy, ph)| (fx * x + fy * y + ph).sin())
                    .sum();
                (0.5 + 0.08 * v) as f32
            })
            .collect();
        GrayImage::new(w, h, data).unwrap()
    }

    /// Image B = α·(image A under x ↦ M x + c) + β, sampled analytically from the same waves.
    fn warped_pair(m: [f64; 4], c: [f64; 2]) -> (GrayImage, GrayImage) {
        let a = texture(160, 160, 7);
        let det = m[0] * m[3] - m[1] * m[2];
        let inv = [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det];
        let (w, h) = (160, 160);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64 - c[0], (i / w) as f64 - c[1]);
                let (u, v) = (inv[0] * x + inv[1] * y, inv[2] * x + inv[3] * y);
                let (x0, x1, fx) = axis(u, w);
                let (y0, y1, fy) = axis(v, h);
                let g = |xx: usize, yy: usize| a.get(xx, yy) as f64;
                let val = (1.0 - fy) * ((1.0 - fx) * g(x0, y0) + fx * g(x1, y0))
                    + fy * ((1.0 - fx) * g(x0, y1) + fx * g(x1, y1));
                (0.9 * val + 0.05) as f32
            })
            .collect();
        (a, GrayImage::new(w, h, data).unwrap())
    }

    #[test]
    fn recovers_a_known_affine_map() {
        // x2 = M x1 + c: A = M everywhere.
        let m = [1.1, 0.25, -0.15, 0.9];
        let c = [8.0, -4.0];
        let (a, b) = warped_pair(m, c);
        let x1 = [70.0, 75.0];
        let x2 = [
            m[0] * x1[0] + m[1] * x1[1] + c[0],
            m[2] * x1[0] + m[3] * x1[1] + c[1],
        ];
        // Start 0.3 off in A (Frobenius) and 1.2 px off in x2; the residual error comes from
        // image B being resampled bilinearly.
        let start = [x1[0], x1[1], x2[0] + 1.0, x2[1] - 0.7, 1.3, 0.1, 0.05, 1.1];
        let r = refine_affine(&a, &b, &[start], &AffineRefineOptions::default()).unwrap();
        assert!(r.refined[0], "zncc {}", r.zncc[0]);
        let out = r.corrs[0];
        let err_a = (0..4)
            .map(|k| (out[4 + k] - m[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let err_x = ((out[2] - x2[0]).powi(2) + (out[3] - x2[1]).powi(2)).sqrt();
        assert!(
            err_a < 0.005 && err_x < 0.03,
            "A error {err_a}, x2 error {err_x}: {out:?}"
        );
        assert!(r.zncc[0] > 0.99);
    }

    #[test]
    fn a_rotated_input_is_not_replaced_by_the_identity() {
        // A quarter turn: the identity start would fail; the input's A, 0.15 off, is kept as
        // the start and refined.
        let m = [0.0, -0.9, 0.9, 0.0];
        let c = [140.0, 10.0];
        let (a, b) = warped_pair(m, c);
        let x1 = [75.0, 80.0];
        let x2 = [
            m[0] * x1[0] + m[1] * x1[1] + c[0],
            m[2] * x1[0] + m[3] * x1[1] + c[1],
        ];
        let start = [x1[0], x1[1], x2[0] + 0.5, x2[1], 0.1, -0.8, 0.95, 0.05];
        let r = refine_affine(&a, &b, &[start], &AffineRefineOptions::default()).unwrap();
        let out = r.corrs[0];
        let err_a = (0..4)
            .map(|k| (out[4 + k] - m[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(r.refined[0] && err_a < 0.005, "{err_a}: {out:?}");
    }

    #[test]
    fn a_zoomed_out_rotated_pair_is_refined_from_its_neighbourhood() {
        // B is A shrunk by 2 and turned by 40°, and every AC starts from a near-identity A, as
        // the shape network's scale does at this zoom; x2 is 0.5 px off. The neighbourhood
        // start (the points' displacements) brings the refinement into the basin.
        let (s, th) = (0.5_f64, 40f64.to_radians());
        let m = [s * th.cos(), -s * th.sin(), s * th.sin(), s * th.cos()];
        let c = [80.0, 20.0];
        let (a, b) = warped_pair(m, c);
        let corrs: Vec<[f64; 8]> = (0..64)
            .map(|k| {
                let x1 = [50.0 + 9.0 * (k % 8) as f64, 50.0 + 9.0 * (k / 8) as f64];
                let x2 = [
                    m[0] * x1[0] + m[1] * x1[1] + c[0] + 0.5 * ((k % 3) as f64 - 1.0),
                    m[2] * x1[0] + m[3] * x1[1] + c[1] + 0.5 * ((k % 5) as f64 / 2.0 - 1.0),
                ];
                [x1[0], x1[1], x2[0], x2[1], 0.95, 0.05, -0.05, 0.95]
            })
            .collect();
        let starts = neighbourhood_similarities(&corrs);
        let start_error = |p: &[f64; 4]| (0..4).map(|k| (p[k] - m[k]).powi(2)).sum::<f64>().sqrt();
        let worst = starts
            .iter()
            .map(|p| p.map_or(f64::INFINITY, |p| start_error(&p)))
            .fold(0.0, f64::max);
        assert!(worst < 0.2, "worst start {worst}");
        let run = |try_neighbours| {
            let options = AffineRefineOptions {
                radius: 12,
                try_neighbours,
                ..AffineRefineOptions::default()
            };
            let r = refine_affine(&a, &b, &corrs, &options).unwrap();
            let mut errors: Vec<f64> = (0..corrs.len())
                .filter(|&i| r.refined[i])
                .map(|i| start_error(&[r.corrs[i][4], r.corrs[i][5], r.corrs[i][6], r.corrs[i][7]]))
                .collect();
            errors.sort_by(f64::total_cmp);
            (errors.len(), errors.get(errors.len() / 2).copied())
        };
        let (with, median) = run(true);
        let (without, _) = run(false);
        assert!(
            with >= 60 && median.unwrap() < 0.02,
            "{with} refined, median {median:?}"
        );
        assert!(
            without + 12 <= with,
            "{without} refined without the neighbourhood, {with} with it"
        );
    }

    #[test]
    fn fixed_points_keep_x2() {
        let m = [0.95, -0.2, 0.2, 0.95];
        let (a, b) = warped_pair(m, [5.0, 3.0]);
        let x1 = [80.0, 70.0];
        let x2 = [
            m[0] * 80.0 + m[1] * 70.0 + 5.0,
            m[2] * 80.0 + m[3] * 70.0 + 3.0,
        ];
        let start = [x1[0], x1[1], x2[0], x2[1], 1.0, 0.0, 0.0, 1.0];
        let options = AffineRefineOptions {
            move_points: false,
            ..Default::default()
        };
        let r = refine_affine(&a, &b, &[start], &options).unwrap();
        let out = r.corrs[0];
        assert!(r.refined[0]);
        assert_eq!((out[2], out[3]), (x2[0], x2[1]));
        let err_a = (0..4)
            .map(|k| (out[4 + k] - m[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err_a < 0.005, "{err_a}");
    }

    #[test]
    fn a_lone_edge_is_not_refined() {
        // A smooth vertical step edge: any vertical shift fits it about equally well (the aperture
        // problem), so the translation is unknown along the edge and the AC must come back as
        // it was, although its ZNCC would pass. Without the check it is "refined".
        let (w, h) = (120, 120);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                // A faint ripple keeps the Gauss–Newton matrix invertible (a perfect edge is
                // singular, and refused as flat).
                (0.5 + 0.3 * ((x - 60.0) / 3.0).tanh() + 0.0005 * (0.8 * y + 0.3 * x).sin()) as f32
            })
            .collect();
        let edge = GrayImage::new(w, h, data).unwrap();
        let c = [60.0, 60.0, 60.5, 61.0, 1.05, 0.0, 0.05, 0.95];
        let r = refine_affine(&edge, &edge, &[c], &AffineRefineOptions::default()).unwrap();
        assert_eq!((r.refined[0], r.corrs[0]), (false, c), "zncc {}", r.zncc[0]);
        let loose = AffineRefineOptions {
            max_shift_std: 1e9,
            ..Default::default()
        };
        assert!(refine_affine(&edge, &edge, &[c], &loose).unwrap().refined[0]);
    }

    #[test]
    fn flat_windows_are_left_alone() {
        let flat = GrayImage::new(100, 100, vec![0.5; 100 * 100]).unwrap();
        let c = [50.0, 50.0, 52.0, 49.0, 1.2, 0.1, -0.1, 0.9];
        let r = refine_affine(&flat, &flat, &[c], &AffineRefineOptions::default()).unwrap();
        assert_eq!((r.refined[0], r.corrs[0]), (false, c));
    }

    #[test]
    fn bad_input_is_named() {
        let img = texture(40, 40, 1);
        let ok = [20.0, 20.0, 20.0, 20.0, 1.0, 0.0, 0.0, 1.0];
        let run = |c: [f64; 8], o: AffineRefineOptions| {
            refine_affine(&img, &img, &[ok, c], &o)
                .unwrap_err()
                .to_string()
        };
        let mut nan = ok;
        nan[5] = f64::NAN;
        assert!(run(nan, Default::default()).contains("corrs"));
        let mut flip = ok;
        flip[4] = -1.0;
        assert!(run(flip, Default::default()).contains("det A"));
        let bad = |o: AffineRefineOptions, name: &str| assert!(run(ok, o).contains(name), "{name}");
        bad(
            AffineRefineOptions {
                radius: 0,
                ..Default::default()
            },
            "radius",
        );
        bad(
            AffineRefineOptions {
                max_shift_std: 0.0,
                ..Default::default()
            },
            "max_shift_std",
        );
        bad(
            AffineRefineOptions {
                blur_sigmas: vec![],
                ..Default::default()
            },
            "blur_sigmas",
        );
        bad(
            AffineRefineOptions {
                blur_sigmas: vec![f64::NAN],
                ..Default::default()
            },
            "blur_sigmas",
        );
        bad(
            AffineRefineOptions {
                iterations: 0,
                ..Default::default()
            },
            "iterations",
        );
        bad(
            AffineRefineOptions {
                min_zncc: 2.0,
                ..Default::default()
            },
            "min_zncc",
        );
    }

    #[test]
    fn gradients_are_the_clamped_central_differences() {
        // Widths 1 and 2 have no interior column; heights 1 and 2 no interior row.
        for (w, h) in [(30, 20), (2, 3), (1, 4), (5, 1), (3, 2)] {
            let plane = Plane::<3>::new(&texture(w, h, 3), 0.0);
            let image = texture(w, h, 3);
            let v = |x: usize, y: usize| image.data()[y * w + x];
            for y in 0..h {
                for x in 0..w {
                    let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
                    let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
                    let want = [
                        v(x, y),
                        (v(xr, y) - v(xl, y)) / (xr - xl).max(1) as f32,
                        (v(x, yd) - v(x, yu)) / (yd - yu).max(1) as f32,
                    ];
                    assert_eq!(plane.data[y * w + x], want, "{w}×{h} at ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn unclamped_reads_equal_clamped_ones_inside() {
        let plane = Plane::<3>::new(&texture(30, 20, 2), 1.0);
        for k in 0..500 {
            let (x, y) = (
                (k * 37 % 2800) as f64 / 100.0,
                (k * 53 % 1800) as f64 / 100.0,
            );
            assert_eq!(plane.sample(x, y), plane.sample_inside(x, y), "({x}, {y})");
        }
        let a = [1.2, 0.3, -0.1, 0.8];
        assert!(plane.contains([14.0, 9.0], &a, 5.0));
        assert!(!plane.contains([14.0, 9.0], &a, 10.0));
        assert!(!plane.contains([28.5, 9.0], &[1.0, 0.0, 0.0, 1.0], 0.1));
    }

    #[test]
    fn blur_is_the_clamped_convolution() {
        // Wide and narrower than the kernel (σ = 2: 13 taps).
        for (w, h) in [(40, 9), (7, 5)] {
            let img = texture(w, h, 5);
            let out = gaussian_blur(&img, 2.0);
            let k: Vec<f64> = (-6..=6).map(|i| (-(i * i) as f64 / 8.0).exp()).collect();
            let sum: f64 = k.iter().sum();
            let at = |x: i64, y: i64| {
                img.get(
                    x.clamp(0, w as i64 - 1) as usize,
                    y.clamp(0, h as i64 - 1) as usize,
                ) as f64
            };
            for y in 0..h as i64 {
                for x in 0..w as i64 {
                    let mut v = 0.0;
                    for (i, ki) in k.iter().enumerate() {
                        for (j, kj) in k.iter().enumerate() {
                            v += ki * kj * at(x + j as i64 - 6, y + i as i64 - 6);
                        }
                    }
                    let got = out[y as usize * w + x as usize] as f64;
                    assert!(
                        (got - v / (sum * sum)).abs() < 1e-5,
                        "({x}, {y}) of {w}×{h}"
                    );
                }
            }
        }
    }

    #[test]
    fn blur_keeps_constants_and_mass() {
        let img = texture(50, 30, 3);
        let flat = GrayImage::new(50, 30, vec![0.25; 1500]).unwrap();
        assert!(
            gaussian_blur(&flat, 2.0)
                .iter()
                .all(|v| (v - 0.25).abs() < 1e-6)
        );
        let (src, out) = (img.data(), gaussian_blur(&img, 1.0));
        let mean = |d: &[f32]| d.iter().map(|&v| v as f64).sum::<f64>() / d.len() as f64;
        assert!((mean(src) - mean(&out)).abs() < 2e-3);
        assert_eq!(gaussian_blur(&img, 0.0), src);
    }
}
