//! The shape network: contract checks on broken fixture models, batched inference, the
//! softmax-mean decoding and AC synthesis. Needs ONNX Runtime (see `common::ort_library`).
//!
//! `echo.onnx` (tests/data/shape/make_fixtures.py) outputs slices of the flattened patches:
//! angle logits = pixels 0..8, scale logits = pixels 8..13, residual shape = pixels 16..19 of
//! patch A, so the tests below choose every logit.

mod common;

use std::f64::consts::PI;

use affcorr_geom::affine::{AffineShape, synthesize};
use affcorr_image::{GrayImage, ImageError, Patches};
use affcorr_runner::{RunnerError, ShapeEstimator, ShapeModel, ShapeModelOptions};
use rand::{Rng, SeedableRng};

const LEN: usize = 32 * 32;

fn echo() -> ShapeModel {
    common::init();
    ShapeModel::load(common::fixture("echo.onnx")).unwrap()
}

fn echo_angles() -> Vec<f64> {
    (0..8)
        .map(|k| -PI + PI / 8.0 + k as f64 * PI / 4.0)
        .collect()
}

const ECHO_SCALES: [f64; 5] = [0.25, 0.5, 1.0, 2.0, 4.0];

/// Patches whose first 19 pixels are random logits / residual-shape values.
fn random_patches(n: usize, seed: u64) -> Patches {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut data = vec![0.5f32; n * LEN];
    for i in 0..n {
        for j in 0..13 {
            data[i * LEN + j] = rng.random_range(-4.0..4.0);
        }
        for j in 16..19 {
            data[i * LEN + j] = rng.random_range(-0.5..0.5);
        }
    }
    Patches::from_vec(data).unwrap()
}

/// softmax-mean, written out independently.
fn decode(logits: &[f32], bins: &[f64], angle: bool) -> f64 {
    let z: f64 = logits.iter().map(|&v| (v as f64).exp()).sum();
    let p: Vec<f64> = logits.iter().map(|&v| (v as f64).exp() / z).collect();
    if angle {
        let s: f64 = p.iter().zip(bins).map(|(p, c)| p * c.sin()).sum();
        let c: f64 = p.iter().zip(bins).map(|(p, c)| p * c.cos()).sum();
        s.atan2(c)
    } else {
        p.iter()
            .zip(bins)
            .map(|(p, s)| p * s.ln())
            .sum::<f64>()
            .exp()
    }
}

#[test]
fn echo_model_loads_with_its_bins_and_metadata() {
    let m = echo();
    assert_eq!(m.bins().angles(), echo_angles().as_slice());
    assert_eq!(m.bins().scales(), ECHO_SCALES.as_slice());
    assert_eq!(m.metadata()["affcorr.contract"], "shape-v1");
    assert!(m.metadata()["trained"].starts_with("no"));
    assert!(m.source().contains("echo.onnx"));
    assert_eq!(m.batch_size(), 512);
    // The symbolic-width variant passes through the probe run.
    ShapeModel::load(common::fixture("echo_symbolic.onnx")).unwrap();
    // From memory.
    let bytes = std::fs::read(common::fixture("echo.onnx")).unwrap();
    let m2 = ShapeModel::from_bytes(&bytes, &ShapeModelOptions::default()).unwrap();
    assert_eq!(m2.source(), "from memory");
    assert_eq!(m2.bins(), m.bins());
}

