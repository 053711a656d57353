//! Bindings of the robust estimators (`affcorr::ransac`): `estimate_homography`,
//! `estimate_fundamental`, `estimate_relative_pose` and their `_batch` forms.
//!
//! The Python package (`affcorr.estimation`) wraps these into `(model, info)` pairs of frozen
//! dataclasses; here each function returns plain arrays and an `info` dict.
//!
//! - Options arrive as keyword arguments. [`estimator_options!`] is the one table that maps each
//!   name to a field of [`EstimatorOptions`]: adding an option is one line there. Unknown names
//!   raise `ValueError` naming them.
//! - Invalid input or options (shapes, NaN, K, threshold, too few correspondences, PROSAC
//!   without quality, ...) raise `ValueError` with the core crate's message, which names the
//!   argument or option.
//! - When no sample gives a model ([`RansacError::NoModel`]), the call does not raise: like
//!   PoseLib, it returns an `info` with `num_inliers == 0`, all-false `inliers` and the
//!   iterations run, and the model is filled with NaN so that it cannot be used by mistake.
//! - Estimation runs with the GIL released; the batch forms run the pairs in parallel with
//!   rayon (`RAYON_NUM_THREADS` caps the threads).

use crate::arrays::{Dim, F64Array, mat3_to_numpy, to_numpy, value_error};
use affcorr::geom::Mat3;
use affcorr::geom::camera::Intrinsics;
use affcorr::ransac::problems::relpose::PoseModel;
use affcorr::ransac::{
    Correspondences, Estimate, EstimatorOptions, LoKind, RansacError, SampleKind, SamplerKind,
    ScoringKind, estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use numpy::{PyArray1, PyArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rayon::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(estimate_homography_py, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_fundamental_py, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_relative_pose_py, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_homography_batch_py, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_fundamental_batch_py, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_relative_pose_batch_py, m)?)?;
    m.add("ESTIMATOR_OPTIONS", OPTION_NAMES.to_vec())?;
    Ok(())
}

type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

const N: Dim = Dim::Any("N");
const CORRS: [&[Dim]; 2] = [&[N, Dim::Is(8)], &[N, Dim::Is(4)]];

// --- options ------------------------------------------------------------------------------------

/// The option table: `"name" => |options, value| assignment;`. It defines [`OPTION_NAMES`] and
/// [`apply_option`]. The Python wrappers give `threshold` and `seed` explicitly, with the
/// defaults of `RansacOptions`.
macro_rules! estimator_options {
    ($($name:literal => |$o:ident, $v:ident| $apply:expr;)*) => {
        /// Names of the keyword options, in the table's order.
        const OPTION_NAMES: &[&str] = &[$($name),*];

        /// Applies option `name`; `Ok(false)` if there is no such option.
        fn apply_option(
            options: &mut EstimatorOptions,
            name: &str,
            value: &Bound<'_, PyAny>,
        ) -> PyResult<bool> {
            match name {
                $($name => {
                    let ($o, $v) = (&mut *options, value);
                    $apply;
                })*
                _ => return Ok(false),
            }
            Ok(true)
        }
    };
}

estimator_options! {
    "threshold" => |o, v| o.ransac.threshold = number(v, "threshold")?;
    "seed" => |o, v| o.ransac.seed = integer(v, "seed")?;
    "sample" => |o, v| o.sample = if v.is_none() { None } else { Some(choice(v, "sample", SAMPLES)?) };
    "sampler" => |o, v| o.sampler = choice(v, "sampler", SAMPLERS)?;
    "quality" => |o, v| o.quality = if v.is_none() { None } else { Some(vector(v, "quality")?) };
    "scoring" => |o, v| o.scoring = choice(v, "scoring", SCORINGS)?;
    "confidence" => |o, v| o.ransac.confidence = number(v, "confidence")?;
    "sample_reliability" => |o, v| o.ransac.sample_reliability = number(v, "sample_reliability")?;
    "min_iterations" => |o, v| o.ransac.min_iterations = integer(v, "min_iterations")?;
    "max_iterations" => |o, v| o.ransac.max_iterations = integer(v, "max_iterations")?;
    "local_optimization" => |o, v| o.ransac.local_optimization = flag(v, "local_optimization")?;
    "lo" => |o, v| o.ransac.lo = choice(v, "lo", LOS)?;
    "lo_iterations" => |o, v| o.ransac.lo_iterations = integer(v, "lo_iterations")?;
    "final_refinement" => |o, v| o.ransac.final_refinement = flag(v, "final_refinement")?;
    "sprt" => |o, v| o.ransac.sprt = flag(v, "sprt")?;
    "affine_weight" => |o, v| o.affine_weight = number(v, "affine_weight")?;
}

