//! Bindings of the end-to-end pipeline (`affcorr::pipeline::Pipeline`): images → matches → ACs
//! → H, F or relative pose. The Python package (`affcorr.pipeline`) wraps [`PipelineRunner`]
//! into `affcorr.Pipeline`, which finds the bundled models; every step, name and default comes
//! from the Rust crate (`PIPELINE_DEFAULTS`, `PIPELINE_MATCHERS`, `PIPELINE_MODEL_FILES`).
//!
//! - Images are file paths (decoded in Rust, timed as `decode`) or numpy arrays (as
//!   `affcorr.ShapeEstimator` takes them; the conversion is timed as `decode`). A dense
//!   matcher gets (H, W, 3 | 4) arrays in colour.
//! - Errors follow `errors.rs`: bad arguments and images raise `ValueError`, missing files
//!   `FileNotFoundError`, model problems (contracts, ONNX Runtime) `RuntimeError`.
//! - Estimation options are `affcorr.estimate_*`'s keyword options (`ransac.rs` parses them);
//!   no model found is a NaN model with no inliers, as there.
//! - Matching and estimation run with the GIL released.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::arrays::{flatten, opt_int_option, to_numpy, to_usize};
use crate::errors::rewrap;
use crate::errors::{image_error, pipeline_error, runner_error};
use crate::image::gray_image;
use crate::interrupt::interruptible;
use crate::ransac::{mat_result, nan_mat3, nan_pose, outcome, parse_options, pose_result};
use affcorr::pipeline::GrowOptions;
use affcorr::pipeline::defaults::{self, Geometry};
use affcorr::pipeline::views::ViewImage;
use affcorr::pipeline::{
    AffineRefineOptions, Features, GrayImage, ImageSource, Matcher, Matches, Pipeline,
    PipelineError, RgbImage, ViewOptions, init_ort as init, model_file,
};
use affcorr::ransac::{
    Correspondences, Estimate, EstimatorOptions, RansacError, estimate_fundamental,
    estimate_homography, estimate_relative_pose,
};
use affcorr::runner::contract::MAX_THREADS;
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyEllipsis, PyList, PySlice, PyTuple};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PipelineRunner>()?;
    m.add_class::<PipelineFeatures>()?;
    let py = m.py();
    let d = PyDict::new(py);
    d.set_item("matcher", defaults::MATCHER.name())?;
    d.set_item("max_keypoints", defaults::MAX_KEYPOINTS)?;
    d.set_item(
        "aliked_detection_threshold",
        defaults::ALIKED_DETECTION_THRESHOLD,
    )?;
    d.set_item("dense_matches", defaults::DENSE_MATCHES)?;
    d.set_item("refine_affine", defaults::REFINE_AFFINE)?;
    d.set_item("exif_orientation", defaults::EXIF_ORIENTATION)?;
    d.set_item("views", defaults::VIEWS.name())?;
    d.set_item("view_relative_budget", defaults::VIEW_RELATIVE_BUDGET)?;
    d.set_item("guided_matching", defaults::GUIDED_MATCHING)?;
    d.set_item("seed", defaults::SEED)?;
    d.set_item("homography_threshold", defaults::HOMOGRAPHY_THRESHOLD)?;
    d.set_item("fundamental_threshold", defaults::FUNDAMENTAL_THRESHOLD)?;
    d.set_item("pose_threshold", defaults::POSE_THRESHOLD)?;
    m.add("PIPELINE_DEFAULTS", d)?;
    let names: Vec<&str> = Matcher::ALL.iter().map(|m| m.name()).collect();
    m.add("PIPELINE_MATCHERS", names)?;
    let needs = PyDict::new(py);
    for matcher in Matcher::ALL {
        let roles: Vec<&str> = matcher.models().iter().map(|r| r.name()).collect();
        needs.set_item(matcher.name(), roles)?;
    }
    m.add("PIPELINE_MATCHER_MODELS", needs)?;
    // The models of the view cascade's screen where another matcher screens (XFeat's backbone
    // for DISK, ALIKED and XFeat*), loaded when the cascade is on.
    let screen = PyDict::new(py);
    for matcher in Matcher::ALL {
        let roles: Vec<&str> = defaults::view_screen(matcher)
            .map_or(&[][..], Matcher::models)
            .iter()
            .map(|r| r.name())
            .collect();
        screen.set_item(matcher.name(), roles)?;
    }
    m.add("PIPELINE_SCREEN_MODELS", screen)?;
    let files = PyDict::new(py);
    for role in affcorr::pipeline::ModelRole::ALL {
        files.set_item(role.name(), model_file(role))?;
    }
    files.set_item("shape", affcorr::pipeline::SHAPE_FILE)?;
    m.add("PIPELINE_MODEL_FILES", files)?;
    Ok(())
}

