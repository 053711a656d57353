//! Shared by the pipeline's integration tests.
#![allow(dead_code, unused_imports)]

pub use affcorr_devtools::{graffiti_homography, models_dir, ort_library, repo_root as root};

/// The bundled shape network.
pub fn bundled_model() -> std::path::PathBuf {
    models_dir().join("shape.onnx")
}

/// Initialises ONNX Runtime for this test binary.
pub fn init() {
    affcorr_pipeline::init_ort(Some(&ort_library())).expect("ONNX Runtime loads");
}

/// The graffiti test pipeline: XFeat + LighterGlue at 1024 keypoints, 2 threads, the view
/// cascade in `views` mode, guided re-matching when `guided`.
pub fn graffiti_pipeline(
    views: affcorr_pipeline::ViewMode,
    guided: bool,
) -> affcorr_pipeline::Pipeline {
    matcher_pipeline(affcorr_pipeline::Matcher::XFeatLighterGlue, views, guided)
}

/// [`graffiti_pipeline`] with `matcher` (its models from the models directory).
pub fn matcher_pipeline(
    matcher: affcorr_pipeline::Matcher,
    views: affcorr_pipeline::ViewMode,
    guided: bool,
) -> affcorr_pipeline::Pipeline {
    matcher_builder(matcher, views, guided).build().unwrap()
}

/// The builder of [`matcher_pipeline`], for a test that changes one more option.
pub fn matcher_builder(
    matcher: affcorr_pipeline::Matcher,
    views: affcorr_pipeline::ViewMode,
    guided: bool,
) -> affcorr_pipeline::PipelineBuilder {
    init();
    affcorr_pipeline::Pipeline::builder()
        .matcher(matcher)
        .max_keypoints(1024)
        .models_dir(models_dir())
        .threads(2)
        .views(affcorr_pipeline::ViewOptions {
            mode: views,
            ..Default::default()
        })
        .guided_matching(guided.then(affcorr_pipeline::GrowOptions::default))
}

/// |H(x1) − x2| and ‖A − A_gt‖_F of an AC row against the plane-induced AC of `h` at x1
/// (`affcorr_geom::homography::ac_from_homography`: x2 = H(x1), A_gt = ∂H(x)/∂x).
pub fn plane_errors(h: &affcorr_geom::Mat3, row: &[f64; 8]) -> (f64, f64) {
    let gt = affcorr_geom::homography::ac_from_homography(
        h,
        &affcorr_geom::Vec2::new(row[0], row[1]),
        0,
    )
    .expect("x1 is not on the vanishing line");
    let ac = affcorr_geom::AffineCorrespondence::from_row(row);
    ((ac.x2 - gt.x2).norm(), (ac.a - gt.a).norm())
}
