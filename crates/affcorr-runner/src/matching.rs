//! Matching XFeat features: mutual nearest neighbours, the XFeat* refinement model
//! (`features-refine-v1`) and LighterGlue (`matcher-lighterglue-v1`) (docs/matchers.md).
//!
//! - [`mutual_nearest_neighbours`]: dot products of all descriptor pairs (cosine similarity for
//!   L2-normalised descriptors), the best match both ways (the first maximum on ties, as
//!   numpy's `argmax`), kept when mutual. The similarity matrix is computed in blocks of rows
//!   with `matrixmultiply`'s SGEMM, in parallel (rayon), and never held whole.
//! - [`RefineModel`]: offsets and confidences of coarse semi-dense matches; [`refine_matches`]
//!   moves the image-A point by offset · (1/s) and keeps confidence > 0.25.
//! - [`LighterGlue`]: keypoints normalised by [`normalize_keypoints_lighterglue`], matches
//!   `matches0 ≥ 0` with `mscores0 > min_conf`; by default LightGlue's adaptive loop over the
//!   network in pieces ([`crate::lightglue`]), else the one-graph network ([`GlueMode`]).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;

use ndarray::{Array2, ArrayView2};
use ort::session::{OutputSelector, RunOptions, Session};
use ort::value::TensorRef;
use rayon::prelude::*;

use crate::contract::{self, CheckedModel, LIGHTERGLUE_SPEC, REFINE_SPEC};
use crate::error::{Result, RunnerError};
use crate::lightglue::{AdaptiveGlue, GlueConfig, GluePieceFiles, GlueTrace};

/// Rows of the similarity matrix computed per block.
const MNN_BLOCK: usize = 256;

/// Mutual nearest-neighbour matches: `idx1[k]` ↔ `idx2[k]` with their similarity.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MnnMatches {
    /// Row indices into the first descriptor set, increasing.
    pub idx1: Vec<usize>,
    /// Row indices into the second set.
    pub idx2: Vec<usize>,
    /// The dot product of each pair.
    pub similarity: Vec<f32>,
}

impl MnnMatches {
    /// The number of matches.
    pub fn len(&self) -> usize {
        self.idx1.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.idx1.is_empty()
    }
}

/// The best column (first maximum) of each row of a block, and the best row (first maximum)
/// of each column within the block.
struct BlockBest {
    row_arg: Vec<usize>,
    row_max: Vec<f32>,
    col_arg: Vec<usize>,
    col_max: Vec<f32>,
}

/// `XFeat.match` (`match_mnn` of the reference): mutual nearest neighbours of the rows of `d1`
/// (n1 × dim) and `d2` (n2 × dim) under the dot product, with no threshold.
pub fn mutual_nearest_neighbours(d1: &[f32], d2: &[f32], dim: usize) -> MnnMatches {
    assert!(dim > 0, "descriptor dimension must be positive");
    assert!(
        d1.len().is_multiple_of(dim) && d2.len().is_multiple_of(dim),
        "descriptor buffers must hold whole rows"
    );
    let (n1, n2) = (d1.len() / dim, d2.len() / dim);
    if n1 == 0 || n2 == 0 {
        return MnnMatches::default();
    }
    let b = ArrayView2::from_shape((n2, dim), d2).expect("shape checked");
    let bt = b.t();
    let blocks: Vec<BlockBest> = d1
        .par_chunks(MNN_BLOCK * dim)
        .enumerate()
        .map(|(k, chunk)| {
            let rows = chunk.len() / dim;
            let a = ArrayView2::from_shape((rows, dim), chunk).expect("shape checked");
            let mut s = Array2::<f32>::zeros((rows, n2));
            ndarray::linalg::general_mat_mul(1.0, &a, &bt, 0.0, &mut s);
            let mut best = BlockBest {
                row_arg: vec![0; rows],
                row_max: vec![f32::NEG_INFINITY; rows],
                col_arg: vec![0; n2],
                col_max: vec![f32::NEG_INFINITY; n2],
            };
            for (r, row) in s.rows().into_iter().enumerate() {
                let row = row.as_slice().expect("standard layout");
                let (mut arg, mut max) = (0, f32::NEG_INFINITY);
                for (j, &v) in row.iter().enumerate() {
                    if v > max {
                        (arg, max) = (j, v);
                    }
                    if v > best.col_max[j] {
                        best.col_max[j] = v;
                        best.col_arg[j] = k * MNN_BLOCK + r;
                    }
                }
                best.row_arg[r] = arg;
                best.row_max[r] = max;
            }
            best
        })
        .collect();
    // Columns: the first block with the largest value wins (first maximum overall).
    let mut col_arg = vec![0usize; n2];
    let mut col_max = vec![f32::NEG_INFINITY; n2];
    for blk in &blocks {
        for j in 0..n2 {
            if blk.col_max[j] > col_max[j] {
                col_max[j] = blk.col_max[j];
                col_arg[j] = blk.col_arg[j];
            }
        }
    }
    let mut out = MnnMatches::default();
    for (k, blk) in blocks.iter().enumerate() {
        for (r, (&j, &v)) in blk.row_arg.iter().zip(&blk.row_max).enumerate() {
            let i = k * MNN_BLOCK + r;
            if col_arg[j] == i {
                out.idx1.push(i);
                out.idx2.push(j);
                out.similarity.push(v);
            }
        }
    }
    out
}

