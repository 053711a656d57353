//! The documented invariances at extreme magnitudes (issue 23, "silent nonsense"): for any
//! finite input the kernels give the scale-free answer, or a typed error; never an infinite
//! scale, NaN distances, zero distances from underflow, NaN rotations or A = 0.

use affcorr_geom::affine::{AffineShape, decompose, residual_shape_matrix, synthesize};
use affcorr_geom::epipolar::decompose_essential;
use affcorr_geom::sampson::{
    sampson_affine_batch, sampson_affine_grad_columns, sampson_point_batch,
    sampson_point_grad_columns,
};
use affcorr_geom::synthetic::PlaneScene;
use affcorr_geom::types::AcRow;
use affcorr_geom::{GeomError, Mat2, Mat3};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_pcg::Pcg64;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1e-300)
}

/// A scene's F and some noisy ACs (non-zero distances).
/// Distances (px²) equal up to rounding: relative 1e-9, or 1e-12 px² for near-zero ones
/// (the residual of an exact AC is cancellation noise).
fn same_distance(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-12
}

fn scene(seed: u64) -> (Mat3, Vec<AcRow>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let s = PlaneScene::random(&mut rng);
    let rows = s
        .sample(&mut rng, 20)
        .iter()
        .enumerate()
        .map(|(i, ac)| {
            let mut r = ac.to_row();
            r[2] += 0.3 * (i as f64 + 1.0);
            r[5] += 0.01 * i as f64;
            r
        })
        .collect();
    (s.fundamental(), rows)
}

type PointGrads = (Vec<f64>, Vec<[f64; 8]>, Vec<[f64; 9]>);
type AffineGrads = (Vec<[f64; 2]>, Vec<[[f64; 8]; 2]>, Vec<[[f64; 9]; 2]>);

/// Point Sampson values and their gradients (corrs, F) of every row under `f`.
fn point_grads(f: &Mat3, rows: &[AcRow]) -> PointGrads {
    let n = rows.len();
    let (mut v, mut d, mut df) = (vec![0.0; n], vec![[0.0; 8]; n], vec![[0.0; 9]; n]);
    sampson_point_grad_columns(f, rows, &mut v, &mut d, &mut df).unwrap();
    (v, d, df)
}

