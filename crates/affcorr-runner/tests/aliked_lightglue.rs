//! ALIKED + LightGlue through the runner (`"aliked-lightglue"`): the models exported at setup
//! time by `python -m affcorr.export.lightglue_models` (not committed), on graffiti 1→3 with
//! 1024 keypoints per image.
//!
//! The parity with the numpy specification and with upstream torch is
//! tests/test_aliked_lightglue.py's (the same images through `affcorr.Pipeline`); here: the
//! matcher loads from a models directory, finds sub-pixel ALIKED keypoints with unit
//! descriptors and LightGlue matches that agree with graffiti's homography, images whose sides
//! are not multiples of 32 are padded and cropped (a tiny one gives no keypoint), and a missing
//! model's error names the file and the export command.
//!
//! Without the exported models the tests say so on stderr and pass, unless
//! `AFFCORR_REQUIRE_EXPORTED_MODELS=1` (scripts/test.sh sets it after exporting them).

mod common;

use affcorr_image::GrayImage;
use affcorr_runner::aliked::{EXPORT_COMMAND, SDDH_FILE};
use affcorr_runner::{GlueConfig, Matcher, MatcherFiles, PointMatcher, RunnerError};

const TOP_K: usize = 1024;

fn files(dir: &std::path::Path) -> MatcherFiles {
    MatcherFiles {
        aliked_backbone: Some(dir.join("aliked_backbone.onnx")),
        aliked_lightglue: Some(dir.join("aliked_lightglue.onnx")),
        ..Default::default()
    }
}

fn matcher() -> Option<PointMatcher> {
    if !common::exported(
        "aliked_lightglue_layer.onnx",
        "ALIKED + LightGlue",
        EXPORT_COMMAND,
    ) {
        return None;
    }
    let dir = affcorr_devtools::models_dir();
    Some(PointMatcher::load(Matcher::AlikedLightGlue, &files(&dir), Some(TOP_K), 0, 2).unwrap())
}

#[test]
fn aliked_lightglue_matches_graffiti_along_its_homography() {
    let Some(m) = matcher() else { return };
    assert_eq!(m.kind(), Matcher::AlikedLightGlue);
    let cfg = m.aliked_backbone().unwrap().config().clone();
    assert_eq!(
        (cfg.descriptor_dim, cfg.input_multiple, cfg.nms_radius),
        (128, 32, 2)
    );
    assert_eq!((cfg.threshold, cfg.temperature), (0.2, 0.1));
    assert_eq!(
        m.glue().unwrap().config(),
        Some(GlueConfig {
            depth_confidence: 0.95,
            width_confidence: 0.99
        })
    );
    let (a, b) = (common::graffiti("graf1.png"), common::graffiti("graf3.png"));
    let fa = m.extract(&a, None).unwrap();
    let fb = m.extract(&b, None).unwrap();
    assert_eq!((fa.len(), fb.len()), (TOP_K, TOP_K));
    // sub-pixel, inside the 2 px border, unit descriptors
    let sub = fa
        .keypoints()
        .iter()
        .filter(|p| p[0].fract() != 0.0)
        .count();
    assert!(sub > TOP_K / 2, "{sub} sub-pixel keypoints");
    for p in fa.keypoints() {
        assert!(p[0] >= 0.0 && p[0] <= (a.width() - 1) as f32, "{p:?}");
        assert!(p[1] >= 0.0 && p[1] <= (a.height() - 1) as f32, "{p:?}");
    }
    let affcorr_runner::FeatureData::Sparse(s) = &fa.data else {
        panic!("sparse features expected")
    };
    for row in s.descriptors.chunks(s.dim) {
        let n: f32 = row.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((n - 1.0).abs() < 1e-4, "{n}");
    }
    assert!(s.scores.iter().all(|&v| v > 0.2 && v <= 1.0));
    let r = m.match_features(&fa, &fb).unwrap();
    let correct = common::graffiti_correct(&r.x1, &r.x2, 3.0);
    // measured: 455 matches, 344 (76 %) within 3 px
    assert!(
        r.x1.len() > 380 && correct > 280,
        "{correct} of {} matches",
        r.x1.len()
    );
    assert!(
        correct as f64 >= 0.65 * r.x1.len() as f64,
        "{correct} of {} within 3 px",
        r.x1.len()
    );
    assert!(r.certainty.iter().all(|&c| c > 0.1 && c <= 1.0));
}

#[test]
fn sides_that_are_not_multiples_of_32_are_padded_and_cropped() {
    let Some(m) = matcher() else { return };
    // the top-left 701 × 601 part of graf1 (800 × 640): padded to 704 × 608 for the network,
    // keypoints and descriptors on the cropped maps (tests/test_aliked_lightglue.py compares
    // such an image with the specification)
    let a = common::graffiti("graf1.png");
    let (w, h) = (701, 601);
    let data: Vec<f32> = (0..h)
        .flat_map(|y| a.data()[y * a.width()..y * a.width() + w].to_vec())
        .collect();
    let part = GrayImage::new(w, h, data).unwrap();
    let f = m.extract(&part, None).unwrap();
    assert_eq!(f.image_size, (w, h));
    assert_eq!(f.len(), TOP_K);
    for p in f.keypoints() {
        assert!(p[0] >= 0.0 && p[0] <= (w - 1) as f32 && p[1] >= 0.0 && p[1] <= (h - 1) as f32);
    }
    // an image smaller than the NMS window's border: no keypoint, no error
    let tiny = GrayImage::new(4, 3, vec![0.5; 12]).unwrap();
    assert!(m.extract(&tiny, None).unwrap().is_empty());
}

#[test]
fn a_missing_descriptor_head_or_piece_is_named_with_the_export_command() {
    let Some(_) = matcher() else { return };
    let dir = common::temp_dir("aliked");
    let models = affcorr_devtools::models_dir();
    std::fs::copy(
        models.join("aliked_backbone.onnx"),
        dir.join("aliked_backbone.onnx"),
    )
    .unwrap();
    let e = PointMatcher::load(Matcher::AlikedLightGlue, &files(&dir), Some(16), 0, 1).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, RunnerError::ModelOpen { .. }), "{msg}");
    assert!(
        msg.contains(SDDH_FILE) && msg.contains(EXPORT_COMMAND),
        "{msg}"
    );
    std::fs::copy(models.join(SDDH_FILE), dir.join(SDDH_FILE)).unwrap();
    let e = PointMatcher::load(Matcher::AlikedLightGlue, &files(&dir), Some(16), 0, 1).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("aliked_lightglue_encode.onnx"), "{msg}");
    assert!(
        msg.contains(EXPORT_COMMAND) && msg.contains("ALIKED"),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_missing_backbone_is_named_with_the_export_command() {
    common::init();
    let dir = common::temp_dir("aliked-none");
    let e = PointMatcher::load(Matcher::AlikedLightGlue, &files(&dir), Some(16), 0, 1).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("aliked_backbone.onnx") && msg.contains(EXPORT_COMMAND),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
