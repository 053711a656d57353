//! Dense matchers (DKM, RoMa) under the `dense-warp-v1` contract (docs/design.md §6,
//! docs/matchers.md), and DKM's balanced sampling of matches from their certainty map.
//!
//! # The contract
//!
//! - Inputs `image_a`, `image_b`: float32 (1, 3, H, W), RGB in [0, 1] (any normalisation such
//!   as ImageNet's is inside the graph). Both images are resized (antialiased triangle filter,
//!   like PIL's bilinear that DKM uses) to one input size: the graph's fixed H and W when it has
//!   them, else metadata `affcorr.nominal_size` = [H, W], else image A's size rounded down to
//!   `affcorr.input_multiple` (default 1).
//! - Outputs `warp` (1, H′, W′, 2): for output cell (i, j) of image A, its position in image B in
//!   normalised coordinates (u, v) ∈ [−1, 1]², x first; `certainty` (1, H′, W′) in [0, 1].
//!
//! # Normalised coordinates (DKM's convention)
//!
//! DKM puts the output cell (i, j) of A at u = −1 + (2j + 1)/W′, v = −1 + (2i + 1)/H′
//! (`torch.linspace(-1 + 1/W′, 1 - 1/W′, W′)`), so −1 and 1 are the *outer edges* of the
//! image (`align_corners=False`), and its `to_pixel_coordinates` maps u to W/2 · (u + 1): pixel
//! units whose first pixel *centre* is at 0.5. affcorr puts pixel centres at integers
//! (docs/design.md §2), so here
//!
//! > x = W/2 · (u + 1) − 0.5,  y = H/2 · (v + 1) − 0.5
//!
//! in an image of W × H pixels, whatever resolution the network ran at (the coordinates are
//! resolution-free). With metadata `affcorr.warp_align_corners` = `true` (−1 and 1 are the
//! centres of the outer pixels) the map is x = (W − 1)/2 · (u + 1) instead; the grid of A is
//! then u = −1 + 2j/(W′ − 1).
//!
//! # Balanced sampling ([`balanced_sample`])
//!
//! DKM's `sample` (`sample_mode = "threshold_balanced"`), with a seeded generator:
//!
//! 1. Cells whose warp leaves [−1, 1]² or is not finite get certainty 0 (DKM's `match` does
//!    this inside its forward pass; a user's export may not). Certainty above `threshold`
//!    (DKM: 0.05) counts as 1: every confident cell is equally good.
//! 2. Draw min(`expansion` · n, cells with certainty > 0) cells *without replacement* with
//!    probability proportional to that certainty (DKM: `torch.multinomial`, expansion 4).
//! 3. Density of each drawn match m = (u_A, v_A, u_B, v_B) among the drawn ones: a Gaussian
//!    kernel density ρ(m) = Σ_k exp(−‖m − m_k‖² / 2σ²), σ = `kde_std` (DKM: 0.1), including
//!    itself.
//! 4. Draw min(n, drawn) of them without replacement with probability ∝ 1/(1 + ρ), and
//!    ∝ 1e-7 when ρ < `min_density` · drawn / 40 000 (isolated matches are likely wrong).
//!    Dense areas are thinned, so the matches spread over the overlap.
//!
//! DKM's cut is ρ < 10 ("at least 10 perfect neighbours") at its default 40 000 first draws
//! (n = 10 000). ρ grows with the number of draws, so an absolute 10 would, at the pipeline's
//! 8 000 draws, drop areas 5× less dense than DKM drops (e.g. the whole sparse side of a
//! certainty map with a 10:1 contrast); scaling the cut by drawn / 40 000 keeps DKM's
//! *relative* rule and equals it at DKM's count.
//!
//! Weighted sampling without replacement uses Efraimidis–Spirakis keys: item i with weight
//! w_i > 0 gets key ln(U_i)/w_i, U_i uniform on (0, 1], and the k largest keys are the sample;
//! this has the distribution of k successive draws ∝ w among the items not yet drawn, which is
//! `torch.multinomial(w, k, replacement=False)`. The generator is PCG-64 seeded with `seed`
//! and draws one U per item in index order, so a seed gives the same matches on any machine
//! and thread count (the density sums run in a fixed order per match).
//!
//! Step 3 costs O((expansion · n)²) kernel evaluations (64 M for n = 2000), parallel over
//! matches; pairs further apart than 6σ (kernel < 1.6e-8) skip the exponential.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;

