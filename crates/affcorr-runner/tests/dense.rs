//! The dense-matcher path (`dense-warp-v1`) on a test model: a graph that returns graffiti's
//! ground-truth homography as the warp (python/affcorr/export/dense_test_model.py, written to a
//! temporary directory by the project's .venv Python, which scripts/setup.sh makes).
//!
//! Bounds: the ACs' points lie on H within 0.5 px (the warp is exact up to float32, ~1e-4 px);
//! the homography estimated from them has a mean corner error below 0.1 px (measured < 1e-3 px:
//! exact points, RANSAC + LO on their coordinates).

mod common;

use std::path::Path;

use affcorr_geom::{Mat3, Vec3};
use affcorr_image::RgbImage;
use affcorr_runner::{DenseMatcher, DenseWarp, RunnerError, SamplingOptions, balanced_sample};

const W: usize = 800;
const H: usize = 640;

fn ground_truth() -> Mat3 {
    Mat3::from_row_slice(&common::graffiti_homography())
}

fn project(h: &Mat3, p: [f64; 2]) -> [f64; 2] {
    let q = h * Vec3::new(p[0], p[1], 1.0);
    [q[0] / q[2], q[1] / q[2]]
}

fn graffiti(name: &str) -> RgbImage {
    RgbImage::open(common::root().join("data/graffiti").join(name)).unwrap()
}

fn run_on_graffiti(model: &Path) -> DenseWarp {
    common::init();
    let m = DenseMatcher::load(model, Some(2)).unwrap();
    m.run(&graffiti("graf1.png"), &graffiti("graf3.png"))
        .unwrap()
}

#[test]
fn the_contract_accepts_the_test_model_and_rejects_broken_ones() {
    common::init();
    let m =
        DenseMatcher::load(affcorr_devtools::dense_test_model("ok.onnx", &[]), Some(1)).unwrap();
    assert_eq!(
        m.metadata().get("affcorr.contract").map(String::as_str),
        Some("dense-warp-v1")
    );
    // Dynamic axes: image A's size; fixed axes: the graph's.
    assert_eq!(m.input_size(W, H), (H, W));
    let fixed = DenseMatcher::load(
        affcorr_devtools::dense_test_model("fixed.onnx", &["--input-size", "120", "160"]),
        Some(1),
    )
    .unwrap();
    assert_eq!(fixed.input_size(W, H), (120, 160));
    let nominal = DenseMatcher::load(
        affcorr_devtools::dense_test_model(
            "nominal.onnx",
            &["--meta", "affcorr.nominal_size=[96, 128]"],
        ),
        Some(1),
    )
    .unwrap();
    assert_eq!(nominal.input_size(W, H), (96, 128));

    for (variant, says) in [
        ("no-certainty", "output certainty is missing"),
        (
            "warp-channels",
            "output warp: axis 3 has size 3, expected 2",
        ),
        ("gray-input", "input image_a: axis 1 has size 1, expected 3"),
        ("wrong-contract", "features-backbone-v1"),
        ("no-contract", "affcorr.contract is missing"),
    ] {
        let path =
            affcorr_devtools::dense_test_model(&format!("{variant}.onnx"), &["--variant", variant]);
        let e = DenseMatcher::load(&path, Some(1)).unwrap_err();
        let msg = e.to_string();
        assert!(
            matches!(
                e,
                RunnerError::Contract {
                    contract: "dense-warp-v1",
                    ..
                }
            ),
            "{variant}: {msg}"
        );
        assert!(msg.contains(says), "{variant}: {msg}");
    }
    let bad = affcorr_devtools::dense_test_model(
        "bad-nominal.onnx",
        &["--meta", "affcorr.nominal_size=[96]"],
    );
    let e = DenseMatcher::load(bad, Some(1)).unwrap_err();
    assert!(e.to_string().contains("nominal_size"), "{e}");
    // A model of another contract.
    let e = DenseMatcher::load(
        common::root().join("python/affcorr/models/xfeat_backbone.onnx"),
        Some(1),
    )
    .unwrap_err();
    assert!(e.to_string().contains("features-backbone-v1"), "{e}");
}

