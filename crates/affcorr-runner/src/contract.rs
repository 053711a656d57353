//! Loading the matcher models and checking them against their ONNX contracts (docs/design.md §6,
//! docs/matchers.md).
//!
//! Every matcher model names its contract in the custom metadata key `affcorr.contract`. A model
//! is accepted only when that key names the contract the caller asked for, its inputs and
//! outputs have the contract's names, element types, ranks and fixed axes, and every required
//! metadata key is present. All violations are reported together in one
//! [`RunnerError::Contract`] that names the file; a model of another contract (e.g. the
//! refinement MLP given as the backbone) is named as such.

use std::collections::BTreeMap;
use std::path::Path;

use ort::session::Session;
use ort::session::builder::SessionBuilder;
use ort::value::{TensorElementType, ValueType};

use crate::error::{Result, RunnerError};
use crate::ort_env;

/// The metadata key that names a model's contract.
pub const CONTRACT_KEY: &str = "affcorr.contract";
/// The XFeat backbone: image → dense descriptors, keypoint logits, reliability.
pub const BACKBONE_CONTRACT: &str = "features-backbone-v1";
/// The XFeat* refinement MLP: descriptor pairs of coarse matches → sub-pixel offsets.
pub const REFINE_CONTRACT: &str = "features-refine-v1";
/// LighterGlue: keypoints and descriptors of two images → matches.
pub const LIGHTERGLUE_CONTRACT: &str = "matcher-lighterglue-v1";
/// LightGlue in pieces (crate::lightglue): input projection and positional encoding.
pub const GLUE_ENCODE_CONTRACT: &str = "matcher-lightglue-encode-v1";
/// LightGlue in pieces: one transformer layer (chosen by an input) with its confidence heads.
pub const GLUE_LAYER_CONTRACT: &str = "matcher-lightglue-layer-v1";
/// LightGlue in pieces: the assignment head of a layer and the mutual filter.
pub const GLUE_ASSIGN_CONTRACT: &str = "matcher-lightglue-assign-v1";
/// The DISK backbone ([`crate::disk`]): RGB image → detection logits and dense descriptors at
/// full resolution.
pub const DISK_BACKBONE_CONTRACT: &str = "features-disk-v1";
/// The ALIKED backbone ([`crate::aliked`]): RGB image → score map and L2-normalised feature
/// map at full resolution.
pub const ALIKED_BACKBONE_CONTRACT: &str = "features-aliked-v1";
/// ALIKED's SDDH descriptor head ([`crate::aliked`]): feature map and keypoints → descriptors.
pub const ALIKED_SDDH_CONTRACT: &str = "features-aliked-sddh-v1";
/// A dense matcher (DKM, RoMa): two images → warp and certainty ([`crate::dense`]).
pub const DENSE_WARP_CONTRACT: &str = "dense-warp-v1";

/// One input or output of a contract.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TensorSpec {
    pub name: &'static str,
    pub ty: TensorElementType,
    pub rank: usize,
    /// (axis, size) pairs that must match when the model fixes the axis.
    pub fixed: &'static [(usize, i64)],
}

/// A contract: its name, inputs, outputs and required metadata keys.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ContractSpec {
    pub name: &'static str,
    pub inputs: &'static [TensorSpec],
    pub outputs: &'static [TensorSpec],
    pub metadata: &'static [&'static str],
}

const F32: TensorElementType = TensorElementType::Float32;
const I64: TensorElementType = TensorElementType::Int64;

pub(crate) const BACKBONE_SPEC: ContractSpec = ContractSpec {
    name: BACKBONE_CONTRACT,
    inputs: &[TensorSpec {
        name: "image",
        ty: F32,
        rank: 4,
        fixed: &[],
    }],
    outputs: &[
        TensorSpec {
            name: "feats",
            ty: F32,
            rank: 4,
            fixed: &[],
        },
        TensorSpec {
            name: "keypoints",
            ty: F32,
            rank: 4,
            fixed: &[(1, 65)],
        },
        TensorSpec {
            name: "heatmap",
            ty: F32,
            rank: 4,
            fixed: &[(1, 1)],
        },
    ],
    metadata: &[
        "affcorr.input_multiple",
        "affcorr.stride",
        "affcorr.descriptor_dim",
        "affcorr.detection.nms_size",
        "affcorr.detection.threshold",
        "affcorr.detection.top_k",
        "affcorr.semidense.scales",
        "affcorr.semidense.split",
    ],
};

