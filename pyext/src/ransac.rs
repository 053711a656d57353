//! Bindings of the robust estimators (`affcorr::ransac`): `estimate_homography`,
//! `estimate_fundamental`, `estimate_relative_pose` and their `_batch` forms, and
//! `planar_twin`.
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

use crate::arrays::{Dim, F64Array, int_option, mat3_to_numpy, to_numpy, to_usize, value_error};
use crate::errors::rewrap;
use crate::interrupt::interruptible;
use affcorr::geom::Mat3;
use affcorr::geom::camera::Intrinsics;
use affcorr::ransac::problems::relpose::PoseModel;
use affcorr::ransac::{
    AffineRefinement, Correspondences, Estimate, EstimatorOptions, LoKind, LoSchedule, RansacError,
    SampleKind, SamplerKind, ScoringKind, estimate_fundamental, estimate_homography,
    estimate_relative_pose, planar_twin,
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
    m.add_function(wrap_pyfunction!(planar_twin_py, m)?)?;
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

/// The most iterations `min_iterations` / `max_iterations` may ask for (a billion: hours of
/// work on the largest inputs; Ctrl-C stops any of them).
pub(crate) const MAX_ITERATIONS: u64 = 1_000_000_000;
/// The most refits `lo_iterations` may ask for in one local optimisation.
pub(crate) const MAX_LO_ITERATIONS: u64 = 10_000;

estimator_options! {
    "threshold" => |o, v| o.ransac.threshold = number(v, "threshold")?;
    "seed" => |o, v| o.ransac.seed = integer(v, "seed", u64::MAX)?;
    "sample" => |o, v| o.sample = if v.is_none() { None } else { Some(choice(v, "sample", SAMPLES)?) };
    "sampler" => |o, v| o.sampler = choice(v, "sampler", SAMPLERS)?;
    "quality" => |o, v| o.quality = if v.is_none() { None } else { Some(vector(v, "quality")?) };
    "scoring" => |o, v| o.scoring = choice(v, "scoring", SCORINGS)?;
    "confidence" => |o, v| o.ransac.confidence = number(v, "confidence")?;
    "sample_reliability" => |o, v| o.ransac.sample_reliability = number(v, "sample_reliability")?;
    "min_iterations" => |o, v| o.ransac.min_iterations = to_usize(integer(v, "min_iterations", MAX_ITERATIONS)?);
    "max_iterations" => |o, v| o.ransac.max_iterations = to_usize(integer(v, "max_iterations", MAX_ITERATIONS)?);
    "local_optimization" => |o, v| o.ransac.local_optimization = flag(v, "local_optimization")?;
    "lo" => |o, v| o.ransac.lo = choice(v, "lo", LOS)?;
    "lo_iterations" => |o, v| o.ransac.lo_iterations = to_usize(integer(v, "lo_iterations", MAX_LO_ITERATIONS)?);
    "lo_schedule" => |o, v| o.ransac.lo_schedule = choice(v, "lo_schedule", LO_SCHEDULES)?;
    "final_refinement" => |o, v| o.ransac.final_refinement = flag(v, "final_refinement")?;
    "sprt" => |o, v| o.ransac.sprt = flag(v, "sprt")?;
    "affine_weight" => |o, v| o.affine_weight = if v.is_none() { None } else { Some(number(v, "affine_weight")?) };
    "affine_refinement" => |o, v| o.ransac.affine_refinement = choice(v, "affine_refinement", AFFINE_REFINEMENTS)?;
    "affine_confidence" => |o, v| o.affine_confidence = if v.is_none() { None } else { Some(vector(v, "affine_confidence")?) };
}

const AFFINE_REFINEMENTS: &[(&str, AffineRefinement)] = &[
    ("off", AffineRefinement::Off),
    ("final", AffineRefinement::Final),
    ("all", AffineRefinement::All),
];

const SAMPLES: &[(&str, SampleKind)] = &[
    ("affine", SampleKind::Affine),
    ("points", SampleKind::Points),
    ("hybrid", SampleKind::Hybrid),
];
const SAMPLERS: &[(&str, SamplerKind)] = &[
    ("uniform", SamplerKind::Uniform),
    ("prosac", SamplerKind::Prosac),
];
const LOS: &[(&str, LoKind)] = &[("irls", LoKind::Irls), ("graph_cut", LoKind::GraphCut)];
const LO_SCHEDULES: &[(&str, LoSchedule)] = &[
    ("auto", LoSchedule::Auto),
    ("widening", LoSchedule::Widening),
    ("threshold", LoSchedule::Threshold),
    ("both", LoSchedule::Both),
];
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
    v.extract()
        .map_err(|e| rewrap(e, |_| type_error(name, "a number", v)))
}

