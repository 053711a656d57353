//! The shape network: its ONNX contract, inference in batches, and the decoding of its logits
//! into orientations and scales (docs/design.md §6, paper eqs. 7–11).
//!
//! # Contract `shape-v1`
//!
//! - Inputs `patch_a`, `patch_b`: float32 `(N, 1, 32, 32)`, grayscale in [0, 1] (the model
//!   normalises each patch itself), cut as [`affcorr_image::patches`] describes.
//! - Outputs `angle_logits_a`, `angle_logits_b`: float32 `(N, Kθ)`; `scale_logits_a`,
//!   `scale_logits_b`: float32 `(N, Ks)`; `residual_shape`: float32 `(N, 3)`, the residual
//!   shape A″ = (x0, x1, x2) of the pair, with 1 + x0 > 0 and 1 + x2 > 0.
//! - Custom metadata: `affcorr.contract = "shape-v1"`, `patch_size = "32"`,
//!   `angle_bins` = JSON list of Kθ bin centres in radians, `scale_bins` = JSON list of Ks
//!   linear scale factors (> 0), `decode = "softmax-mean"`.
//!
//! [`ShapeModel::load`] checks all of it (and runs the model once on one patch pair to check
//! the logits' widths when the graph leaves them symbolic) and reports every violation in one
//! [`RunnerError::Contract`].
//!
//! # Decoding (`softmax-mean`)
//!
//! With p = softmax(logits) over the bins c_k (angles) or s_k (scales):
//!
//! ```text
//! O = atan2(Σ p_k sin c_k, Σ p_k cos c_k)      (circular mean, in (−π, π])
//! S = exp(Σ p_k ln s_k)                          (geometric mean)
//! ```
//!
//! The spread of each distribution is the network's own uncertainty, kept for the AC's
//! confidence ([`affcorr_image::confidence`]): 1 − R for the angle, R = ‖Σ p_k e^{i c_k}‖ the
//! mean resultant length (0 when one bin has all the mass, 1 for a uniform one), and the
//! standard deviation of ln s under p for the scale.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;

use ort::session::Session;
use ort::value::{TensorElementType, TensorRef, ValueType};
use rayon::prelude::*;

use crate::contract;
use crate::error::{Result, RunnerError};
use affcorr_image::{PATCH_LEN, PATCH_SIZE, Patches};

/// The contract name in the `affcorr.contract` metadata.
pub const SHAPE_CONTRACT: &str = "shape-v1";
/// The model's input names, in the order of the contract.
pub const SHAPE_INPUTS: [&str; 2] = ["patch_a", "patch_b"];
/// The model's output names, in the order of the contract.
pub const SHAPE_OUTPUTS: [&str; 5] = [
    "angle_logits_a",
    "angle_logits_b",
    "scale_logits_a",
    "scale_logits_b",
    "residual_shape",
];
/// The default number of patch pairs per inference run.
pub const DEFAULT_BATCH_SIZE: usize = 512;

/// The bin centres of the orientation and scale classifiers, with what decoding needs.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeBins {
    angles: Vec<f64>,
    scales: Vec<f64>,
    sin: Vec<f64>,
    cos: Vec<f64>,
    ln_scales: Vec<f64>,
    ln_scales_sq: Vec<f64>,
}

impl ShapeBins {
    /// Bins from angle centres (radians, finite, |c| ≤ 2π) and scale factors (in
    /// [`SCALE_BIN_RANGE`]);
    /// both lists non-empty.
    pub fn new(angles: Vec<f64>, scales: Vec<f64>) -> Result<Self> {
        check_bins("angle_bins", &angles, |c| {
            c.abs() <= 2.0 * std::f64::consts::PI
        })
        .map_err(|r| RunnerError::invalid("angle_bins", r))?;
        check_bins("scale_bins", &scales, scale_bin_ok)
            .map_err(|r| RunnerError::invalid("scale_bins", r))?;
        Ok(Self {
            sin: angles.iter().map(|c| c.sin()).collect(),
            cos: angles.iter().map(|c| c.cos()).collect(),
            ln_scales: scales.iter().map(|s| s.ln()).collect(),
            ln_scales_sq: scales.iter().map(|s| s.ln() * s.ln()).collect(),
            angles,
            scales,
        })
    }

