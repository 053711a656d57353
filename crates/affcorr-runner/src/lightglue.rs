//! LightGlue's adaptive layer loop over the network exported in pieces (docs/matchers.md,
//! `python/affcorr/export/lightglue_pieces.py`, whose `AdaptiveGlueOnnx` is the numpy
//! specification of this module):
//!
//! - `matcher-lightglue-encode-v1`: keypoints (normalised) and descriptors of one image → the
//!   projected descriptors and the rotary encoding (cos, sin);
//! - `matcher-lightglue-layer-v1`: one transformer layer, chosen by the input `layer`, with the
//!   layer's token-confidence and matchability sigmoids;
//! - `matcher-lightglue-assign-v1`: the assignment head of a layer and the mutual filter.
//!
//! The loop is kornia's `LightGlue._forward` (kornia/feature/lightglue.py), with L layers and
//! t_i = 0.8 + 0.1·exp(−4i/L) (float32):
//!
//! 1. after layer i < L − 1, with `depth_confidence` > 0: stop when
//!    `1 − #{token < t_i} / (M₀ + N₀) > depth_confidence`, the count over the points still in
//!    play of both images, M₀ and N₀ the original counts (pruned points count as confident);
//! 2. else, with `width_confidence` > 0: keep the points whose matchability is
//!    `> 1 − width_confidence`, and (depth on) those whose token is `≤ t_i` (points the network
//!    is not yet sure about are never pruned); kornia's CPU pruning threshold is −1, so this
//!    happens at every size;
//! 3. the assignment of the layer the loop ended at; matches are mutual best pairs with
//!    `mscores0 > min_conf`, mapped back to the original indices.
//!
//! Nothing here depends on the descriptor or embedding size, the number of heads or layers: they
//! come from the models' metadata, so LightGlue for other features reuses it. A side whose points
//! are all pruned gives no matches (kornia would run on empty tensors and find none).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use ort::session::Session;
use ort::value::TensorRef;

use crate::contract::{
    self, CheckedModel, ContractSpec, GLUE_ASSIGN_SPEC, GLUE_ENCODE_SPEC, GLUE_LAYER_SPEC,
};
use crate::error::{Result, RunnerError};
use crate::matching::GlueMatches;

/// The rules of the adaptive loop; a value ≤ 0 turns its rule off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlueConfig {
    /// Early exit: stop once more than this fraction of all points is confident (LightGlue:
    /// 0.95; ≤ 0: every layer).
    pub depth_confidence: f32,
    /// Point pruning: drop points whose matchability is ≤ 1 − this (XFeat's LighterGlue: 0.95,
    /// LightGlue: 0.99; ≤ 0: no pruning).
    pub width_confidence: f32,
}

impl GlueConfig {
    /// Every layer on every point: no early exit, no pruning.
    pub const EXHAUSTIVE: Self = Self {
        depth_confidence: -1.0,
        width_confidence: -1.0,
    };

    /// Checks that both values are finite and below 1 (1 would stop or prune nothing ever, and
    /// is rejected as a likely mistake for 0.99).
    pub fn validate(&self) -> Result<()> {
        for (what, v) in [
            ("depth_confidence", self.depth_confidence),
            ("width_confidence", self.width_confidence),
        ] {
            if !v.is_finite() || v >= 1.0 {
                return Err(RunnerError::invalid(
                    what,
                    format!("{v} must be finite and below 1 (≤ 0 turns the rule off)"),
                ));
            }
        }
        Ok(())
    }
}

/// What the loop did on one pair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GlueTrace {
    /// The layers run (L when there was no early exit).
    pub layers: usize,
    /// Points of image A that went into each layer run.
    pub points0: Vec<usize>,
    /// Points of image B that went into each layer run.
    pub points1: Vec<usize>,
}

/// kornia's `LightGlue.confidence_threshold`: 0.8 + 0.1·exp(−4i/L), clipped to [0, 1].
pub fn confidence_threshold(layer: usize, layers: usize) -> f32 {
    let t = 0.8 + 0.1 * (-4.0 * layer as f64 / layers as f64).exp();
    t.clamp(0.0, 1.0) as f32
}

/// kornia's `check_if_stop`: whether `1 − #{token < threshold} / total > depth_confidence`
/// (float32, as kornia), with `total` the original number of points of both images.
pub fn should_stop(
    token0: &[f32],
    token1: &[f32],
    threshold: f32,
    total: usize,
    depth_confidence: f32,
) -> bool {
    let unconfident = token0
        .iter()
        .chain(token1)
        .filter(|&&t| t < threshold)
        .count();
    let ratio = 1.0f32 - unconfident as f32 / total as f32;
    ratio > depth_confidence
}

