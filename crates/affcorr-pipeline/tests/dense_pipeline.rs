//! The pipeline with a dense matcher (`dense-warp-v1`) on a test model whose warp is
//! graffiti's ground-truth homography (python/affcorr/export/dense_test_model.py, written to a
//! temporary directory by the project's .venv Python, which scripts/setup.sh makes).
//!
//! Bounds: the ACs' points lie on H within 0.5 px (the warp is exact up to float32, ~1e-4 px);
//! the homography estimated from them has a mean corner error below 0.1 px (measured < 1e-3 px:
//! exact points, RANSAC + LO on their coordinates).

mod common;

use affcorr_geom::{Mat3, Vec3};
use affcorr_pipeline::{EstimatorOptions, Matcher, Pipeline, PipelineError};
use affcorr_runner::RunnerError;

const W: usize = 800;
const H: usize = 640;

fn ground_truth() -> Mat3 {
    Mat3::from_row_slice(&affcorr_devtools::graffiti_homography())
}

fn project(h: &Mat3, p: [f64; 2]) -> [f64; 2] {
    let q = h * Vec3::new(p[0], p[1], 1.0);
    [q[0] / q[2], q[1] / q[2]]
}

fn dense_pipeline(max_matches: usize) -> Pipeline {
    common::init();
    Pipeline::builder()
        .dense_matcher(affcorr_devtools::dense_test_model("ok.onnx", &[]))
        .shape_model(common::bundled_model())
        .max_matches(max_matches)
        .threads(2)
        // The tests check the matcher's own points; the refinement would move them.
        .affine_refinement(None)
        .build()
        .unwrap()
}

#[test]
fn the_pipeline_with_the_ground_truth_as_matcher_gives_exact_points() {
    let p = dense_pipeline(400);
    assert_eq!(p.matcher(), Matcher::Dense);
    assert!(p.backbone().is_none() && p.dense_matcher().is_some());
    let dir = common::root().join("data/graffiti");
    let (a, b) = (dir.join("graf1.png"), dir.join("graf3.png"));
    let m = p.match_pair(&a, &b).unwrap();
    assert_eq!(m.len(), 400);
    assert_eq!(m.certainty.len(), 400);
    let gt = ground_truth();
    let worst = m
        .corrs
        .iter()
        .map(|c| {
            let q = project(&gt, [c[0], c[1]]);
            ((q[0] - c[2]).powi(2) + (q[1] - c[3]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max);
    assert!(worst < 0.5, "worst transfer error {worst} px");
    assert!(m.corrs.iter().all(|c| c[4] * c[7] - c[5] * c[6] > 0.0));
    assert!(m.timings.matcher > std::time::Duration::ZERO);
    // Seeded: the same ACs again.
    assert_eq!(p.match_pair(&a, &b).unwrap().corrs, m.corrs);

    let mut opts = EstimatorOptions::default();
    opts.ransac.threshold = 2.0;
    let est = p.homography(&a, &b, &opts).unwrap();
    let corners = [
        [0.0, 0.0],
        [W as f64 - 1.0, 0.0],
        [W as f64 - 1.0, H as f64 - 1.0],
        [0.0, H as f64 - 1.0],
    ];
    let err = corners
        .iter()
        .map(|&c| {
            let (p, q) = (project(&est.estimate.model, c), project(&gt, c));
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
        })
        .sum::<f64>()
        / 4.0;
    eprintln!(
        "dense GT: worst point error {worst:.2e} px, H corner error {err:.2e} px, {} / {} inliers; {}",
        est.estimate.num_inliers,
        est.matches.len(),
        est.matches.timings
    );
    assert!(err < 0.1, "mean corner error {err} px");
}

#[test]
fn a_dense_pipeline_names_its_missing_model() {
    common::init();
    let e = Pipeline::builder()
        .matcher(Matcher::Dense)
        .shape_model(common::bundled_model())
        .build()
        .unwrap_err();
    assert!(e.to_string().contains("dense_matcher"), "{e}");
    let e = Pipeline::builder()
        .dense_matcher("/nonexistent/dkm.onnx")
        .shape_model(common::bundled_model())
        .build()
        .unwrap_err();
    assert!(
        matches!(e, PipelineError::Runner(RunnerError::ModelOpen { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("dkm.onnx"), "{e}");
    assert_eq!("dense".parse::<Matcher>().unwrap(), Matcher::Dense);
}