    /// Angle bin centres in radians (Kθ of them).
    pub fn angles(&self) -> &[f64] {
        &self.angles
    }

    /// Scale bin centres, linear factors (Ks of them).
    pub fn scales(&self) -> &[f64] {
        &self.scales
    }

    /// O = atan2(Σ p sin c, Σ p cos c) with p = softmax(logits); `None` for non-finite logits.
    /// `logits.len()` must be Kθ.
    pub fn decode_orientation(&self, logits: &[f32]) -> Option<f64> {
        assert_eq!(logits.len(), self.angles.len(), "angle logits width");
        // atan2 is invariant to the common positive factor 1 / Σ exp, so it is not divided out.
        let ([s, c], _) = softmax_weighted_sums(logits, [&self.sin, &self.cos])?;
        Some(s.atan2(c))
    }

    /// S = exp(Σ p ln s) with p = softmax(logits); `None` for non-finite logits.
    /// `logits.len()` must be Ks.
    pub fn decode_scale(&self, logits: &[f32]) -> Option<f64> {
        assert_eq!(logits.len(), self.scales.len(), "scale logits width");
        let ([e], sum) = softmax_weighted_sums(logits, [&self.ln_scales])?;
        Some((e / sum).exp())
    }

    /// (O, 1 − R): the orientation and its spread, R = ‖Σ p e^{ic}‖ ∈ [0, 1] the mean
    /// resultant length; `None` for non-finite logits.
    pub fn decode_orientation_spread(&self, logits: &[f32]) -> Option<(f64, f64)> {
        assert_eq!(logits.len(), self.angles.len(), "angle logits width");
        let ([s, c], sum) = softmax_weighted_sums(logits, [&self.sin, &self.cos])?;
        let r = (s.hypot(c) / sum).min(1.0);
        Some((s.atan2(c), 1.0 - r))
    }

    /// (S, σ): the scale and the standard deviation of ln s under p; `None` for non-finite
    /// logits.
    pub fn decode_scale_spread(&self, logits: &[f32]) -> Option<(f64, f64)> {
        assert_eq!(logits.len(), self.scales.len(), "scale logits width");
        let ([e, e2], sum) = softmax_weighted_sums(logits, [&self.ln_scales, &self.ln_scales_sq])?;
        let mean = e / sum;
        Some((mean.exp(), (e2 / sum - mean * mean).max(0.0).sqrt()))
    }
}

fn check_bins(
    what: &str,
    values: &[f64],
    ok: impl Fn(f64) -> bool,
) -> std::result::Result<(), String> {
    if values.is_empty() {
        return Err(format!("{what} is empty"));
    }
    match values.iter().position(|&v| !(v.is_finite() && ok(v))) {
        Some(i) => Err(format!(
            "{what}[{i}] = {} is out of range (angles: radians with |c| ≤ 2π; scales: factors \
             in [1e-6, 1e6])",
            values[i]
        )),
        None => Ok(()),
    }
}

/// (Σ_k e_k w_m[k] for each m, Σ_k e_k) with e_k = exp(l_k − max l): the softmax-weighted sums
/// of `weights` before the division by Σ e. One exponential per logit, since decoding runs on every
/// pair's Kθ + Ks logits twice and the exponentials are its whole cost. `None` if any logit is
/// not finite.
fn softmax_weighted_sums<const M: usize>(
    logits: &[f32],
    weights: [&[f64]; M],
) -> Option<([f64; M], f64)> {
    if logits.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let max = logits
        .iter()
        .fold(f64::NEG_INFINITY, |m, &v| m.max(v as f64));
    let (mut acc, mut sum) = ([0.0; M], 0.0);
    for (k, &v) in logits.iter().enumerate() {
        let e = (v as f64 - max).exp();
        sum += e;
        for (a, w) in acc.iter_mut().zip(&weights) {
            *a += e * w[k];
        }
    }
    Some((acc, sum))
}

/// Options of [`ShapeModel`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShapeModelOptions {
    /// ONNX Runtime intra-op threads; `None` uses every core ([`crate::ort_env::default_threads`]).
    pub threads: Option<usize>,
    /// Patch pairs per inference run (≥ 1).
    pub batch_size: usize,
}