#[test]
fn the_warp_is_the_homography_in_dkm_coordinates() {
    let warp = run_on_graffiti(&affcorr_devtools::dense_test_model("ok.onnx", &[]));
    assert_eq!((warp.height, warp.width), (H, W));
    let gt = ground_truth();
    let (mut inside, mut checked) = (0, 0);
    for k in (0..H * W).step_by(997) {
        let (a, b) = warp.to_pixels(&[k], (W, H), (W, H));
        // Full resolution: cell (i, j) is pixel (j, i) of A.
        assert!((a[0][0] - (k % W) as f64).abs() < 1e-9 && (a[0][1] - (k / W) as f64).abs() < 1e-9);
        let want = project(&gt, a[0]);
        let err = ((b[0][0] - want[0]).powi(2) + (b[0][1] - want[1]).powi(2)).sqrt();
        assert!(err < 1e-2, "cell {k}: {:?} vs {want:?}", b[0]);
        let in_b =
            (0.0..W as f64 - 1.0).contains(&want[0]) && (0.0..H as f64 - 1.0).contains(&want[1]);
        if !in_b {
            assert_eq!(warp.certainty[k], 0.0, "cell {k} maps outside B");
        } else {
            inside += 1;
        }
        checked += 1;
    }
    assert!(inside > checked / 2, "{inside} of {checked} inside B");
    // Input at 120×160: the grid is coarser, the warp the same map.
    let coarse = run_on_graffiti(&affcorr_devtools::dense_test_model(
        "fixed.onnx",
        &["--input-size", "120", "160"],
    ));
    assert_eq!((coarse.height, coarse.width), (120, 160));
    let k = 60 * 160 + 80;
    let (a, b) = coarse.to_pixels(&[k], (W, H), (W, H));
    let want = project(&gt, a[0]);
    assert!((b[0][0] - want[0]).abs() < 1e-2 && (b[0][1] - want[1]).abs() < 1e-2);
}

#[test]
fn sampling_is_seeded_balanced_and_confident() {
    let warp = run_on_graffiti(&affcorr_devtools::dense_test_model("ok.onnx", &[]));
    let o = SamplingOptions {
        num: 1000,
        seed: 3,
        ..Default::default()
    };
    let s = balanced_sample(&warp, &o).unwrap();
    assert_eq!(
        s,
        balanced_sample(&warp, &o).unwrap(),
        "same seed, same sample"
    );
    let other = balanced_sample(&warp, &SamplingOptions { seed: 4, ..o }).unwrap();
    assert_ne!(s.index, other.index);
    assert_eq!(s.index.len(), 1000);
    // Only from confident cells: every match lands in B.
    assert!(s.certainty.iter().all(|&c| c > 0.0));
    let (a, b) = warp.to_pixels(&s.index, (W, H), (W, H));
    assert!(
        b.iter()
            .all(|p| (-0.5..W as f64 - 0.5).contains(&p[0])
                && (-0.5..H as f64 - 0.5).contains(&p[1]))
    );
    // Spread: every 100×100 px block of A whose warp lies inside B gets matches, in
    // proportion to its area (a 0.1-wide kernel in normalised units is 40 px).
    let gt = ground_truth();
    let mut empty = Vec::new();
    for by in 0..H / 100 {
        for bx in 0..W / 100 {
            let corners = [(0, 0), (99, 0), (0, 99), (99, 99)]
                .map(|(dx, dy)| project(&gt, [(bx * 100 + dx) as f64, (by * 100 + dy) as f64]));
            let inside = corners.iter().all(|p| {
                (30.0..W as f64 - 30.0).contains(&p[0]) && (30.0..H as f64 - 30.0).contains(&p[1])
            });
            let n = a
                .iter()
                .filter(|p| p[0] as usize / 100 == bx && p[1] as usize / 100 == by)
                .count();
            if inside && n < 5 {
                empty.push((bx, by, n));
            }
        }
    }
    assert!(
        empty.is_empty(),
        "blocks inside the overlap with < 5 matches: {empty:?}"
    );
}