use ort::session::Session;
use ort::value::{TensorRef, ValueType};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

use crate::contract::{self, CheckedModel, DENSE_WARP_SPEC};
use crate::error::{Result, RunnerError};
use affcorr_image::RgbImage;

/// A dense matcher's output for one pair: the warp of every cell of A's output grid.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseWarp {
    /// Output grid rows H′.
    pub height: usize,
    /// Output grid columns W′.
    pub width: usize,
    /// Per cell, row-major: its position in B, normalised (u, v).
    pub warp: Vec<[f32; 2]>,
    /// Per cell: the certainty in [0, 1].
    pub certainty: Vec<f32>,
    /// Whether ±1 are the outer pixel centres (`affcorr.warp_align_corners`) rather than the
    /// image edges.
    pub align_corners: bool,
}

impl DenseWarp {
    /// The normalised position (u, v) in A of output cell `index` (row-major).
    pub fn grid_point(&self, index: usize) -> [f64; 2] {
        let (i, j) = (index / self.width, index % self.width);
        [
            grid_coord(j, self.width, self.align_corners),
            grid_coord(i, self.height, self.align_corners),
        ]
    }

    /// The 4-vector (u_A, v_A, u_B, v_B) of cell `index`, what the density is computed on.
    fn match_vector(&self, index: usize) -> [f32; 4] {
        let [ua, va] = self.grid_point(index);
        let [ub, vb] = self.warp[index];
        [ua as f32, va as f32, ub, vb]
    }

    /// The pixel positions of cells `indices` in an image A of `size_a` = (W, H) pixels and
    /// their warps in an image B of `size_b` pixels (module docs: x = W/2 · (u + 1) − 0.5).
    pub fn to_pixels(
        &self,
        indices: &[usize],
        size_a: (usize, usize),
        size_b: (usize, usize),
    ) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let ac = self.align_corners;
        let px =
            |[u, v]: [f64; 2], (w, h): (usize, usize)| [to_pixel(u, w, ac), to_pixel(v, h, ac)];
        indices
            .iter()
            .map(|&k| {
                let [ub, vb] = self.warp[k];
                (
                    px(self.grid_point(k), size_a),
                    px([f64::from(ub), f64::from(vb)], size_b),
                )
            })
            .unzip()
    }

    /// The certainty DKM samples from (module docs, step 1): 0 where the warp leaves
    /// [−1, 1]² or is not finite, clamped to [0, 1] (NaN → 0).
    fn usable_certainty(&self) -> Vec<f32> {
        self.warp
            .iter()
            .zip(&self.certainty)
            .map(|(w, &c)| {
                let inside = w.iter().all(|x| x.is_finite() && x.abs() <= 1.0);
                if inside && c > 0.0 { c.min(1.0) } else { 0.0 }
            })
            .collect()
    }
}

/// Normalised coordinate of cell `k` of `n` (module docs).
fn grid_coord(k: usize, n: usize, align_corners: bool) -> f64 {
    if align_corners {
        if n == 1 {
            0.0
        } else {
            -1.0 + 2.0 * k as f64 / (n - 1) as f64
        }
    } else {
        -1.0 + (2 * k + 1) as f64 / n as f64
    }
}

/// Normalised coordinate to pixels of an axis of `n` pixels, centres at integers.
fn to_pixel(u: f64, n: usize, align_corners: bool) -> f64 {
    if align_corners {
        (n as f64 - 1.0) / 2.0 * (u + 1.0)
    } else {
        n as f64 / 2.0 * (u + 1.0) - 0.5
    }
}

/// A `dense-warp-v1` model (DKM, RoMa exports), checked on loading.
#[derive(Debug)]
pub struct DenseMatcher {
    session: Mutex<Session>,
    /// (H, W) fixed by the graph or by `affcorr.nominal_size`.
    input_size: Option<(usize, usize)>,
    input_multiple: usize,
    align_corners: bool,
    metadata: BTreeMap<String, String>,
    source: String,
}