impl Default for ShapeModelOptions {
    fn default() -> Self {
        Self {
            threads: None,
            batch_size: DEFAULT_BATCH_SIZE,
        }
    }
}

/// The raw outputs of the network for N patch pairs, row-major.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ShapeOutputs {
    /// `(N, Kθ)`.
    pub angle_logits_a: Vec<f32>,
    /// `(N, Kθ)`.
    pub angle_logits_b: Vec<f32>,
    /// `(N, Ks)`.
    pub scale_logits_a: Vec<f32>,
    /// `(N, Ks)`.
    pub scale_logits_b: Vec<f32>,
    /// `(N, 3)`.
    pub residual_shape: Vec<f32>,
}

impl ShapeOutputs {
    fn outputs_mut(&mut self) -> [&mut Vec<f32>; 5] {
        [
            &mut self.angle_logits_a,
            &mut self.angle_logits_b,
            &mut self.scale_logits_a,
            &mut self.scale_logits_b,
            &mut self.residual_shape,
        ]
    }
}

/// Decoded per-patch orientations and scales, and the pair's residual shape.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ShapePrediction {
    /// O of each patch of image A, radians in (−π, π].
    pub orientation_a: Vec<f64>,
    /// O of each patch of image B, radians in (−π, π].
    pub orientation_b: Vec<f64>,
    /// S of each patch of image A (> 0).
    pub scale_a: Vec<f64>,
    /// S of each patch of image B (> 0).
    pub scale_b: Vec<f64>,
    /// A″ = (x0, x1, x2) of each pair.
    pub residual_shape: Vec<[f64; 3]>,
    /// 1 − R of each patch of image A's angle distribution (see the module docs), in [0, 1].
    pub angle_spread_a: Vec<f64>,
    /// 1 − R of each patch of image B's angle distribution, in [0, 1].
    pub angle_spread_b: Vec<f64>,
    /// The standard deviation of ln S under each patch of image A's scale distribution.
    pub scale_spread_a: Vec<f64>,
    /// The standard deviation of ln S under each patch of image B's scale distribution.
    pub scale_spread_b: Vec<f64>,
}

impl ShapePrediction {
    /// The network's uncertainty about each pair, both patches together, as the confidence
    /// takes it ([`affcorr_image::confidence`]): angle Σ (1 − R), scale √(σ_a² + σ_b²).
    /// A pair without spreads (a prediction not made by [`ShapeModel::decode`]) gets NaN,
    /// which the confidence takes as the widest spread.
    pub fn spread(&self) -> Vec<affcorr_image::NetworkSpread> {
        let at = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(f64::NAN);
        (0..self.len())
            .map(|i| affcorr_image::NetworkSpread {
                angle: at(&self.angle_spread_a, i) + at(&self.angle_spread_b, i),
                scale: at(&self.scale_spread_a, i).hypot(at(&self.scale_spread_b, i)),
            })
            .collect()
    }

    /// The number of pairs.
    pub fn len(&self) -> usize {
        self.orientation_a.len()
    }

    /// Whether there are no pairs.
    pub fn is_empty(&self) -> bool {
        self.orientation_a.is_empty()
    }

    /// The affine maps A = S_AB · R(O_AB) · A′(A″), row-major (a11, a12, a21, a22), with
    /// O_AB = O_B − O_A and S_AB = S_B / S_A (paper eq. 9, [`affcorr_geom::affine::synthesize`]).
    pub fn affine(&self) -> Result<Vec<[f64; 4]>> {
        (0..self.len())
            .map(|i| {
                let shape = affcorr_geom::affine::AffineShape {
                    orientation: self.orientation_b[i] - self.orientation_a[i],
                    scale: self.scale_b[i] / self.scale_a[i],
                    residual_shape: self.residual_shape[i],
                };
                let a = affcorr_geom::affine::synthesize(&shape, i)?;
                Ok(affcorr_geom::types::mat2_to_row(&a))
            })
            .collect()
    }
}

/// A loaded shape network whose contract has been checked.
///
/// Inference runs under a mutex (ONNX Runtime sessions are not re-entrant); the model is `Send`
/// and `Sync`.
#[derive(Debug)]
pub struct ShapeModel {
    session: Mutex<Session>,
    bins: ShapeBins,
    metadata: BTreeMap<String, String>,
    source: String,
    batch_size: usize,
    threads: usize,
}