// ------------------------------------------------------------------------------ XFeat*

/// The XFeat* refinement MLP, checked against `features-refine-v1`.
#[derive(Debug)]
pub struct RefineModel {
    session: Mutex<Session>,
    dim: usize,
    min_confidence: f32,
    metadata: BTreeMap<String, String>,
    source: String,
}

/// Sub-pixel offsets of coarse matches.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Refinement {
    /// (dx, dy) in coarse pixels of the scale the image-A point came from.
    pub offset: Vec<[f32; 2]>,
    /// The largest probability of the offset distribution.
    pub confidence: Vec<f32>,
}

impl RefineModel {
    /// Loads and checks a refinement model (`threads` intra-op threads; `None`: every core).
    pub fn load(path: impl AsRef<Path>, threads: Option<usize>) -> Result<Self> {
        let threads = contract::resolve_threads(threads)?;
        let model = contract::load(path.as_ref(), threads, &REFINE_SPEC)?;
        let dim = model.meta_usize(&REFINE_SPEC, "affcorr.descriptor_dim")?;
        let grid = model.meta_usize(&REFINE_SPEC, "affcorr.refine.grid")?;
        if grid != 8 {
            return Err(model.violation(
                &REFINE_SPEC,
                format!("metadata affcorr.refine.grid is {grid}; the 64 logits are an 8×8 grid"),
            ));
        }
        model.meta_f64(&REFINE_SPEC, "affcorr.refine.temperature", |t| t > 0.0)?;
        let min_confidence = model.meta_f64(&REFINE_SPEC, "affcorr.refine.confidence", |c| {
            (0.0..=1.0).contains(&c)
        })? as f32;
        let CheckedModel {
            session,
            metadata,
            source,
        } = model;
        Ok(Self {
            session: Mutex::new(session),
            dim,
            min_confidence,
            metadata,
            source,
        })
    }

    /// Descriptor length D (the input is N × 2D).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Matches are kept when their confidence exceeds this (metadata, 0.25).
    pub fn min_confidence(&self) -> f32 {
        self.min_confidence
    }

    /// All custom metadata.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The model's file path in backquotes.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Offsets and confidences of `pair_feats` (N × 2D: raw descriptor in A, raw in B).
    pub fn run(&self, pair_feats: &[f32]) -> Result<Refinement> {
        let w = 2 * self.dim;
        if !pair_feats.len().is_multiple_of(w) {
            return Err(RunnerError::invalid(
                "pair_feats",
                format!(
                    "{} values is not a whole number of rows of {w}",
                    pair_feats.len()
                ),
            ));
        }
        let n = pair_feats.len() / w;
        if n == 0 {
            return Ok(Refinement::default());
        }
        let tensor = TensorRef::from_array_view(([n, w], pair_feats))
            .map_err(|e| RunnerError::ort("wrapping pair_feats", e))?;
        let options = RunOptions::new()
            .map_err(|e| RunnerError::ort("creating run options", e))?
            .with_outputs(
                OutputSelector::no_default()
                    .with("offset")
                    .with("confidence"),
            );
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let outputs = session
            .run_with_options(ort::inputs!["pair_feats" => tensor], &options)
            .map_err(|e| RunnerError::ort("running the refinement model", e))?;
        let offset = contract::output::<f32>(&outputs, "offset", &[n as i64, 2])?;
        let confidence = contract::output::<f32>(&outputs, "confidence", &[n as i64])?;
        Ok(Refinement {
            offset: offset.chunks_exact(2).map(|o| [o[0], o[1]]).collect(),
            confidence: confidence.to_vec(),
        })
    }
}

