//! The per-image feature cache: [`Pipeline::extract`] + [`Pipeline::match_features`] (and
//! `match_pairs`, which reuses the features of shared images) give `match_pair`'s results bit
//! for bit, for every XFeat matcher and with the view cascade on.

mod common;

use affcorr_pipeline::{Features, Matcher, Matches, Pipeline, ViewMode, ViewOptions};

fn pipeline(matcher: Matcher, views: ViewMode, threads: usize) -> Pipeline {
    common::init();
    Pipeline::builder()
        .matcher(matcher)
        .models_dir(common::models_dir())
        .max_keypoints(128)
        .max_side(192)
        .views(ViewOptions {
            mode: views,
            max_views: 1,
            ..Default::default()
        })
        .threads(threads)
        .build()
        .unwrap()
}

/// Equal in everything but wall times.
fn assert_same(a: &Matches, b: &Matches) {
    assert_eq!(a.corrs, b.corrs);
    assert_eq!(a.certainty, b.certainty);
    assert_eq!(a.num_keypoints, b.num_keypoints);
    assert_eq!(a.views.len(), b.views.len());
    for (u, v) in a.views.iter().zip(&b.views) {
        assert_eq!(
            (&u.view, u.matches, u.inliers, u.verified),
            (&v.view, v.matches, v.inliers, v.verified)
        );
    }
}

#[test]
fn features_match_like_match_pair_bit_for_bit() {
    let dir = common::root().join("data/graffiti");
    let (a, b) = (dir.join("graf1.png"), dir.join("graf3.png"));
    for (matcher, views) in [
        (Matcher::XFeatMnn, ViewMode::Full),
        (Matcher::XFeatLighterGlue, ViewMode::Off),
        (Matcher::XFeatStar, ViewMode::Off),
    ] {
        let p = pipeline(matcher, views, 2);
        let direct = p.match_pair(&a, &b).unwrap();
        assert!(direct.corrs.len() > 10, "{matcher}: {}", direct.corrs.len());
        let (fa, fb) = (p.extract(&a).unwrap(), p.extract(&b).unwrap());
        assert_eq!(fa.matcher(), matcher);
        assert_eq!(fa.image_size(), (800, 640));
        assert_eq!(fa.working_size(), (192, 154));
        assert!(fa.len() > 30 && fa.len() <= 128 * 2, "{}", fa.len());
        assert_same(&p.match_features(&fa, &fb).unwrap(), &direct);
        // Twice, and after a round trip through bytes (the batch's disk cache).
        assert_same(&p.match_features(&fa, &fb).unwrap(), &direct);
        let (ra, rb) = (
            Features::from_bytes(&fa.to_bytes()).unwrap(),
            Features::from_bytes(&fb.to_bytes()).unwrap(),
        );
        assert_eq!(
            (&ra.keypoints(), ra.descriptors()),
            (&fa.keypoints(), fa.descriptors())
        );
        assert_same(&p.match_features(&ra, &rb).unwrap(), &direct);
        // Without views every x1 is a keypoint of A (the matcher's points; the affine
        // refinement moves x2 only): how the batch's hloc output indexes the matches.
        if matcher == Matcher::XFeatLighterGlue {
            let kp = fa.keypoints();
            for c in &direct.corrs {
                assert!(
                    kp.contains(&[c[0], c[1]]),
                    "{matcher}: x1 {c:?} is no keypoint"
                );
            }
        }
    }
}

#[test]
fn features_of_another_configuration_are_refused() {
    let dir = common::root().join("data/graffiti");
    let p = pipeline(Matcher::XFeatMnn, ViewMode::Off, 1);
    let f = p.extract(dir.join("graf1.png").as_path()).unwrap();
    let q = pipeline(Matcher::XFeatLighterGlue, ViewMode::Off, 1);
    let e = q.match_features(&f, &f).unwrap_err().to_string();
    assert!(
        e.starts_with("features_a: extracted with matcher xfeat"),
        "{e}"
    );
    let e = Features::from_bytes(b"nonsense").unwrap_err().to_string();
    assert!(e.starts_with("data:"), "{e}");
    let e = p.extract("/nonexistent.png").unwrap_err().to_string();
    assert!(e.contains("nonexistent"), "{e}");
}

#[test]
fn a_detection_threshold_keeps_fewer_keypoints_and_its_features_apart() {
    let dir = common::root().join("data/graffiti");
    let image = dir.join("graf1.png");
    let p = pipeline(Matcher::XFeatMnn, ViewMode::Off, 1);
    // XFeat's metadata: 0.05 on its heatmap (probabilities); the budget of 128 is full.
    assert_eq!(p.detection_threshold(), Some(0.05));
    let all = p.extract(image.as_path()).unwrap();
    assert_eq!(all.len(), 128);
    let with = |threshold: f32| {
        common::init();
        Pipeline::builder()
            .matcher(Matcher::XFeatMnn)
            .models_dir(common::models_dir())
            .max_keypoints(128)
            .max_side(192)
            .detection_threshold(threshold)
            .threads(1)
            .build()
    };
    let strict = with(0.5).unwrap();
    assert_eq!(strict.detection_threshold(), Some(0.5));
    let few = strict.extract(image.as_path()).unwrap();
    assert!(
        !few.is_empty() && few.len() < all.len(),
        "{} keypoints",
        few.len()
    );
    let e = strict.match_features(&all, &all).unwrap_err().to_string();
    assert!(e.contains("detection_threshold Some(0.05)"), "{e}");
    let e = with(f32::NAN).unwrap_err().to_string();
    assert!(
        e.starts_with("detection_threshold: must be a finite number"),
        "{e}"
    );
    let e = Pipeline::builder()
        .matcher(Matcher::XFeatStar)
        .models_dir(common::models_dir())
        .detection_threshold(0.1)
        .build()
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("detection_threshold: the xfeat-star matcher"),
        "{e}"
    );
    assert_eq!(
        pipeline(Matcher::XFeatStar, ViewMode::Off, 1).detection_threshold(),
        None
    );
}

#[test]
fn match_pairs_reuses_shared_images_with_match_pair_results() {
    let dir = common::root().join("data/graffiti");
    let (a, b) = (dir.join("graf1.png"), dir.join("graf3.png"));
    let missing = dir.join("missing.png");
    let pairs = [
        (a.as_path(), b.as_path()),
        (b.as_path(), a.as_path()),
        (a.as_path(), a.as_path()),
        (a.as_path(), missing.as_path()),
        (b.as_path(), b.as_path()),
    ];
    let serial = pipeline(Matcher::XFeatMnn, ViewMode::Auto, 1);
    let want: Vec<_> = pairs
        .iter()
        .map(|&(x, y)| serial.match_pair(x, y))
        .collect();
    for threads in [1, 2] {
        let p = pipeline(Matcher::XFeatMnn, ViewMode::Auto, threads);
        let batch = p.match_pairs(pairs);
        for (w, r) in want.iter().zip(&batch) {
            match (w, r) {
                (Ok(w), Ok(got)) => assert_same(got, w),
                (Err(w), Err(got)) => assert_eq!(got.to_string(), w.to_string()),
                (want, got) => panic!("{threads} threads: {want:?} vs {got:?}"),
            }
        }
    }
}