impl ShapeModel {
    /// Loads and checks a model file with the default options (all cores, batches of 512).
    /// ONNX Runtime is initialised from `ORT_DYLIB_PATH` unless [`crate::init_ort`] ran before.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        Self::load_with(path, &ShapeModelOptions::default())
    }

    /// Loads and checks a model file.
    pub fn load_with(path: impl AsRef<Path>, options: &ShapeModelOptions) -> Result<Self> {
        let path = path.as_ref();
        let source = format!("`{}`", path.display());
        contract::check_model_file(path)?;
        let threads = check_options(options)?;
        let session = contract::session_builder(threads)?
            .commit_from_file(path)
            .map_err(|e| RunnerError::ModelLoad {
                model: source.clone(),
                reason: e.to_string(),
            })?;
        Self::checked(session, source, options.batch_size, threads)
    }

    /// Loads and checks a model held in memory (the bytes of an `.onnx` file).
    pub fn from_bytes(bytes: &[u8], options: &ShapeModelOptions) -> Result<Self> {
        let source = "from memory".to_string();
        let threads = check_options(options)?;
        let session = contract::session_builder(threads)?
            .commit_from_memory(bytes)
            .map_err(|e| RunnerError::ModelLoad {
                model: source.clone(),
                reason: e.to_string(),
            })?;
        Self::checked(session, source, options.batch_size, threads)
    }

    fn checked(
        mut session: Session,
        source: String,
        batch_size: usize,
        threads: usize,
    ) -> Result<Self> {
        let (bins, metadata) = check_contract(&mut session, &source)?;
        Ok(Self {
            session: Mutex::new(session),
            bins,
            metadata,
            source,
            batch_size,
            threads,
        })
    }

    /// The bin centres from the metadata.
    pub fn bins(&self) -> &ShapeBins {
        &self.bins
    }

    /// All custom metadata of the model (model card fields such as `trained`).
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The model's file path in backquotes, or `"from memory"`.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Patch pairs per inference run.
    pub fn batch_size(&self) -> usize {
        self.batch_size
    }

    /// ONNX Runtime intra-op threads.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The raw network outputs for pairs of patches, run in batches of [`Self::batch_size`].
    pub fn predict_raw(&self, patch_a: &Patches, patch_b: &Patches) -> Result<ShapeOutputs> {
        self.predict_raw_slices(patch_a.as_slice(), patch_b.as_slice())
    }

    /// [`Self::predict_raw`] on borrowed `(N, 1, 32, 32)` row-major data, for callers that hold
    /// patches in their own buffers (the Python bindings: numpy arrays, without a copy).
    pub fn predict_raw_slices(&self, patch_a: &[f32], patch_b: &[f32]) -> Result<ShapeOutputs> {
        for (name, data) in [("patch_a", patch_a), ("patch_b", patch_b)] {
            if !data.len().is_multiple_of(PATCH_LEN) {
                return Err(RunnerError::invalid(
                    name,
                    format!(
                        "{} values is not a whole number of 32x32 patches",
                        data.len()
                    ),
                ));
            }
        }
        let n = patch_a.len() / PATCH_LEN;
        if patch_b.len() / PATCH_LEN != n {
            return Err(RunnerError::invalid(
                "patch_b",
                format!("{} patches, but patch_a has {n}", patch_b.len() / PATCH_LEN),
            ));
        }
        let widths = self.widths();
        let mut out = ShapeOutputs::default();
        for (v, w) in out.outputs_mut().into_iter().zip(widths) {
            v.reserve_exact(n * w);
        }
        let mut session = self
            .session
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let mut start = 0;
        while start < n {
            let end = (start + self.batch_size).min(n);
            run_batch(
                &mut session,
                &patch_a[start * PATCH_LEN..end * PATCH_LEN],
                &patch_b[start * PATCH_LEN..end * PATCH_LEN],
                end - start,
                &widths,
                &mut out,
            )?;
            start = end;
        }
        Ok(out)
    }

    /// Orientations, scales and residual shapes for pairs of patches (see the module docs for
    /// the decoding).
    pub fn predict(&self, patch_a: &Patches, patch_b: &Patches) -> Result<ShapePrediction> {
        let raw = self.predict_raw(patch_a, patch_b)?;
        self.decode(&raw)
    }

    /// Decodes raw outputs of this model (softmax-mean; see the module docs).
    pub fn decode(&self, raw: &ShapeOutputs) -> Result<ShapePrediction> {
        let [ka, _, ks, _, _] = self.widths();
        let n = raw.residual_shape.len() / 3;
        let lens = [n * ka, n * ka, n * ks, n * ks, n * 3];
        let got = [
            raw.angle_logits_a.len(),
            raw.angle_logits_b.len(),
            raw.scale_logits_a.len(),
            raw.scale_logits_b.len(),
            raw.residual_shape.len(),
        ];
        for ((name, want), have) in SHAPE_OUTPUTS.iter().zip(lens).zip(got) {
            if want != have {
                return Err(RunnerError::ModelOutput {
                    what: name,
                    reason: format!("{have} values, expected {want} for {n} pairs"),
                });
            }
        }
        let non_finite = |what: &'static str, row: usize| RunnerError::ModelOutput {
            what,
            reason: format!("row {row} contains NaN or infinity"),
        };
        type Row = ((f64, f64), (f64, f64), (f64, f64), (f64, f64), [f64; 3]);
        let decode_row = |i: usize| -> Result<Row> {
            let angle = |v: &[f32], what| {
                self.bins
                    .decode_orientation_spread(&v[i * ka..(i + 1) * ka])
                    .ok_or_else(|| non_finite(what, i))
            };
            let scale = |v: &[f32], what| {
                self.bins
                    .decode_scale_spread(&v[i * ks..(i + 1) * ks])
                    .ok_or_else(|| non_finite(what, i))
            };
            let r = &raw.residual_shape[3 * i..3 * i + 3];
            if r.iter().any(|v| !v.is_finite()) {
                return Err(non_finite("residual_shape", i));
            }
            Ok((
                angle(&raw.angle_logits_a, "angle_logits_a")?,
                angle(&raw.angle_logits_b, "angle_logits_b")?,
                scale(&raw.scale_logits_a, "scale_logits_a")?,
                scale(&raw.scale_logits_b, "scale_logits_b")?,
                [r[0] as f64, r[1] as f64, r[2] as f64],
            ))
        };
        // Rows in parallel (the caller's rayon pool): decoding is about a tenth of the fast
        // networks' inference time, and ONNX Runtime's threads are idle meanwhile.
        let rows = (0..n)
            .into_par_iter()
            .with_min_len(64)
            .map(decode_row)
            .collect::<Vec<_>>()
            .into_iter()
            // In order, so that the error names the first bad row.
            .collect::<Result<Vec<_>>>()?;
        let mut p = ShapePrediction::default();
        for ((oa, ua), (ob, ub), (sa, va), (sb, vb), r) in rows {
            p.orientation_a.push(oa);
            p.orientation_b.push(ob);
            p.scale_a.push(sa);
            p.scale_b.push(sb);
            p.residual_shape.push(r);
            p.angle_spread_a.push(ua);
            p.angle_spread_b.push(ub);
            p.scale_spread_a.push(va);
            p.scale_spread_b.push(vb);
        }
        Ok(p)
    }

    /// Output widths in [`SHAPE_OUTPUTS`] order.
    fn widths(&self) -> [usize; 5] {
        let (ka, ks) = (self.bins.angles.len(), self.bins.scales.len());
        [ka, ka, ks, ks, 3]
    }
}