pub(crate) const REFINE_SPEC: ContractSpec = ContractSpec {
    name: REFINE_CONTRACT,
    inputs: &[TensorSpec {
        name: "pair_feats",
        ty: F32,
        rank: 2,
        fixed: &[],
    }],
    outputs: &[
        TensorSpec {
            name: "logits",
            ty: F32,
            rank: 2,
            fixed: &[(1, 64)],
        },
        TensorSpec {
            name: "offset",
            ty: F32,
            rank: 2,
            fixed: &[(1, 2)],
        },
        TensorSpec {
            name: "confidence",
            ty: F32,
            rank: 1,
            fixed: &[],
        },
    ],
    metadata: &[
        "affcorr.descriptor_dim",
        "affcorr.refine.grid",
        "affcorr.refine.temperature",
        "affcorr.refine.confidence",
    ],
};

pub(crate) const LIGHTERGLUE_SPEC: ContractSpec = ContractSpec {
    name: LIGHTERGLUE_CONTRACT,
    inputs: &[
        TensorSpec {
            name: "keypoints0",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1), (2, 2)],
        },
        TensorSpec {
            name: "keypoints1",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1), (2, 2)],
        },
        TensorSpec {
            name: "descriptors0",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1)],
        },
        TensorSpec {
            name: "descriptors1",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1)],
        },
    ],
    outputs: &[
        TensorSpec {
            name: "scores",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1)],
        },
        TensorSpec {
            name: "matches0",
            ty: I64,
            rank: 2,
            fixed: &[(0, 1)],
        },
        TensorSpec {
            name: "mscores0",
            ty: F32,
            rank: 2,
            fixed: &[(0, 1)],
        },
    ],
    metadata: &[
        "affcorr.descriptor_dim",
        "affcorr.keypoint_normalisation",
        "affcorr.min_conf",
    ],
};

const fn t(name: &'static str, ty: TensorElementType, rank: usize) -> TensorSpec {
    TensorSpec {
        name,
        ty,
        rank,
        fixed: &[(0, 1)],
    }
}

/// Metadata every LightGlue piece carries.
const GLUE_META: [&str; 5] = [
    "affcorr.descriptor_dim",
    "affcorr.embedding_dim",
    "affcorr.heads",
    "affcorr.head_dim",
    "affcorr.layers",
];

pub(crate) const GLUE_ENCODE_SPEC: ContractSpec = ContractSpec {
    name: GLUE_ENCODE_CONTRACT,
    inputs: &[
        TensorSpec {
            name: "keypoints",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1), (2, 2)],
        },
        t("descriptors", F32, 3),
    ],
    outputs: &[t("desc", F32, 3), t("cos", F32, 3), t("sin", F32, 3)],
    metadata: &[
        GLUE_META[0],
        GLUE_META[1],
        GLUE_META[2],
        GLUE_META[3],
        GLUE_META[4],
        "affcorr.keypoint_normalisation",
    ],
};

pub(crate) const GLUE_LAYER_SPEC: ContractSpec = ContractSpec {
    name: GLUE_LAYER_CONTRACT,
    inputs: &[
        t("layer", I64, 1),
        t("desc0", F32, 3),
        t("desc1", F32, 3),
        t("cos0", F32, 3),
        t("sin0", F32, 3),
        t("cos1", F32, 3),
        t("sin1", F32, 3),
    ],
    outputs: &[
        t("desc0_out", F32, 3),
        t("desc1_out", F32, 3),
        t("token0", F32, 2),
        t("token1", F32, 2),
        t("match0", F32, 2),
        t("match1", F32, 2),
    ],
    metadata: &[
        GLUE_META[0],
        GLUE_META[1],
        GLUE_META[2],
        GLUE_META[3],
        GLUE_META[4],
        "affcorr.min_conf",
        "affcorr.glue.width_confidence",
        "affcorr.glue.depth_confidence",
        "affcorr.glue.confidence_thresholds",
    ],
};

pub(crate) const GLUE_ASSIGN_SPEC: ContractSpec = ContractSpec {
    name: GLUE_ASSIGN_CONTRACT,
    inputs: &[t("layer", I64, 1), t("desc0", F32, 3), t("desc1", F32, 3)],
    outputs: &[t("matches0", I64, 2), t("mscores0", F32, 2)],
    metadata: &GLUE_META,
};