/// Affine Sampson values and their gradients (corrs, F) of every row under `f`.
fn affine_grads(f: &Mat3, rows: &[AcRow]) -> AffineGrads {
    let n = rows.len();
    let (mut v, mut d, mut df) = (
        vec![[0.0; 2]; n],
        vec![[[0.0; 8]; 2]; n],
        vec![[[0.0; 9]; 2]; n],
    );
    sampson_affine_grad_columns(f, rows, &mut v, &mut d, &mut df).unwrap();
    (v, d, df)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn sampson_distances_do_not_depend_on_the_scale_of_f(seed in 0u64..1000, exp in -300i32..=300) {
        let (f, rows) = scene(seed);
        let c = 10f64.powi(exp);
        let n = rows.len();
        let (mut p, mut pc) = (vec![0.0; n], vec![0.0; n]);
        sampson_point_batch(&f, &rows, &mut p).unwrap();
        sampson_point_batch(&(f * c), &rows, &mut pc).unwrap();
        let (mut a, mut ac) = (vec![[0.0; 2]; n], vec![[0.0; 2]; n]);
        sampson_affine_batch(&f, &rows, &mut a).unwrap();
        sampson_affine_batch(&(f * c), &rows, &mut ac).unwrap();
        for i in 0..n {
            prop_assert!(pc[i].is_finite() && pc[i] > 0.0, "row {i}: {}", pc[i]);
            prop_assert!(same_distance(p[i], pc[i],), "row {i}: {} vs {}", p[i], pc[i]);
            for k in 0..2 {
                prop_assert!(same_distance(a[i][k], ac[i][k],), "row {i}: {:?} vs {:?}", a[i], ac[i]);
            }
        }
        // The F-gradient scales as 1/c; the others not at all.
        let (_, d, df) = point_grads(&f, &rows);
        let (_, dc, dfc) = point_grads(&(f * c), &rows);
        let (av, _, adf) = affine_grads(&f, &rows);
        let (avc, _, adfc) = affine_grads(&(f * c), &rows);
        // The F-gradient's round-off under an ordinary rescaling of F (by 3 and by 0.3), per
        // row: an F whose entries span ten decades (a pixel F) loses up to ~1e-8 of the
        // gradient's largest entry to any rescaling that is not a power of two, so extreme
        // magnitudes must do as well as that, not better.
        let floor = |dfs: &[[f64; 9]], s: f64, i: usize, g: &[f64; 9]| {
            let scale = g.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            (0..9).map(|j| (g[j] - dfs[i][j] * s).abs() / scale).fold(0.0, f64::max)
        };
        let point_floor: Vec<f64> = [3.0, 0.3]
            .map(|s| point_grads(&(f * s), &rows).2)
            .iter()
            .zip([3.0, 0.3])
            .fold(vec![0.0; n], |acc, (dfs, s)| {
                (0..n).map(|i| acc[i].max(floor(dfs, s, i, &df[i]))).collect()
            });
        let affine_floor: Vec<[f64; 2]> = [3.0, 0.3]
            .map(|s| affine_grads(&(f * s), &rows).2)
            .iter()
            .zip([3.0, 0.3])
            .fold(vec![[0.0; 2]; n], |acc, (adfs, s)| {
                (0..n)
                    .map(|i| {
                        std::array::from_fn(|k| {
                            let per_k: Vec<[f64; 9]> = adfs.iter().map(|r| r[k]).collect();
                            acc[i][k].max(floor(&per_k, s, i, &adf[i][k]))
                        })
                    })
                    .collect()
            });
        let tolerance = |floor: f64| (4.0 * floor).max(1e-8);
        for i in 0..n {
            for j in 0..4 {
                prop_assert!(close(d[i][j], dc[i][j], 1e-8), "d_corrs[{i}][{j}]");
            }
            // (The F-gradient of F · c is that of F over c: it is checked where that fits in
            // f64, as an F-gradient of F · 1e-300 need not.)
            let scale = df[i].iter().fold(0.0f64, |m, x| m.max(x.abs()));
            if scale / c < 1e300 {
                let tol = tolerance(point_floor[i]);
                for j in 0..9 {
                    prop_assert!((df[i][j] - dfc[i][j] * c).abs() <= tol * scale, "d_f[{i}][{j}]");
                }
            }
            for k in 0..2 {
                let scale = adf[i][k].iter().fold(0.0f64, |m, x| m.max(x.abs()));
                if scale / c < 1e300 {
                    let tol = tolerance(affine_floor[i][k]);
                    for j in 0..9 {
                        prop_assert!(
                            (adf[i][k][j] - adfc[i][k][j] * c).abs() <= tol * scale,
                            "d_f[{i}][{k}][{j}] beyond {tol:e} of {scale:e}"
                        );
                    }
                }
                prop_assert!(same_distance(av[i][k], avc[i][k],));
            }
        }
    }

    #[test]
    fn decomposition_scales_with_a_and_keeps_its_shape(
        theta in -3.0f64..3.0, a in 0.2f64..5.0, b in -2.0f64..2.0, exp in -300i32..=300,
    ) {
        let m = affcorr_geom::affine::rotation(theta) * Mat2::new(a, 0.0, b, 1.0 / a);
        let c = 10f64.powi(exp);
        let s1 = decompose(&m, 0).unwrap();
        let sc = decompose(&(m * c), 0).unwrap();
        prop_assert!(sc.scale.is_finite() && close(sc.scale, c * s1.scale, 1e-12), "{:e}", sc.scale);
        prop_assert!((sc.orientation - s1.orientation).abs() < 1e-12);
        for k in 0..3 {
            prop_assert!((sc.residual_shape[k] - s1.residual_shape[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn essential_factorisation_ignores_the_scale_of_e(seed in 0u64..1000, exp in -300i32..=300) {
        let mut rng = Pcg64::seed_from_u64(seed);
        let e = PlaneScene::random(&mut rng).essential();
        let c = 10f64.powi(exp);
        let p1 = decompose_essential(&e).unwrap();
        let pc = decompose_essential(&(e * c)).unwrap();
        // E's two equal singular values leave the SVD free within their plane, so the four
        // factorisations are compared as a set.
        for b in &pc {
            prop_assert!(b.r.iter().all(|v| v.is_finite()) && b.t.iter().all(|v| v.is_finite()));
            let nearest = p1
                .iter()
                .map(|a| (a.r - b.r).norm() + (a.t - b.t).norm())
                .fold(f64::INFINITY, f64::min);
            prop_assert!(nearest < 1e-9, "{nearest}");
        }
    }

    #[test]
    fn residual_shapes_of_any_finite_size_give_det_one_or_an_error(
        x0 in -0.999f64..1e300, x1 in -1e300f64..1e300, x2 in -0.999f64..1e300, s in 1e-300f64..1e300,
    ) {
        let ap = residual_shape_matrix(&[x0, x1, x2]).unwrap();
        prop_assert!(ap.iter().all(|v| v.is_finite()));
        // det A′ = 1 whenever its entries are representable (x1 ≤ 1e300 keeps them so).
        prop_assert!((ap[(0, 0)] * ap[(1, 1)] - 1.0).abs() < 1e-12);
        prop_assert!(ap[(0, 0)] > 0.0 && ap[(1, 1)] > 0.0);
        let shape = AffineShape { orientation: 0.3, scale: s, residual_shape: [x0, x1, x2] };
        match synthesize(&shape, 7) {
            Ok(a) => {
                prop_assert!(a.iter().all(|v| v.is_finite()));
                prop_assert!(a.determinant() != 0.0 || s < 1e-150, "A = 0 from a finite shape");
            }
            Err(e) => prop_assert!(matches!(e, GeomError::Overflow { what: "A", index: 7, .. }), "{e}"),
        }
    }
}

#[test]
fn the_issue_examples() {
    // decompose_affine(1e155·I): scale 1e155, not infinity.
    let s = decompose(&(Mat2::identity() * 1e155), 0).unwrap();
    assert!(close(s.scale, 1e155, 1e-15), "{:e}", s.scale);
    // ... and 1e-160·I: 1e-160, not "det A = 0 is not positive".
    let s = decompose(&(Mat2::identity() * 1e-160), 0).unwrap();
    assert!(close(s.scale, 1e-160, 1e-15), "{:e}", s.scale);
    // A huge residual shape: A′ with det 1, not A = 0.
    let ap = residual_shape_matrix(&[1e200, 0.0, 1e200]).unwrap();
    assert!(close(ap[(0, 0)], 1.0, 1e-15) && close(ap[(1, 1)], 1.0, 1e-15));
    // E · 1e200: proper rotations, not NaN.
    let mut rng = Pcg64::seed_from_u64(3);
    let e = PlaneScene::random(&mut rng).essential();
    for p in decompose_essential(&(e * 1e200)).unwrap() {
        assert!((p.r.determinant() - 1.0).abs() < 1e-12);
    }
    // An A that overflows is an error naming the row, not infinity.
    let shape = AffineShape {
        orientation: 0.0,
        scale: 1e300,
        residual_shape: [1e20, 0.0, 0.0],
    };
    assert!(matches!(
        synthesize(&shape, 3),
        Err(GeomError::Overflow { index: 3, .. })
    ));
}

/// Found by the `geom_scale` fuzz target: a nearly singular A (det Â a subnormal) made
/// M = Â/√det Â reach ~1e162, whose squares underflowed or overflowed: an infinite or NaN
/// orientation and shape. Its A′ is representable, so it must decompose finitely.
#[test]
fn nearly_singular_maps_decompose_to_finite_shapes() {
    let cases = [
        Mat2::new(1.0, 0.0, 0.0, 5e-324),
        Mat2::new(5e-324, 0.0, 0.0, 1.0),
        Mat2::new(1.0, 1.0, 0.0, 1e-310),
        Mat2::new(1e-310, 1.0, -1.0, 1e-310),
        Mat2::new(1.0, 1.0, 1.0 - 1e-16, 1.0) * 1e300,
    ];
    for m in cases {
        match decompose(&m, 0) {
            Ok(s) => {
                assert!(
                    s.orientation.is_finite() && s.residual_shape.iter().all(|v| v.is_finite()),
                    "{s:?} of {m}"
                );
                assert!(s.scale.is_finite() && s.scale > 0.0);
            }
            Err(e) => assert!(
                matches!(e, GeomError::NonPositiveDeterminant { .. }),
                "{e}: {m}"
            ),
        }
    }
}