/// The largest `batch_size`: 65 536 patch pairs, 512 MiB of float32 patches per run.
pub const MAX_BATCH_SIZE: usize = 1 << 16;

/// The range of a scale bin: a factor beyond it decodes to scales no image pair has, and
/// overflows (exp of the weighted log) for the absurd ones, failing far from the model.
pub const SCALE_BIN_RANGE: (f64, f64) = (1e-6, 1e6);

fn scale_bin_ok(s: f64) -> bool {
    (SCALE_BIN_RANGE.0..=SCALE_BIN_RANGE.1).contains(&s)
}

fn check_options(options: &ShapeModelOptions) -> Result<usize> {
    if options.batch_size == 0 {
        return Err(RunnerError::invalid("batch_size", "must be at least 1"));
    }
    if options.batch_size > MAX_BATCH_SIZE {
        return Err(RunnerError::invalid(
            "batch_size",
            format!(
                "{} is over the limit of {MAX_BATCH_SIZE}",
                options.batch_size
            ),
        ));
    }
    contract::resolve_threads(options.threads)
}

/// Runs one batch of `n` pairs and appends the outputs to `out`, checking their shapes.
fn run_batch(
    session: &mut Session,
    a: &[f32],
    b: &[f32],
    n: usize,
    widths: &[usize; 5],
    out: &mut ShapeOutputs,
) -> Result<()> {
    let shape = [n, 1, PATCH_SIZE, PATCH_SIZE];
    debug_assert_eq!(a.len(), n * PATCH_LEN);
    let tensor = |data| {
        TensorRef::from_array_view((shape, data))
            .map_err(|e| RunnerError::ort("wrapping patches", e))
    };
    let inputs = ort::inputs![
        SHAPE_INPUTS[0] => tensor(a)?,
        SHAPE_INPUTS[1] => tensor(b)?,
    ];
    let outputs = session
        .run(inputs)
        .map_err(|e| RunnerError::ort("running the shape network", e))?;
    for ((name, &w), dst) in SHAPE_OUTPUTS.iter().zip(widths).zip(out.outputs_mut()) {
        let value = outputs.get(name).ok_or_else(|| RunnerError::ModelOutput {
            what: name,
            reason: "missing from the session's outputs".to_string(),
        })?;
        let (got, data) =
            value
                .try_extract_tensor::<f32>()
                .map_err(|e| RunnerError::ModelOutput {
                    what: name,
                    reason: e.to_string(),
                })?;
        if got.len() != 2 || got[0] != n as i64 || got[1] != w as i64 {
            return Err(RunnerError::ModelOutput {
                what: name,
                reason: format!("shape {got}, expected [{n}, {w}]"),
            });
        }
        dst.extend_from_slice(data);
    }
    Ok(())
}