/// `XFeat.refine_matches`: x1 += offset · inv_scale1 (the 1/s of x1's scale); matches with
/// confidence > `min_confidence` are kept. Returns the indices kept.
pub fn refine_matches(
    x1: &mut [[f32; 2]],
    inv_scale1: &[f32],
    refinement: &Refinement,
    min_confidence: f32,
) -> Vec<usize> {
    for ((p, o), s) in x1.iter_mut().zip(&refinement.offset).zip(inv_scale1) {
        p[0] += o[0] * s;
        p[1] += o[1] * s;
    }
    (0..x1.len())
        .filter(|&i| refinement.confidence[i] > min_confidence)
        .collect()
}

// ------------------------------------------------------------------------------ LighterGlue

/// kornia's `normalize_keypoints`: (xy − (W, H)/2) / (max(W, H)/2), float32.
pub fn normalize_keypoints_lighterglue(kpts: &[[f32; 2]], size_wh: (usize, usize)) -> Vec<f32> {
    let (w, h) = (size_wh.0 as f32, size_wh.1 as f32);
    let half = w.max(h) / 2.0;
    let (cx, cy) = (w / 2.0, h / 2.0);
    kpts.iter()
        .flat_map(|&[x, y]| [(x - cx) / half, (y - cy) / half])
        .collect()
}

/// LighterGlue's matches: `idx0[k]` ↔ `idx1[k]` with confidence `score[k]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GlueMatches {
    /// Indices into the keypoints of image A, increasing.
    pub idx0: Vec<usize>,
    /// Indices into the keypoints of image B.
    pub idx1: Vec<usize>,
    /// `mscores0`: exp of the log assignment of the pair.
    pub score: Vec<f32>,
}

/// Which LighterGlue network runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GlueMode {
    /// The pieces (`matcher-lightglue-*-v1`) with the adaptive layer loop in Rust
    /// ([`crate::lightglue`]): early exit and point pruning.
    Adaptive,
    /// The one-graph network (`matcher-lighterglue-v1`): every layer, XFeat's pruning (width
    /// 0.95) inside the graph.
    Full,
}

/// How [`LighterGlue::load_with`] chooses its network; `None` fields take the defaults.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LighterGlueOptions {
    /// `None`: adaptive when the pieces lie beside the model file
    /// ([`GluePieceFiles::beside`]), else the full graph.
    pub mode: Option<GlueMode>,
    /// The adaptive loop's early-exit rule (`None`: the pieces' metadata, 0.95; ≤ 0: off).
    pub depth_confidence: Option<f32>,
    /// The adaptive loop's pruning rule (`None`: the pieces' metadata, 0.95; ≤ 0: off).
    pub width_confidence: Option<f32>,
}

impl LighterGlueOptions {
    /// The environment's overrides, for benchmarks and parity checks without an API change:
    /// `AFFCORR_LIGHTERGLUE` = `full` | `adaptive`, `AFFCORR_LIGHTERGLUE_DEPTH` and
    /// `AFFCORR_LIGHTERGLUE_WIDTH` (numbers). Unset variables are `None`; bad values are
    /// errors that name the variable.
    pub fn from_env() -> Result<Self> {
        let var = |key: &str| std::env::var(key).ok().filter(|v| !v.trim().is_empty());
        let mode = match var("AFFCORR_LIGHTERGLUE").as_deref().map(str::trim) {
            None => None,
            Some(v) if v.eq_ignore_ascii_case("full") => Some(GlueMode::Full),
            Some(v) if v.eq_ignore_ascii_case("adaptive") => Some(GlueMode::Adaptive),
            Some(v) => {
                return Err(RunnerError::invalid(
                    "AFFCORR_LIGHTERGLUE",
                    format!("{v:?} is neither \"full\" nor \"adaptive\""),
                ));
            }
        };
        let number = |key: &'static str| -> Result<Option<f32>> {
            var(key)
                .map(|v| {
                    v.trim()
                        .parse::<f32>()
                        .map_err(|_| RunnerError::invalid(key, format!("{v:?} is not a number")))
                })
                .transpose()
        };
        Ok(Self {
            mode,
            depth_confidence: number("AFFCORR_LIGHTERGLUE_DEPTH")?,
            width_confidence: number("AFFCORR_LIGHTERGLUE_WIDTH")?,
        })
    }
}

