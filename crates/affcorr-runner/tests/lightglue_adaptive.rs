//! LighterGlue's adaptive loop over the shipped pieces (`xfeat_lighterglue_{encode,layer,
//! assign}.onnx`) against the full graph (`xfeat_lighterglue.onnx`) on graffiti 1→3, 1024
//! keypoints per image (the XFeat features of the shipped backbone).
//!
//! Tolerances (benches/results/lighterglue_adaptive.md has the measured table):
//! - without early exit (depth −1, width 0.95: the full graph's own rule) the loop is the same
//!   computation: ≥ 99 % of the full graph's matches identical (measured 100 %);
//! - with the default early exit (depth 0.95) the loop stops after layer 4 of 6 and uses that
//!   layer's assignment head, so matches move: ≥ 88 % of the full graph's index pairs identical
//!   (measured 93 %) and at least 95 % as many correct matches within 3 px (measured 101 %).

mod common;

use std::collections::HashSet;

use affcorr_geom::{Mat3, Vec3};
use affcorr_image::GrayImage;
use affcorr_runner::features::{detect_and_compute, preprocess};
use affcorr_runner::matching::normalize_keypoints_lighterglue;
use affcorr_runner::{
    Backbone, GlueConfig, GlueMatches, GlueMode, GluePieceFiles, LighterGlue, LighterGlueOptions,
    RunnerError, SparseFeatures,
};

const TOP_K: usize = 1024;

fn models() -> std::path::PathBuf {
    affcorr_devtools::models_dir()
}

fn features(backbone: &Backbone, name: &str) -> SparseFeatures {
    let img = GrayImage::open(common::root().join("data/graffiti").join(name)).unwrap();
    let (w, h) = (img.width(), img.height());
    let cfg = backbone.config();
    let input = preprocess(img.data(), h, w, cfg.input_multiple).unwrap();
    let maps = backbone
        .run(&input.data, input.height, input.width, true)
        .unwrap();
    detect_and_compute(
        &maps,
        TOP_K,
        cfg.threshold,
        cfg.nms_size,
        (input.rh, input.rw),
        (w, h),
    )
}

struct Pair {
    a: SparseFeatures,
    b: SparseFeatures,
    k0: Vec<f32>,
    k1: Vec<f32>,
}

fn graffiti() -> Pair {
    common::init();
    let backbone = Backbone::load(models().join("xfeat_backbone.onnx"), Some(2)).unwrap();
    let a = features(&backbone, "graf1.png");
    let b = features(&backbone, "graf3.png");
    let k0 = normalize_keypoints_lighterglue(&a.keypoints, a.image_size);
    let k1 = normalize_keypoints_lighterglue(&b.keypoints, b.image_size);
    Pair { a, b, k0, k1 }
}

fn glue(options: LighterGlueOptions) -> LighterGlue {
    LighterGlue::load_with(models().join("xfeat_lighterglue.onnx"), Some(2), &options).unwrap()
}

fn run(g: &LighterGlue, p: &Pair) -> GlueMatches {
    g.run(
        &p.k0,
        &p.a.descriptors,
        &p.k1,
        &p.b.descriptors,
        g.min_conf(),
    )
    .unwrap()
}

fn pairs(m: &GlueMatches) -> HashSet<(usize, usize)> {
    m.idx0.iter().copied().zip(m.idx1.iter().copied()).collect()
}

fn correct(m: &GlueMatches, p: &Pair) -> usize {
    let h = Mat3::from_row_slice(&common::graffiti_homography());
    m.idx0
        .iter()
        .zip(&m.idx1)
        .filter(|&(&i, &j)| {
            let [x, y] = p.a.keypoints[i];
            let q = h * Vec3::new(x as f64, y as f64, 1.0);
            let [u, v] = p.b.keypoints[j];
            let (dx, dy) = (q[0] / q[2] - u as f64, q[1] / q[2] - v as f64);
            (dx * dx + dy * dy).sqrt() <= 3.0
        })
        .count()
}

