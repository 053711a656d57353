//! EXIF orientation: image files are matched as their orientation tag shows them (upright), and
//! every coordinate comes back in their stored pixels.
//!
//! Graffiti 3 is stored turned a quarter turn counter-clockwise and tagged "turn 90° clockwise
//! to show" (EXIF 6), as a camera held in portrait stores it. Shown, it is graffiti 3 again, so
//! the plain pass solves the pair; its ACs are checked against the plane-induced ACs of the
//! homography into the *stored* pixels.

mod common;

use std::path::{Path, PathBuf};

use affcorr_devtools::with_exif_orientation;
use affcorr_geom::Mat3;
use affcorr_image::{GrayImage, Orientation};
use affcorr_pipeline::{Features, Geometry, Pipeline, ViewSpec};

/// graf1.png, and graf3.png stored so that the turn of `tag` shows it as it is (turned back,
/// with `tag`'s EXIF value written in its eXIf chunk), in `dir`; the homography from graf1
/// into the stored pixels.
fn tagged_graffiti(dir: &Path, tag: Orientation) -> (PathBuf, PathBuf, Mat3) {
    let src = common::root().join("data/graffiti");
    let mut img = image::open(src.join("graf3.png")).unwrap();
    // The pipeline turns a file by its tag's turn (the mirror is not applied).
    let turn = tag.turn();
    let back = match turn {
        Orientation::Rotate90 => Orientation::Rotate270,
        Orientation::Rotate270 => Orientation::Rotate90,
        o => o,
    };
    back.apply(&mut img);
    let stored = (img.width() as usize, img.height() as usize);
    let mut png = std::io::Cursor::new(Vec::new());
    img.to_luma8()
        .write_to(&mut png, image::ImageFormat::Png)
        .unwrap();
    let b = dir.join(format!("graf3-exif{}.png", tag.exif()));
    std::fs::write(
        &b,
        with_exif_orientation(png.get_ref(), u16::from(tag.exif())),
    )
    .unwrap();
    // x_upright = W x_stored, so the homography into the stored pixels is W⁻¹ H.
    let (w, ..) = turn.display_warp(stored.0, stored.1);
    let w = Mat3::new(
        w.m[0], w.m[1], w.c[0], w.m[2], w.m[3], w.c[1], 0.0, 0.0, 1.0,
    );
    let h = Mat3::from_row_slice(&common::graffiti_homography());
    (src.join("graf1.png"), b, w.try_inverse().unwrap() * h)
}

/// [`tagged_graffiti`] of a camera held in portrait (EXIF 6: graf3 stored 640 × 800).
fn portrait_graffiti(dir: &Path) -> (PathBuf, PathBuf, Mat3) {
    tagged_graffiti(dir, Orientation::Rotate90)
}

/// The stored size of [`portrait_graffiti`]'s image B (800 × 640 shown).
const STORED: (usize, usize) = (640, 800);

fn pipeline(exif: bool) -> Pipeline {
    common::init();
    Pipeline::builder()
        .max_keypoints(1024)
        .models_dir(common::models_dir())
        .threads(2)
        .exif_orientation(exif)
        .build()
        .unwrap()
}

/// Median |H(x1) − x2| and ‖A − A_gt‖_F over the inliers of a homography estimate of the pair.
fn median_plane_errors(p: &Pipeline, a: &Path, b: &Path, gt: &Mat3) -> (f64, f64, usize) {
    let est = p
        .homography(a, b, &Geometry::Homography.default_options())
        .unwrap();
    let (mut dx, mut da): (Vec<f64>, Vec<f64>) = est
        .matches
        .corrs
        .iter()
        .zip(&est.estimate.inliers)
        .filter(|(_, i)| **i)
        .map(|(r, _)| common::plane_errors(gt, r))
        .unzip();
    dx.sort_by(f64::total_cmp);
    da.sort_by(f64::total_cmp);
    (dx[dx.len() / 2], da[da.len() / 2], dx.len())
}