/// Checks the whole contract; every violation goes into one [`RunnerError::Contract`].
fn check_contract(
    session: &mut Session,
    source: &str,
) -> Result<(ShapeBins, BTreeMap<String, String>)> {
    let mut problems: Vec<String> = Vec::new();

    let metadata =
        contract::read_metadata(session).map_err(|e| RunnerError::ort("reading metadata", e))?;
    let key = |k: &str| metadata.get(k).map(String::as_str);
    match key("affcorr.contract") {
        Some(SHAPE_CONTRACT) => {}
        Some(other) => problems.push(format!(
            "metadata affcorr.contract is {other:?}, expected {SHAPE_CONTRACT:?}"
        )),
        None => problems.push(format!(
            "metadata affcorr.contract is missing (expected {SHAPE_CONTRACT:?}; is this an \
             affcorr shape network?)"
        )),
    }
    match key("patch_size") {
        Some("32") => {}
        Some(other) => problems.push(format!("metadata patch_size is {other:?}, expected \"32\"")),
        None => problems.push("metadata patch_size is missing (expected \"32\")".to_string()),
    }
    match key("decode") {
        Some("softmax-mean") => {}
        Some(other) => problems.push(format!(
            "metadata decode is {other:?}, expected \"softmax-mean\""
        )),
        None => problems.push("metadata decode is missing (expected \"softmax-mean\")".to_string()),
    }
    let angles = parse_bins(key("angle_bins"), "angle_bins", &mut problems, |c| {
        c.abs() <= 2.0 * std::f64::consts::PI
    });
    let scales = parse_bins(key("scale_bins"), "scale_bins", &mut problems, scale_bin_ok);
    let bins = match (angles, scales) {
        (Some(a), Some(s)) => ShapeBins::new(a, s).ok(),
        _ => None,
    };
    let widths = bins.as_ref().map(|b| {
        [
            b.angles.len(),
            b.angles.len(),
            b.scales.len(),
            b.scales.len(),
            3,
        ]
    });

    // Inputs: exactly patch_a and patch_b, float32 (N, 1, 32, 32).
    let input_names: Vec<String> = session
        .inputs()
        .iter()
        .map(|o| o.name().to_string())
        .collect();
    for name in SHAPE_INPUTS {
        match session.inputs().iter().find(|o| o.name() == name) {
            None => problems.push(format!(
                "input {name} is missing (the model's inputs are {input_names:?})"
            )),
            Some(o) => {
                if let Err(r) =
                    check_tensor(o.dtype(), &[-1, 1, PATCH_SIZE as i64, PATCH_SIZE as i64])
                {
                    problems.push(format!("input {name}: {r}"));
                }
            }
        }
    }
    for name in &input_names {
        if !SHAPE_INPUTS.contains(&name.as_str()) {
            problems.push(format!(
                "unexpected input {name} (only patch_a and patch_b are fed)"
            ));
        }
    }
    // Outputs: the five, float32 (N, width); other outputs are ignored.
    let output_names: Vec<String> = session
        .outputs()
        .iter()
        .map(|o| o.name().to_string())
        .collect();
    for (i, name) in SHAPE_OUTPUTS.iter().enumerate() {
        match session.outputs().iter().find(|o| o.name() == *name) {
            None => problems.push(format!(
                "output {name} is missing (the model's outputs are {output_names:?})"
            )),
            Some(o) => {
                let width = widths.map_or(-1, |w| w[i] as i64);
                if let Err(r) = check_tensor(o.dtype(), &[-1, width]) {
                    problems.push(format!("output {name}: {r}{}", bins_hint(name)));
                }
            }
        }
    }

    // Symbolic widths are only known by running the model: one pair of gray patches.
    if problems.is_empty()
        && let Some(widths) = widths
    {
        let probe = vec![0.5f32; PATCH_LEN];
        let mut out = ShapeOutputs::default();
        if let Err(e) = run_batch(session, &probe, &probe, 1, &widths, &mut out) {
            problems.push(match e {
                RunnerError::ModelOutput { what, reason } => {
                    format!(
                        "output {what} on one patch pair: {reason}{}",
                        bins_hint(what)
                    )
                }
                other => format!("running the model on one patch pair failed: {other}"),
            });
        }
    }
    match bins {
        Some(bins) if problems.is_empty() => Ok((bins, metadata)),
        _ => Err(RunnerError::Contract {
            model: source.to_string(),
            contract: SHAPE_CONTRACT,
            reason: problems.join("; "),
        }),
    }
}

