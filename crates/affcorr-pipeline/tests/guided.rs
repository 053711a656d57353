//! Guided re-matching on graffiti 1→3 (exact H): it keeps every match of the plain pipeline,
//! adds matches, and the added ACs agree with the plane's ground truth, point and A.
//!
//! Bounds, with margin over what this test printed when written (see its stderr: 278 plain
//! matches, 587 grown, 90.5% of them within 3 px of H(x1) against 83.1% of the plain ones,
//! median ‖A − A_gt‖_F 0.027): at least 20% more matches; of the grown ACs, at least the plain
//! matches' share within 3 px (and 85%); median ‖A − A_gt‖_F < 0.05.

mod common;

use affcorr_geom::Mat3;
use affcorr_image::GrayImage;
use affcorr_pipeline::{GrowOptions, Pipeline, ViewMode};

fn pipeline(guided: bool) -> Pipeline {
    common::graffiti_pipeline(ViewMode::Off, guided)
}

#[test]
fn grown_matches_agree_with_the_plane() {
    let dir = common::root().join("data/graffiti");
    let a = GrayImage::open(dir.join("graf1.png")).unwrap();
    let b = GrayImage::open(dir.join("graf3.png")).unwrap();
    let h = Mat3::from_row_slice(&common::graffiti_homography());

    let plain = pipeline(false).match_pair(&a, &b).unwrap();
    let guided = pipeline(true).match_pair(&a, &b).unwrap();
    let n = plain.corrs.len();
    // The plain matches come first, unchanged; the grown ones follow.
    assert_eq!(&guided.corrs[..n], &plain.corrs[..]);
    assert!(guided.timings.guided > std::time::Duration::ZERO);
    let grown = &guided.corrs[n..];
    let (mut point, mut affine): (Vec<f64>, Vec<f64>) =
        grown.iter().map(|r| common::plane_errors(&h, r)).unzip();
    point.sort_by(f64::total_cmp);
    affine.sort_by(f64::total_cmp);
    let within = point.iter().filter(|d| **d < 3.0).count() as f64 / point.len().max(1) as f64;
    let median_a = affine.get(affine.len() / 2).copied().unwrap_or(f64::NAN);
    eprintln!(
        "plain {n} matches, grown {} more; within 3 px {:.3}, median point error {:.3} px, \
         median A error {median_a:.4}, {:?}",
        grown.len(),
        within,
        point.get(point.len() / 2).copied().unwrap_or(f64::NAN),
        guided.timings.guided
    );
    let pct = |v: &[f64], q: f64| v[((v.len() as f64 * q) as usize).min(v.len() - 1)];
    let mut plain_err: Vec<f64> = plain
        .corrs
        .iter()
        .map(|r| common::plane_errors(&h, r).0)
        .collect();
    plain_err.sort_by(f64::total_cmp);
    let plain_within = plain_err.iter().filter(|d| **d < 3.0).count() as f64 / n as f64;
    eprintln!(
        "grown p80/p90/p95 {:.2} {:.2} {:.2}; plain within 3 px {plain_within:.3}, p90 {:.2}",
        pct(&point, 0.8),
        pct(&point, 0.9),
        pct(&point, 0.95),
        pct(&plain_err, 0.9)
    );
    assert!(
        grown.len() as f64 >= 0.2 * n as f64,
        "{} grown of {n}",
        grown.len()
    );
    // At least as precise as the matcher's own matches (and never below 85%).
    assert!(
        within >= plain_within.max(0.85),
        "{within} vs {plain_within}"
    );
    assert!(median_a < 0.05, "{median_a}");
    assert!(guided.reliable[n..].iter().all(|r| *r));
    assert!(
        guided.affine_confidence[n..]
            .iter()
            .all(|c| (0.0..=1.0).contains(c))
    );
}

#[test]
fn bad_guided_options_are_named() {
    common::init();
    let e = Pipeline::builder()
        .models_dir(common::models_dir())
        .guided_matching(Some(GrowOptions {
            radius: -1.0,
            ..Default::default()
        }))
        .build()
        .unwrap_err()
        .to_string();
    assert!(e.contains("radius"), "{e}");
}