/// A non-negative integer option up to `max` (Python or numpy integers; see
/// [`int_option`]).
fn integer(v: &Bound<'_, PyAny>, name: &str, max: u64) -> PyResult<u64> {
    int_option(v, name, "a non-negative integer", 0, max)
}

fn flag(v: &Bound<'_, PyAny>, name: &str) -> PyResult<bool> {
    v.extract()
        .map_err(|e| rewrap(e, |_| type_error(name, "a bool", v)))
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
/// The error for option names that are not in the table (all of them, with the valid ones).
fn unknown_options(unknown: &[String]) -> PyResult<()> {
    if unknown.is_empty() {
        return Ok(());
    }
    Err(PyValueError::new_err(format!(
        "unknown option{} {}; valid options: {}",
        if unknown.len() > 1 { "s" } else { "" },
        unknown.join(", "),
        OPTION_NAMES.join(", ")
    )))
}

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
    unknown_options(&unknown)?;
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
    affine_weight: f64,
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
            affine_weight: e.affine_weight,
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
            affine_weight: 0.0,
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
    d.set_item("affine_weight", o.affine_weight)?;
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
    let mut opts = parse_options(options, EstimatorOptions::default())?;
    let a = F64Array::extract(corrs, "corrs")?.expect_one_of(&CORRS)?;
    let (slice, width) = (a.as_slice(), a.shape()[1]);
    interruptible(py, move |cancel| {
        opts.ransac.cancel = Some(cancel.clone());
        let data = rows_to_corrs(slice, width)?;
        outcome(f(&data, &opts), data.len(), nan)
    })?
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

/// A planar twin for Python: `(R, t, normal, planar_share, H)`.
type TwinTuple<'py> = (Array<'py>, Array<'py>, Array<'py>, f64, Array<'py>);

/// The twin of a planar relative pose (`affcorr::ransac::planar_twin`): `None`, or
/// `(R, t, normal, planar_share, H)`. Runs with the GIL released.
#[pyfunction]
#[pyo3(name = "planar_twin", signature = (corrs, K1, K2, R, t, inliers, threshold))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn planar_twin_py<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    K1: &Bound<'py, PyAny>,
    K2: &Bound<'py, PyAny>,
    R: &Bound<'py, PyAny>,
    t: &Bound<'py, PyAny>,
    inliers: &Bound<'py, PyAny>,
    threshold: f64,
) -> PyResult<Option<TwinTuple<'py>>> {
    let k1 = crate::geom::intrinsics(K1, "K1")?;
    let k2 = crate::geom::intrinsics(K2, "K2")?;
    let r = crate::geom::matrix3(R, "R")?;
    let t = F64Array::extract(t, "t")?.expect(&[Dim::Is(3)])?;
    let t = affcorr::geom::Vec3::from_column_slice(t.as_slice());
    if !(t.iter().all(|v| v.is_finite()) && t.norm() > 0.0) {
        return Err(value_error("t must be a finite, non-zero 3-vector"));
    }
    let a = F64Array::extract(corrs, "corrs")?.expect_one_of(&CORRS)?;
    let mask = F64Array::extract(inliers, "inliers")?.expect(&[N])?;
    if mask.as_slice().iter().any(|&v| v != 0.0 && v != 1.0) {
        return Err(value_error(
            "inliers must be a boolean mask (one flag per correspondence), not indices",
        ));
    }
    let flags: Vec<bool> = mask.as_slice().iter().map(|&v| v == 1.0).collect();
    let (slice, width) = (a.as_slice(), a.shape()[1]);
    let pose = affcorr::geom::epipolar::Pose { r, t };
    let twin = py
        .detach(|| {
            let data = rows_to_corrs(slice, width)?;
            planar_twin(&data, &k1, &k2, &pose, &flags, threshold)
        })
        .map_err(value_error)?;
    twin.map(|w| {
        Ok((
            mat3_to_numpy(py, &w.pose.r)?,
            to_numpy(py, &[3], w.pose.t.iter().copied().collect())?,
            to_numpy(py, &[3], w.normal.iter().copied().collect())?,
            w.planar_share,
            mat3_to_numpy(py, &w.homography)?,
        ))
    })
    .transpose()
}