#[test]
fn predict_decodes_softmax_means() {
    let m = echo();
    let (a, b) = (random_patches(37, 1), random_patches(37, 2));
    let raw = m.predict_raw(&a, &b).unwrap();
    let p = m.predict(&a, &b).unwrap();
    assert_eq!(p.len(), 37);
    let angles = echo_angles();
    for i in 0..37 {
        let (pa, pb) = (a.patch(i), b.patch(i));
        // The echo model's outputs are the pixels.
        assert_eq!(&raw.angle_logits_a[8 * i..8 * i + 8], &pa[..8]);
        assert_eq!(&raw.scale_logits_b[5 * i..5 * i + 5], &pb[8..13]);
        assert_eq!(&raw.residual_shape[3 * i..3 * i + 3], &pa[16..19]);
        assert!((p.orientation_a[i] - decode(&pa[..8], &angles, true)).abs() < 1e-12);
        assert!((p.orientation_b[i] - decode(&pb[..8], &angles, true)).abs() < 1e-12);
        assert!((p.scale_a[i] / decode(&pa[8..13], &ECHO_SCALES, false) - 1.0).abs() < 1e-12);
        assert!((p.scale_b[i] / decode(&pb[8..13], &ECHO_SCALES, false) - 1.0).abs() < 1e-12);
        assert_eq!(
            p.residual_shape[i],
            [pa[16] as f64, pa[17] as f64, pa[18] as f64]
        );
    }
}

#[test]
fn a_dominant_bin_decodes_to_its_centre() {
    let m = echo();
    let mut data = vec![0.0f32; 2 * LEN];
    data[5] = 60.0; // angle bin 5 of pair 0
    data[8 + 3] = 60.0; // scale bin 3 (2.0)
    data[LEN] = 60.0; // angle bin 0 of pair 1
    data[LEN + 8] = 60.0; // scale bin 0 (0.25)
    let a = Patches::from_vec(data).unwrap();
    let p = m.predict(&a, &a).unwrap();
    assert!((p.orientation_a[0] - echo_angles()[5]).abs() < 1e-9);
    assert!((p.scale_a[0] - 2.0).abs() < 1e-9);
    assert!((p.orientation_a[1] - echo_angles()[0]).abs() < 1e-9);
    assert!((p.scale_a[1] - 0.25).abs() < 1e-9);
}

#[test]
fn batching_does_not_change_the_result() {
    common::init();
    let (a, b) = (random_patches(23, 3), random_patches(23, 4));
    let small = ShapeModelOptions {
        threads: Some(1),
        batch_size: 4,
    };
    let m1 = ShapeModel::load_with(common::fixture("echo.onnx"), &small).unwrap();
    assert_eq!((m1.threads(), m1.batch_size()), (1, 4));
    assert_eq!(m1.predict(&a, &b).unwrap(), echo().predict(&a, &b).unwrap());
    let empty = Patches::from_vec(vec![]).unwrap();
    assert!(m1.predict(&empty, &empty).unwrap().is_empty());
}

/// `e` is the typed error for a bad argument called `what`.
fn assert_invalid(e: &RunnerError, what: &str) {
    assert!(
        matches!(e, RunnerError::InvalidInput { what: w, .. } if *w == what),
        "{e:?}"
    );
}

#[test]
fn borrowed_slices_predict_as_patches_do() {
    common::init();
    let (a, b) = (random_patches(5, 7), random_patches(5, 8));
    let m = echo();
    assert_eq!(
        m.predict_raw_slices(a.as_slice(), b.as_slice()).unwrap(),
        m.predict_raw(&a, &b).unwrap()
    );
    let e = m
        .predict_raw_slices(&a.as_slice()[..1000], b.as_slice())
        .unwrap_err();
    assert_invalid(&e, "patch_a");
    let e = m
        .predict_raw_slices(a.as_slice(), &b.as_slice()[..LEN])
        .unwrap_err();
    assert_invalid(&e, "patch_b");
}