/// Where an output's expected width comes from.
fn bins_hint(output: &str) -> &'static str {
    if output.starts_with("angle") {
        " (the width must be the number of angle_bins)"
    } else if output.starts_with("scale") {
        " (the width must be the number of scale_bins)"
    } else {
        ""
    }
}

/// Parses and checks a JSON list of bin centres; problems are pushed onto `problems`.
fn parse_bins(
    value: Option<&str>,
    key: &str,
    problems: &mut Vec<String>,
    ok: impl Fn(f64) -> bool,
) -> Option<Vec<f64>> {
    let Some(value) = value else {
        problems.push(format!(
            "metadata {key} is missing (a JSON list of bin centres)"
        ));
        return None;
    };
    let bins = match serde_json::from_str::<Vec<f64>>(value) {
        Ok(v) => v,
        Err(e) => {
            problems.push(format!("metadata {key} is not a JSON list of numbers: {e}"));
            return None;
        }
    };
    match check_bins(key, &bins, ok) {
        Ok(()) => Some(bins),
        Err(reason) => {
            problems.push(format!("metadata {reason}"));
            None
        }
    }
}

/// Checks a tensor type: float32 with `dims.len()` dimensions; a dimension of `expected` ≥ 0
/// must match unless the model leaves it symbolic (−1).
fn check_tensor(dtype: &ValueType, expected: &[i64]) -> std::result::Result<(), String> {
    let ValueType::Tensor { ty, shape, .. } = dtype else {
        return Err(format!("is a {dtype}, expected a float32 tensor"));
    };
    if *ty != TensorElementType::Float32 {
        return Err(format!("has element type {ty}, expected float32"));
    }
    let ok = shape.len() == expected.len()
        && shape
            .iter()
            .zip(expected)
            .all(|(&got, &want)| want < 0 || got < 0 || got == want);
    if ok {
        Ok(())
    } else {
        Err(format!(
            "has shape {}, expected {}",
            fmt_dims(shape),
            fmt_dims(expected)
        ))
    }
}