// --- batches --------------------------------------------------------------------------------------
//
// Each pair gets its own result: `(model, info)`, or the exception the single call would have
// raised for it (a `ValueError` "pair i: ..."), returned in its place (the Python wrappers turn
// it into `affcorr.PairError`). A pair with fewer correspondences than a minimal sample is a
// no-model result (as `NoModel`), not an error: matching gives such pairs. Errors of the batch
// as a whole (corrs not a sequence, invalid shared options, per-pair lists of the wrong length)
// raise.

/// One pair's rows and options, or the error that stopped it before estimation.
type PairInput<'py> = PyResult<(F64Array<'py>, EstimatorOptions)>;

fn pair_error(i: usize, e: PyErr) -> PyErr {
    rewrap(e, |e| {
        Python::attach(|py| PyValueError::new_err(format!("pair {i}: {}", e.value(py))))
    })
}

/// The per-pair lists `name` (quality, pair_options): `None`, or one entry per pair.
fn per_pair_list<'py>(
    value: Option<Bound<'py, PyAny>>,
    name: &str,
    what: &str,
    n: usize,
) -> PyResult<Option<Vec<Bound<'py, PyAny>>>> {
    let Some(v) = value.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    // A dict or a string iterates, but over keys / characters: say what was meant.
    if name == "pair_options"
        && (v.is_instance_of::<PyDict>() || v.is_instance_of::<pyo3::types::PyString>())
    {
        return Err(PyValueError::new_err(format!(
            "pair_options must be a sequence with one dict (or None) per pair, got a {}",
            v.get_type().name()?
        )));
    }
    let list: Vec<Bound<'py, PyAny>> = v
        .try_iter()
        .map_err(|e| {
            rewrap(e, |_| {
                PyValueError::new_err(format!("{name} must be a sequence of {what}, one per pair"))
            })
        })?
        .collect::<PyResult<_>>()?;
    if list.len() != n {
        return Err(PyValueError::new_err(format!(
            "{name} must have one entry per pair: got {} for {n} pairs",
            list.len()
        )));
    }
    Ok(Some(list))
}

/// One pair's options: the shared ones, its `quality` and its `pair_options` entry.
fn pair_options(
    shared: &EstimatorOptions,
    quality: Option<&Bound<'_, PyAny>>,
    entry: Option<&Bound<'_, PyAny>>,
) -> PyResult<EstimatorOptions> {
    let mut o = shared.clone();
    if let Some(q) = quality {
        o.quality = if q.is_none() {
            None
        } else {
            Some(vector(q, "quality")?)
        };
    }
    let Some(d) = entry.filter(|d| !d.is_none()) else {
        return Ok(o);
    };
    let d = d
        .cast::<PyDict>()
        .map_err(|_| PyValueError::new_err("pair_options entries must be dicts (or None)"))?;
    let mut unknown = Vec::new();
    for (key, value) in d.iter() {
        let name: String = key.extract()?;
        if name == "quality" {
            o.quality = if value.is_none() {
                None
            } else {
                Some(vector(&value, "quality")?)
            };
        } else if !apply_option(&mut o, &name, &value)? {
            unknown.push(name);
        }
    }
    unknown_options(&unknown)?;
    Ok(o)
}