#[derive(Debug)]
enum GlueNet {
    Full(Mutex<Session>),
    Adaptive(Box<AdaptiveGlue>, GlueConfig),
}

/// LighterGlue: the adaptive loop over its pieces (the default when they are shipped) or the
/// full graph checked against `matcher-lighterglue-v1`.
#[derive(Debug)]
pub struct LighterGlue {
    net: GlueNet,
    dim: usize,
    min_conf: f32,
    metadata: BTreeMap<String, String>,
    source: String,
}

impl LighterGlue {
    /// Loads and checks a LighterGlue model (`threads` intra-op threads; `None`: every core):
    /// the adaptive pieces beside `path` when they exist, else the full graph at `path`
    /// ([`LighterGlueOptions::from_env`] can override either).
    pub fn load(path: impl AsRef<Path>, threads: Option<usize>) -> Result<Self> {
        Self::load_with(path, threads, &LighterGlueOptions::from_env()?)
    }

    /// [`Self::load`] with explicit options (the environment is not read).
    pub fn load_with(
        path: impl AsRef<Path>,
        threads: Option<usize>,
        options: &LighterGlueOptions,
    ) -> Result<Self> {
        let path = path.as_ref();
        let pieces = GluePieceFiles::beside(path);
        let mode = options.mode.unwrap_or(if pieces.exist() {
            GlueMode::Adaptive
        } else {
            GlueMode::Full
        });
        match mode {
            GlueMode::Full => Self::load_full(path, threads),
            GlueMode::Adaptive => {
                contract::check_model_file(path)?;
                Self::load_pieces(&pieces, threads, options)
            }
        }
    }

    /// The adaptive loop over the three pieces `files` alone (a LightGlue exported only in
    /// pieces, as DISK's); `options.mode` is ignored. A missing piece is a
    /// [`RunnerError::ModelOpen`] that names it.
    pub fn load_pieces(
        files: &GluePieceFiles,
        threads: Option<usize>,
        options: &LighterGlueOptions,
    ) -> Result<Self> {
        for p in [&files.encode, &files.layer, &files.assign] {
            contract::check_model_file(p)?;
        }
        let glue = AdaptiveGlue::load(files, threads)?;
        let d = glue.default_config();
        let config = GlueConfig {
            depth_confidence: options.depth_confidence.unwrap_or(d.depth_confidence),
            width_confidence: options.width_confidence.unwrap_or(d.width_confidence),
        };
        config.validate()?;
        Ok(Self {
            dim: glue.dims().input_dim,
            min_conf: glue.min_conf(),
            metadata: glue.metadata().clone(),
            source: glue.source().to_string(),
            net: GlueNet::Adaptive(Box::new(glue), config),
        })
    }

    fn load_full(path: &Path, threads: Option<usize>) -> Result<Self> {
        let threads = contract::resolve_threads(threads)?;
        let model = contract::load(path, threads, &LIGHTERGLUE_SPEC)?;
        let dim = model.meta_usize(&LIGHTERGLUE_SPEC, "affcorr.descriptor_dim")?;
        let min_conf = model.meta_f64(&LIGHTERGLUE_SPEC, "affcorr.min_conf", |c| {
            (0.0..1.0).contains(&c)
        })? as f32;
        let CheckedModel {
            session,
            metadata,
            source,
        } = model;
        Ok(Self {
            net: GlueNet::Full(Mutex::new(session)),
            dim,
            min_conf,
            metadata,
            source,
        })
    }

    /// Descriptor length D.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The confidence threshold from the metadata (0.1).
    pub fn min_conf(&self) -> f32 {
        self.min_conf
    }

    /// Which network runs.
    pub fn mode(&self) -> GlueMode {
        match self.net {
            GlueNet::Full(_) => GlueMode::Full,
            GlueNet::Adaptive(..) => GlueMode::Adaptive,
        }
    }

    /// The adaptive loop's rules (`None` for the full graph).
    pub fn config(&self) -> Option<GlueConfig> {
        match &self.net {
            GlueNet::Full(_) => None,
            GlueNet::Adaptive(_, c) => Some(*c),
        }
    }