/// An image argument, ready for the pipeline.
enum ImageArg {
    Path(PathBuf),
    Image(GrayImage),
    Rgb(RgbImage),
}

impl ImageArg {
    fn source(&self) -> ImageSource<'_> {
        match self {
            Self::Path(p) => ImageSource::Path(p),
            Self::Image(img) => ImageSource::Image(img),
            Self::Rgb(img) => ImageSource::Rgb(img),
        }
    }
}

/// A path stays a path (the pipeline decodes it); an array is converted here (to colour for a
/// dense matcher when it has 3 or 4 channels). Returns the conversion time.
fn image_arg(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    name: &str,
    colour: bool,
) -> PyResult<(ImageArg, Duration)> {
    let t = Instant::now();
    let Ok(array) = obj.cast::<PyUntypedArray>() else {
        if let Ok(path) = obj.extract::<PathBuf>() {
            return Ok((ImageArg::Path(path), Duration::ZERO));
        }
        // Not a path: gray_image names the argument in its error.
        return gray_image(py, obj, name).map(|img| (ImageArg::Image(img), t.elapsed()));
    };
    if colour && let [h, w, 3 | 4] = array.shape()[..] {
        // Gray conversion validates dtype, values and shape first (and names the argument);
        // the colour samples then take its scale: uint8 / 255, uint16 / 65535, float as is.
        gray_image(py, obj, name)?;
        let kind: String = array.dtype().getattr("kind")?.extract()?;
        let itemsize: usize = array.dtype().getattr("itemsize")?.extract()?;
        let scale = match (kind.as_str(), itemsize) {
            ("u", 1) => 255.0,
            ("u", 2) => 65535.0,
            _ => 1.0,
        };
        let np = py.import("numpy")?;
        let rgb = obj.get_item((PyEllipsis::get(py), PySlice::new(py, 0, 3, 1)))?;
        let kwargs = PyDict::new(py);
        kwargs.set_item("dtype", "float32")?;
        let rgb = np.call_method("ascontiguousarray", (rgb,), Some(&kwargs))?;
        let rgb = rgb.call_method1("__truediv__", (scale,))?;
        let rgb = rgb.cast::<PyArrayDyn<f32>>()?.readonly();
        let img = RgbImage::new(w, h, rgb.as_slice()?.to_vec())
            .map_err(|e| image_error(e, Some(name)))?;
        return Ok((ImageArg::Rgb(img), t.elapsed()));
    }
    let img = gray_image(py, obj, name)?;
    Ok((ImageArg::Image(img), t.elapsed()))
}

type MatchTuple<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyDict>,
    (usize, usize),
    Bound<'py, PyList>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
);

/// The view cascade's report: one dict per view tried (`label`, `image` "A" | "B" | None,
/// `rotation` (rad), `scale`, `tilt`, `tilt_angle` (rad), `guided`, `window`, `other_scale`,
/// `other_rotation` (rad), `matches`, `inliers`, `screen` (None unless ranked in a group),
/// `verified`, `seconds`, `work` (the relative budget's work it took, in plain passes) and
/// `used`: whether its ACs are the result's, `Matches::view`).
fn view_reports<'py>(py: Python<'py>, m: &Matches) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    let used = m.view();
    for v in &m.views {
        let d = PyDict::new(py);
        d.set_item("label", v.view.label())?;
        d.set_item("used", used.is_some_and(|u| std::ptr::eq(u, v)))?;
        let image = match v.view.image {
            ViewImage::None => None,
            ViewImage::A => Some("A"),
            ViewImage::B => Some("B"),
        };
        d.set_item("image", image)?;
        d.set_item("rotation", v.view.rotation)?;
        d.set_item("scale", v.view.scale)?;
        d.set_item("tilt", v.view.tilt)?;
        d.set_item("tilt_angle", v.view.tilt_angle)?;
        d.set_item("guided", v.view.guided.map(|m| m.to_vec()))?;
        d.set_item("window", v.view.window.map(|w| w.to_vec()))?;
        d.set_item("other_scale", v.view.other_scale)?;
        d.set_item("other_rotation", v.view.other_rotation)?;
        d.set_item("matches", v.matches)?;
        d.set_item("inliers", v.inliers)?;
        d.set_item("verified", v.verified)?;
        d.set_item("screen", v.screen)?;
        d.set_item("seconds", v.time.as_secs_f64())?;
        d.set_item("work", v.work)?;
        d.set_item("started", v.started)?;
        d.set_item("screen_extraction", v.screen_extraction)?;
        out.append(d)?;
    }
    Ok(out)
}

