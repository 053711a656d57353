//! Bindings of affcorr-geom. Docstrings live in `python/affcorr/_native.pyi` and the Python
//! package; names and argument names mirror the Rust functions.

use crate::arrays::{Dim, F64Array, flatten, mat3_to_numpy, to_numpy, value_error};
use affcorr::geom::affine::{self, AffineShape};
use affcorr::geom::camera::{self, Intrinsics};
use affcorr::geom::{Mat3, Vec2, Vec3, epipolar, homography};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

const N: Dim = Dim::Any("N");
const MAT3: [Dim; 2] = [Dim::Is(3), Dim::Is(3)];

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(synthesize_affine, m)?)?;
    m.add_function(wrap_pyfunction!(decompose_affine, m)?)?;
    m.add_function(wrap_pyfunction!(affine_from_homography, m)?)?;
    m.add_function(wrap_pyfunction!(correspondences_from_homography, m)?)?;
    m.add_function(wrap_pyfunction!(normalize_correspondences, m)?)?;
    m.add_function(wrap_pyfunction!(laf_to_affine, m)?)?;
    m.add_function(wrap_pyfunction!(affine_to_laf, m)?)?;
    m.add_function(wrap_pyfunction!(essential_from_pose, m)?)?;
    m.add_function(wrap_pyfunction!(fundamental_from_essential, m)?)?;
    m.add_function(wrap_pyfunction!(decompose_essential, m)?)?;
    m.add_function(wrap_pyfunction!(pose_from_essential, m)?)?;
    Ok(())
}

type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// Reads a 3×3 intrinsic matrix argument.
pub fn intrinsics(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Intrinsics> {
    let k = F64Array::extract(obj, name)?.expect(&MAT3)?.mat3();
    Intrinsics::new(k, name).map_err(value_error)
}

/// Reads a 3×3 matrix argument that must be finite.
pub fn matrix3(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Mat3> {
    let m = F64Array::extract(obj, name)?.expect(&MAT3)?.mat3();
    if m.iter().any(|v| !v.is_finite()) {
        return Err(value_error(format!("{name} contains NaN or infinity")));
    }
    Ok(m)
}

#[pyfunction]
fn synthesize_affine<'py>(
    py: Python<'py>,
    orientation: &Bound<'py, PyAny>,
    scale: &Bound<'py, PyAny>,
    residual_shape: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let o = F64Array::extract(orientation, "orientation")?.expect(&[N])?;
    let s = F64Array::extract(scale, "scale")?.expect(&[N])?;
    let r = F64Array::extract(residual_shape, "residual_shape")?.expect(&[N, Dim::Is(3)])?;
    let (o, s, r) = (o.as_slice(), s.as_slice(), r.rows::<3>());
    let mut out = vec![[0.0; 4]; o.len()];
    crate::interrupt::parallel(py, o.len(), || affine::synthesize_affine(o, s, r, &mut out))
        .map_err(value_error)?;
    to_numpy(py, &[out.len(), 2, 2], flatten(out))
}

// Capital argument names, as documented (`decompose_affine(A=...)` must work).
#[pyfunction]
#[allow(non_snake_case)]
fn decompose_affine<'py>(
    py: Python<'py>,
    A: &Bound<'py, PyAny>,
) -> PyResult<(Array<'py>, Array<'py>, Array<'py>)> {
    let a = F64Array::extract(A, "A")?.expect(&[N, Dim::Is(2), Dim::Is(2)])?;
    let a = a.rows::<4>();
    let blank = AffineShape {
        orientation: 0.0,
        scale: 0.0,
        residual_shape: [0.0; 3],
    };
    let mut out = vec![blank; a.len()];
    crate::interrupt::parallel(py, a.len(), || affine::decompose_affine(a, &mut out))
        .map_err(value_error)?;
    let n = out.len();
    Ok((
        to_numpy(py, &[n], out.iter().map(|s| s.orientation).collect())?,
        to_numpy(py, &[n], out.iter().map(|s| s.scale).collect())?,
        to_numpy(
            py,
            &[n, 3],
            out.iter().flat_map(|s| s.residual_shape).collect(),
        )?,
    ))
}