#[test]
fn estimate_synthesises_acs_from_the_patches() {
    let m = echo();
    let est = ShapeEstimator::new(m);
    let (w, h) = (90, 70);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let img_a = GrayImage::new(w, h, (0..w * h).map(|_| rng.random::<f32>()).collect()).unwrap();
    let img_b = GrayImage::new(w, h, (0..w * h).map(|_| rng.random::<f32>()).collect()).unwrap();
    let x1: Vec<[f64; 2]> = (0..50)
        .map(|_| [rng.random_range(0.0..90.0), rng.random_range(0.0..70.0)])
        .collect();
    let x2: Vec<[f64; 2]> = (0..50)
        .map(|_| [rng.random_range(0.0..90.0), rng.random_range(0.0..70.0)])
        .collect();
    let e = est.estimate(&img_a, &img_b, &x1, &x2).unwrap();
    assert_eq!(e.corrs.len(), 50);

    let pa = affcorr_image::extract_patches(&img_a, &x1).unwrap();
    let pb = affcorr_image::extract_patches(&img_b, &x2).unwrap();
    let p = est.model().predict(&pa, &pb).unwrap();
    assert_eq!(p.orientation_a, e.orientation_a);
    assert_eq!(p.scale_b, e.scale_b);
    for i in 0..50 {
        let row = e.corrs[i];
        assert_eq!(&row[..4], &[x1[i][0], x1[i][1], x2[i][0], x2[i][1]]);
        let shape = AffineShape {
            orientation: e.orientation_b[i] - e.orientation_a[i],
            scale: e.scale_b[i] / e.scale_a[i],
            residual_shape: e.residual_shape[i],
        };
        let a = synthesize(&shape, i).unwrap();
        let want = [a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]];
        for k in 0..4 {
            assert!((row[4 + k] - want[k]).abs() < 1e-12, "row {i}");
        }
        // det A = S_AB² (A′ has det 1).
        let det = row[4] * row[7] - row[5] * row[6];
        assert!((det / (shape.scale * shape.scale) - 1.0).abs() < 1e-9);
    }
}

#[test]
fn bad_estimator_inputs_are_named() {
    let est = ShapeEstimator::new(echo());
    let img = GrayImage::new(40, 40, vec![0.5; 1600]).unwrap();
    let e = est
        .estimate(&img, &img, &[[1.0, 2.0]; 3], &[[1.0, 2.0]; 2])
        .unwrap_err();
    assert!(
        matches!(e, RunnerError::InvalidInput { what: "x2", .. }),
        "{e:?}"
    );
    assert!(e.to_string().contains("x1 has 3"), "{e}");
    let e = est
        .estimate(
            &img,
            &img,
            &[[1.0, 2.0]; 3],
            &[[1.0, 2.0], [f64::NAN, 0.0], [0.0, 0.0]],
        )
        .unwrap_err();
    assert!(
        matches!(
            e,
            RunnerError::Image(ImageError::NonFinite { what: "x2", row: 1 })
        ),
        "{e:?}"
    );
    let e = est
        .model()
        .predict(&random_patches(3, 0), &random_patches(2, 0))
        .unwrap_err();
    assert_invalid(&e, "patch_b");
    assert!(matches!(
        Patches::from_vec(vec![0.0; 1000]),
        Err(ImageError::InvalidInput {
            what: "patches",
            ..
        })
    ));
}

/// The contract error for a fixture; each expected fragment must be in the message.
fn contract_error(name: &str, fragments: &[&str]) {
    common::init();
    let e = ShapeModel::load(common::fixture(name)).unwrap_err();
    assert!(
        matches!(
            e,
            RunnerError::Contract {
                contract: "shape-v1",
                ..
            }
        ),
        "{name}: {e:?}"
    );
    let msg = e.to_string();
    assert!(msg.contains(name), "{msg}");
    for f in fragments {
        assert!(msg.contains(f), "{name}: {f:?} not in {msg:?}");
    }
}