impl DenseMatcher {
    /// Loads and checks a dense matcher (`threads` intra-op threads; `None`: every core).
    pub fn load(path: impl AsRef<Path>, threads: Option<usize>) -> Result<Self> {
        let spec = &DENSE_WARP_SPEC;
        let threads = contract::resolve_threads(threads)?;
        let model = contract::load(path.as_ref(), threads, spec)?;
        let fixed = fixed_input_size(&model);
        let nominal = match model.metadata.get("affcorr.nominal_size") {
            None => None,
            Some(_) => {
                let l = model.meta_list(spec, "affcorr.nominal_size", |v| {
                    v >= 1.0 && v.fract() == 0.0
                })?;
                if l.len() != 2 {
                    return Err(model.violation(
                        spec,
                        format!("metadata affcorr.nominal_size is {l:?}, expected [H, W]"),
                    ));
                }
                Some((l[0] as usize, l[1] as usize))
            }
        };
        let input_multiple = match model.metadata.get("affcorr.input_multiple") {
            None => 1,
            Some(_) => model.meta_usize(spec, "affcorr.input_multiple")?,
        };
        let align_corners = match model
            .metadata
            .get("affcorr.warp_align_corners")
            .map(|s| s.trim().to_ascii_lowercase())
            .as_deref()
        {
            None | Some("false") => false,
            Some("true") => true,
            Some(other) => {
                return Err(model.violation(
                    spec,
                    format!(
                        "metadata affcorr.warp_align_corners is {other:?}, expected true or false"
                    ),
                ));
            }
        };
        let CheckedModel {
            session,
            metadata,
            source,
        } = model;
        Ok(Self {
            session: Mutex::new(session),
            input_size: fixed.or(nominal),
            input_multiple,
            align_corners,
            metadata,
            source,
        })
    }

    /// All custom metadata.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The model's file path in backquotes.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The (H, W) both images are resized to for an image A of `width` × `height` (module
    /// docs).
    pub fn input_size(&self, width: usize, height: usize) -> (usize, usize) {
        self.input_size.unwrap_or_else(|| {
            let m = self.input_multiple;
            ((height / m).max(1) * m, (width / m).max(1) * m)
        })
    }

    /// Runs the network on a pair.
    pub fn run(&self, a: &RgbImage, b: &RgbImage) -> Result<DenseWarp> {
        let (h, w) = self.input_size(a.width(), a.height());
        let (pa, pb) = (a.to_planar(w, h), b.to_planar(w, h));
        let shape = [1usize, 3, h, w];
        let ta = TensorRef::from_array_view((shape, pa.as_slice()))
            .map_err(|e| RunnerError::ort("wrapping image_a", e))?;
        let tb = TensorRef::from_array_view((shape, pb.as_slice()))
            .map_err(|e| RunnerError::ort("wrapping image_b", e))?;
        let inputs = ort::inputs!["image_a" => ta, "image_b" => tb];
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let outputs = session
            .run(inputs)
            .map_err(|e| RunnerError::ort("running the dense matcher", e))?;
        let (shape, _) = outputs
            .get("certainty")
            .ok_or_else(|| RunnerError::ModelOutput {
                what: "certainty",
                reason: "missing from the session's outputs".to_string(),
            })?
            .try_extract_tensor::<f32>()
            .map_err(|e| RunnerError::ModelOutput {
                what: "certainty",
                reason: e.to_string(),
            })?;
        let (gh, gw) = match **shape {
            [1, gh, gw] if gh > 0 && gw > 0 => (gh, gw),
            _ => {
                return Err(RunnerError::ModelOutput {
                    what: "certainty",
                    reason: format!("shape {shape}, expected [1, H′, W′] with H′, W′ ≥ 1"),
                });
            }
        };
        let certainty = contract::output::<f32>(&outputs, "certainty", &[1, gh, gw])?.to_vec();
        let warp = contract::output::<f32>(&outputs, "warp", &[1, gh, gw, 2])?
            .chunks_exact(2)
            .map(|p| [p[0], p[1]])
            .collect();
        Ok(DenseWarp {
            height: gh as usize,
            width: gw as usize,
            warp,
            certainty,
            align_corners: self.align_corners,
        })
    }
}