fn read_batch<'py>(
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Vec<PairInput<'py>>> {
    let items: Vec<Bound<'py, PyAny>> = corrs
        .try_iter()
        .map_err(|e| {
            rewrap(e, |_| {
                PyValueError::new_err("corrs must be a sequence of (N, 8) or (N, 4) arrays")
            })
        })?
        .collect::<PyResult<_>>()?;
    let n = items.len();
    // `quality` is per pair in a batch: a sequence of (N_i,) arrays (or None entries);
    // `pair_options` a sequence of option dicts, one per pair, over the shared options.
    let (quality, entries, shared) = match options {
        Some(d) => {
            let d = d.copy()?;
            let quality = d.get_item("quality")?;
            d.del_item("quality").ok();
            let entries = d.get_item("pair_options")?;
            d.del_item("pair_options").ok();
            (quality, entries, Some(d))
        }
        None => (None, None, None),
    };
    let shared = parse_options(shared.as_ref(), EstimatorOptions::default())?;
    // Shared options apply to every pair: invalid ones are the batch's error.
    affcorr::ransac::engine::check_options(&shared.ransac).map_err(value_error)?;
    let quality = per_pair_list(quality, "quality", "(N,) arrays", n)?;
    let entries = per_pair_list(entries, "pair_options", "dicts", n)?;
    items
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let pair = || -> PairInput<'py> {
                let a = F64Array::extract(c, "corrs")?.expect_one_of(&CORRS)?;
                let o = pair_options(
                    &shared,
                    quality.as_ref().map(|q| &q[i]),
                    entries.as_ref().map(|e| &e[i]),
                )?;
                Ok((a, o))
            };
            pair().map_err(|e| pair_error(i, e))
        })
        // A KeyboardInterrupt (in an argument's __array__, say) stops the batch.
        .map(|r| match r {
            Err(e) if Python::attach(|py| crate::errors::passes_through(py, &e)) => Err(e),
            r => Ok(r),
        })
        .collect::<PyResult<Vec<_>>>()
}

/// One pair's outcome: `NotEnoughData` is a no-model result too in a batch.
fn batch_outcome<M>(
    r: Result<Estimate<M>, RansacError>,
    n: usize,
    nan: M,
) -> Result<Outcome<M>, RansacError> {
    match r {
        Err(RansacError::NotEnoughData { .. }) => {
            outcome(Err(RansacError::NoModel { iterations: 0 }), n, nan)
        }
        r => outcome(r, n, nan),
    }
}