/// `(corrs (N, 8), certainty (N,), timings {stage: seconds}, (keypoints A, keypoints B),
/// views [report per view], affine_confidence (N,), reliable (N,) bool)`.
fn match_tuple<'py>(
    py: Python<'py>,
    m: Matches,
    extra_decode: Duration,
) -> PyResult<MatchTuple<'py>> {
    let n = m.corrs.len();
    let views = view_reports(py, &m)?;
    let mut timings = m.timings;
    timings.decode += extra_decode;
    timings.total += extra_decode;
    let d = PyDict::new(py);
    for (name, v) in timings.stages() {
        d.set_item(name, v.as_secs_f64())?;
    }
    Ok((
        to_numpy(py, &[n, 8], flatten(m.corrs))?.into_any(),
        to_numpy(py, &[n], m.certainty)?.into_any(),
        d,
        m.num_keypoints,
        views,
        to_numpy(py, &[n], m.affine_confidence)?.into_any(),
        crate::image::bool_vec(py, m.reliable)?.into_any(),
    ))
}

/// The pipeline with its models; see `affcorr.Pipeline` for the documentation.
#[pyclass(name = "PipelineRunner", module = "affcorr._native", frozen)]
pub struct PipelineRunner {
    inner: Pipeline,
}

#[pymethods]
impl PipelineRunner {
    #[new]
    #[pyo3(signature = (
        *, matcher, shape_model, backbone_model = None, refine_model = None,
        lighterglue_model = None, dense_model = None, disk_backbone_model = None,
        disk_lightglue_model = None, aliked_backbone_model = None,
        aliked_lightglue_model = None, ort_library = None, max_keypoints = None,
        detection_threshold = None, max_matches = None, max_side = None, threads = None, seed = None,
        refine_affine = defaults::REFINE_AFFINE, drop_unreliable = false,
        exif_orientation = defaults::EXIF_ORIENTATION,
        guided_matching = defaults::GUIDED_MATCHING,
        views = None, view_budget = None,
        view_relative_budget = defaults::VIEW_RELATIVE_BUDGET, max_views = None
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        matcher: &str,
        shape_model: PathBuf,
        backbone_model: Option<PathBuf>,
        refine_model: Option<PathBuf>,
        lighterglue_model: Option<PathBuf>,
        dense_model: Option<PathBuf>,
        disk_backbone_model: Option<PathBuf>,
        disk_lightglue_model: Option<PathBuf>,
        aliked_backbone_model: Option<PathBuf>,
        aliked_lightglue_model: Option<PathBuf>,
        ort_library: Option<PathBuf>,
        max_keypoints: Option<&Bound<'_, PyAny>>,
        detection_threshold: Option<f64>,
        max_matches: Option<&Bound<'_, PyAny>>,
        max_side: Option<&Bound<'_, PyAny>>,
        threads: Option<&Bound<'_, PyAny>>,
        seed: Option<&Bound<'_, PyAny>>,
        refine_affine: bool,
        drop_unreliable: bool,
        exif_orientation: bool,
        guided_matching: bool,
        views: Option<&str>,
        view_budget: Option<f64>,
        view_relative_budget: Option<f64>,
        max_views: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        // Integer options: Python or numpy ints, each bounded and named in its errors.
        let positive = |v, name, max: u64| opt_int_option(v, name, "a positive int", 1, max);
        let max_keypoints = positive(max_keypoints, "max_keypoints", MAX_KEYPOINTS)?;
        let max_matches = positive(max_matches, "max_matches", MAX_MATCHES)?;
        let max_side = positive(max_side, "max_side", MAX_SIDE)?;
        let threads = opt_int_option(
            threads,
            "threads",
            "a positive int or None",
            1,
            MAX_THREADS as u64,
        )?;
        let seed = opt_int_option(seed, "seed", "a non-negative int", 0, u64::MAX)?
            .unwrap_or(defaults::SEED);
        let max_views = positive(max_views, "max_views", MAX_VIEWS)?;
        let matcher: Matcher = matcher.parse().map_err(|e| runner_error(e, None))?;
        let mut b = Pipeline::builder()
            .matcher(matcher)
            .shape_model(shape_model)
            .seed(seed);
        if let Some(p) = backbone_model {
            b = b.backbone_model(p);
        }
        if let Some(p) = dense_model {
            if matcher != Matcher::Dense {
                return Err(PyValueError::new_err(format!(
                    "dense_model is only used with matcher=\"dense\", not {:?}",
                    matcher.name()
                )));
            }
            b = b.dense_matcher(p);
        }
        if let Some(p) = refine_model {
            b = b.refine_model(p);
        }
        if let Some(p) = lighterglue_model {
            b = b.lighterglue_model(p);
        }
        if let Some(p) = disk_backbone_model {
            b = b.disk_backbone_model(p);
        }
        if let Some(p) = disk_lightglue_model {
            b = b.disk_lightglue_model(p);
        }
        if let Some(p) = aliked_backbone_model {
            b = b.aliked_backbone_model(p);
        }
        if let Some(p) = aliked_lightglue_model {
            b = b.aliked_lightglue_model(p);
        }
        if let Some(n) = max_keypoints {
            b = b.max_keypoints(to_usize(n));
        }
        if let Some(t) = detection_threshold {
            if !t.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "detection_threshold must be a finite number or None, got {t}"
                )));
            }
            b = b.detection_threshold(t as f32);
        }
        if let Some(n) = max_matches {
            b = b.max_matches(to_usize(n));
        }
        if let Some(n) = max_side {
            b = b.max_side(to_usize(n));
        }
        if let Some(n) = threads {
            b = b.threads(to_usize(n));
        }
        b = b.affine_refinement(refine_affine.then(AffineRefineOptions::default));
        b = b.drop_unreliable(drop_unreliable);
        b = b.exif_orientation(exif_orientation);
        b = b.guided_matching(guided_matching.then(GrowOptions::default));
        let mut view_options = ViewOptions::default();
        if let Some(mode) = views {
            view_options.mode = mode.parse().map_err(|e| pipeline_error(e, None))?;
        }
        if let Some(seconds) = view_budget {
            if !(seconds >= 0.0 && seconds.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "view_budget must be a non-negative number of seconds or None, got {seconds}"
                )));
            }
            view_options.time_budget = Some(Duration::from_secs_f64(seconds));
        }
        if let Some(r) = view_relative_budget
            && !(r > 0.0 && r.is_finite())
        {
            return Err(PyValueError::new_err(format!(
                "view_relative_budget must be a positive number (times the plain pass) or None, \
                 got {r}"
            )));
        }
        view_options.relative_budget = view_relative_budget;
        if let Some(n) = max_views {
            view_options.max_views = to_usize(n);
        }
        b = b.views(view_options);
        py.detach(|| {
            init(ort_library.as_deref())?;
            b.build()
        })
        .map(|inner| Self { inner })
        .map_err(|e| pipeline_error(e, None))
    }

    /// ACs of one pair: `(corrs, certainty, timings, num_keypoints)`.
    fn match_pair<'py>(
        &self,
        py: Python<'py>,
        image_a: &Bound<'py, PyAny>,
        image_b: &Bound<'py, PyAny>,
    ) -> PyResult<MatchTuple<'py>> {
        let colour = self.inner.matcher() == Matcher::Dense;
        let (a, ta) = image_arg(py, image_a, "image_a", colour)?;
        let (b, tb) = image_arg(py, image_b, "image_b", colour)?;
        let m = interruptible(py, |_| self.inner.match_pair(a.source(), b.source()))?
            .map_err(|e| pipeline_error(e, None))?;
        match_tuple(py, m, ta + tb)
    }

    /// `((model, info), match tuple)` of a pair: `geometry` is `"homography"` (model H),
    /// `"fundamental"` (F) or `"relative_pose"` (`(R, t, E, F)`, needs `K1`, `K2`, checked
    /// before any matching); `affcorr.estimate_*`'s keyword options; `threshold=None` is the
    /// pipeline's default for the geometry.
    #[pyo3(signature = (geometry, image_a, image_b, *, K1 = None, K2 = None, threshold = None, **options))]
    #[allow(non_snake_case, clippy::too_many_arguments)]
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        geometry: &str,
        image_a: &Bound<'py, PyAny>,
        image_b: &Bound<'py, PyAny>,
        K1: Option<&Bound<'py, PyAny>>,
        K2: Option<&Bound<'py, PyAny>>,
        threshold: Option<f64>,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<(Bound<'py, PyAny>, MatchTuple<'py>)> {
        let geometry = match geometry {
            "homography" => Geometry::Homography,
            "fundamental" => Geometry::Fundamental,
            "relative_pose" => Geometry::RelativePose,
            _ => {
                return Err(PyValueError::new_err(format!(
                    "geometry must be \"homography\", \"fundamental\" or \"relative_pose\", \
                     got {geometry:?}"
                )));
            }
        };
        let intrinsics = match (geometry, K1, K2) {
            (Geometry::RelativePose, Some(k1), Some(k2)) => Some((
                crate::geom::intrinsics(k1, "K1")?,
                crate::geom::intrinsics(k2, "K2")?,
            )),
            (Geometry::RelativePose, _, _) => {
                return Err(PyValueError::new_err("relative_pose needs K1 and K2"));
            }
            (_, None, None) => None,
            _ => {
                return Err(PyValueError::new_err(
                    "K1 and K2 are only used with geometry=\"relative_pose\"",
                ));
            }
        };
        let mut opts = parse_options(options, geometry.default_options())?;
        if let Some(t) = threshold {
            opts.ransac.threshold = t;
        }
        let (a, b, t) = self.images(py, image_a, image_b)?;
        let (a, b) = (a.source(), b.source());
        let inner = &self.inner;
        let (model, m) = match intrinsics {
            Some((k1, k2)) => {
                let (o, m) = interruptible(py, |cancel| {
                    opts.ransac.cancel = Some(cancel.clone());
                    estimate_or_empty(inner, a, b, &opts, nan_pose(), |d, o| {
                        estimate_relative_pose(d, &k1, &k2, o)
                    })
                })??;
                (pose_result(py, &o)?.into_pyobject(py)?.into_any(), m)
            }
            None => {
                let estimator = if geometry == Geometry::Homography {
                    estimate_homography
                } else {
                    estimate_fundamental
                };
                let (o, m) = interruptible(py, |cancel| {
                    opts.ransac.cancel = Some(cancel.clone());
                    estimate_or_empty(inner, a, b, &opts, nan_mat3(), estimator)
                })??;
                (mat_result(py, &o)?.into_pyobject(py)?.into_any(), m)
            }
        };
        Ok((model, match_tuple(py, m, t)?))
    }

    /// ACs of many pairs (a sequence of `(image_a, image_b)`), in parallel on single-threaded
    /// copies of the models (`Pipeline::match_pairs`). Each pair gets its match tuple, or the
    /// exception `match_pair` would have raised for it (its message prefixed `pairs[i]: `), in
    /// its place: one unreadable image costs its own pair only. A malformed `pairs` (not a
    /// sequence, an item that is not a pair) raises.
    fn match_pairs<'py>(
        &self,
        py: Python<'py>,
        pairs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyList>> {
        let items: Vec<Bound<'py, PyAny>> = pairs
            .try_iter()
            .map_err(|e| {
                rewrap(e, |_| {
                    PyValueError::new_err("pairs must be a sequence of (image_a, image_b)")
                })
            })?
            .collect::<PyResult<_>>()?;
        let colour = self.inner.matcher() == Matcher::Dense;
        // Each distinct image object is converted once, so that the pipeline extracts its
        // features once (`Pipeline::match_pairs` shares them by path or buffer).
        let mut images: Vec<ImageArg> = Vec::new();
        // `items` keeps every object alive, so an address names one object throughout.
        let mut seen: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
        let mut convert = |obj: &Bound<'py, PyAny>, name: &str| -> PyResult<(usize, Duration)> {
            if let Some(&k) = seen.get(&(obj.as_ptr() as usize)) {
                return Ok((k, Duration::ZERO));
            }
            let (arg, t) = image_arg(py, obj, name, colour)?;
            images.push(arg);
            seen.insert(obj.as_ptr() as usize, images.len() - 1);
            Ok((images.len() - 1, t))
        };
        let mut args: Vec<PyResult<(usize, usize, Duration)>> = Vec::with_capacity(items.len());
        for (i, item) in items.iter().enumerate() {
            let pair = item
                .cast::<PyTuple>()
                .ok()
                .filter(|t| t.len() == 2)
                .map(|t| (t.get_item(0), t.get_item(1)))
                .or_else(|| {
                    let l = item.cast::<PyList>().ok().filter(|l| l.len() == 2)?;
                    Some((l.get_item(0), l.get_item(1)))
                });
            let Some((Ok(a), Ok(b))) = pair else {
                return Err(PyValueError::new_err(format!(
                    "pairs[{i}] must be a pair (image_a, image_b)"
                )));
            };
            let arg = convert(&a, "image_a")
                .and_then(|(a, ta)| convert(&b, "image_b").map(|(b, tb)| (a, b, ta + tb)));
            match arg {
                // A KeyboardInterrupt (in an argument's __array__, say) stops the batch.
                Err(e) if crate::errors::passes_through(py, &e) => return Err(e),
                arg => args.push(arg.map_err(|e| prefix_error(py, i, e))),
            }
        }
        let runnable: Vec<(usize, ImageSource<'_>, ImageSource<'_>)> = args
            .iter()
            .enumerate()
            .filter_map(|(i, a)| {
                a.as_ref()
                    .ok()
                    .map(|&(a, b, _)| (i, images[a].source(), images[b].source()))
            })
            .collect();
        let results = interruptible(py, |cancel| {
            self.inner
                .match_pairs_until(runnable.iter().map(|&(_, a, b)| (a, b)), cancel)
        })?;
        let mut matched: Vec<Option<Result<Matches, PipelineError>>> =
            (0..args.len()).map(|_| None).collect();
        for (&(i, _, _), r) in runnable.iter().zip(results) {
            matched[i] = Some(r.expect("an uncancelled batch matches every pair"));
        }
        let mut out = Vec::with_capacity(args.len());
        for (i, (arg, r)) in args.into_iter().zip(matched).enumerate() {
            let item = match (arg, r) {
                (Err(e), _) => e.into_value(py).into_bound(py).into_any(),
                (Ok((_, _, t)), Some(Ok(m))) => {
                    match_tuple(py, m, t)?.into_pyobject(py)?.into_any()
                }
                (Ok(_), Some(Err(e))) => prefix_error(py, i, pipeline_error(e, None))
                    .into_value(py)
                    .into_bound(py)
                    .into_any(),
                (Ok(_), None) => unreachable!("every readable pair is matched"),
            };
            out.push(item);
        }
        PyList::new(py, out)
    }

    /// The features of one image (`Pipeline::extract`): a `PipelineFeatures`.
    fn extract(&self, py: Python<'_>, image: &Bound<'_, PyAny>) -> PyResult<PipelineFeatures> {
        let colour = self.inner.matcher() == Matcher::Dense;
        let (img, t) = image_arg(py, image, "image", colour)?;
        let mut f = interruptible(py, |_| self.inner.extract(img.source()))?
            .map_err(|e| pipeline_error(e, None))?;
        f.add_decode_time(t);
        Ok(PipelineFeatures { inner: Arc::new(f) })
    }

    /// The match tuple of two images' features (`Pipeline::match_features`): `match_pair`'s
    /// result for the two images.
    fn match_features<'py>(
        &self,
        py: Python<'py>,
        features_a: &Bound<'py, PyAny>,
        features_b: &Bound<'py, PyAny>,
    ) -> PyResult<MatchTuple<'py>> {
        let fa = features_arg(features_a, "features_a")?;
        let fb = features_arg(features_b, "features_b")?;
        let m = interruptible(py, |_| self.inner.match_features(&fa, &fb))?
            .map_err(|e| pipeline_error(e, None))?;
        match_tuple(py, m, Duration::ZERO)
    }

    /// `"xfeat"`, `"xfeat-star"`, `"xfeat-lighterglue"` or `"dense"`.
    #[getter]
    fn matcher(&self) -> &'static str {
        self.inner.matcher().name()
    }

    /// Keypoints (or semi-dense cells) per image; a dense matcher's matches drawn.
    #[getter]
    fn max_keypoints(&self) -> usize {
        self.inner.max_keypoints()
    }

    /// The score a keypoint needs in the detector's map, or None (no keypoints by score).
    #[getter]
    fn detection_threshold(&self) -> Option<f64> {
        // The shortest decimal that round-trips the f32 (0.05, not 0.05000000074505806), so
        // that it compares equal to what was passed.
        self.inner
            .detection_threshold()
            .and_then(|t| t.to_string().parse().ok())
    }

    /// The cap on matches, or None.
    #[getter]
    fn max_matches(&self) -> Option<usize> {
        self.inner.max_matches()
    }

    /// The working resolution's longest side, or None.
    #[getter]
    fn max_side(&self) -> Option<usize> {
        self.inner.max_side()
    }

    /// ONNX Runtime intra-op threads and Rust threads.
    #[getter]
    fn threads(&self) -> usize {
        self.inner.threads()
    }

    /// The seed of a dense matcher's balanced sampling.
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed()
    }

    /// Whether image files are matched upright, as their EXIF orientation shows them.
    #[getter]
    fn exif_orientation(&self) -> bool {
        self.inner.exif_orientation()
    }

    /// The view cascade's mode: "off", "auto" or "full".
    #[getter]
    fn views(&self) -> &'static str {
        self.inner.views().mode.name()
    }

    /// The matcher whose features screen the view cascade's groups: "xfeat" for DISK, ALIKED
    /// (when XFeat's backbone was given) and XFeat*, else the pipeline's own.
    #[getter]
    fn view_screen(&self) -> &'static str {
        self.inner.view_screen().name()
    }

    /// The matcher model's custom metadata: the XFeat, DISK or ALIKED backbone's, or the dense
    /// matcher's.
    #[getter]
    fn matcher_metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let inner = &self.inner;
        let meta = if let Some(b) = inner.backbone() {
            b.metadata()
        } else if let Some(b) = inner.disk_backbone() {
            b.metadata()
        } else if let Some(b) = inner.aliked_backbone() {
            b.metadata()
        } else if let Some(m) = inner.dense_matcher() {
            m.metadata()
        } else {
            return Ok(d);
        };
        for (k, v) in meta {
            d.set_item(k, v)?;
        }
        Ok(d)
    }
}