/// (H, W) of `image_a` when the graph fixes both.
fn fixed_input_size(model: &CheckedModel) -> Option<(usize, usize)> {
    let input = model
        .session
        .inputs()
        .iter()
        .find(|o| o.name() == "image_a")?;
    let ValueType::Tensor { shape, .. } = input.dtype() else {
        return None;
    };
    match (shape[2], shape[3]) {
        (h, w) if h > 0 && w > 0 => Some((h as usize, w as usize)),
        _ => None,
    }
}

/// DKM's first draws at its default count (4 × 10 000), where its density cut of 10 applies.
const DKM_FIRST_DRAWS: f32 = 40_000.0;

/// DKM's balanced sampling (module docs); the defaults are DKM's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplingOptions {
    /// Matches to draw (fewer when fewer cells are certain).
    pub num: usize,
    /// Certainty above this counts as 1 (0.05).
    pub threshold: f32,
    /// First draw `expansion · num` cells (4); 1 turns the density balancing off.
    pub expansion: usize,
    /// σ of the Gaussian kernel in normalised coordinates (0.1).
    pub kde_std: f32,
    /// Matches with a kernel density below this × drawn / 40 000 are all but excluded (10:
    /// DKM's cut at its 40 000 first draws; module docs).
    pub min_density: f32,
    /// Seed of the generator.
    pub seed: u64,
}

impl Default for SamplingOptions {
    fn default() -> Self {
        Self {
            num: 10_000,
            threshold: 0.05,
            expansion: 4,
            kde_std: 0.1,
            min_density: 10.0,
            seed: 0,
        }
    }
}

/// Sampled cells of a [`DenseWarp`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DenseSample {
    /// Row-major cell indices, in the order they were drawn.
    pub index: Vec<usize>,
    /// The model's certainty of each (not the thresholded one).
    pub certainty: Vec<f32>,
    /// Cells that could be drawn: certainty > 0 and a warp inside B.
    pub candidates: usize,
}

/// DKM's balanced sampling from `warp` (module docs).
pub fn balanced_sample(warp: &DenseWarp, options: &SamplingOptions) -> Result<DenseSample> {
    let o = options;
    if o.num == 0 {
        return Err(RunnerError::invalid("num", "must be at least 1"));
    }
    if o.expansion == 0 {
        return Err(RunnerError::invalid("expansion", "must be at least 1"));
    }
    if !(o.kde_std.is_finite() && o.kde_std > 0.0) {
        return Err(RunnerError::invalid(
            "kde_std",
            format!("{} is not a positive number", o.kde_std),
        ));
    }
    for (what, v) in [("threshold", o.threshold), ("min_density", o.min_density)] {
        if !v.is_finite() {
            return Err(RunnerError::invalid(what, format!("{v} is not finite")));
        }
    }
    let cells = warp.height * warp.width;
    if warp.warp.len() != cells || warp.certainty.len() != cells {
        return Err(RunnerError::invalid(
            "warp",
            format!(
                "{} warp and {} certainty values for a {}×{} grid",
                warp.warp.len(),
                warp.certainty.len(),
                warp.width,
                warp.height
            ),
        ));
    }
    let certainty = warp.usable_certainty();
    let weights: Vec<f32> = certainty
        .iter()
        .map(|&c| if c > o.threshold { 1.0 } else { c })
        .collect();
    let mut rng = Pcg64::seed_from_u64(o.seed);
    let first = o.num.saturating_mul(o.expansion);
    let good = sample_without_replacement(&weights, first, &mut rng);
    let index = if o.expansion == 1 {
        good
    } else {
        let points: Vec<[f32; 4]> = good.iter().map(|&k| warp.match_vector(k)).collect();
        let density = kernel_density(&points, o.kde_std);
        let cut = o.min_density * points.len() as f32 / DKM_FIRST_DRAWS;
        let p: Vec<f32> = density
            .iter()
            .map(|&d| if d < cut { 1e-7 } else { 1.0 / (d + 1.0) })
            .collect();
        sample_without_replacement(&p, o.num, &mut rng)
            .into_iter()
            .map(|i| good[i])
            .collect()
    };
    let candidates = certainty.iter().filter(|&&c| c > 0.0).count();
    let certainty = index.iter().map(|&k| certainty[k]).collect();
    Ok(DenseSample {
        index,
        certainty,
        candidates,
    })
}