/// Runs `f` over every valid pair in parallel, interruptibly, with the GIL released; each pair
/// gets its outcome or its error (`pair i: ...`).
fn run_batch<M: Send + Clone + Sync>(
    py: Python<'_>,
    pairs: &[PairInput<'_>],
    nan: M,
    f: impl Fn(usize, &Correspondences, &EstimatorOptions) -> Result<Estimate<M>, RansacError>
    + Sync
    + Send,
) -> PyResult<Vec<PyResult<Outcome<M>>>> {
    let views: Vec<Option<(&[f64], usize, &EstimatorOptions)>> = pairs
        .iter()
        .map(|p| {
            p.as_ref()
                .ok()
                .map(|(a, o)| (a.as_slice(), a.shape()[1], o))
        })
        .collect();
    let results: Vec<Option<Result<Outcome<M>, RansacError>>> =
        interruptible(py, |cancel| {
            views
                .par_iter()
                .enumerate()
                .map(|(i, view)| {
                    let &(slice, width, opts) = view.as_ref()?;
                    if cancel.is_cancelled() {
                        return None;
                    }
                    let mut opts = opts.clone();
                    opts.ransac.cancel = Some(cancel.clone());
                    Some(rows_to_corrs(slice, width).and_then(|data| {
                        batch_outcome(f(i, &data, &opts), data.len(), nan.clone())
                    }))
                })
                .collect()
        })?;
    Ok(pairs
        .iter()
        .zip(results)
        .enumerate()
        .map(|(i, (p, r))| match (p, r) {
            (Err(e), _) => Err(e.clone_ref(py)),
            (Ok(_), Some(Ok(o))) => Ok(o),
            (Ok(_), Some(Err(e))) => Err(PyValueError::new_err(format!("pair {i}: {e}"))),
            (Ok(_), None) => unreachable!("an uncancelled batch runs every valid pair"),
        })
        .collect())
}

/// Reads `K` for a batch of `n` pairs: one (3, 3) for all, or (n, 3, 3) / a list of n. A bad
/// shape raises; an invalid K of one pair is that pair's error.
fn batch_intrinsics(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    n: usize,
) -> PyResult<Vec<PyResult<Intrinsics>>> {
    let a = F64Array::extract(obj, name)?.expect_one_of(&[
        &[Dim::Is(3), Dim::Is(3)],
        &[Dim::Is(n), Dim::Is(3), Dim::Is(3)],
    ])?;
    let shared = a.shape().len() == 2;
    let ks: Vec<PyResult<Intrinsics>> = a
        .rows::<9>()
        .iter()
        .enumerate()
        .map(|(i, r)| {
            Intrinsics::new(Mat3::from_row_slice(r), name).map_err(|e| {
                if shared {
                    value_error(e)
                } else {
                    PyValueError::new_err(format!("pair {i}: {e}"))
                }
            })
        })
        .collect();
    if shared {
        // One K for every pair: invalid, it is the batch's error.
        let k = ks.into_iter().next().expect("one matrix")?;
        return Ok((0..n).map(|_| Ok(k)).collect());
    }
    Ok(ks)
}

/// The items of a batch's list: `(model, info)` tuples, or the pair's exception object.
fn batch_list<'py, M>(
    py: Python<'py>,
    out: Vec<PyResult<Outcome<M>>>,
    convert: impl Fn(Python<'py>, &Outcome<M>) -> PyResult<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let items = out
        .into_iter()
        .map(|r| match r {
            Ok(o) => convert(py, &o),
            Err(e) => Ok(e.into_value(py).into_bound(py).into_any()),
        })
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}

/// A batch of a 3×3-matrix estimator (H or F).
fn matrix_batch<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
    estimator: fn(&Correspondences, &EstimatorOptions) -> affcorr::ransac::Result<Estimate<Mat3>>,
) -> PyResult<Bound<'py, PyList>> {
    let pairs = read_batch(corrs, options)?;
    let out = run_batch(py, &pairs, nan_mat3(), |_, d, o| estimator(d, o))?;
    batch_list(py, out, |py, o| {
        Ok(mat_result(py, o)?.into_pyobject(py)?.into_any())
    })
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
    let mut pairs = read_batch(corrs, options)?;
    let n = pairs.len();
    let k1 = batch_intrinsics(K1, "K1", n)?;
    let k2 = batch_intrinsics(K2, "K2", n)?;
    // A pair with an invalid K fails with that K's error (its rows' error first).
    let mut ks = Vec::with_capacity(n);
    for (i, (a, b)) in k1.into_iter().zip(k2).enumerate() {
        match (a, b) {
            (Ok(a), Ok(b)) => ks.push(Some((a, b))),
            (Err(e), _) | (_, Err(e)) => {
                if pairs[i].is_ok() {
                    pairs[i] = Err(e);
                }
                ks.push(None);
            }
        }
    }
    let out = run_batch(py, &pairs, nan_pose(), |i, d, o| {
        let (k1, k2) = ks[i].as_ref().expect("pairs with an invalid K do not run");
        estimate_relative_pose(d, k1, k2, o)
    })?;
    batch_list(py, out, |py, o| {
        Ok(pose_result(py, o)?.into_pyobject(py)?.into_any())
    })
}