#[pyfunction]
#[pyo3(name = "affine_from_homography")]
#[allow(non_snake_case)]
fn affine_from_homography<'py>(
    py: Python<'py>,
    H: &Bound<'py, PyAny>,
    x1: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let h = matrix3(H, "H")?;
    let x1 = F64Array::extract(x1, "x1")?.expect(&[N, Dim::Is(2)])?;
    let x1 = x1.rows::<2>();
    let mut out = vec![[0.0; 4]; x1.len()];
    crate::interrupt::parallel(py, x1.len(), || {
        homography::affine_from_homography(&h, x1, &mut out)
    })
    .map_err(value_error)?;
    to_numpy(py, &[out.len(), 2, 2], flatten(out))
}

#[pyfunction]
#[allow(non_snake_case)]
fn correspondences_from_homography<'py>(
    py: Python<'py>,
    H: &Bound<'py, PyAny>,
    x1: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let h = matrix3(H, "H")?;
    let x1 = F64Array::extract(x1, "x1")?.expect(&[N, Dim::Is(2)])?;
    let x1 = x1.rows::<2>();
    let mut out = vec![[0.0; 8]; x1.len()];
    crate::interrupt::parallel(py, x1.len(), || {
        homography::correspondences_from_homography(&h, x1, &mut out)
    })
    .map_err(value_error)?;
    to_numpy(py, &[out.len(), 8], flatten(out))
}

#[pyfunction]
#[pyo3(name = "normalize_correspondences")]
#[allow(non_snake_case)]
fn normalize_correspondences<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    K1: &Bound<'py, PyAny>,
    K2: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let c = F64Array::extract(corrs, "corrs")?.expect(&[N, Dim::Is(8)])?;
    let (k1, k2) = (intrinsics(K1, "K1")?, intrinsics(K2, "K2")?);
    let rows = c.rows::<8>();
    let mut out = vec![[0.0; 8]; rows.len()];
    crate::interrupt::parallel(py, rows.len(), || {
        camera::normalize_correspondences(rows, &k1, &k2, &mut out)
    })
    .map_err(value_error)?;
    to_numpy(py, &[out.len(), 8], flatten(out))
}

#[pyfunction]
fn laf_to_affine<'py>(
    py: Python<'py>,
    laf1: &Bound<'py, PyAny>,
    laf2: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let shapes: [&[Dim]; 2] = [
        &[Dim::Any("B"), N, Dim::Is(2), Dim::Is(3)],
        &[N, Dim::Is(2), Dim::Is(3)],
    ];
    let l1 = F64Array::extract(laf1, "laf1")?.expect_one_of(&shapes)?;
    let l2 = F64Array::extract(laf2, "laf2")?.expect_one_of(&shapes)?;
    if l1.shape() != l2.shape() {
        return Err(value_error(format!(
            "laf2 must have the shape of laf1 {:?}, got {:?}",
            l1.shape(),
            l2.shape()
        )));
    }
    let mut shape = l1.shape()[..l1.shape().len() - 2].to_vec();
    shape.push(8);
    let (r1, r2) = (l1.rows::<6>(), l2.rows::<6>());
    let mut out = vec![[0.0; 8]; r1.len()];
    crate::interrupt::parallel(py, r1.len(), || affine::laf_to_affine(r1, r2, &mut out))
        .map_err(value_error)?;
    to_numpy(py, &shape, flatten(out))
}

