//! Bindings of affcorr-image: decoding images as the networks see them, 32×32 patches and the
//! affine Lucas–Kanade refinement of ACs.
//!
//! - Images are a file path (`str` / `os.PathLike`, PNG or JPEG, decoded in Rust) or a numpy
//!   array `(H, W)` or `(H, W, C)` with C in 1..=4 (gray, gray + alpha, RGB, RGBA) of dtype
//!   uint8 (÷255), uint16 (÷65535) or float (taken as [0, 1]).
//! - Errors as `errors.rs` maps them: bad arguments and undecodable images raise `ValueError`
//!   naming the argument; a missing image file raises `FileNotFoundError`.
//! - Decoding, extraction and refinement run with the GIL released.

use std::path::PathBuf;

use crate::arrays::{Dim, F64Array, flatten, to_numpy};
use crate::errors::image_error;
use affcorr::image::confidence::{FEATURE_NAMES, FEATURES};
use affcorr::image::{
    AcConfidence, AffineRefineOptions, AffineRefinement, ConfidenceModel, GrayImage, ImageError,
    PixelData, extract_patches as extract, refine_affine,
};
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(extract_patches, m)?)?;
    m.add_function(wrap_pyfunction!(read_gray_image, m)?)?;
    m.add_function(wrap_pyfunction!(refine_affine_py, m)?)?;
    m.add_function(wrap_pyfunction!(confidence_model, m)?)?;
    Ok(())
}

/// The per-AC confidence (and the refinement's report, when there is one) as numpy arrays:
/// `affine_confidence` (N,), `reliable` (N,) bool, `confidence_features` (N, F),
/// `confidence_model` (str); with a refinement also `status` (list of str), `refined` (N,) bool,
/// `zncc`, `shift_std`, `affine_std` (N,).
pub fn confidence_dict<'py>(
    py: Python<'py>,
    conf: AcConfidence,
    refinement: Option<AffineRefinement>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let n = conf.confidence.len();
    d.set_item("affine_confidence", f64_vec(py, conf.confidence)?)?;
    d.set_item("reliable", bool_vec(py, conf.reliable)?)?;
    d.set_item(
        "confidence_features",
        to_numpy(py, &[n, FEATURES], flatten(conf.features))?,
    )?;
    d.set_item("confidence_model", conf.model.name())?;
    if let Some(r) = refinement {
        let status: Vec<&str> = r.status.iter().map(|s| s.name()).collect();
        d.set_item("status", status)?;
        d.set_item("refined", bool_vec(py, r.refined)?)?;
        d.set_item("zncc", f64_vec(py, r.zncc)?)?;
        d.set_item("shift_std", f64_vec(py, r.shift_std)?)?;
        d.set_item("affine_std", f64_vec(py, r.affine_std)?)?;
    }
    Ok(d)
}

/// A (N,) bool array.
pub fn bool_vec(py: Python<'_>, v: Vec<bool>) -> PyResult<Bound<'_, PyArrayDyn<bool>>> {
    let n = v.len();
    ArrayD::from_shape_vec(IxDyn(&[n]), v)
        .map(|a| a.into_pyarray(py))
        .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))
}

/// `(weights (F,), threshold, feature names)` of a confidence model: `"network"`,
/// `"refinement"` or `"network_refinement"`.
#[pyfunction]
fn confidence_model<'py>(
    py: Python<'py>,
    name: &str,
) -> PyResult<(F64<'py>, f64, Vec<&'static str>)> {
    let model = ConfidenceModel::ALL
        .into_iter()
        .find(|m| m.name() == name)
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "name must be one of {:?}, got {name:?}",
                ConfidenceModel::ALL.map(|m| m.name())
            ))
        })?;
    Ok((
        f64_vec(py, model.weights().to_vec())?,
        model.threshold(),
        FEATURE_NAMES.to_vec(),
    ))
}

type F64<'py> = Bound<'py, PyArrayDyn<f64>>;
type F32<'py> = Bound<'py, PyArrayDyn<f32>>;

const N: Dim = Dim::Any("N");