/// `k` indices drawn without replacement with probability ∝ `weights` (Efraimidis–Spirakis,
/// module docs), in draw order; items of weight ≤ 0 are never drawn.
fn sample_without_replacement(weights: &[f32], k: usize, rng: &mut Pcg64) -> Vec<usize> {
    let mut keyed: Vec<(f64, usize)> = weights
        .iter()
        .enumerate()
        .filter_map(|(i, &w)| {
            // One draw per item whatever its weight, so that the stream stays aligned.
            let u = 1.0 - rng.random::<f64>(); // (0, 1]
            (w > 0.0).then(|| (u.ln() / f64::from(w), i))
        })
        .collect();
    let k = k.min(keyed.len());
    let by_key = |a: &(f64, usize), b: &(f64, usize)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
    if k < keyed.len() && k > 0 {
        keyed.select_nth_unstable_by(k - 1, by_key);
    }
    keyed.truncate(k);
    keyed.sort_unstable_by(by_key);
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// ρ_i = Σ_k exp(−‖p_i − p_k‖² / 2σ²) (module docs, step 3).
fn kernel_density(points: &[[f32; 4]], std: f32) -> Vec<f32> {
    let inv = 1.0 / (2.0 * std * std);
    // exp(−18) = 1.5e-8: farther pairs add nothing a float32 sum of ≥ 1 keeps.
    let cutoff = 18.0 / inv;
    points
        .par_iter()
        .map(|p| {
            let mut sum = 0f32;
            for q in points {
                let d2: f32 = (0..4).map(|c| (p[c] - q[c]) * (p[c] - q[c])).sum();
                if d2 < cutoff {
                    sum += (-d2 * inv).exp();
                }
            }
            sum
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform_warp(h: usize, w: usize, cert: impl Fn(usize, usize) -> f32) -> DenseWarp {
        let mut warp = DenseWarp {
            height: h,
            width: w,
            warp: Vec::new(),
            certainty: Vec::new(),
            align_corners: false,
        };
        for i in 0..h {
            for j in 0..w {
                let k = i * w + j;
                warp.warp.push(warp_identity(&warp, k));
                warp.certainty.push(cert(i, j));
            }
        }
        warp
    }

    fn warp_identity(w: &DenseWarp, k: usize) -> [f32; 2] {
        let [u, v] = w.grid_point(k);
        [u as f32, v as f32]
    }

    #[test]
    fn grid_and_pixels_follow_dkm() {
        let w = uniform_warp(2, 4, |_, _| 1.0);
        // linspace(-1 + 1/4, 1 - 1/4, 4) = -0.75, -0.25, 0.25, 0.75.
        assert_eq!(w.grid_point(0), [-0.75, -0.5]);
        assert_eq!(w.grid_point(7), [0.75, 0.5]);
        // DKM: W/2 (u + 1) = 0.5 for the first cell of a 4-wide image; here 0.
        let (a, b) = w.to_pixels(&[0, 7], (4, 2), (8, 4));
        assert_eq!(a, vec![[0.0, 0.0], [3.0, 1.0]]);
        assert_eq!(b, vec![[0.5, 0.5], [6.5, 2.5]]);
        assert_eq!(to_pixel(-1.0, 10, false), -0.5);
        assert_eq!(to_pixel(1.0, 10, true), 9.0);
    }

    #[test]
    fn weighted_sampling_matches_successive_draws() {
        // Weights 1, 2, 3, 0: P(first = i) = w_i / 6; item 3 is never drawn.
        let w = [1.0f32, 2.0, 3.0, 0.0];
        let mut firsts = [0usize; 4];
        let mut rng = Pcg64::seed_from_u64(7);
        let trials = 30_000;
        for _ in 0..trials {
            let s = sample_without_replacement(&w, 3, &mut rng);
            assert_eq!(s.len(), 3);
            assert!(!s.contains(&3));
            firsts[s[0]] += 1;
        }
        for (i, &wi) in w.iter().enumerate().take(3) {
            let p = firsts[i] as f64 / trials as f64;
            let want = f64::from(wi) / 6.0;
            // 5 standard deviations of a binomial proportion.
            let sd = (want * (1.0 - want) / trials as f64).sqrt();
            assert!((p - want).abs() < 5.0 * sd, "item {i}: {p} vs {want}");
        }
    }

    #[test]
    fn density_counts_close_neighbours() {
        let pts = [[0.0f32; 4], [0.0, 0.0, 0.0, 0.1], [1.0, 1.0, 1.0, 1.0]];
        let d = kernel_density(&pts, 0.1);
        let near = (-0.5f32).exp();
        assert!((d[0] - (1.0 + near)).abs() < 1e-6);
        assert!((d[1] - (1.0 + near)).abs() < 1e-6);
        assert!((d[2] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn sampling_is_seeded_and_skips_uncertain_cells() {
        // Certain only in the left half.
        let w = uniform_warp(40, 60, |_, j| if j < 30 { 0.9 } else { 0.0 });
        let o = SamplingOptions {
            num: 200,
            ..Default::default()
        };
        let s1 = balanced_sample(&w, &o).unwrap();
        let s2 = balanced_sample(&w, &o).unwrap();
        assert_eq!(s1, s2);
        assert_eq!(s1.index.len(), 200);
        assert!(s1.index.iter().all(|&k| k % 60 < 30));
        assert!(s1.certainty.iter().all(|&c| c == 0.9));
        let s3 = balanced_sample(&w, &SamplingOptions { seed: 1, ..o }).unwrap();
        assert_ne!(s1.index, s3.index);
    }

    #[test]
    fn balancing_evens_out_a_concentrated_draw() {
        // Certainty below the threshold, 10× higher in the left quarter: the certainty-
        // proportional draw puts 10/(10 + 3) = 77 % of the matches there; balancing by the
        // inverse density brings it towards the quarter's share of the area.
        let w = uniform_warp(100, 100, |_, j| if j < 25 { 0.05 } else { 0.005 });
        let left = |s: &DenseSample| {
            s.index.iter().filter(|&&k| k % 100 < 25).count() as f64 / s.index.len() as f64
        };
        let o = SamplingOptions {
            num: 300,
            threshold: 0.5,
            ..Default::default()
        };
        let plain = balanced_sample(&w, &SamplingOptions { expansion: 1, ..o }).unwrap();
        let balanced = balanced_sample(&w, &o).unwrap();
        let (lp, lb) = (left(&plain), left(&balanced));
        eprintln!("left-quarter share: {lp:.3} drawn, {lb:.3} balanced");
        assert!(lp > 0.7, "unbalanced: {lp}");
        assert!(lb < 0.55, "balanced: {lb}");
    }

    #[test]
    fn warps_outside_b_are_not_sampled() {
        let mut w = uniform_warp(10, 10, |_, _| 1.0);
        for k in 0..50 {
            w.warp[k][0] = 1.5;
        }
        w.warp[60] = [f32::NAN, 0.0];
        let s = balanced_sample(
            &w,
            &SamplingOptions {
                num: 1000,
                expansion: 1,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(s.index.len(), 49);
        assert!(s.index.iter().all(|&k| k >= 50 && k != 60));
    }

    #[test]
    fn bad_options_are_errors() {
        let w = uniform_warp(2, 2, |_, _| 1.0);
        for o in [
            SamplingOptions {
                num: 0,
                ..Default::default()
            },
            SamplingOptions {
                kde_std: 0.0,
                ..Default::default()
            },
            SamplingOptions {
                expansion: 0,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                balanced_sample(&w, &o),
                Err(RunnerError::InvalidInput { .. })
            ));
        }
    }
}