pub(crate) const DISK_BACKBONE_SPEC: ContractSpec = ContractSpec {
    name: DISK_BACKBONE_CONTRACT,
    inputs: &[TensorSpec {
        name: "image",
        ty: F32,
        rank: 4,
        fixed: &[(0, 1), (1, 3)],
    }],
    outputs: &[
        TensorSpec {
            name: "heatmap",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1), (1, 1)],
        },
        t("descriptors", F32, 4),
    ],
    metadata: &[
        "affcorr.input_multiple",
        "affcorr.descriptor_dim",
        "affcorr.detection.nms_size",
        "affcorr.detection.threshold",
        "affcorr.detection.top_k",
    ],
};

pub(crate) const ALIKED_BACKBONE_SPEC: ContractSpec = ContractSpec {
    name: ALIKED_BACKBONE_CONTRACT,
    inputs: &[TensorSpec {
        name: "image",
        ty: F32,
        rank: 4,
        fixed: &[(0, 1), (1, 3)],
    }],
    outputs: &[
        TensorSpec {
            name: "scores",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1), (1, 1)],
        },
        TensorSpec {
            name: "features",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1)],
        },
    ],
    metadata: &[
        "affcorr.input_multiple",
        "affcorr.descriptor_dim",
        "affcorr.detection.nms_radius",
        "affcorr.detection.threshold",
        "affcorr.detection.temperature",
        "affcorr.detection.top_k",
    ],
};

pub(crate) const ALIKED_SDDH_SPEC: ContractSpec = ContractSpec {
    name: ALIKED_SDDH_CONTRACT,
    inputs: &[
        TensorSpec {
            name: "features",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1)],
        },
        TensorSpec {
            name: "keypoints",
            ty: F32,
            rank: 2,
            fixed: &[(1, 2)],
        },
    ],
    outputs: &[t("descriptors", F32, 2)],
    metadata: &["affcorr.descriptor_dim"],
};

pub(crate) const DENSE_WARP_SPEC: ContractSpec = ContractSpec {
    name: DENSE_WARP_CONTRACT,
    inputs: &[
        TensorSpec {
            name: "image_a",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1), (1, 3)],
        },
        TensorSpec {
            name: "image_b",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1), (1, 3)],
        },
    ],
    outputs: &[
        TensorSpec {
            name: "warp",
            ty: F32,
            rank: 4,
            fixed: &[(0, 1), (3, 2)],
        },
        TensorSpec {
            name: "certainty",
            ty: F32,
            rank: 3,
            fixed: &[(0, 1)],
        },
    ],
    metadata: &[],
};

/// A session whose contract has been checked, with the model's custom metadata.
#[derive(Debug)]
pub(crate) struct CheckedModel {
    pub session: Session,
    pub metadata: BTreeMap<String, String>,
    /// The file path in backquotes.
    pub source: String,
}

impl CheckedModel {
    /// A [`RunnerError::Contract`] about this model.
    pub fn violation(&self, spec: &ContractSpec, reason: impl Into<String>) -> RunnerError {
        RunnerError::Contract {
            model: self.source.clone(),
            contract: spec.name,
            reason: reason.into(),
        }
    }

    /// The value of a required metadata key parsed as JSON; a missing key or bad JSON is a
    /// contract violation naming the key.
    fn json(&self, spec: &ContractSpec, key: &str) -> Result<serde_json::Value> {
        let value = self
            .metadata
            .get(key)
            .ok_or_else(|| self.violation(spec, format!("metadata {key} is missing")))?;
        serde_json::from_str(value).map_err(|e| {
            self.violation(spec, format!("metadata {key} = {value:?} is not JSON: {e}"))
        })
    }

    /// A metadata number (`"0.05"`, `"8"`); `ok` says whether it is in range.
    pub fn meta_f64(
        &self,
        spec: &ContractSpec,
        key: &str,
        ok: impl Fn(f64) -> bool,
    ) -> Result<f64> {
        let v = self.json(spec, key)?;
        match v.as_f64() {
            Some(x) if x.is_finite() && ok(x) => Ok(x),
            _ => Err(self.violation(spec, format!("metadata {key} = {v} is not a valid number"))),
        }
    }

    /// A metadata positive integer (`"8"`).
    pub fn meta_usize(&self, spec: &ContractSpec, key: &str) -> Result<usize> {
        let v = self.json(spec, key)?;
        match v.as_u64() {
            Some(x) if x > 0 => Ok(x as usize),
            _ => Err(self.violation(
                spec,
                format!("metadata {key} = {v} is not a positive integer"),
            )),
        }
    }

