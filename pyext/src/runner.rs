//! Bindings of the ONNX runner (`affcorr::runner`): the shape network, patch extraction and
//! image decoding. The Python package (`affcorr.shape`) wraps [`ShapeRunner`] into
//! `affcorr.ShapeEstimator`, which finds the bundled model and the ONNX Runtime library.
//!
//! - Images are a file path (`str` / `os.PathLike`, PNG or JPEG, decoded in Rust) or a numpy
//!   array `(H, W)` or `(H, W, C)` with C in 1..=4 (gray, gray + alpha, RGB, RGBA) of dtype
//!   uint8 (÷255), uint16 (÷65535) or float (taken as [0, 1]).
//! - Errors: bad arguments (shapes, NaN, undecodable images, options) raise `ValueError`
//!   naming the argument; a missing image or model file raises `FileNotFoundError`; ONNX
//!   Runtime and model problems (library not found, not ONNX, contract violations) raise
//!   `RuntimeError`.
//! - Decoding, extraction and inference run with the GIL released.

use std::path::PathBuf;

use crate::arrays::{Dim, F64Array, flatten, to_numpy};
use affcorr::runner::{
    AffineRefineOptions, GrayImage, PixelData, RunnerError, ShapeEstimator, ShapeModelOptions,
    ShapeOutputs, extract_patches as extract, init_ort as init, ort_library as loaded_library,
    refine_affine,
};
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ShapeRunner>()?;
    m.add_function(wrap_pyfunction!(init_ort, m)?)?;
    m.add_function(wrap_pyfunction!(ort_library, m)?)?;
    m.add_function(wrap_pyfunction!(extract_patches, m)?)?;
    m.add_function(wrap_pyfunction!(read_gray_image, m)?)?;
    m.add_function(wrap_pyfunction!(refine_affine_py, m)?)?;
    Ok(())
}

type F64<'py> = Bound<'py, PyArrayDyn<f64>>;
type F32<'py> = Bound<'py, PyArrayDyn<f32>>;

const N: Dim = Dim::Any("N");
const PATCH_DIMS: [usize; 3] = [1, 32, 32];
const PATCH_LEN: usize = 32 * 32;

/// Maps a runner error to the Python exception its kind calls for; `what` (an argument name)
/// prefixes messages that do not start with it already.
pub(crate) fn py_error(e: RunnerError, what: Option<&str>) -> PyErr {
    let text = e.to_string();
    let msg = match what {
        Some(w) if !text.starts_with(w) => format!("{w}: {text}"),
        _ => text,
    };
    match &e {
        RunnerError::ImageOpen { path, .. } | RunnerError::ModelOpen { path, .. }
            if !path.exists() =>
        {
            PyFileNotFoundError::new_err(msg)
        }
        RunnerError::ImageOpen { .. }
        | RunnerError::ImageDecode { .. }
        | RunnerError::ImageBuffer { .. }
        | RunnerError::InvalidInput { .. }
        | RunnerError::NonFinite { .. } => PyValueError::new_err(msg),
        _ => PyRuntimeError::new_err(msg),
    }
}

/// An image argument: a path, or a numpy array of uint8 / uint16 / float.
pub(crate) fn gray_image(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    name: &str,
) -> PyResult<GrayImage> {
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
            .map_err(|e| py_error(e, Some(name)));
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
    built.map_err(|e| py_error(e, Some(name)))
}

/// Points `(N, 2)` as rows.
fn points(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<[f64; 2]>> {
    let a = F64Array::extract(obj, name)?.expect(&[N, Dim::Is(2)])?;
    Ok(a.rows::<2>().to_vec())
}

/// `obj` (any float dtype) as a C-contiguous float32 (N, 1, 32, 32) array of finite values,
/// borrowed (no copy when it already is one).
fn patches<'py>(
    py: Python<'py>,
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyReadonlyArrayDyn<'py, f32>> {
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", "float32")?;
    let a = py
        .import("numpy")?
        .call_method("ascontiguousarray", (obj,), Some(&kwargs))
        .map_err(|e| PyValueError::new_err(format!("{name} must be a numeric array: {e}")))?;
    let a = a.cast_into::<PyArrayDyn<f32>>()?.readonly();
    let shape = a.shape();
    if shape.len() != 4 || shape[1..] != PATCH_DIMS {
        return Err(PyValueError::new_err(format!(
            "{name} must have shape (N, 1, 32, 32), got {shape:?}"
        )));
    }
    if let Some(i) = a.as_slice()?.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name}[{}] contains NaN or infinity",
            i / PATCH_LEN
        )));
    }
    Ok(a)
}