const SAMPLES: &[(&str, SampleKind)] = &[
    ("affine", SampleKind::Affine),
    ("points", SampleKind::Points),
];
const SAMPLERS: &[(&str, SamplerKind)] = &[
    ("uniform", SamplerKind::Uniform),
    ("prosac", SamplerKind::Prosac),
];
const LOS: &[(&str, LoKind)] = &[("irls", LoKind::Irls), ("graph_cut", LoKind::GraphCut)];
const SCORINGS: &[(&str, ScoringKind)] = &[
    ("auto", ScoringKind::Auto),
    ("msac", ScoringKind::Msac),
    ("magsac", ScoringKind::Magsac),
];

fn choice<T: Copy>(v: &Bound<'_, PyAny>, name: &str, choices: &[(&str, T)]) -> PyResult<T> {
    let names: Vec<String> = choices.iter().map(|(n, _)| format!("'{n}'")).collect();
    let bad = || {
        PyValueError::new_err(format!(
            "{name} must be one of [{}], got {}",
            names.join(", "),
            repr(v)
        ))
    };
    let s: String = v.extract().map_err(|_| bad())?;
    choices
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(&s))
        .map(|(_, k)| *k)
        .ok_or_else(bad)
}

fn number(v: &Bound<'_, PyAny>, name: &str) -> PyResult<f64> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(type_error(name, "a number", v));
    }
    v.extract().map_err(|_| type_error(name, "a number", v))
}

fn integer<T: for<'a, 'py> FromPyObject<'a, 'py>>(v: &Bound<'_, PyAny>, name: &str) -> PyResult<T> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(type_error(name, "a non-negative integer", v));
    }
    v.extract()
        .map_err(|_| type_error(name, "a non-negative integer", v))
}

fn flag(v: &Bound<'_, PyAny>, name: &str) -> PyResult<bool> {
    v.extract().map_err(|_| type_error(name, "a bool", v))
}

fn vector(v: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<f64>> {
    let a = F64Array::extract(v, name)?.expect(&[N])?;
    if let Some(i) = a.as_slice().iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name}[{i}] is NaN or infinite"
        )));
    }
    Ok(a.as_slice().to_vec())
}

fn repr(v: &Bound<'_, PyAny>) -> String {
    v.repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "?".into())
}

fn type_error(name: &str, what: &str, v: &Bound<'_, PyAny>) -> PyErr {
    PyValueError::new_err(format!("{name} must be {what}, got {}", repr(v)))
}

/// Builds the options from the explicit arguments and the keyword options. Unknown names are
/// collected and reported together, with the valid names.
pub(crate) fn parse_options(
    options: Option<&Bound<'_, PyDict>>,
    defaults: EstimatorOptions,
) -> PyResult<EstimatorOptions> {
    let mut o = defaults;
    let mut unknown = Vec::new();
    if let Some(options) = options {
        for (key, value) in options.iter() {
            let name: String = key.extract()?;
            if !apply_option(&mut o, &name, &value)? {
                unknown.push(name);
            }
        }
    }
    if !unknown.is_empty() {
        return Err(PyValueError::new_err(format!(
            "unknown option{} {}; valid options: {}",
            if unknown.len() > 1 { "s" } else { "" },
            unknown.join(", "),
            OPTION_NAMES.join(", ")
        )));
    }
    Ok(o)
}

// --- inputs and outputs ---------------------------------------------------------------------------

/// What the estimators return, before conversion to Python.
pub(crate) struct Outcome<M> {
    model: M,
    inliers: Vec<bool>,
    num_inliers: usize,
    iterations: usize,
    score: f64,
    lo_runs: usize,
    refinements: usize,
    residual_evaluations: u64,
    sprt_rejections: usize,
}

/// `NoModel` becomes a NaN model with no inliers; every other error is a `ValueError`.
pub(crate) fn outcome<M>(
    r: Result<Estimate<M>, RansacError>,
    n: usize,
    nan: M,
) -> Result<Outcome<M>, RansacError> {
    match r {
        Ok(e) => Ok(Outcome {
            model: e.model,
            inliers: e.inliers,
            num_inliers: e.num_inliers,
            iterations: e.iterations,
            score: e.score,
            lo_runs: e.lo_runs,
            refinements: e.refinements,
            residual_evaluations: e.residual_evaluations,
            sprt_rejections: e.sprt_rejections,
        }),
        Err(RansacError::NoModel { iterations }) => Ok(Outcome {
            model: nan,
            inliers: vec![false; n],
            num_inliers: 0,
            iterations,
            score: 0.0,
            lo_runs: 0,
            refinements: 0,
            residual_evaluations: 0,
            sprt_rejections: 0,
        }),
        Err(e) => Err(e),
    }
}