impl PipelineRunner {
    /// Both image arguments, converted (a dense matcher takes colour), and the conversion time.
    fn images(
        &self,
        py: Python<'_>,
        image_a: &Bound<'_, PyAny>,
        image_b: &Bound<'_, PyAny>,
    ) -> PyResult<(ImageArg, ImageArg, Duration)> {
        let colour = self.inner.matcher() == Matcher::Dense;
        let (a, ta) = image_arg(py, image_a, "image_a", colour)?;
        let (b, tb) = image_arg(py, image_b, "image_b", colour)?;
        Ok((a, b, ta + tb))
    }
}

/// The pair's matches and the estimate as `affcorr.estimate_*` returns it: no model (NaN,
/// no inliers) also when the matches are fewer than a minimal sample, a normal outcome of
/// matching; image, model and option errors raise.
fn estimate_or_empty<M>(
    pipeline: &Pipeline,
    a: ImageSource<'_>,
    b: ImageSource<'_>,
    options: &EstimatorOptions,
    nan: M,
    estimator: impl Fn(&Correspondences, &EstimatorOptions) -> Result<Estimate<M>, RansacError>,
) -> PyResult<(crate::ransac::Outcome<M>, Matches)> {
    let matches = pipeline
        .match_pair(a, b)
        .map_err(|e| pipeline_error(e, None))?;
    let n = matches.len();
    match pipeline.estimate(matches.clone(), options, estimator) {
        Ok(e) => {
            let o = outcome(Ok(e.estimate), n, nan).map_err(crate::arrays::value_error)?;
            Ok((o, e.matches))
        }
        // No model, or fewer matches than a minimal sample: NaN with no inliers.
        Err(PipelineError::Ransac(RansacError::NoModel { iterations })) => {
            let o = outcome(Err(RansacError::NoModel { iterations }), n, nan)
                .map_err(crate::arrays::value_error)?;
            Ok((o, matches))
        }
        Err(PipelineError::Ransac(RansacError::NotEnoughData { .. })) => {
            let o = outcome(Err(RansacError::NoModel { iterations: 0 }), n, nan)
                .map_err(crate::arrays::value_error)?;
            Ok((o, matches))
        }
        Err(e) => Err(pipeline_error(e, None)),
    }
}