    /// All custom metadata (the layer model's for the adaptive network).
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The model's file path in backquotes (the layer model's for the adaptive network).
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Matches between keypoints `kpts0` (M × 2, normalised by
    /// [`normalize_keypoints_lighterglue`]) with descriptors `desc0` (M × D) and `kpts1`,
    /// `desc1`: pairs with `matches0 ≥ 0` and `mscores0 > min_conf`. No keypoints on either
    /// side give no matches (the model is not run).
    pub fn run(
        &self,
        kpts0: &[f32],
        desc0: &[f32],
        kpts1: &[f32],
        desc1: &[f32],
        min_conf: f32,
    ) -> Result<GlueMatches> {
        self.run_traced(kpts0, desc0, kpts1, desc1, min_conf)
            .map(|(m, _)| m)
    }

    /// [`Self::run`] with what the adaptive loop did (`None` for the full graph).
    pub fn run_traced(
        &self,
        kpts0: &[f32],
        desc0: &[f32],
        kpts1: &[f32],
        desc1: &[f32],
        min_conf: f32,
    ) -> Result<(GlueMatches, Option<GlueTrace>)> {
        match &self.net {
            GlueNet::Full(session) => {
                run_full(session, self.dim, kpts0, desc0, kpts1, desc1, min_conf).map(|m| (m, None))
            }
            GlueNet::Adaptive(glue, config) => glue
                .run(kpts0, desc0, kpts1, desc1, min_conf, config)
                .map(|(m, t)| (m, Some(t))),
        }
    }
}