pub(crate) fn nan_mat3() -> Mat3 {
    Mat3::from_element(f64::NAN)
}

pub(crate) fn nan_pose() -> PoseModel {
    PoseModel {
        pose: affcorr::geom::epipolar::Pose {
            r: nan_mat3(),
            t: affcorr::geom::Vec3::from_element(f64::NAN),
        },
        essential: nan_mat3(),
        fundamental: nan_mat3(),
    }
}

fn info<'py, M>(py: Python<'py>, o: &Outcome<M>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("inliers", PyArray1::from_slice(py, &o.inliers))?;
    d.set_item("num_inliers", o.num_inliers)?;
    d.set_item("num_iterations", o.iterations)?;
    d.set_item("score", o.score)?;
    d.set_item("lo_runs", o.lo_runs)?;
    d.set_item("refinements", o.refinements)?;
    d.set_item("residual_evaluations", o.residual_evaluations)?;
    d.set_item("sprt_rejections", o.sprt_rejections)?;
    Ok(d)
}

pub(crate) type MatResult<'py> = (Array<'py>, Bound<'py, PyDict>);
pub(crate) type PoseResult<'py> = (
    (Array<'py>, Array<'py>, Array<'py>, Array<'py>),
    Bound<'py, PyDict>,
);

pub(crate) fn mat_result<'py>(py: Python<'py>, o: &Outcome<Mat3>) -> PyResult<MatResult<'py>> {
    Ok((mat3_to_numpy(py, &o.model)?, info(py, o)?))
}

pub(crate) fn pose_result<'py>(
    py: Python<'py>,
    o: &Outcome<PoseModel>,
) -> PyResult<PoseResult<'py>> {
    let m = &o.model;
    let t = to_numpy(py, &[3], m.pose.t.iter().copied().collect())?;
    Ok((
        (
            mat3_to_numpy(py, &m.pose.r)?,
            t,
            mat3_to_numpy(py, &m.essential)?,
            mat3_to_numpy(py, &m.fundamental)?,
        ),
        info(py, o)?,
    ))
}

// --- single pair ----------------------------------------------------------------------------------

/// Runs `f` on one pair with the GIL released.
fn run_one<M: Send>(
    py: Python<'_>,
    corrs: &Bound<'_, PyAny>,
    options: Option<&Bound<'_, PyDict>>,
    nan: M,
    f: impl Fn(&Correspondences, &EstimatorOptions) -> Result<Estimate<M>, RansacError> + Send,
) -> PyResult<Outcome<M>> {
    let opts = parse_options(options, EstimatorOptions::default())?;
    let a = F64Array::extract(corrs, "corrs")?.expect_one_of(&CORRS)?;
    let (slice, width) = (a.as_slice(), a.shape()[1]);
    py.detach(move || {
        let data = rows_to_corrs(slice, width)?;
        outcome(f(&data, &opts), data.len(), nan)
    })
    .map_err(value_error)
}

fn rows_to_corrs(slice: &[f64], width: usize) -> Result<Correspondences, RansacError> {
    if width == 8 {
        Correspondences::from_ac_rows(slice.as_chunks::<8>().0)
    } else {
        Correspondences::from_point_rows(slice.as_chunks::<4>().0)
    }
}

#[pyfunction]
#[pyo3(name = "estimate_homography", signature = (corrs, *, **options))]
fn estimate_homography_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<MatResult<'py>> {
    let o = run_one(py, corrs, options, nan_mat3(), estimate_homography)?;
    mat_result(py, &o)
}

#[pyfunction]
#[pyo3(name = "estimate_fundamental", signature = (corrs, *, **options))]
fn estimate_fundamental_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<MatResult<'py>> {
    let o = run_one(py, corrs, options, nan_mat3(), estimate_fundamental)?;
    mat_result(py, &o)
}