/// kornia's `get_pruning_mask`: the indices of the points kept, those with
/// `matchability > 1 − width_confidence` or (with tokens) `token ≤ threshold`.
pub fn kept_points(
    matchability: &[f32],
    token: Option<&[f32]>,
    threshold: f32,
    width_confidence: f32,
) -> Vec<usize> {
    let cut = (1.0 - width_confidence as f64) as f32;
    (0..matchability.len())
        .filter(|&k| matchability[k] > cut || token.is_some_and(|t| t[k] <= threshold))
        .collect()
}

/// The rows `keep` of a row-major buffer of rows of `width` values.
fn gather_rows(data: &[f32], width: usize, keep: &[usize]) -> Vec<f32> {
    let mut out = Vec::with_capacity(keep.len() * width);
    for &k in keep {
        out.extend_from_slice(&data[k * width..(k + 1) * width]);
    }
    out
}

/// One image's state in the loop: descriptors (n × dim), encodings (n × head_dim) and the
/// original index of each row.
struct Side {
    desc: Vec<f32>,
    cos: Vec<f32>,
    sin: Vec<f32>,
    index: Vec<usize>,
}

impl Side {
    fn len(&self) -> usize {
        self.index.len()
    }

    fn keep(&mut self, keep: &[usize], dim: usize, head_dim: usize) {
        if keep.len() == self.len() {
            return;
        }
        self.desc = gather_rows(&self.desc, dim, keep);
        self.cos = gather_rows(&self.cos, head_dim, keep);
        self.sin = gather_rows(&self.sin, head_dim, keep);
        self.index = keep.iter().map(|&k| self.index[k]).collect();
    }
}

#[derive(Debug)]
struct Pieces {
    encode: Session,
    layer: Session,
    assign: Session,
}

/// The sizes of a LightGlue, from its pieces' metadata.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GlueDims {
    /// Input descriptor length D_in (64 for XFeat).
    pub input_dim: usize,
    /// Embedding length D (96 for LighterGlue, 256 for LightGlue).
    pub dim: usize,
    /// Attention heads.
    pub heads: usize,
    /// D / heads: the length of the rotary encoding.
    pub head_dim: usize,
    /// Transformer layers L.
    pub layers: usize,
}

/// LightGlue over its three pieces, with the adaptive loop.
#[derive(Debug)]
pub struct AdaptiveGlue {
    pieces: Mutex<Pieces>,
    dims: GlueDims,
    thresholds: Vec<f32>,
    defaults: GlueConfig,
    min_conf: f32,
    metadata: BTreeMap<String, String>,
    source: String,
}

/// The three files of a LightGlue in pieces.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GluePieceFiles {
    /// `matcher-lightglue-encode-v1`.
    pub encode: PathBuf,
    /// `matcher-lightglue-layer-v1`.
    pub layer: PathBuf,
    /// `matcher-lightglue-assign-v1`.
    pub assign: PathBuf,
}

impl GluePieceFiles {
    /// The pieces beside a full model `dir/name.onnx`: `dir/name_encode.onnx`,
    /// `dir/name_layer.onnx`, `dir/name_assign.onnx`.
    pub fn beside(full_model: &Path) -> Self {
        let stem = full_model
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let f = |piece: &str| full_model.with_file_name(format!("{stem}_{piece}.onnx"));
        Self {
            encode: f("encode"),
            layer: f("layer"),
            assign: f("assign"),
        }
    }

    /// Whether all three files exist.
    pub fn exist(&self) -> bool {
        [&self.encode, &self.layer, &self.assign]
            .iter()
            .all(|p| p.is_file())
    }
}

fn dims_of(model: &CheckedModel, spec: &ContractSpec) -> Result<GlueDims> {
    let dims = GlueDims {
        input_dim: model.meta_usize(spec, "affcorr.descriptor_dim")?,
        dim: model.meta_usize(spec, "affcorr.embedding_dim")?,
        heads: model.meta_usize(spec, "affcorr.heads")?,
        head_dim: model.meta_usize(spec, "affcorr.head_dim")?,
        layers: model.meta_usize(spec, "affcorr.layers")?,
    };
    if dims.heads * dims.head_dim != dims.dim {
        return Err(model.violation(
            spec,
            format!(
                "metadata says {} heads of {} for an embedding of {}",
                dims.heads, dims.head_dim, dims.dim
            ),
        ));
    }
    Ok(dims)
}