#[test]
fn a_portrait_photo_is_matched_upright_and_reported_in_its_stored_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, gt) = portrait_graffiti(dir.path());
    let p = pipeline(true);
    let fb = p.extract(b.as_path()).unwrap();
    assert_eq!(fb.orientation(), Orientation::Rotate90);
    assert_eq!(fb.image_size(), STORED);
    assert_eq!(fb.working_size(), (STORED.1, STORED.0));
    // Keypoints are reported in the stored pixels: inside the stored 640 × 800 frame, and
    // some beyond the shown frame's 640 rows.
    let k = fb.keypoints();
    assert!(
        k.iter().all(|&[x, y]| x <= 639.5 && y <= 799.5),
        "outside the stored frame"
    );
    assert!(
        k.iter().any(|&[_, y]| y > 640.0),
        "no keypoint below the shown frame's rows"
    );

    // Upright, it is the easy graffiti pair: the plain pass verifies and no view runs.
    let m = p.match_pair(a.as_path(), b.as_path()).unwrap();
    assert_eq!(m.views.len(), 1, "{:?}", m.views);
    assert!(m.views[0].verified && m.views[0].view == ViewSpec::PLAIN);
    let (dx, da, n) = median_plane_errors(&p, &a, &b, &gt);
    eprintln!("EXIF upright: {n} inliers, median |H x1 - x2| {dx:.3} px, ‖A - A_gt‖ {da:.4}");
    assert!(
        n > 100 && dx < 1.0 && da < 0.1,
        "{n} inliers, {dx} px, {da}"
    );

    // The same files without the tag's turn: the coordinates are the same stored pixels, but
    // the matcher meets a quarter turn, which only the view cascade undoes.
    let off = pipeline(false);
    assert_eq!(
        off.extract(b.as_path()).unwrap().orientation(),
        Orientation::Upright
    );
    let m = off.match_pair(a.as_path(), b.as_path()).unwrap();
    assert!(
        m.views.len() > 1,
        "the plain pass verified a quarter turn: {:?}",
        m.views
    );
    let (dx, da, n) = median_plane_errors(&off, &a, &b, &gt);
    eprintln!("as stored, through the cascade: {n} inliers, {dx:.3} px, {da:.4}");
    assert!(dx < 1.0 && da < 0.1, "{n} inliers, {dx} px, {da}");
}

#[test]
fn every_tag_is_turned_upright_unmirrored_and_maps_back_to_the_stored_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let p = pipeline(true);
    for o in Orientation::ALL {
        let (a, b, gt) = tagged_graffiti(dir.path(), o);
        let f = p.extract(b.as_path()).unwrap();
        assert_eq!(f.orientation(), o.turn(), "{o:?}");
        let m = p.match_pair(a.as_path(), b.as_path()).unwrap();
        assert_eq!(m.views.len(), 1, "{o:?}: {:?}", m.views);
        let (dx, da, n) = median_plane_errors(&p, &a, &b, &gt);
        eprintln!("EXIF {}: {n} inliers, {dx:.3} px, {da:.4}", o.exif());
        assert!(
            n > 100 && dx < 1.0 && da < 0.1,
            "{o:?}: {n} inliers, {dx} px, {da}"
        );
    }
}

#[test]
fn arrays_are_taken_as_they_are_and_a_bad_tag_reads_upright() {
    let dir = tempfile::tempdir().unwrap();
    let p = pipeline(true);
    // An array of the stored pixels has no tag: it is matched as it is.
    let (_, b, _) = portrait_graffiti(dir.path());
    let stored = GrayImage::open(&b).unwrap();
    assert_eq!((stored.width(), stored.height()), STORED);
    let f = p.extract(&stored).unwrap();
    assert_eq!(f.orientation(), Orientation::Upright);
    assert_eq!((f.image_size(), f.working_size()), (STORED, STORED));
    // A tag outside 1-8 is no orientation: the file reads as stored.
    let bad = dir.path().join("bad.png");
    let png = std::fs::read(common::root().join("data/graffiti/graf3.png")).unwrap();
    std::fs::write(&bad, with_exif_orientation(&png, 0)).unwrap();
    let f = p.extract(bad.as_path()).unwrap();
    assert_eq!(f.orientation(), Orientation::Upright);
    assert_eq!(f.working_size(), (800, 640));
}

#[test]
fn features_of_a_turned_image_survive_the_cache_and_match_as_the_pair_does() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, _) = portrait_graffiti(dir.path());
    let p = pipeline(true);
    let fa = p.extract(a.as_path()).unwrap();
    let fb = Features::from_bytes(&p.extract(b.as_path()).unwrap().to_bytes()).unwrap();
    assert_eq!(fb.orientation(), Orientation::Rotate90);
    let cached = p.match_features(&fa, &fb).unwrap();
    let direct = p.match_pair(a.as_path(), b.as_path()).unwrap();
    assert_eq!(cached.corrs, direct.corrs);
}