/// `(N, 1, 32, 32)`: symbolic (negative) dimensions shown as `N`.
fn fmt_dims(dims: &[i64]) -> String {
    let parts: Vec<String> = dims
        .iter()
        .map(|d| {
            if *d < 0 {
                "N".to_string()
            } else {
                d.to_string()
            }
        })
        .collect();
    format!("({})", parts.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_scale_bins_and_batch_sizes_are_refused_with_the_bound() {
        for bad in [1e300, 1e-300, 0.0] {
            let e = ShapeBins::new(vec![0.0], vec![1.0, bad])
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("scale_bins[1]") && e.contains("[1e-6, 1e6]"),
                "{e}"
            );
        }
        let big = ShapeModelOptions {
            threads: Some(1),
            batch_size: MAX_BATCH_SIZE + 1,
        };
        let e = check_options(&big).unwrap_err().to_string();
        assert_eq!(e, "batch_size: 65537 is over the limit of 65536");
        let many = ShapeModelOptions {
            threads: Some(1 << 20),
            batch_size: 1,
        };
        assert!(
            check_options(&many)
                .unwrap_err()
                .to_string()
                .contains("limit of 1024")
        );
    }

    #[test]
    fn softmax_mean_decoding() {
        let bins = ShapeBins::new(vec![-1.0, 0.5, 2.0], vec![0.5, 1.0, 4.0]).unwrap();
        let logits = [0.3f32, -1.2, 2.5];
        let z: f64 = logits.iter().map(|&v| (v as f64).exp()).sum();
        let p: Vec<f64> = logits.iter().map(|&v| (v as f64).exp() / z).collect();
        let (s, c) = bins
            .angles()
            .iter()
            .zip(&p)
            .fold((0.0, 0.0), |(s, c), (a, p)| {
                (s + p * a.sin(), c + p * a.cos())
            });
        assert!((bins.decode_orientation(&logits).unwrap() - s.atan2(c)).abs() < 1e-12);
        let e: f64 = bins.scales().iter().zip(&p).map(|(s, p)| p * s.ln()).sum();
        assert!((bins.decode_scale(&logits).unwrap() - e.exp()).abs() < 1e-12);
        // Huge logits do not overflow; a NaN logit is reported.
        assert!((bins.decode_scale(&[1e30, 0.0, 0.0]).unwrap() - 0.5).abs() < 1e-12);
        assert!(bins.decode_orientation(&[f32::NAN, 0.0, 0.0]).is_none());
        // The spreads: R and the std of ln s under p, against the sums written out.
        let (o, u) = bins.decode_orientation_spread(&logits).unwrap();
        assert!((o - s.atan2(c)).abs() < 1e-12);
        assert!((u - (1.0 - s.hypot(c))).abs() < 1e-12);
        let e2: f64 = bins
            .scales()
            .iter()
            .zip(&p)
            .map(|(s, p)| p * s.ln() * s.ln())
            .sum();
        let (sc, sd) = bins.decode_scale_spread(&logits).unwrap();
        assert!((sc - e.exp()).abs() < 1e-12 && (sd - (e2 - e * e).sqrt()).abs() < 1e-12);
        // One certain bin: no spread; equal logits over opposite angles: R = 0.
        let (_, u) = bins.decode_orientation_spread(&[80.0, 0.0, 0.0]).unwrap();
        let (_, sd) = bins.decode_scale_spread(&[0.0, 80.0, 0.0]).unwrap();
        assert!(u < 1e-12 && sd < 1e-12, "{u} {sd}");
        let opposite = ShapeBins::new(vec![0.0, std::f64::consts::PI], vec![1.0]).unwrap();
        let (_, u) = opposite.decode_orientation_spread(&[1.0, 1.0]).unwrap();
        assert!((u - 1.0).abs() < 1e-12, "{u}");
    }

    #[test]
    fn bins_are_validated() {
        assert!(ShapeBins::new(vec![], vec![1.0]).is_err());
        assert!(ShapeBins::new(vec![0.0], vec![0.0]).is_err());
        assert!(ShapeBins::new(vec![0.0], vec![-1.0]).is_err());
        assert!(ShapeBins::new(vec![f64::NAN], vec![1.0]).is_err());
        let e = ShapeBins::new(vec![0.0, 90.0], vec![1.0])
            .unwrap_err()
            .to_string();
        assert!(e.contains("angle_bins[1] = 90"), "{e}");
    }
}