#[test]
fn the_adaptive_loop_without_early_exit_is_the_full_graph() {
    let p = graffiti();
    let full = glue(LighterGlueOptions {
        mode: Some(GlueMode::Full),
        ..Default::default()
    });
    assert_eq!(full.mode(), GlueMode::Full);
    let adaptive = glue(LighterGlueOptions {
        mode: Some(GlueMode::Adaptive),
        depth_confidence: Some(-1.0),
        width_confidence: Some(0.95),
    });
    let (mf, ma) = (run(&full, &p), run(&adaptive, &p));
    let (sf, sa) = (pairs(&mf), pairs(&ma));
    let common = sf.intersection(&sa).count();
    assert!(sf.len() > 150, "{} matches", sf.len());
    assert!(
        common as f64 >= 0.99 * sf.len() as f64 && sa.len().abs_diff(sf.len()) <= sf.len() / 100,
        "full {} adaptive {} common {common}",
        sf.len(),
        sa.len()
    );
    let (_, trace) = adaptive
        .run_traced(&p.k0, &p.a.descriptors, &p.k1, &p.b.descriptors, 0.1)
        .unwrap();
    let trace = trace.unwrap();
    assert_eq!(trace.layers, 6);
    assert_eq!(trace.points0[0], p.a.keypoints.len());
    assert!(trace.points0.windows(2).all(|w| w[1] <= w[0]), "{trace:?}");
}

#[test]
fn the_default_adaptive_loop_keeps_the_full_graphs_matches() {
    let p = graffiti();
    let full = glue(LighterGlueOptions {
        mode: Some(GlueMode::Full),
        ..Default::default()
    });
    // the default: the pieces are shipped beside the full model
    let adaptive = glue(LighterGlueOptions::default());
    assert_eq!(adaptive.mode(), GlueMode::Adaptive);
    assert_eq!(
        adaptive.config(),
        Some(GlueConfig {
            depth_confidence: 0.95,
            width_confidence: 0.95
        })
    );
    let (mf, ma) = (run(&full, &p), run(&adaptive, &p));
    let (sf, sa) = (pairs(&mf), pairs(&ma));
    let common = sf.intersection(&sa).count();
    let (cf, ca) = (correct(&mf, &p), correct(&ma, &p));
    assert!(
        common as f64 >= 0.88 * sf.len() as f64,
        "full {} adaptive {} common {common}",
        sf.len(),
        sa.len()
    );
    assert!(
        ca as f64 >= 0.95 * cf as f64,
        "correct: full {cf}, adaptive {ca}"
    );
    let (_, trace) = adaptive
        .run_traced(&p.k0, &p.a.descriptors, &p.k1, &p.b.descriptors, 0.1)
        .unwrap();
    assert!(trace.unwrap().layers < 6, "early exit expected on graffiti");
}

#[test]
fn empty_sides_give_no_matches_and_bad_shapes_are_named() {
    common::init();
    let g = glue(LighterGlueOptions {
        mode: Some(GlueMode::Adaptive),
        ..Default::default()
    });
    let d = vec![0.125f32; 64];
    let m = g.run(&[], &[], &[0.0, 0.0], &d, 0.1).unwrap();
    assert!(m.idx0.is_empty());
    let e = g
        .run(&[0.0, 0.0], &d[..63], &[0.0, 0.0], &d, 0.1)
        .unwrap_err();
    assert!(
        matches!(e, RunnerError::InvalidInput { what: "kpts0", .. }),
        "{e}"
    );
}

#[test]
fn pieces_are_checked_against_their_contracts() {
    common::init();
    let dir = models();
    let mut files = GluePieceFiles::beside(&dir.join("xfeat_lighterglue.onnx"));
    files.encode = dir.join("xfeat_lighterglue.onnx");
    let e = affcorr_runner::AdaptiveGlue::load(&files, Some(1)).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("matcher-lightglue-encode-v1") && msg.contains("matcher-lighterglue-v1"),
        "{msg}"
    );
    // a depth rule of 1 is rejected (it could never stop)
    let e = LighterGlue::load_with(
        dir.join("xfeat_lighterglue.onnx"),
        Some(1),
        &LighterGlueOptions {
            mode: Some(GlueMode::Adaptive),
            depth_confidence: Some(1.0),
            width_confidence: None,
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("depth_confidence"), "{e}");
}
