//! The pipeline on a real pair with ground truth: graffiti 1→3 (data/graffiti, H1to3p).
//!
//! Bounds (measured with the committed models, with margin; benches/results/pipeline_timing.md
//! and tests/test_pipeline.py have the numbers): correct matches within 3 px per matcher, and
//! the mean corner error of the homography estimated from the ACs.

mod common;

use std::path::PathBuf;
use std::sync::OnceLock;

use affcorr_geom::Mat3;
use affcorr_image::ImageError;
use affcorr_pipeline::{
    EstimatorOptions, GrayImage, ImageSource, Matcher, Pipeline, PipelineError, ViewMode,
    ViewOptions,
};
use affcorr_runner::RunnerError;

fn graffiti() -> &'static (GrayImage, GrayImage, Mat3) {
    static DATA: OnceLock<(GrayImage, GrayImage, Mat3)> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = common::root().join("data/graffiti");
        (
            GrayImage::open(dir.join("graf1.png")).unwrap(),
            GrayImage::open(dir.join("graf3.png")).unwrap(),
            Mat3::from_row_slice(&common::graffiti_homography()),
        )
    })
}

fn models() -> PathBuf {
    common::models_dir()
}

/// The matcher at 4096 keypoints (the bounds below were measured there), without the view
/// cascade (the tests check the matcher's own matches).
fn pipeline(matcher: Matcher) -> Pipeline {
    common::init();
    Pipeline::builder()
        .matcher(matcher)
        .models_dir(models())
        .max_keypoints(4096)
        .views(ViewOptions {
            mode: ViewMode::Off,
            ..Default::default()
        })
        .threads(2)
        .build()
        .unwrap()
}

fn project(h: &Mat3, x: f64, y: f64) -> (f64, f64) {
    let p = h * affcorr_geom::Vec3::new(x, y, 1.0);
    (p[0] / p[2], p[1] / p[2])
}

fn correct(corrs: &[[f64; 8]], h: &Mat3, px: f64) -> usize {
    corrs
        .iter()
        .filter(|c| {
            let (u, v) = project(h, c[0], c[1]);
            ((u - c[2]).powi(2) + (v - c[3]).powi(2)).sqrt() <= px
        })
        .count()
}

/// Mean distance between the image-1 corners mapped by `h` and by the ground truth.
fn corner_error(h: &Mat3, gt: &Mat3, w: f64, hgt: f64) -> f64 {
    let corners = [(0.0, 0.0), (w, 0.0), (w, hgt), (0.0, hgt)];
    corners
        .iter()
        .map(|&(x, y)| {
            let (a, b) = project(h, x, y);
            let (c, d) = project(gt, x, y);
            ((a - c).powi(2) + (b - d).powi(2)).sqrt()
        })
        .sum::<f64>()
        / 4.0
}

#[test]
fn every_matcher_finds_correct_matches_on_graffiti() {
    let (a, b, h) = graffiti();
    // (matcher, minimum correct within 3 px, minimum share correct)
    for (matcher, min_correct, min_ratio) in [
        (Matcher::XFeatMnn, 650, 0.40),
        (Matcher::XFeatStar, 350, 0.40),
        (Matcher::XFeatLighterGlue, 1000, 0.65),
    ] {
        let p = pipeline(matcher);
        let m = p.match_pair(a, b).unwrap();
        let c = correct(&m.corrs, h, 3.0);
        eprintln!(
            "{matcher}: {c} / {} correct, keypoints {:?}; {}",
            m.len(),
            m.num_keypoints,
            m.timings
        );
        assert!(c >= min_correct, "{matcher}: {c} correct < {min_correct}");
        assert!(
            c as f64 >= min_ratio * m.len() as f64,
            "{matcher}: {c} / {}",
            m.len()
        );
        assert_eq!(m.certainty.len(), m.len());
        assert!(
            m.certainty.windows(2).all(|w| w[0] >= w[1]),
            "sorted by certainty"
        );
        // The ACs' A: finite with positive determinant.
        assert!(m.corrs.iter().all(|c| c[4] * c[7] - c[5] * c[6] > 0.0));
    }
}

#[test]
fn homography_from_acs_is_close_to_the_ground_truth() {
    let (a, b, h) = graffiti();
    let p = pipeline(Matcher::XFeatMnn);
    let mut opts = EstimatorOptions::default();
    opts.ransac.threshold = 3.0;
    let est = p.homography(a, b, &opts).unwrap();
    let err = corner_error(&est.estimate.model, h, a.width() as f64, a.height() as f64);
    eprintln!(
        "H corner error {err:.2} px, {} / {} inliers; {}",
        est.estimate.num_inliers,
        est.matches.len(),
        est.matches.timings
    );
    assert!(err < 3.0, "mean corner error {err} px");
    assert!(est.matches.timings.ransac > std::time::Duration::ZERO);
}