impl AdaptiveGlue {
    /// Loads and checks the three pieces (`threads` intra-op threads each; `None`: every core).
    /// They must agree on every size.
    pub fn load(files: &GluePieceFiles, threads: Option<usize>) -> Result<Self> {
        let threads = contract::resolve_threads(threads)?;
        let encode = contract::load(&files.encode, threads, &GLUE_ENCODE_SPEC)?;
        let layer = contract::load(&files.layer, threads, &GLUE_LAYER_SPEC)?;
        let assign = contract::load(&files.assign, threads, &GLUE_ASSIGN_SPEC)?;
        let dims = dims_of(&layer, &GLUE_LAYER_SPEC)?;
        for (m, spec) in [(&encode, &GLUE_ENCODE_SPEC), (&assign, &GLUE_ASSIGN_SPEC)] {
            let d = dims_of(m, spec)?;
            if d != dims {
                return Err(m.violation(
                    spec,
                    format!("its sizes {d:?} differ from the layer model's {dims:?}"),
                ));
            }
        }
        let spec = &GLUE_LAYER_SPEC;
        let thresholds: Vec<f32> = layer
            .meta_list(spec, "affcorr.glue.confidence_thresholds", |t| {
                (0.0..=1.0).contains(&t)
            })?
            .into_iter()
            .map(|t| t as f32)
            .collect();
        if thresholds.len() != dims.layers {
            return Err(layer.violation(
                spec,
                format!(
                    "{} confidence thresholds for {} layers",
                    thresholds.len(),
                    dims.layers
                ),
            ));
        }
        let conf = |key| layer.meta_f64(spec, key, |c| c < 1.0).map(|c| c as f32);
        let defaults = GlueConfig {
            depth_confidence: conf("affcorr.glue.depth_confidence")?,
            width_confidence: conf("affcorr.glue.width_confidence")?,
        };
        let min_conf =
            layer.meta_f64(spec, "affcorr.min_conf", |c| (0.0..1.0).contains(&c))? as f32;
        let CheckedModel {
            session: layer,
            metadata,
            source,
        } = layer;
        Ok(Self {
            pieces: Mutex::new(Pieces {
                encode: encode.session,
                layer,
                assign: assign.session,
            }),
            dims,
            thresholds,
            defaults,
            min_conf,
            metadata,
            source,
        })
    }

    /// The sizes.
    pub fn dims(&self) -> GlueDims {
        self.dims
    }

    /// The per-layer confidence thresholds t_i (metadata).
    pub fn thresholds(&self) -> &[f32] {
        &self.thresholds
    }

    /// The configuration the metadata recommends (LightGlue's depth 0.95, the model's width).
    pub fn default_config(&self) -> GlueConfig {
        self.defaults
    }

    /// The match threshold from the metadata (0.1).
    pub fn min_conf(&self) -> f32 {
        self.min_conf
    }