#[pyfunction]
#[pyo3(signature = (corrs, radius = None))]
fn affine_to_laf<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    radius: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Array<'py>, Array<'py>)> {
    // Not a bare `f64` argument: PyO3's TypeError for a string would not name `radius`.
    let radius: f64 = match radius {
        None => 1.0,
        Some(r) => r
            .extract()
            .map_err(|_| value_error(format!("radius must be a number, got {r}")))?,
    };
    let c = F64Array::extract(corrs, "corrs")?.expect(&[N, Dim::Is(8)])?;
    let rows = c.rows::<8>();
    let n = rows.len();
    let (mut l1, mut l2) = (vec![[0.0; 6]; n], vec![[0.0; 6]; n]);
    crate::interrupt::parallel(py, n, || {
        affine::affine_to_laf(rows, radius, &mut l1, &mut l2)
    })
    .map_err(value_error)?;
    Ok((
        to_numpy(py, &[1, n, 2, 3], flatten(l1))?,
        to_numpy(py, &[1, n, 2, 3], flatten(l2))?,
    ))
}

fn vec3(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec3> {
    let v =
        F64Array::extract(obj, name)?.expect_one_of(&[&[Dim::Is(3)], &[Dim::Is(3), Dim::Is(1)]])?;
    let s = v.as_slice();
    if s.iter().any(|x| !x.is_finite()) {
        return Err(value_error(format!("{name} contains NaN or infinity")));
    }
    Ok(Vec3::new(s[0], s[1], s[2]))
}

fn rotation(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Mat3> {
    let r = matrix3(obj, name)?;
    if (r.transpose() * r - Mat3::identity()).norm() > 1e-6 || r.determinant() < 0.0 {
        return Err(value_error(format!(
            "{name} must be a rotation matrix (RᵀR = I, det R = 1)"
        )));
    }
    Ok(r)
}

#[pyfunction]
#[pyo3(name = "essential_from_pose", signature = (R, t))]
#[allow(non_snake_case)]
fn essential_from_pose<'py>(
    py: Python<'py>,
    R: &Bound<'py, PyAny>,
    t: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let (r, t) = (rotation(R, "R")?, vec3(t, "t")?);
    mat3_to_numpy(py, &epipolar::essential_from_pose(&r, &t))
}

#[pyfunction]
#[pyo3(signature = (E, K1, K2))]
#[allow(non_snake_case)]
fn fundamental_from_essential<'py>(
    py: Python<'py>,
    E: &Bound<'py, PyAny>,
    K1: &Bound<'py, PyAny>,
    K2: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let e = matrix3(E, "E")?;
    let (k1, k2) = (intrinsics(K1, "K1")?, intrinsics(K2, "K2")?);
    mat3_to_numpy(py, &epipolar::fundamental_from_essential(&e, &k1, &k2))
}

#[pyfunction]
#[pyo3(signature = (E,))]
#[allow(non_snake_case)]
fn decompose_essential<'py>(
    py: Python<'py>,
    E: &Bound<'py, PyAny>,
) -> PyResult<Vec<(Array<'py>, Array<'py>)>> {
    let e = matrix3(E, "E")?;
    let poses = epipolar::decompose_essential(&e).map_err(value_error)?;
    poses
        .iter()
        .map(|p| {
            Ok((
                mat3_to_numpy(py, &p.r)?,
                to_numpy(py, &[3], p.t.as_slice().to_vec())?,
            ))
        })
        .collect()
}

#[pyfunction]
#[pyo3(signature = (E, x1, x2))]
#[allow(non_snake_case)]
fn pose_from_essential<'py>(
    py: Python<'py>,
    E: &Bound<'py, PyAny>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<(Array<'py>, Array<'py>, usize)> {
    let e = matrix3(E, "E")?;
    let a = F64Array::extract(x1, "x1")?.expect(&[N, Dim::Is(2)])?;
    let b = F64Array::extract(x2, "x2")?.expect(&[N, Dim::Is(2)])?;
    let to_points = |rows: &[[f64; 2]]| {
        rows.iter()
            .map(|p| Vec2::new(p[0], p[1]))
            .collect::<Vec<_>>()
    };
    let (p1, p2) = (to_points(a.rows::<2>()), to_points(b.rows::<2>()));
    let (pose, n) = epipolar::pose_from_essential(&e, &p1, &p2).map_err(value_error)?;
    Ok((
        mat3_to_numpy(py, &pose.r)?,
        to_numpy(py, &[3], pose.t.as_slice().to_vec())?,
        n,
    ))
}