fn f32_array<'py>(py: Python<'py>, shape: &[usize], data: Vec<f32>) -> PyResult<F32<'py>> {
    let array = ArrayD::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok(array.into_pyarray(py))
}

fn f64_vec<'py>(py: Python<'py>, data: Vec<f64>) -> PyResult<F64<'py>> {
    let n = data.len();
    to_numpy(py, &[n], data)
}

/// The shape network with its options; see `affcorr.ShapeEstimator` for the documentation.
#[pyclass(name = "ShapeRunner", module = "affcorr._native", frozen)]
pub struct ShapeRunner {
    inner: ShapeEstimator,
}

#[pymethods]
impl ShapeRunner {
    #[new]
    #[pyo3(signature = (model_path, *, ort_library = None, threads = None, batch_size = 512))]
    fn new(
        py: Python<'_>,
        model_path: PathBuf,
        ort_library: Option<PathBuf>,
        threads: Option<usize>,
        batch_size: usize,
    ) -> PyResult<Self> {
        let options = ShapeModelOptions {
            threads,
            batch_size,
        };
        py.detach(|| {
            init(ort_library.as_deref())?;
            ShapeEstimator::load(&model_path, &options)
        })
        .map(|inner| Self { inner })
        .map_err(|e| py_error(e, None))
    }

    /// Decoded predictions (and optionally the raw outputs) for patch pairs.
    #[pyo3(signature = (patches_a, patches_b, return_logits = false))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        patches_a: &Bound<'py, PyAny>,
        patches_b: &Bound<'py, PyAny>,
        return_logits: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let a = patches(py, patches_a, "patches_a")?;
        let b = patches(py, patches_b, "patches_b")?;
        if a.shape()[0] != b.shape()[0] {
            return Err(PyValueError::new_err(format!(
                "patches_b has {} patches, but patches_a has {}",
                b.shape()[0],
                a.shape()[0]
            )));
        }
        let model = self.inner.model();
        let (a, b) = (a.as_slice()?, b.as_slice()?);
        let (raw, p) = py
            .detach(|| {
                let raw = model.predict_raw_slices(a, b)?;
                let p = model.decode(&raw)?;
                Ok((raw, p))
            })
            .map_err(|e| py_error(e, None))?;
        let n = p.len();
        let out = PyDict::new(py);
        out.set_item("orientation_a", f64_vec(py, p.orientation_a)?)?;
        out.set_item("orientation_b", f64_vec(py, p.orientation_b)?)?;
        out.set_item("scale_a", f64_vec(py, p.scale_a)?)?;
        out.set_item("scale_b", f64_vec(py, p.scale_b)?)?;
        out.set_item(
            "residual_shape",
            to_numpy(py, &[n, 3], flatten(p.residual_shape))?,
        )?;
        if return_logits {
            let ShapeOutputs {
                angle_logits_a,
                angle_logits_b,
                scale_logits_a,
                scale_logits_b,
                residual_shape,
            } = raw;
            let (ka, ks) = (model.bins().angles().len(), model.bins().scales().len());
            out.set_item("angle_logits_a", f32_array(py, &[n, ka], angle_logits_a)?)?;
            out.set_item("angle_logits_b", f32_array(py, &[n, ka], angle_logits_b)?)?;
            out.set_item("scale_logits_a", f32_array(py, &[n, ks], scale_logits_a)?)?;
            out.set_item("scale_logits_b", f32_array(py, &[n, ks], scale_logits_b)?)?;
            out.set_item(
                "residual_shape_raw",
                f32_array(py, &[n, 3], residual_shape)?,
            )?;
        }
        Ok(out)
    }

    /// `(corrs (N, 8), orientation_a, orientation_b, scale_a, scale_b, residual_shape (N, 3))`;
    /// with `refine`, the corrs refined by `refine_affine` (default options) on the same
    /// decoded images.
    #[pyo3(signature = (image_a, image_b, x1, x2, refine = false))]
    #[allow(clippy::type_complexity)]
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        image_a: &Bound<'py, PyAny>,
        image_b: &Bound<'py, PyAny>,
        x1: &Bound<'py, PyAny>,
        x2: &Bound<'py, PyAny>,
        refine: bool,
    ) -> PyResult<(F64<'py>, F64<'py>, F64<'py>, F64<'py>, F64<'py>, F64<'py>)> {
        let x1 = points(x1, "x1")?;
        let x2 = points(x2, "x2")?;
        if x1.len() != x2.len() {
            return Err(PyValueError::new_err(format!(
                "x2 has {} points, but x1 has {}",
                x2.len(),
                x1.len()
            )));
        }
        let img_a = gray_image(py, image_a, "image_a")?;
        let img_b = gray_image(py, image_b, "image_b")?;
        let e = py
            .detach(|| {
                let mut e = self.inner.estimate(&img_a, &img_b, &x1, &x2)?;
                if refine {
                    let options = AffineRefineOptions::default();
                    e.corrs = refine_affine(&img_a, &img_b, &e.corrs, &options)?.corrs;
                }
                Ok(e)
            })
            .map_err(|e| py_error(e, None))?;
        let n = e.corrs.len();
        Ok((
            to_numpy(py, &[n, 8], flatten(e.corrs))?,
            f64_vec(py, e.orientation_a)?,
            f64_vec(py, e.orientation_b)?,
            f64_vec(py, e.scale_a)?,
            f64_vec(py, e.scale_b)?,
            to_numpy(py, &[n, 3], flatten(e.residual_shape))?,
        ))
    }

    /// Angle bin centres (radians) from the model's metadata.
    #[getter]
    fn angle_bins<'py>(&self, py: Python<'py>) -> PyResult<F64<'py>> {
        f64_vec(py, self.inner.model().bins().angles().to_vec())
    }

    /// Scale bin centres (linear factors) from the model's metadata.
    #[getter]
    fn scale_bins<'py>(&self, py: Python<'py>) -> PyResult<F64<'py>> {
        f64_vec(py, self.inner.model().bins().scales().to_vec())
    }

    /// All custom metadata of the model.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self.inner.model().metadata() {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// ONNX Runtime intra-op threads.
    #[getter]
    fn threads(&self) -> usize {
        self.inner.model().threads()
    }

    /// Patch pairs per inference run.
    #[getter]
    fn batch_size(&self) -> usize {
        self.inner.model().batch_size()
    }
}