    /// A metadata list of numbers (`"[0.6, 1.3]"`), each in range.
    pub fn meta_list(
        &self,
        spec: &ContractSpec,
        key: &str,
        ok: impl Fn(f64) -> bool,
    ) -> Result<Vec<f64>> {
        let v = self.json(spec, key)?;
        let list: Option<Vec<f64>> = v.as_array().and_then(|a| {
            a.iter()
                .map(|x| x.as_f64().filter(|x| x.is_finite() && ok(*x)))
                .collect()
        });
        match list {
            Some(l) if !l.is_empty() => Ok(l),
            _ => Err(self.violation(
                spec,
                format!("metadata {key} = {v} is not a non-empty list of valid numbers"),
            )),
        }
    }
}

/// The most threads a model (or the pipeline) may be given. Each thread costs a stack and a
/// share of every inference; far more threads than cores only slow ONNX Runtime down, and
/// `threads = 10**6` used to spawn threads until memory ran out instead of failing.
pub const MAX_THREADS: usize = 1024;

/// The intra-op thread count of `threads` (`None`: every core); 1 to [`MAX_THREADS`].
pub fn resolve_threads(threads: Option<usize>) -> Result<usize> {
    match threads {
        Some(0) => Err(RunnerError::invalid(
            "threads",
            "must be at least 1 (or None for every core)",
        )),
        Some(t) if t > MAX_THREADS => Err(RunnerError::invalid(
            "threads",
            format!("{t} is over the limit of {MAX_THREADS} (or None for every core)"),
        )),
        Some(t) => Ok(t),
        None => Ok(ort_env::default_threads()),
    }
}

/// Fails with [`RunnerError::ModelOpen`] unless `path` is a readable regular file, so that a
/// missing model gets a clearer error than ONNX Runtime's.
pub(crate) fn check_model_file(path: &Path) -> Result<()> {
    let reason = match std::fs::metadata(path) {
        Ok(m) if m.is_file() => return Ok(()),
        Ok(_) => "not a file".to_string(),
        Err(e) => e.to_string(),
    };
    Err(RunnerError::ModelOpen {
        path: path.to_path_buf(),
        reason,
    })
}

/// A session builder on the process's environment with `threads` intra-op threads.
pub(crate) fn session_builder(threads: usize) -> Result<SessionBuilder> {
    let env = ort_env::environment()?;
    let context = "configuring the session";
    Session::builder(env)
        .map_err(|e| RunnerError::ort(context, e))?
        .with_intra_threads(threads)
        .map_err(|e| RunnerError::ort(context, e))?
        .with_inter_threads(1)
        .map_err(|e| RunnerError::ort(context, e))?
        // Idle intra-op threads block instead of spinning: the pipeline runs several sessions
        // in turn (backbone, LighterGlue or refinement, shape network), and a session's spinning
        // workers would take the cores from the next one (measured: the second of two
        // spinning backbone sessions ran 1.8× slower; without spinning both run at full speed).
        .with_intra_op_spinning(false)
        .map_err(|e| RunnerError::ort(context, e))
}

/// Loads `path` with `threads` intra-op threads and checks it against `spec`.
pub(crate) fn load(path: &Path, threads: usize, spec: &ContractSpec) -> Result<CheckedModel> {
    let source = format!("`{}`", path.display());
    check_model_file(path)?;
    let session = session_builder(threads)?
        .commit_from_file(path)
        .map_err(|e| RunnerError::ModelLoad {
            model: source.clone(),
            reason: e.to_string(),
        })?;
    let metadata = read_metadata(&session).map_err(|e| RunnerError::ort("reading metadata", e))?;
    let model = CheckedModel {
        session,
        metadata,
        source,
    };
    let problems = check(&model, spec);
    if problems.is_empty() {
        Ok(model)
    } else {
        Err(model.violation(spec, problems.join("; ")))
    }
}

pub(crate) fn read_metadata(session: &Session) -> ort::Result<BTreeMap<String, String>> {
    let meta = session.metadata()?;
    let mut map = BTreeMap::new();
    for key in meta.custom_keys()? {
        if let Some(value) = meta.custom(&key) {
            map.insert(key, value);
        }
    }
    Ok(map)
}

