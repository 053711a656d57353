//! The scale-normalised geometry kernels (issue 23) on arbitrary finite inputs of any
//! magnitude: the batched Sampson distances, `decompose`, `synthesize` and
//! `decompose_essential` give a finite answer or a typed error, never NaN, an infinite scale
//! or A = 0; and the documented invariances hold when F, A or E is multiplied by 2^k (exact, so
//! the answers must be bit-identical, or, for F, the distances identical and the F-gradient
//! scaled by 2^-k).
#![no_main]

use affcorr_fuzz::Reader;
use affcorr_geom::affine::{AffineShape, decompose, synthesize};
use affcorr_geom::epipolar::decompose_essential;
use affcorr_geom::sampson::{sampson_affine_batch, sampson_point_batch};
use affcorr_geom::types::AcRow;
use affcorr_geom::{GeomError, Mat3};
use libfuzzer_sys::fuzz_target;

/// A finite value: NaN and infinities (which the kernels reject up front) become 1.
fn finite(v: f64) -> f64 {
    if v.is_finite() { v } else { 1.0 }
}

/// Whether `scaled` = `x` · 2^k exactly: every entry zero in both or normal in both.
fn exact<'a>(scaled: impl IntoIterator<Item = &'a f64>, x: impl IntoIterator<Item = &'a f64>) -> bool {
    scaled
        .into_iter()
        .zip(x)
        .all(|(a, b)| (*a == 0.0 && *b == 0.0) || (a.is_normal() && b.is_normal()))
}

fuzz_target!(|data: &[u8]| {
    let mut r = Reader::new(data);
    // A power of two, 2^-1000 to 2^1000: products with it are exact away from the ends of f64.
    let k = i32::from(r.u8() as i8) * 8;
    let scale = 2f64.powi(k);

    let f = r.mat3().map(finite);
    let n = usize::from(r.u8() % 8);
    let rows: Vec<AcRow> = (0..n).map(|_| std::array::from_fn(|_| finite(r.f64()))).collect();
    let (mut d, mut ds) = (vec![0.0; n], vec![0.0; n]);
    let (mut a, mut as_) = (vec![[0.0; 2]; n], vec![[0.0; 2]; n]);
    sampson_point_batch(&f, &rows, &mut d).unwrap();
    sampson_affine_batch(&f, &rows, &mut a).unwrap();
    let fs = f * scale;
    if exact(fs.as_slice(), f.as_slice()) {
        sampson_point_batch(&fs, &rows, &mut ds).unwrap();
        sampson_affine_batch(&fs, &rows, &mut as_).unwrap();
        for i in 0..n {
            // F and F·2^k normalise to the same matrix: the same bits, NaN included.
            assert_eq!(d[i].to_bits(), ds[i].to_bits(), "row {i}: {} vs {}", d[i], ds[i]);
            assert_eq!(a[i].map(f64::to_bits), as_[i].map(f64::to_bits), "row {i}");
        }
    }

    let m = r.mat2().map(finite);
    match decompose(&m, 0) {
        Ok(s) => {
            assert!(s.scale.is_finite() && s.scale > 0.0, "scale {:e} of {m}", s.scale);
            assert!(
                s.orientation.is_finite() && s.residual_shape.iter().all(|v| v.is_finite()),
                "{s:?} of {m}"
            );
            let ms = m * scale;
            if exact(ms.as_slice(), m.as_slice()) {
                let t = decompose(&ms, 0).expect("det > 0 does not depend on the scale");
                assert_eq!(t.orientation.to_bits(), s.orientation.to_bits());
                assert_eq!(t.residual_shape.map(f64::to_bits), s.residual_shape.map(f64::to_bits));
            }
        }
        Err(e) => assert!(
            matches!(e, GeomError::NonPositiveDeterminant { .. } | GeomError::Overflow { .. }),
            "{e}"
        ),
    }

    let shape = AffineShape {
        orientation: finite(r.f64()),
        scale: finite(r.f64()),
        residual_shape: std::array::from_fn(|_| finite(r.f64())),
    };
    if let Ok(a) = synthesize(&shape, 0) {
        assert!(a.iter().all(|v| v.is_finite()), "{a}");
    }

    let e: Mat3 = r.mat3().map(finite);
    if let Ok(poses) = decompose_essential(&e) {
        for p in poses {
            assert!(p.r.iter().chain(p.t.iter()).all(|v| v.is_finite()), "{e}");
        }
    }
});