/// The full graph (`matcher-lighterglue-v1`).
fn run_full(
    session: &Mutex<Session>,
    d: usize,
    kpts0: &[f32],
    desc0: &[f32],
    kpts1: &[f32],
    desc1: &[f32],
    min_conf: f32,
) -> Result<GlueMatches> {
    let (m, n) = (kpts0.len() / 2, kpts1.len() / 2);
    for (what, k, desc) in [("kpts0", kpts0, desc0), ("kpts1", kpts1, desc1)] {
        if k.len() % 2 != 0 || desc.len() != k.len() / 2 * d {
            return Err(RunnerError::invalid(
                what,
                format!(
                    "{} keypoint values with {} descriptor values (D = {d})",
                    k.len(),
                    desc.len()
                ),
            ));
        }
    }
    if m == 0 || n == 0 {
        return Ok(GlueMatches::default());
    }
    let wrap = |shape: [usize; 3], data, what| {
        TensorRef::from_array_view((shape, data))
            .map_err(|e| RunnerError::ort(format!("wrapping {what}"), e))
    };
    let inputs = ort::inputs![
        "keypoints0" => wrap([1, m, 2], kpts0, "keypoints0")?,
        "keypoints1" => wrap([1, n, 2], kpts1, "keypoints1")?,
        "descriptors0" => wrap([1, m, d], desc0, "descriptors0")?,
        "descriptors1" => wrap([1, n, d], desc1, "descriptors1")?,
    ];
    let options = RunOptions::new()
        .map_err(|e| RunnerError::ort("creating run options", e))?
        .with_outputs(
            OutputSelector::no_default()
                .with("matches0")
                .with("mscores0"),
        );
    let mut session = session
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    let outputs = session
        .run_with_options(inputs, &options)
        .map_err(|e| RunnerError::ort("running LighterGlue", e))?;
    let m0 = contract::output::<i64>(&outputs, "matches0", &[1, m as i64])?;
    let s0 = contract::output::<f32>(&outputs, "mscores0", &[1, m as i64])?;
    let mut out = GlueMatches::default();
    for (i, (&j, &s)) in m0.iter().zip(s0).enumerate() {
        if j >= 0 && s > min_conf {
            if j as usize >= n {
                return Err(RunnerError::ModelOutput {
                    what: "matches0",
                    reason: format!("row {i} matches keypoint {j} of {n}"),
                });
            }
            out.idx0.push(i);
            out.idx1.push(j as usize);
            out.score.push(s);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference: the full matrix, argmax both ways (first maximum), mutual.
    fn brute_force(d1: &[f32], d2: &[f32], dim: usize) -> Vec<(usize, usize)> {
        let (n1, n2) = (d1.len() / dim, d2.len() / dim);
        let sim = |i: usize, j: usize| -> f32 {
            (0..dim).map(|k| d1[i * dim + k] * d2[j * dim + k]).sum()
        };
        let argmax = |vals: Vec<f32>| {
            vals.iter()
                .enumerate()
                .fold(
                    (0, f32::NEG_INFINITY),
                    |(a, m), (i, &v)| if v > m { (i, v) } else { (a, m) },
                )
                .0
        };
        let m12: Vec<usize> = (0..n1)
            .map(|i| argmax((0..n2).map(|j| sim(i, j)).collect()))
            .collect();
        let m21: Vec<usize> = (0..n2)
            .map(|j| argmax((0..n1).map(|i| sim(i, j)).collect()))
            .collect();
        (0..n1)
            .filter(|&i| m21[m12[i]] == i)
            .map(|i| (i, m12[i]))
            .collect()
    }

    #[test]
    fn mnn_on_a_permutation_with_distractors() {
        // d2 = a permutation of d1 plus noise, and extra rows; one-hot-ish integer vectors so
        // that products are exact.
        let dim = 4;
        let d1: Vec<f32> = (0..6 * dim)
            .map(|i| ((i * 7 + 3) % 5) as f32 - 2.0)
            .collect();
        let perm = [3usize, 0, 5, 1, 4, 2];
        let mut d2 = Vec::new();
        for &p in &perm {
            d2.extend_from_slice(&d1[p * dim..(p + 1) * dim]);
        }
        d2.extend_from_slice(&[9.0, -9.0, 0.0, 0.0]);
        let got = mutual_nearest_neighbours(&d1, &d2, dim);
        let want = brute_force(&d1, &d2, dim);
        assert_eq!(
            got.idx1
                .iter()
                .zip(&got.idx2)
                .map(|(&a, &b)| (a, b))
                .collect::<Vec<_>>(),
            want
        );
        for (k, (&i, &j)) in got.idx1.iter().zip(&got.idx2).enumerate() {
            let s: f32 = (0..dim).map(|c| d1[i * dim + c] * d2[j * dim + c]).sum();
            assert_eq!(got.similarity[k], s);
        }
    }

    #[test]
    fn mnn_matches_brute_force_across_blocks() {
        // More rows than one block, random unit vectors: the blocked, parallel result must be
        // the brute-force one (ties are improbable with random data).
        let dim = 8;
        let mut state = 12345u64;
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as f32 / (1u64 << 31) as f32) - 0.5
        };
        let mut d1: Vec<f32> = (0..700 * dim).map(|_| rnd()).collect();
        let mut d2: Vec<f32> = (0..650 * dim).map(|_| rnd()).collect();
        crate::features::l2_normalize_rows(&mut d1, dim);
        crate::features::l2_normalize_rows(&mut d2, dim);
        let got = mutual_nearest_neighbours(&d1, &d2, dim);
        let want = brute_force(&d1, &d2, dim);
        assert!(!want.is_empty());
        let got: Vec<(usize, usize)> = got
            .idx1
            .iter()
            .zip(&got.idx2)
            .map(|(&a, &b)| (a, b))
            .collect();
        assert_eq!(got, want);
    }

    #[test]
    fn mnn_ties_take_the_first_maximum() {
        // Rows 0 and 1 of d1 are equal: column 0's best is row 0 (first), so only (0, 0) is
        // mutual.
        let d1 = [1.0f32, 0.0, 1.0, 0.0, 0.0, 1.0];
        let d2 = [1.0f32, 0.0, 0.0, 1.0];
        let got = mutual_nearest_neighbours(&d1, &d2, 2);
        assert_eq!((got.idx1, got.idx2), (vec![0, 2], vec![0, 1]));
        assert!(mutual_nearest_neighbours(&[], &d2, 2).is_empty());
    }

    #[test]
    fn refinement_moves_image_a_points_and_filters() {
        let mut x1 = vec![[10.0f32, 20.0], [5.0, 5.0]];
        let r = Refinement {
            offset: vec![[1.0, -2.0], [0.5, 0.5]],
            confidence: vec![0.9, 0.2],
        };
        let keep = refine_matches(&mut x1, &[1.0 / 0.6, 1.0 / 1.3], &r, 0.25);
        assert_eq!(keep, vec![0]);
        assert!((x1[0][0] - (10.0 + 1.0 / 0.6)).abs() < 1e-5);
        assert!((x1[0][1] - (20.0 - 2.0 / 0.6)).abs() < 1e-5);
    }

    #[test]
    fn lighterglue_normalisation() {
        let k = normalize_keypoints_lighterglue(
            &[[0.0, 0.0], [640.0, 480.0], [320.0, 240.0]],
            (640, 480),
        );
        assert_eq!(k, vec![-1.0, -0.75, 1.0, 0.75, 0.0, 0.0]);
    }
}