#[pyfunction]
#[pyo3(name = "estimate_relative_pose", signature = (corrs, K1, K2, *, **options))]
#[allow(non_snake_case)]
fn estimate_relative_pose_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    K1: &Bound<'py, PyAny>,
    K2: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<PoseResult<'py>> {
    let k1 = crate::geom::intrinsics(K1, "K1")?;
    let k2 = crate::geom::intrinsics(K2, "K2")?;
    let o = run_one(py, corrs, options, nan_pose(), move |d, o| {
        estimate_relative_pose(d, &k1, &k2, o)
    })?;
    pose_result(py, &o)
}

// --- batches --------------------------------------------------------------------------------------

/// Per-pair inputs of a batch: the rows (borrowed views) and each pair's options (a shared
/// option set, with `quality` given per pair as a list of arrays).
struct Batch<'py> {
    arrays: Vec<F64Array<'py>>,
    options: Vec<EstimatorOptions>,
}

fn read_batch<'py>(
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Batch<'py>> {
    let items: Vec<Bound<'py, PyAny>> = corrs
        .try_iter()
        .map_err(|_| PyValueError::new_err("corrs must be a sequence of (N, 8) or (N, 4) arrays"))?
        .collect::<PyResult<_>>()?;
    let arrays = items
        .iter()
        .enumerate()
        .map(|(i, c)| {
            F64Array::extract(c, "corrs")
                .and_then(|a| a.expect_one_of(&CORRS))
                .map_err(|e| pair_error(i, e))
        })
        .collect::<PyResult<Vec<_>>>()?;
    // `quality` is per pair in a batch: a sequence of (N_i,) arrays (or None entries);
    // `pair_options` a sequence of option dicts, one per pair, over the shared options.
    let (quality, pair_options, options) = match options {
        Some(d) => {
            let d = d.copy()?;
            let quality = d.get_item("quality")?;
            d.del_item("quality").ok();
            let pair_options = d.get_item("pair_options")?;
            d.del_item("pair_options").ok();
            (quality, pair_options, Some(d))
        }
        None => (None, None, None),
    };
    let options = (quality, options);
    let shared = parse_options(options.1.as_ref(), EstimatorOptions::default())?;
    let mut per_pair = vec![shared; arrays.len()];
    if let Some(q) = options.0.filter(|q| !q.is_none()) {
        let list: Vec<Bound<'py, PyAny>> = q
            .try_iter()
            .map_err(|_| {
                PyValueError::new_err("quality must be a sequence of (N,) arrays, one per pair")
            })?
            .collect::<PyResult<_>>()?;
        if list.len() != arrays.len() {
            return Err(PyValueError::new_err(format!(
                "quality must have one entry per pair: got {} for {} pairs",
                list.len(),
                arrays.len()
            )));
        }
        for (i, (o, q)) in per_pair.iter_mut().zip(&list).enumerate() {
            o.quality = if q.is_none() {
                None
            } else {
                Some(vector(q, "quality").map_err(|e| pair_error(i, e))?)
            };
        }
    }
    if let Some(p) = pair_options.filter(|p| !p.is_none()) {
        // A dict or a string iterates, but over keys / characters: say what was meant.
        if p.is_instance_of::<PyDict>() || p.is_instance_of::<pyo3::types::PyString>() {
            return Err(PyValueError::new_err(format!(
                "pair_options must be a sequence with one dict (or None) per pair, got a {}",
                p.get_type().name()?
            )));
        }
        let list: Vec<Bound<'py, PyAny>> = p
            .try_iter()
            .map_err(|_| {
                PyValueError::new_err("pair_options must be a sequence of dicts, one per pair")
            })?
            .collect::<PyResult<_>>()?;
        if list.len() != arrays.len() {
            return Err(PyValueError::new_err(format!(
                "pair_options must have one entry per pair: got {} for {} pairs",
                list.len(),
                arrays.len()
            )));
        }
        for (i, (o, d)) in per_pair.iter_mut().zip(&list).enumerate() {
            if d.is_none() {
                continue;
            }
            let d = d.cast::<PyDict>().map_err(|_| {
                PyValueError::new_err(format!("pair {i}: pair_options entries must be dicts"))
            })?;
            let mut unknown = Vec::new();
            for (key, value) in d.iter() {
                let name: String = key.extract()?;
                if name == "quality" {
                    o.quality = if value.is_none() {
                        None
                    } else {
                        Some(vector(&value, "quality").map_err(|e| pair_error(i, e))?)
                    };
                } else if !apply_option(o, &name, &value).map_err(|e| pair_error(i, e))? {
                    unknown.push(name);
                }
            }
            if !unknown.is_empty() {
                return Err(PyValueError::new_err(format!(
                    "pair {i}: unknown option{} {}; valid options: {}",
                    if unknown.len() > 1 { "s" } else { "" },
                    unknown.join(", "),
                    OPTION_NAMES.join(", ")
                )));
            }
        }
    }
    Ok(Batch {
        arrays,
        options: per_pair,
    })
}