/// The most keypoints per image (each costs descriptor memory and matching time).
const MAX_KEYPOINTS: u64 = 1 << 20;
/// The most matches kept (a dense matcher draws this many).
const MAX_MATCHES: u64 = 1 << 24;
/// The longest working side in pixels.
const MAX_SIDE: u64 = 1 << 20;
/// The most views the cascade may try.
const MAX_VIEWS: u64 = 1 << 10;

/// The same exception type, its message prefixed with `pairs[i]: ` (a KeyboardInterrupt and
/// the like pass unchanged).
fn prefix_error(py: Python<'_>, i: usize, e: PyErr) -> PyErr {
    if crate::errors::passes_through(py, &e) {
        return e;
    }
    let msg = format!("pairs[{i}]: {}", e.value(py));
    let ty = e.get_type(py);
    PyErr::from_type(ty, msg)
}

/// `features_a` / `features_b`: a `PipelineFeatures` (of `PipelineRunner.extract`).
fn features_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Arc<Features>> {
    obj.cast::<PipelineFeatures>()
        .map(|f| f.get().inner.clone())
        .map_err(|_| {
            PyValueError::new_err(format!(
                "{name} must be the Features of Pipeline.extract, got {}",
                obj.get_type()
                    .name()
                    .map_or_else(|_| "?".to_string(), |n| n.to_string())
            ))
        })
}