    /// The layer model's custom metadata.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The layer model's file path in backquotes.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Matches of `kpts0` (M × 2, normalised) with `desc0` (M × D_in) and `kpts1`, `desc1`
    /// under `config`: mutual pairs with `mscores0 > min_conf`, and what the loop did.
    pub fn run(
        &self,
        kpts0: &[f32],
        desc0: &[f32],
        kpts1: &[f32],
        desc1: &[f32],
        min_conf: f32,
        config: &GlueConfig,
    ) -> Result<(GlueMatches, GlueTrace)> {
        config.validate()?;
        let GlueDims {
            input_dim,
            dim,
            head_dim,
            layers,
            ..
        } = self.dims;
        for (what, k, desc) in [("kpts0", kpts0, desc0), ("kpts1", kpts1, desc1)] {
            if k.len() % 2 != 0 || desc.len() != k.len() / 2 * input_dim {
                return Err(RunnerError::invalid(
                    what,
                    format!(
                        "{} keypoint values with {} descriptor values (D = {input_dim})",
                        k.len(),
                        desc.len()
                    ),
                ));
            }
        }
        let (m, n) = (kpts0.len() / 2, kpts1.len() / 2);
        let mut trace = GlueTrace::default();
        if m == 0 || n == 0 {
            return Ok((GlueMatches::default(), trace));
        }
        let mut guard = self
            .pieces
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let pieces = &mut *guard;
        let mut a = encode(&mut pieces.encode, kpts0, desc0, self.dims)?;
        let mut b = encode(&mut pieces.encode, kpts1, desc1, self.dims)?;
        let depth = config.depth_confidence > 0.0;
        let width = config.width_confidence > 0.0;
        let mut stop = 0;
        for i in 0..layers {
            stop = i;
            trace.points0.push(a.len());
            trace.points1.push(b.len());
            let (t0, t1, p0, p1) = run_layer(&mut pieces.layer, i, &mut a, &mut b, dim, head_dim)?;
            if i == layers - 1 {
                break;
            }
            let th = self.thresholds[i];
            if depth && should_stop(&t0, &t1, th, m + n, config.depth_confidence) {
                break;
            }
            if width {
                let k0 = kept_points(&p0, depth.then_some(&t0[..]), th, config.width_confidence);
                let k1 = kept_points(&p1, depth.then_some(&t1[..]), th, config.width_confidence);
                if k0.is_empty() || k1.is_empty() {
                    trace.layers = i + 1;
                    return Ok((GlueMatches::default(), trace));
                }
                a.keep(&k0, dim, head_dim);
                b.keep(&k1, dim, head_dim);
            }
        }
        trace.layers = stop + 1;
        let (m0, s0) = assign(&mut pieces.assign, stop, &a, &b, dim)?;
        let mut out = GlueMatches::default();
        for (r, (&j, &s)) in m0.iter().zip(&s0).enumerate() {
            if j >= 0 && s > min_conf {
                let j = j as usize;
                if j >= b.len() {
                    return Err(RunnerError::ModelOutput {
                        what: "matches0",
                        reason: format!("row {r} matches point {j} of {}", b.len()),
                    });
                }
                out.idx0.push(a.index[r]);
                out.idx1.push(b.index[j]);
                out.score.push(s);
            }
        }
        Ok((out, trace))
    }
}

fn wrap<'a>(shape: [usize; 3], data: &'a [f32], what: &str) -> Result<TensorRef<'a, f32>> {
    TensorRef::from_array_view((shape, data))
        .map_err(|e| RunnerError::ort(format!("wrapping {what}"), e))
}

fn encode(session: &mut Session, kpts: &[f32], desc: &[f32], dims: GlueDims) -> Result<Side> {
    let n = kpts.len() / 2;
    let outputs = session
        .run(ort::inputs![
            "keypoints" => wrap([1, n, 2], kpts, "keypoints")?,
            "descriptors" => wrap([1, n, dims.input_dim], desc, "descriptors")?,
        ])
        .map_err(|e| RunnerError::ort("running the LightGlue encoder", e))?;
    let (n64, d, h) = (n as i64, dims.dim as i64, dims.head_dim as i64);
    Ok(Side {
        desc: contract::output::<f32>(&outputs, "desc", &[1, n64, d])?.to_vec(),
        cos: contract::output::<f32>(&outputs, "cos", &[1, n64, h])?.to_vec(),
        sin: contract::output::<f32>(&outputs, "sin", &[1, n64, h])?.to_vec(),
        index: (0..n).collect(),
    })
}

type Heads = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>);

/// Runs layer `i` on both sides in place; returns (token0, token1, match0, match1).
fn run_layer(
    session: &mut Session,
    i: usize,
    a: &mut Side,
    b: &mut Side,
    dim: usize,
    head_dim: usize,
) -> Result<Heads> {
    let (m, n) = (a.len(), b.len());
    let layer = [i as i64];
    let layer = TensorRef::from_array_view(([1usize], &layer[..]))
        .map_err(|e| RunnerError::ort("wrapping layer", e))?;
    let outputs = session
        .run(ort::inputs![
            "layer" => layer,
            "desc0" => wrap([1, m, dim], &a.desc, "desc0")?,
            "desc1" => wrap([1, n, dim], &b.desc, "desc1")?,
            "cos0" => wrap([1, m, head_dim], &a.cos, "cos0")?,
            "sin0" => wrap([1, m, head_dim], &a.sin, "sin0")?,
            "cos1" => wrap([1, n, head_dim], &b.cos, "cos1")?,
            "sin1" => wrap([1, n, head_dim], &b.sin, "sin1")?,
        ])
        .map_err(|e| RunnerError::ort(format!("running LightGlue layer {i}"), e))?;
    let (m64, n64, d) = (m as i64, n as i64, dim as i64);
    a.desc = contract::output::<f32>(&outputs, "desc0_out", &[1, m64, d])?.to_vec();
    b.desc = contract::output::<f32>(&outputs, "desc1_out", &[1, n64, d])?.to_vec();
    let get = |name, len| contract::output::<f32>(&outputs, name, &[1, len]).map(<[f32]>::to_vec);
    Ok((
        get("token0", m64)?,
        get("token1", n64)?,
        get("match0", m64)?,
        get("match1", n64)?,
    ))
}