fn pair_error(i: usize, e: PyErr) -> PyErr {
    Python::attach(|py| PyValueError::new_err(format!("pair {i}: {}", e.value(py))))
}

/// Runs `f` over every pair in parallel with the GIL released; the first invalid pair raises
/// `ValueError` naming its index.
fn run_batch<M: Send + Clone + Sync>(
    py: Python<'_>,
    batch: &Batch<'_>,
    nan: M,
    f: impl Fn(usize, &Correspondences, &EstimatorOptions) -> Result<Estimate<M>, RansacError>
    + Sync
    + Send,
) -> PyResult<Vec<Outcome<M>>> {
    let views: Vec<(&[f64], usize)> = batch
        .arrays
        .iter()
        .map(|a| (a.as_slice(), a.shape()[1]))
        .collect();
    let opts = &batch.options;
    let results: Vec<Result<Outcome<M>, (usize, RansacError)>> = py.detach(|| {
        views
            .par_iter()
            .enumerate()
            .map(|(i, &(slice, width))| {
                let data = rows_to_corrs(slice, width).map_err(|e| (i, e))?;
                outcome(f(i, &data, &opts[i]), data.len(), nan.clone()).map_err(|e| (i, e))
            })
            .collect()
    });
    results
        .into_iter()
        .map(|r| r.map_err(|(i, e)| PyValueError::new_err(format!("pair {i}: {e}"))))
        .collect()
}

/// Reads `K` for a batch of `n` pairs: one (3, 3) for all, or (n, 3, 3) / a list of n.
fn batch_intrinsics(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    n: usize,
) -> PyResult<Vec<Intrinsics>> {
    let a = F64Array::extract(obj, name)?.expect_one_of(&[
        &[Dim::Is(3), Dim::Is(3)],
        &[Dim::Is(n), Dim::Is(3), Dim::Is(3)],
    ])?;
    let mats: Vec<Mat3> = a
        .rows::<9>()
        .iter()
        .map(|r| Mat3::from_row_slice(r))
        .collect();
    let ks = mats
        .into_iter()
        .enumerate()
        .map(|(i, k)| {
            Intrinsics::new(k, name).map_err(|e| {
                if a.shape().len() == 2 {
                    value_error(e)
                } else {
                    PyValueError::new_err(format!("pair {i}: {e}"))
                }
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok(if ks.len() == 1 && a.shape().len() == 2 {
        vec![ks[0]; n]
    } else {
        ks
    })
}

/// A batch of a 3×3-matrix estimator (H or F) as a list of `(model, info)`.
fn matrix_batch<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
    estimator: fn(&Correspondences, &EstimatorOptions) -> affcorr::ransac::Result<Estimate<Mat3>>,
) -> PyResult<Bound<'py, PyList>> {
    let batch = read_batch(corrs, options)?;
    let out = run_batch(py, &batch, nan_mat3(), |_, d, o| estimator(d, o))?;
    let items = out
        .iter()
        .map(|o| mat_result(py, o))
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}

#[pyfunction]
#[pyo3(name = "estimate_homography_batch", signature = (corrs, *, **options))]
fn estimate_homography_batch_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyList>> {
    matrix_batch(py, corrs, options, estimate_homography)
}

#[pyfunction]
#[pyo3(name = "estimate_fundamental_batch", signature = (corrs, *, **options))]
fn estimate_fundamental_batch_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyList>> {
    matrix_batch(py, corrs, options, estimate_fundamental)
}

#[pyfunction]
#[pyo3(name = "estimate_relative_pose_batch", signature = (corrs, K1, K2, *, **options))]
#[allow(non_snake_case)]
fn estimate_relative_pose_batch_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    K1: &Bound<'py, PyAny>,
    K2: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyList>> {
    let batch = read_batch(corrs, options)?;
    let n = batch.arrays.len();
    let k1 = batch_intrinsics(K1, "K1", n)?;
    let k2 = batch_intrinsics(K2, "K2", n)?;
    let out = run_batch(py, &batch, nan_pose(), |i, d, o| {
        estimate_relative_pose(d, &k1[i], &k2[i], o)
    })?;
    let items = out
        .iter()
        .map(|o| pose_result(py, o))
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}