/// Loads ONNX Runtime (`path`, else `$ORT_DYLIB_PATH`) and returns the library in use.
#[pyfunction]
#[pyo3(signature = (path = None))]
fn init_ort(py: Python<'_>, path: Option<PathBuf>) -> PyResult<PathBuf> {
    py.detach(|| init(path.as_deref()))
        .map_err(|e| py_error(e, None))?;
    Ok(loaded_library()
        .map(|p| p.to_path_buf())
        .unwrap_or_default())
}

/// The loaded ONNX Runtime library, or `None` before the first model is loaded.
#[pyfunction]
fn ort_library() -> Option<PathBuf> {
    loaded_library().map(|p| p.to_path_buf())
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
    let p = py.detach(|| extract(&img, &xy)).map_err(|e| match e {
        RunnerError::NonFinite { row, .. } => {
            PyValueError::new_err(format!("xy[{row}] contains NaN or infinity"))
        }
        e => py_error(e, Some("xy")),
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
/// Returns `(corrs (N, 8), refined (N,) bool, zncc (N,))`.
#[pyfunction]
#[pyo3(name = "refine_affine")]
#[pyo3(signature = (
    image_a, image_b, corrs, *, radius, blur_sigmas, iterations, min_zncc, move_points, try_identity,
    max_shift_std
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
    max_shift_std: f64,
) -> PyResult<(F64<'py>, Bound<'py, PyArrayDyn<bool>>, F64<'py>)> {
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
        max_shift_std,
    };
    let r = py
        .detach(|| refine_affine(&img_a, &img_b, &rows, &options))
        .map_err(|e| py_error(e, None))?;
    let n = r.corrs.len();
    let refined = ArrayD::from_shape_vec(IxDyn(&[n]), r.refined)
        .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok((
        to_numpy(py, &[n, 8], flatten(r.corrs))?,
        refined.into_pyarray(py),
        f64_vec(py, r.zncc)?,
    ))
}
