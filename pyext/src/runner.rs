//! Bindings of the ONNX runner (`affcorr::runner`): the shape network and the loading of ONNX
//! Runtime. The Python package (`affcorr.shape`) wraps [`ShapeRunner`] into
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

use crate::arrays::{flatten, opt_int_option, to_numpy, to_usize};
use crate::errors::runner_error;
use crate::image::{confidence_dict, f32_array, f64_vec, gray_image, points};
use crate::interrupt::interruptible;
use affcorr::image::AffineRefineOptions;
use affcorr::runner::contract::MAX_THREADS;
use affcorr::runner::shape::MAX_BATCH_SIZE;
use affcorr::runner::{
    ShapeEstimator, ShapeModelOptions, ShapeOutputs, init_ort as init,
    ort_library as loaded_library,
};
use numpy::{PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ShapeRunner>()?;
    m.add_function(wrap_pyfunction!(init_ort, m)?)?;
    m.add_function(wrap_pyfunction!(ort_library, m)?)?;
    Ok(())
}

type F64<'py> = Bound<'py, PyArrayDyn<f64>>;

const PATCH_DIMS: [usize; 3] = [1, 32, 32];
const PATCH_LEN: usize = 32 * 32;

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

/// The shape network with its options; see `affcorr.ShapeEstimator` for the documentation.
#[pyclass(name = "ShapeRunner", module = "affcorr._native", frozen)]
pub struct ShapeRunner {
    inner: ShapeEstimator,
}

#[pymethods]
impl ShapeRunner {
    #[new]
    #[pyo3(signature = (model_path, *, ort_library = None, threads = None, batch_size = None))]
    fn new(
        py: Python<'_>,
        model_path: PathBuf,
        ort_library: Option<PathBuf>,
        threads: Option<&Bound<'_, PyAny>>,
        batch_size: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let threads = opt_int_option(
            threads,
            "threads",
            "a positive int or None",
            1,
            MAX_THREADS as u64,
        )?;
        let batch_size = opt_int_option(
            batch_size,
            "batch_size",
            "a positive int",
            1,
            MAX_BATCH_SIZE as u64,
        )?;
        let options = ShapeModelOptions {
            threads: threads.map(to_usize),
            batch_size: batch_size.map_or(ShapeModelOptions::default().batch_size, to_usize),
        };
        py.detach(|| {
            init(ort_library.as_deref())?;
            ShapeEstimator::load(&model_path, &options)
        })
        .map(|inner| Self { inner })
        .map_err(|e| runner_error(e, None))
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
        let (raw, p) = interruptible(py, |_| {
            let raw = model.predict_raw_slices(a, b)?;
            let p = model.decode(&raw)?;
            Ok((raw, p))
        })?
        .map_err(|e| runner_error(e, None))?;
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

    /// `(corrs (N, 8), orientation_a, orientation_b, scale_a, scale_b, residual_shape (N, 3),
    /// report)`; with `refine`, the corrs refined by `refine_affine` (default options) on the
    /// same decoded images. The report (`image::confidence_dict`) has the confidence, and the
    /// network's `angle_spread` and `scale_spread` (N,).
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
    ) -> PyResult<(
        F64<'py>,
        F64<'py>,
        F64<'py>,
        F64<'py>,
        F64<'py>,
        F64<'py>,
        Bound<'py, PyDict>,
    )> {
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
        let e = interruptible(py, |_| -> PyResult<_> {
            if refine {
                let options = AffineRefineOptions::default();
                self.inner
                    .estimate_refined(&img_a, &img_b, &x1, &x2, &options)
                    .map_err(|e| runner_error(e, None))
            } else {
                self.inner
                    .estimate(&img_a, &img_b, &x1, &x2)
                    .map_err(|e| runner_error(e, None))
            }
        })??;
        let n = e.corrs.len();
        let (angle, scale): (Vec<f64>, Vec<f64>) =
            e.spread.iter().map(|s| (s.angle, s.scale)).unzip();
        let report = confidence_dict(py, e.confidence, e.refinement)?;
        report.set_item("angle_spread", f64_vec(py, angle)?)?;
        report.set_item("scale_spread", f64_vec(py, scale)?)?;
        Ok((
            to_numpy(py, &[n, 8], flatten(e.corrs))?,
            f64_vec(py, e.orientation_a)?,
            f64_vec(py, e.orientation_b)?,
            f64_vec(py, e.scale_a)?,
            f64_vec(py, e.scale_b)?,
            to_numpy(py, &[n, 3], flatten(e.residual_shape))?,
            report,
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
        .map_err(|e| runner_error(e, None))?;
    Ok(loaded_library()
        .map(|p| p.to_path_buf())
        .unwrap_or_default())
}

/// The loaded ONNX Runtime library, or `None` before the first model is loaded.
#[pyfunction]
fn ort_library() -> Option<PathBuf> {
    loaded_library().map(|p| p.to_path_buf())
}