#[test]
fn max_side_and_max_matches_keep_original_pixels() {
    let (a, b, h) = graffiti();
    common::init();
    let p = Pipeline::builder()
        .matcher(Matcher::XFeatMnn)
        .models_dir(models())
        .max_side(400)
        .max_matches(300)
        .threads(2)
        .build()
        .unwrap();
    let m = p.match_pair(a, b).unwrap();
    assert_eq!(m.len(), 300);
    // Coordinates are in the 800×640 originals: most of the 300 most certain are correct
    // within 6 px (2 px at half resolution, 3 px rounding of the downscale).
    let c = correct(&m.corrs, h, 6.0);
    eprintln!("max_side 400: {c} / 300 within 6 px");
    assert!(c >= 170, "{c}");
    assert!(m.corrs.iter().any(|c| c[0] > 500.0 || c[2] > 500.0));
}

#[test]
fn bad_models_and_images_are_named() {
    common::init();
    let e = Pipeline::builder()
        .models_dir("/nonexistent/models")
        .build()
        .unwrap_err();
    assert!(
        matches!(e, PipelineError::Runner(RunnerError::ModelOpen { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("xfeat_backbone.onnx"), "{e}");
    // The refinement model given as the backbone: its contract is named.
    let e = Pipeline::builder()
        .models_dir(models())
        .backbone_model(models().join("xfeat_refine.onnx"))
        .build()
        .unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(
            e,
            PipelineError::Runner(RunnerError::Contract {
                contract: "features-backbone-v1",
                ..
            })
        ),
        "{msg}"
    );
    assert!(msg.contains("features-refine-v1"), "{msg}");
    // The shape network is not a matcher.
    let e = Pipeline::builder()
        .models_dir(models())
        .backbone_model(models().join("shape.onnx"))
        .build()
        .unwrap_err();
    assert!(e.to_string().contains("shape-v1"), "{e}");
    let e = Pipeline::builder().build().unwrap_err();
    assert!(e.to_string().contains("models_dir"), "{e}");
    let e = Pipeline::builder()
        .models_dir(models())
        .max_keypoints(0)
        .build()
        .unwrap_err();
    assert!(e.to_string().contains("max_keypoints"), "{e}");

    let p = pipeline(Matcher::XFeatMnn);
    let e = p
        .match_pair("/nonexistent.png", "/nonexistent2.png")
        .unwrap_err();
    assert!(
        matches!(e, PipelineError::Image(ImageError::Open { .. })),
        "{e}"
    );
    let tiny = GrayImage::new(20, 20, vec![0.5; 400]).unwrap();
    let e = p.match_pair(&tiny, &tiny).unwrap_err();
    assert!(e.to_string().contains("too small"), "{e}");
}

#[test]
fn match_pairs_in_parallel_equal_single_calls() {
    let (a, b, _) = graffiti();
    common::init();
    let p = Pipeline::builder()
        .matcher(Matcher::XFeatMnn)
        .models_dir(models())
        .max_keypoints(1024)
        .threads(2)
        .build()
        .unwrap();
    let missing = PathBuf::from("/nonexistent/graf.png");
    let pairs: Vec<(ImageSource<'_>, ImageSource<'_>)> = vec![
        (a.into(), b.into()),
        (b.into(), a.into()),
        (a.into(), (&missing).into()),
        (a.into(), b.into()),
    ];
    let out = p.match_pairs(pairs);
    assert_eq!(out.len(), 4);
    let ab = p.match_pair(a, b).unwrap();
    let ba = p.match_pair(b, a).unwrap();
    for (got, want) in [(&out[0], &ab), (&out[1], &ba), (&out[3], &ab)] {
        let got = got.as_ref().unwrap();
        assert_eq!(got.corrs, want.corrs);
        assert_eq!(got.certainty, want.certainty);
    }
    assert!(
        matches!(&out[2], Err(PipelineError::Image(ImageError::Open { path, .. })) if *path == missing),
        "{:?}",
        out[2].as_ref().err()
    );
    // One pair, or one thread: no workers needed, same results.
    assert_eq!(p.match_pairs([(a, b)])[0].as_ref().unwrap().corrs, ab.corrs);
}