fn assign(
    session: &mut Session,
    i: usize,
    a: &Side,
    b: &Side,
    dim: usize,
) -> Result<(Vec<i64>, Vec<f32>)> {
    let (m, n) = (a.len(), b.len());
    let layer = [i as i64];
    let layer = TensorRef::from_array_view(([1usize], &layer[..]))
        .map_err(|e| RunnerError::ort("wrapping layer", e))?;
    let outputs = session
        .run(ort::inputs![
            "layer" => layer,
            "desc0" => wrap([1, m, dim], &a.desc, "desc0")?,
            "desc1" => wrap([1, n, dim], &b.desc, "desc1")?,
        ])
        .map_err(|e| RunnerError::ort("running the LightGlue assignment", e))?;
    let m0 = contract::output::<i64>(&outputs, "matches0", &[1, m as i64])?.to_vec();
    let s0 = contract::output::<f32>(&outputs, "mscores0", &[1, m as i64])?.to_vec();
    Ok((m0, s0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_are_kornias() {
        // 0.8 + 0.1 * exp(-4 i / 6) for i = 0..6
        let want = [
            0.9,
            0.851_341_7,
            0.826_359_2,
            0.813_533_5,
            0.806_948_5,
            0.803_567_6,
        ];
        for (i, w) in want.iter().enumerate() {
            assert!((confidence_threshold(i, 6) - w).abs() < 1e-6, "layer {i}");
        }
    }

    #[test]
    fn stop_counts_unconfident_points_over_the_original_total() {
        // 2 of 5 remaining points below 0.9; original total 40: ratio 1 - 2/40 = 0.95, not > 0.95
        let t0 = [0.95, 0.5, 0.91];
        let t1 = [0.2, 0.99];
        assert!(!should_stop(&t0, &t1, 0.9, 40, 0.95));
        assert!(should_stop(&t0, &t1, 0.9, 41, 0.95));
        // a token equal to the threshold is confident (the rule is token < threshold)
        assert!(should_stop(&[0.9], &[0.9], 0.9, 2, 0.95));
    }

    #[test]
    fn pruning_keeps_matchable_and_unsure_points() {
        let p = [0.04, 0.06, 0.05, 0.5];
        // width 0.95: keep matchability > 0.05 (0.05 itself is pruned)
        assert_eq!(kept_points(&p, None, 0.9, 0.95), vec![1, 3]);
        // with tokens: a point with token <= threshold is never pruned
        let t = [0.95, 0.1, 0.9, 0.99];
        assert_eq!(kept_points(&p, Some(&t), 0.9, 0.95), vec![1, 2, 3]);
    }

    #[test]
    fn gathering_rows_keeps_the_original_indices() {
        let mut s = Side {
            desc: (0..8).map(|v| v as f32).collect(),
            cos: vec![0.0, 1.0, 2.0, 3.0],
            sin: vec![4.0, 5.0, 6.0, 7.0],
            index: vec![10, 11, 12, 13],
        };
        s.keep(&[1, 3], 2, 1);
        assert_eq!(s.desc, vec![2.0, 3.0, 6.0, 7.0]);
        assert_eq!(
            (s.cos.clone(), s.sin.clone()),
            (vec![1.0, 3.0], vec![5.0, 7.0])
        );
        assert_eq!(s.index, vec![11, 13]);
    }

    #[test]
    fn configs_are_validated() {
        assert!(GlueConfig::EXHAUSTIVE.validate().is_ok());
        let bad = GlueConfig {
            depth_confidence: 1.0,
            width_confidence: 0.95,
        };
        assert!(bad.validate().is_err());
        let nan = GlueConfig {
            depth_confidence: 0.95,
            width_confidence: f32::NAN,
        };
        assert!(nan.validate().is_err());
    }

    #[test]
    fn pieces_are_found_beside_the_full_model() {
        let f = GluePieceFiles::beside(Path::new("/m/xfeat_lighterglue.onnx"));
        assert_eq!(f.layer, Path::new("/m/xfeat_lighterglue_layer.onnx"));
        assert_eq!(f.encode, Path::new("/m/xfeat_lighterglue_encode.onnx"));
        assert_eq!(f.assign, Path::new("/m/xfeat_lighterglue_assign.onnx"));
    }
}