#[test]
fn contract_violations_say_what_is_wrong() {
    contract_error(
        "no_contract.onnx",
        &[
            "affcorr.contract is missing",
            "patch_size is missing",
            "angle_bins is missing",
            "scale_bins is missing",
            "decode is missing",
        ],
    );
    contract_error(
        "wrong_contract.onnx",
        &["affcorr.contract is \"dense-v1\", expected \"shape-v1\""],
    );
    contract_error(
        "bad_metadata.onnx",
        &[
            "patch_size is \"64\"",
            "decode is \"argmax\"",
            "angle_bins is not a JSON list",
            "scale_bins[1] = -2",
        ],
    );
    contract_error(
        "wrong_input_name.onnx",
        &["input patch_a is missing", "unexpected input patch"],
    );
    contract_error(
        "wrong_input_shape.onnx",
        &["input patch_a", "expected (N, 1, 32, 32)"],
    );
    contract_error(
        "wrong_outputs.onnx",
        &[
            "output angle_logits_b is missing",
            "output residual_shape is missing",
            "\"residual\"",
        ],
    );
    contract_error(
        "wrong_dtype.onnx",
        &["output residual_shape", "expected float32"],
    );
    contract_error(
        "width_mismatch.onnx",
        &[
            "output angle_logits_a",
            "has shape (N, 8), expected (N, 7)",
            "number of angle_bins",
        ],
    );
    contract_error(
        "width_mismatch_symbolic.onnx",
        &[
            "output scale_logits_a",
            "expected [1, 6]",
            "number of scale_bins",
        ],
    );
}

#[test]
fn unreadable_models_are_typed_errors() {
    common::init();
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.onnx");
    let e = ShapeModel::load(&missing).unwrap_err();
    assert!(matches!(e, RunnerError::ModelOpen { .. }), "{e:?}");
    assert!(e.to_string().contains("missing.onnx"), "{e}");
    assert!(matches!(
        ShapeModel::load(dir.path()),
        Err(RunnerError::ModelOpen { .. })
    ));

    let junk = dir.path().join("junk.onnx");
    std::fs::write(&junk, b"definitely not a protobuf model").unwrap();
    let e = ShapeModel::load(&junk).unwrap_err();
    assert!(matches!(e, RunnerError::ModelLoad { .. }), "{e:?}");
    assert!(e.to_string().contains("junk.onnx"), "{e}");

    let bytes = std::fs::read(common::fixture("echo.onnx")).unwrap();
    let truncated = dir.path().join("truncated.onnx");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert!(matches!(
        ShapeModel::load(&truncated),
        Err(RunnerError::ModelLoad { .. })
    ));
    let e = ShapeModel::from_bytes(&bytes[..100], &ShapeModelOptions::default()).unwrap_err();
    assert!(matches!(e, RunnerError::ModelLoad { .. }), "{e:?}");

    for (opts, what) in [
        (
            ShapeModelOptions {
                threads: Some(0),
                batch_size: 8,
            },
            "threads",
        ),
        (
            ShapeModelOptions {
                threads: None,
                batch_size: 0,
            },
            "batch_size",
        ),
    ] {
        let e = ShapeModel::load_with(common::fixture("echo.onnx"), &opts).unwrap_err();
        assert!(
            matches!(e, RunnerError::InvalidInput { what: w, .. } if w == what),
            "{e:?}"
        );
    }
}

#[test]
fn bundled_model_runs() {
    common::init();
    let m = ShapeModel::load_with(
        common::bundled_model(),
        &ShapeModelOptions {
            threads: Some(2),
            batch_size: 512,
        },
    )
    .unwrap();
    assert_eq!(m.metadata()["affcorr.contract"], "shape-v1");
    let mut rng = rand_pcg::Pcg64::seed_from_u64(6);
    let n = 20;
    let a = Patches::from_vec((0..n * LEN).map(|_| rng.random::<f32>()).collect()).unwrap();
    let b = Patches::from_vec((0..n * LEN).map(|_| rng.random::<f32>()).collect()).unwrap();
    let p = m.predict(&a, &b).unwrap();
    for i in 0..n {
        assert!(p.orientation_a[i].abs() <= PI && p.orientation_b[i].abs() <= PI);
        assert!(p.scale_a[i] > 0.0 && p.scale_b[i] > 0.0);
        assert!(p.residual_shape[i][0] > -1.0 && p.residual_shape[i][2] > -1.0);
    }
    let acs = p.affine().unwrap();
    assert!(acs.iter().all(|a| a[0] * a[3] - a[1] * a[2] > 0.0));
}