/// An image argument: a path, or a numpy array of uint8 / uint16 / float.
pub fn gray_image(py: Python<'_>, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<GrayImage> {
    let Ok(array) = obj.cast::<PyUntypedArray>() else {
        let path: PathBuf = obj.extract().map_err(|_| {
            PyValueError::new_err(format!(
                "{name} must be a file path or a numpy array (H, W) / (H, W, C), got {}",
                obj.get_type()
                    .name()
                    .map_or_else(|_| "?".to_string(), |n| n.to_string())
            ))
        })?;
        return py
            .detach(|| GrayImage::open(&path))
            .map_err(|e| image_error(e, Some(name)));
    };
    let shape = array.shape().to_vec();
    let (h, w, c) = match shape[..] {
        [h, w] => (h, w, 1),
        [h, w, c] if (1..=4).contains(&c) => (h, w, c),
        _ => {
            return Err(PyValueError::new_err(format!(
                "{name} must have shape (H, W) or (H, W, C) with C in 1..4, got {shape:?}"
            )));
        }
    };
    let np = py.import("numpy")?;
    let kind: String = array.dtype().getattr("kind")?.extract()?;
    let itemsize: usize = array.dtype().getattr("itemsize")?.extract()?;
    let contiguous = |dtype: &str| -> PyResult<Bound<'_, PyAny>> {
        let kwargs = PyDict::new(py);
        kwargs.set_item("dtype", dtype)?;
        np.call_method("ascontiguousarray", (obj,), Some(&kwargs))
    };
    let built = match (kind.as_str(), itemsize) {
        ("u", 1) => {
            let a = contiguous("uint8")?;
            let a = a.cast::<PyArrayDyn<u8>>()?.readonly();
            let data = a.as_slice()?;
            py.detach(|| GrayImage::from_raw(w, h, c, PixelData::U8(data)))
        }
        ("u", 2) => {
            let a = contiguous("uint16")?;
            let a = a.cast::<PyArrayDyn<u16>>()?.readonly();
            let data = a.as_slice()?;
            py.detach(|| GrayImage::from_raw(w, h, c, PixelData::U16(data)))
        }
        ("f", _) => {
            let a = contiguous("float32")?;
            let a = a.cast::<PyArrayDyn<f32>>()?.readonly();
            let data = a.as_slice()?;
            py.detach(|| GrayImage::from_raw(w, h, c, PixelData::F32(data)))
        }
        _ => {
            return Err(PyValueError::new_err(format!(
                "{name} has dtype {}; expected uint8, uint16 or float (values in [0, 1])",
                array.dtype()
            )));
        }
    };
    built.map_err(|e| image_error(e, Some(name)))
}

/// Points `(N, 2)` as rows.
pub fn points(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<[f64; 2]>> {
    let a = F64Array::extract(obj, name)?.expect(&[N, Dim::Is(2)])?;
    Ok(a.rows::<2>().to_vec())
}

pub fn f32_array<'py>(py: Python<'py>, shape: &[usize], data: Vec<f32>) -> PyResult<F32<'py>> {
    let array = ArrayD::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok(array.into_pyarray(py))
}

pub fn f64_vec<'py>(py: Python<'py>, data: Vec<f64>) -> PyResult<F64<'py>> {
    let n = data.len();
    to_numpy(py, &[n], data)
}

/// 32×32 bilinear patches `(N, 1, 32, 32)` float32 around `xy (N, 2)`.
#[pyfunction]
fn extract_patches<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    xy: &Bound<'py, PyAny>,
) -> PyResult<F32<'py>> {
    let xy = points(xy, "xy")?;
    let img = gray_image(py, image, "image")?;
    let p =
        crate::interrupt::parallel(py, usize::MAX, || extract(&img, &xy)).map_err(|e| match e {
            ImageError::NonFinite { row, .. } => {
                PyValueError::new_err(format!("xy[{row}] contains NaN or infinity"))
            }
            e => image_error(e, Some("xy")),
        })?;
    let n = p.len();
    f32_array(py, &[n, 1, 32, 32], p.into_vec())
}

/// An image as the networks see it: `(H, W)` float32 gray in [0, 1].
#[pyfunction]
fn read_gray_image<'py>(py: Python<'py>, image: &Bound<'py, PyAny>) -> PyResult<F32<'py>> {
    let img = gray_image(py, image, "image")?;
    let (h, w) = (img.height(), img.width());
    f32_array(py, &[h, w], img.into_data())
}

/// Affine Lucas–Kanade refinement of ACs; see `affcorr.refine_affine` for the documentation.
/// Returns `(corrs (N, 8), report)`, the report as [`confidence_dict`] gives it.
#[pyfunction]
#[pyo3(name = "refine_affine")]
#[pyo3(signature = (
    image_a, image_b, corrs, *, radius, blur_sigmas, iterations, min_zncc, move_points, try_identity,
    try_neighbours, max_shift_std
))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn refine_affine_py<'py>(
    py: Python<'py>,
    image_a: &Bound<'py, PyAny>,
    image_b: &Bound<'py, PyAny>,
    corrs: &Bound<'py, PyAny>,
    radius: usize,
    blur_sigmas: Vec<f64>,
    iterations: usize,
    min_zncc: f64,
    move_points: bool,
    try_identity: bool,
    try_neighbours: bool,
    max_shift_std: f64,
) -> PyResult<(F64<'py>, Bound<'py, PyDict>)> {
    let rows = F64Array::extract(corrs, "corrs")?
        .expect(&[N, Dim::Is(8)])?
        .rows::<8>()
        .to_vec();
    let img_a = gray_image(py, image_a, "image_a")?;
    let img_b = gray_image(py, image_b, "image_b")?;
    let options = AffineRefineOptions {
        radius,
        blur_sigmas,
        iterations,
        min_zncc,
        move_points,
        try_identity,
        try_neighbours,
        max_shift_std,
    };
    let r =
        crate::interrupt::interruptible(py, |_| refine_affine(&img_a, &img_b, &rows, &options))?
            .map_err(|e| image_error(e, None))?;
    let n = r.corrs.len();
    // The same confidence as r.affine_confidence, with its features.
    let conf = affcorr::image::affine_confidence(&r.corrs, None, Some(&r))
        .map_err(|e| image_error(e, None))?;
    let corrs = to_numpy(py, &[n, 8], flatten(r.corrs.clone()))?;
    let report = confidence_dict(py, conf, Some(r))?;
    Ok((corrs, report))
}