/// Every violation of `spec` (empty when the model follows it).
fn check(model: &CheckedModel, spec: &ContractSpec) -> Vec<String> {
    let mut problems = Vec::new();
    match model.metadata.get(CONTRACT_KEY).map(String::as_str) {
        Some(name) if name == spec.name => {}
        Some(other) => {
            // Another contract: the rest of the checks would only repeat it.
            problems.push(format!(
                "metadata {CONTRACT_KEY} is {other:?}, expected {:?} (is this the right model \
                 file?)",
                spec.name
            ));
            return problems;
        }
        None => problems.push(format!(
            "metadata {CONTRACT_KEY} is missing (expected {:?}; is this an affcorr matcher \
             model? affcorr.export.contracts.set_metadata adds it)",
            spec.name
        )),
    }
    let session = &model.session;
    let input_names: Vec<&str> = session.inputs().iter().map(|o| o.name()).collect();
    for t in spec.inputs {
        match session.inputs().iter().find(|o| o.name() == t.name) {
            None => problems.push(format!(
                "input {} is missing (the model's inputs are {input_names:?})",
                t.name
            )),
            Some(o) => {
                if let Err(r) = check_tensor(o.dtype(), t) {
                    problems.push(format!("input {}: {r}", t.name));
                }
            }
        }
    }
    for name in &input_names {
        if !spec.inputs.iter().any(|t| t.name == *name) {
            problems.push(format!(
                "unexpected input {name} (the runner feeds only {:?})",
                spec.inputs.iter().map(|t| t.name).collect::<Vec<_>>()
            ));
        }
    }
    let output_names: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
    for t in spec.outputs {
        match session.outputs().iter().find(|o| o.name() == t.name) {
            None => problems.push(format!(
                "output {} is missing (the model's outputs are {output_names:?})",
                t.name
            )),
            Some(o) => {
                if let Err(r) = check_tensor(o.dtype(), t) {
                    problems.push(format!("output {}: {r}", t.name));
                }
            }
        }
    }
    for key in spec.metadata {
        if !model.metadata.contains_key(*key) {
            problems.push(format!("metadata {key} is missing"));
        }
    }
    problems
}

fn check_tensor(dtype: &ValueType, spec: &TensorSpec) -> std::result::Result<(), String> {
    let ValueType::Tensor { ty, shape, .. } = dtype else {
        return Err(format!("is a {dtype}, expected a {} tensor", spec.ty));
    };
    if *ty != spec.ty {
        return Err(format!("has element type {ty}, expected {}", spec.ty));
    }
    if shape.len() != spec.rank {
        return Err(format!("has rank {}, expected {}", shape.len(), spec.rank));
    }
    for &(axis, size) in spec.fixed {
        if shape[axis] >= 0 && shape[axis] != size {
            return Err(format!(
                "axis {axis} has size {}, expected {size}",
                shape[axis]
            ));
        }
    }
    Ok(())
}

/// Reads an output tensor of element type `T`, checking its shape against `expected` (negative
/// entries are not checked); returns the data.
pub(crate) fn output<'a, T: ort::value::PrimitiveTensorElementType>(
    outputs: &'a ort::session::SessionOutputs<'_>,
    name: &'static str,
    expected: &[i64],
) -> Result<&'a [T]> {
    let value = outputs.get(name).ok_or_else(|| RunnerError::ModelOutput {
        what: name,
        reason: "missing from the session's outputs".to_string(),
    })?;
    let (shape, data) = value
        .try_extract_tensor::<T>()
        .map_err(|e| RunnerError::ModelOutput {
            what: name,
            reason: e.to_string(),
        })?;
    let ok = shape.len() == expected.len()
        && shape
            .iter()
            .zip(expected)
            .all(|(&got, &want)| want < 0 || got == want);
    if !ok {
        let want: Vec<String> = expected
            .iter()
            .map(|d| if *d < 0 { "?".into() } else { d.to_string() })
            .collect();
        return Err(RunnerError::ModelOutput {
            what: name,
            reason: format!("shape {shape}, expected [{}]", want.join(", ")),
        });
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_counts_are_bounded_and_the_message_gives_the_bound() {
        assert_eq!(resolve_threads(Some(1)).unwrap(), 1);
        assert_eq!(resolve_threads(Some(MAX_THREADS)).unwrap(), MAX_THREADS);
        let e = resolve_threads(Some(1_000_000)).unwrap_err().to_string();
        assert_eq!(
            e,
            "threads: 1000000 is over the limit of 1024 (or None for every core)"
        );
        assert!(resolve_threads(Some(0)).is_err());
        assert!(resolve_threads(None).unwrap() >= 1);
    }
}