/// One image's features (`affcorr_pipeline::Features`), immutable; pickled as its bytes.
#[pyclass(name = "PipelineFeatures", module = "affcorr._native", frozen)]
pub struct PipelineFeatures {
    inner: Arc<Features>,
}

#[pymethods]
impl PipelineFeatures {
    /// The matcher that extracted them.
    #[getter]
    fn matcher(&self) -> &'static str {
        self.inner.matcher().name()
    }

    /// (W, H) of the original image as stored.
    #[getter]
    fn image_size(&self) -> (usize, usize) {
        self.inner.image_size()
    }

    /// (W, H) at the working resolution, upright.
    #[getter]
    fn working_size(&self) -> (usize, usize) {
        self.inner.working_size()
    }

    /// The EXIF orientation (1-8) the image was turned upright by before extraction; 1 for
    /// arrays, untagged files, or with the pipeline's `exif_orientation` off.
    #[getter]
    fn orientation(&self) -> u8 {
        self.inner.orientation().exif()
    }

    /// (N, 2) float64 keypoints in the original pixels (empty for a dense matcher).
    #[getter]
    fn keypoints<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let k = self.inner.keypoints();
        Ok(to_numpy(py, &[k.len(), 2], flatten(k))?.into_any())
    }

    /// (N,) float32 detector scores (sparse matchers; empty otherwise).
    #[getter]
    fn scores<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let s = self.inner.scores().to_vec();
        Ok(crate::image::f32_array(py, &[s.len()], s)?.into_any())
    }

    /// (N, D) float32 descriptors (empty for a dense matcher).
    #[getter]
    fn descriptors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let d = self.inner.descriptor_dim();
        let v = self.inner.descriptors().to_vec();
        let n = v.len().checked_div(d).unwrap_or(0);
        Ok(crate::image::f32_array(py, &[n, d], v)?.into_any())
    }

    /// Seconds spent decoding and extracting (0 after `from_bytes`).
    #[getter]
    fn seconds(&self) -> f64 {
        self.inner.extraction_time().as_secs_f64()
    }

    /// The features as bytes (`from_bytes` reads them back).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.inner.to_bytes())
    }

    /// Features from `to_bytes`; anything else raises ValueError naming `data`.
    #[staticmethod]
    fn from_bytes(data: &[u8]) -> PyResult<Self> {
        Features::from_bytes(data)
            .map(|f| Self { inner: Arc::new(f) })
            .map_err(|e| pipeline_error(e, None))
    }

    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let py = slf.py();
        let ctor = slf.get_type().getattr("from_bytes")?;
        Ok((ctor, (slf.get().to_bytes(py),)))
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __repr__(&self) -> String {
        let (w, h) = self.inner.image_size();
        format!(
            "Features({}, {} keypoints, image {w}x{h})",
            self.inner.matcher(),
            self.inner.len()
        )
    }
}
