//! Bad-input battery of the public Rust API, through the facade (docs/reliability.md).
//!
//! Every case asserts the typed error variant *and* what its message names, or the documented
//! sane behaviour (a solver's 0 models, an estimator's `NoModel`). Cases that need ONNX Runtime
//! run when `ORT_DYLIB_PATH` or the checkout's `.venv` provides the library, and say so when
//! skipped; the ORT library itself (missing, not ONNX Runtime) is tested in `bad_input_ort.rs`,
//! a binary that never loads a working library.

use std::path::PathBuf;

use affcorr::geom::affine::{
    AffineShape, decompose, decompose_affine, laf_to_affine, synthesize_affine,
};
use affcorr::geom::camera::{Intrinsics, normalize_correspondences};
use affcorr::geom::epipolar::pose_from_essential;
use affcorr::geom::homography::correspondences_from_homography;
use affcorr::geom::sampson::sampson_point_batch;
use affcorr::geom::{AffineCorrespondence, GeomError, Mat2, Mat3, Vec2, Vec3};
use affcorr::image::{GrayImage, ImageError, PixelData, extract_patches};
use affcorr::ransac::{
    Correspondences, EstimatorOptions, RansacError, SampleKind, SamplerKind, estimate_fundamental,
    estimate_homography, estimate_homography_batch, estimate_relative_pose,
};
use affcorr::runner::{RunnerError, ShapeEstimator, ShapeModelOptions};
use affcorr::solvers::essential::essential_2ac;
use affcorr::solvers::fundamental::{fundamental_3ac, fundamental_7pt, fundamental_8pt};
use affcorr::solvers::homography::{homography_2ac, homography_4pt, homography_lsq};
use affcorr::{Pipeline, PipelineError};

// --- data ---------------------------------------------------------------------------------------

fn h_true() -> Mat3 {
    Mat3::new(1.1, 0.05, 12.0, -0.02, 0.95, -7.0, 2e-4, -1e-4, 1.0)
}

/// Exact ACs of `h_true` at `n` scattered pixels.
fn ac_rows(n: usize) -> Vec<[f64; 8]> {
    let x1: Vec<[f64; 2]> = (0..n)
        .map(|i| {
            let t = i as f64;
            [(t * 97.3 + t * t * 31.1) % 640.0, (t * 61.7 + 13.0) % 480.0]
        })
        .collect();
    let mut out = vec![[0.0; 8]; n];
    correspondences_from_homography(&h_true(), &x1, &mut out).unwrap();
    out
}

fn acs(rows: &[[f64; 8]]) -> Vec<AffineCorrespondence> {
    rows.iter().map(AffineCorrespondence::from_row).collect()
}

fn points(rows: &[[f64; 8]]) -> (Vec<Vec2>, Vec<Vec2>) {
    rows.iter()
        .map(|r| (Vec2::new(r[0], r[1]), Vec2::new(r[2], r[3])))
        .unzip()
}

fn k() -> Intrinsics {
    Intrinsics::from_focal(500.0, 520.0, 320.0, 240.0).unwrap()
}

/// `f` must fail with an error whose message contains every fragment.
fn message<T: std::fmt::Debug, E: std::fmt::Display>(r: Result<T, E>, fragments: &[&str]) {
    let msg = match r {
        Ok(v) => panic!("expected an error, got {v:?}"),
        Err(e) => e.to_string(),
    };
    for f in fragments {
        assert!(msg.contains(f), "{msg:?} lacks {f:?}");
    }
}

// --- geometry -----------------------------------------------------------------------------------

#[test]
fn geometry_rejects_nan_shapes_and_determinants_by_name() {
    let mut out = vec![[0.0; 4]; 2];
    let r = synthesize_affine(&[0.0, f64::NAN], &[1.0, 1.0], &[[0.0; 3]; 2], &mut out);
    assert!(
        matches!(
            r,
            Err(GeomError::NonFinite {
                what: "orientation",
                index: 1
            })
        ),
        "{r:?}"
    );
    let r = synthesize_affine(&[0.0], &[1.0], &[[0.0, 0.0, f64::NAN]], &mut out[..1]);
    assert!(
        matches!(
            r,
            Err(GeomError::NonFinite {
                what: "residual_shape",
                index: 0
            })
        ),
        "{r:?}"
    );
    let r = synthesize_affine(&[0.0], &[0.0], &[[0.0; 3]], &mut out[..1]);
    assert!(
        matches!(r, Err(GeomError::NotPositive { what: "scale", .. })),
        "{r:?}"
    );
    let r = synthesize_affine(&[0.0, 1.0], &[1.0], &[[0.0; 3]; 2], &mut out);
    assert!(
        matches!(r, Err(GeomError::LengthMismatch { what: "scale", .. })),
        "{r:?}"
    );

    // det A <= 0: reflection and singular maps.
    for a in [
        Mat2::new(1.0, 0.0, 0.0, -1.0),
        Mat2::new(1.0, 1.0, 1.0, 1.0),
    ] {
        let r = decompose(&a, 3);
        assert!(
            matches!(r, Err(GeomError::NonPositiveDeterminant { index: 3, .. })),
            "{r:?}"
        );
    }
    let blank = AffineShape {
        orientation: 0.0,
        scale: 0.0,
        residual_shape: [0.0; 3],
    };
    let r = decompose_affine(
        &[[1.0, 0.0, 0.0, 1.0], [f64::INFINITY, 0.0, 0.0, 1.0]],
        &mut [blank; 2],
    );
    message(r, &["A[1]", "NaN or infinity"]);
}

#[test]
fn invalid_intrinsics_are_named() {
    let cases = [
        (Mat3::zeros(), "K[2,2] must be positive"),
        (
            Mat3::new(0.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0),
            "focal lengths",
        ),
        (
            Mat3::new(500.0, 0.0, 320.0, 0.0, -5.0, 240.0, 0.0, 0.0, 1.0),
            "focal lengths",
        ),
        (
            Mat3::new(500.0, 0.0, 320.0, 1.0, 500.0, 240.0, 0.0, 0.0, 1.0),
            "upper triangular",
        ),
        (Mat3::from_element(f64::NAN), "NaN or infinity"),
        // Positive but so small that K⁻¹ overflows: numerically singular.
        (
            Mat3::new(1e-200, 0.0, 0.0, 0.0, 1e-200, 0.0, 0.0, 0.0, 1.0),
            "numerically singular",
        ),
    ];
    for (m, fragment) in cases {
        let r = Intrinsics::new(m, "K2");
        assert!(
            matches!(r, Err(GeomError::InvalidIntrinsics { what: "K2", .. })),
            "{r:?}"
        );
        message(r, &["K2", fragment]);
    }
}

#[test]
fn batched_geometry_names_the_bad_row() {
    let mut rows = ac_rows(5);
    rows[3][2] = f64::NAN;
    let mut out = vec![[0.0; 8]; 5];
    message(
        normalize_correspondences(&rows, &k(), &k(), &mut out),
        &["corrs[3]", "NaN"],
    );
    let mut d = vec![0.0; 5];
    message(
        sampson_point_batch(&Mat3::identity(), &rows, &mut d),
        &["corrs[3]", "NaN"],
    );
    let per_row = vec![[0.0; 9]; 4];
    message(
        sampson_point_batch(&per_row, &ac_rows(5), &mut d),
        &["F", "expected 5 rows, got 4"],
    );

    // A point that H sends to infinity.
    let h = Mat3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let r = correspondences_from_homography(&h, &[[0.0, 5.0]], &mut out[..1]);
    assert!(
        matches!(r, Err(GeomError::PointAtInfinity { index: 0, .. })),
        "{r:?}"
    );

    // LAF centres are checked like the frames (a NaN centre used to pass through).
    let good = [[1.0, 0.0, 5.0, 0.0, 1.0, 6.0]; 2];
    let mut bad = good;
    bad[1][2] = f64::NAN;
    let r = laf_to_affine(&good, &bad, &mut out[..2]);
    assert!(
        matches!(
            r,
            Err(GeomError::NonFinite {
                what: "laf2",
                index: 1
            })
        ),
        "{r:?}"
    );

    // Cheirality counts no NaN point silently.
    let e = affcorr::geom::epipolar::essential_from_pose(&Mat3::identity(), &Vec3::x());
    let x = [Vec2::new(0.0, 0.0), Vec2::new(f64::NAN, 0.0)];
    let r = pose_from_essential(&e, &x[..1], &x[1..]);
    assert!(
        matches!(
            r,
            Err(GeomError::NonFinite {
                what: "x2",
                index: 0
            })
        ),
        "{r:?}"
    );
}

// --- solvers ------------------------------------------------------------------------------------

#[test]
fn solvers_give_no_model_for_degenerate_or_malformed_samples() {
    let rows = ac_rows(8);
    let (x1, x2) = points(&rows);
    let mut out = [Mat3::zeros(); 10];
    // The valid samples work (so the zeros below are not vacuous).
    assert_eq!(homography_4pt(&x1[..4], &x2[..4], &mut out), 1);
    assert_eq!(homography_2ac(&acs(&rows[..2]), &mut out), 1);

    // Wrong sample sizes, including N below the minimal sample.
    assert_eq!(homography_4pt(&x1[..3], &x2[..3], &mut out), 0);
    assert_eq!(homography_4pt(&x1[..4], &x2[..3], &mut out), 0);
    assert_eq!(fundamental_7pt(&x1[..6], &x2[..6], &mut out), 0);
    assert_eq!(fundamental_8pt(&x1[..7], &x2[..7], &mut out), 0);
    assert_eq!(homography_lsq(&[], &[], &mut out), 0);
    assert_eq!(fundamental_3ac(&acs(&rows[..2]), &mut out), 0);
    assert_eq!(essential_2ac(&acs(&rows[..1]), &mut out), 0);

    // NaN and infinity.
    let mut nan = x1.clone();
    nan[2].x = f64::NAN;
    assert_eq!(homography_4pt(&nan[..4], &x2[..4], &mut out), 0);
    let mut inf = acs(&rows[..2]);
    inf[1].a[(0, 1)] = f64::INFINITY;
    assert_eq!(homography_2ac(&inf, &mut out), 0);

    // Duplicate and collinear points.
    let dup = vec![x1[0]; 8];
    assert_eq!(homography_4pt(&dup[..4], &x2[..4], &mut out), 0);
    assert_eq!(fundamental_8pt(&dup, &dup, &mut out), 0);
    let line: Vec<Vec2> = (0..8)
        .map(|i| Vec2::new(10.0 * i as f64, 5.0 * i as f64))
        .collect();
    assert_eq!(homography_4pt(&line[..4], &x2[..4], &mut out), 0);

    // det A <= 0.
    let mut reflected = acs(&rows[..3]);
    for ac in &mut reflected {
        ac.a = Mat2::new(1.0, 0.0, 0.0, -1.0);
    }
    assert_eq!(homography_2ac(&reflected[..2], &mut out), 0);
    assert_eq!(fundamental_3ac(&reflected, &mut out), 0);
    assert_eq!(essential_2ac(&reflected[..2], &mut out), 0);
    // A singular pixel A, normalised (K⁻¹ A K): its det is rounding noise (+7e-16 here), still
    // no model (the solver used to accept it and return up to 10).
    let singular: Vec<[f64; 8]> = rows
        .iter()
        .map(|r| [r[0], r[1], r[2], r[3], 1.0, 2.0, 2.0, 4.0])
        .collect();
    let k2 = Intrinsics::from_focal(610.0, 590.0, 300.0, 250.0).unwrap();
    let mut normalised = vec![[0.0; 8]; 8];
    normalize_correspondences(&singular, &k(), &k2, &mut normalised).unwrap();
    let n = acs(&normalised);
    for pair in n.windows(2) {
        assert_eq!(essential_2ac(pair, &mut out), 0);
    }
}

/// A caller-owned buffer shorter than `*_MAX_SOLUTIONS` is a programming error (documented in
/// the solvers' module docs), not bad data: it panics with a message.
#[test]
#[should_panic(expected = "out too short")]
fn a_too_short_solution_buffer_is_a_documented_panic() {
    let (x1, x2) = points(&ac_rows(7));
    fundamental_7pt(&x1, &x2, &mut [Mat3::zeros(); 1]);
}

// --- robust estimation --------------------------------------------------------------------------

fn opts() -> EstimatorOptions {
    let mut o = EstimatorOptions::default();
    o.ransac.max_iterations = 200;
    o
}

#[test]
fn estimators_reject_bad_data_and_options_with_typed_errors() {
    let rows = ac_rows(30);
    let data = Correspondences::from_ac_rows(&rows).unwrap();
    assert!(estimate_homography(&data, &opts()).is_ok());

    let mut nan = rows.clone();
    nan[29][7] = f64::NAN;
    let r = Correspondences::from_ac_rows(&nan);
    assert!(
        matches!(
            r,
            Err(RansacError::NonFinite {
                what: "corrs",
                index: 29
            })
        ),
        "{r:?}"
    );

    // N below the sample size (and empty).
    let few = Correspondences::from_ac_rows(&rows[..2]).unwrap();
    let r = estimate_fundamental(&few, &opts());
    assert!(
        matches!(
            r,
            Err(RansacError::NotEnoughData {
                needed: 3,
                got: 2,
                ..
            })
        ),
        "{r:?}"
    );
    let r = estimate_homography(&Correspondences::default(), &opts());
    assert!(
        matches!(r, Err(RansacError::NotEnoughData { got: 0, .. })),
        "{r:?}"
    );

    for threshold in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut o = opts();
        o.ransac.threshold = threshold;
        let r = estimate_homography(&data, &o);
        assert!(
            matches!(
                r,
                Err(RansacError::InvalidOption {
                    name: "threshold",
                    ..
                })
            ),
            "{r:?}"
        );
    }
    let mut o = opts();
    o.ransac.confidence = 1.0;
    message(estimate_homography(&data, &o), &["confidence", "(0, 1)"]);
    let mut o = opts();
    o.sampler = SamplerKind::Prosac;
    message(estimate_homography(&data, &o), &["quality", "PROSAC"]);
    o.quality = Some(vec![1.0; 29]);
    message(estimate_homography(&data, &o), &["quality", "29 values"]);
    o.quality = Some(
        (0..30)
            .map(|i| if i == 4 { f64::NAN } else { 1.0 })
            .collect(),
    );
    message(estimate_homography(&data, &o), &["quality", "finite"]);
    let mut o = opts();
    o.sample = Some(SampleKind::Affine);
    let pts = Correspondences::from_ac_rows(&rows).unwrap().points_only();
    message(estimate_homography(&pts, &o), &["sample", "(N, 8)"]);

    // A per-pair option list of the wrong length fails every pair.
    let per_pair = vec![opts(); 3];
    let out = estimate_homography_batch(&[data.clone(), data.clone()], &per_pair);
    assert!(out.iter().all(|r| matches!(
        r,
        Err(RansacError::InvalidOption {
            name: "options",
            ..
        })
    )));
}

#[test]
fn hand_built_correspondences_are_validated_too() {
    // The fields are public: inconsistent lengths or NaN must be errors, not panics.
    let data = Correspondences::from_ac_rows(&ac_rows(30)).unwrap();
    let mut short = data.clone();
    short.x2.pop();
    message(
        estimate_homography(&short, &opts()),
        &["corrs", "x2 has 29"],
    );
    let mut partial_a = data.clone();
    partial_a.a.truncate(10);
    message(
        estimate_relative_pose(&partial_a, &k(), &k(), &opts()),
        &["corrs", "a has 10"],
    );
    let mut nan = data.clone();
    nan.x1[7].y = f64::NAN;
    let r = estimate_fundamental(&nan, &opts());
    assert!(
        matches!(
            r,
            Err(RansacError::NonFinite {
                what: "corrs",
                index: 7
            })
        ),
        "{r:?}"
    );
}

#[test]
fn degenerate_data_finds_no_model_without_panicking() {
    let rows = ac_rows(30);
    let dup = vec![rows[0]; 30];
    let data = Correspondences::from_ac_rows(&dup).unwrap();
    let r = estimate_homography(&data, &opts());
    assert!(
        matches!(r, Err(RansacError::NoModel { iterations: 200 })),
        "{r:?}"
    );
    let reflected: Vec<[f64; 8]> = rows
        .iter()
        .map(|r| [r[0], r[1], r[2], r[3], 1.0, 0.0, 0.0, -1.0])
        .collect();
    let data = Correspondences::from_ac_rows(&reflected).unwrap();
    for r in [
        estimate_homography(&data, &opts()).map(|_| ()),
        estimate_fundamental(&data, &opts()).map(|_| ()),
        estimate_relative_pose(&data, &k(), &k(), &opts()).map(|_| ()),
    ] {
        assert!(matches!(r, Err(RansacError::NoModel { .. })), "{r:?}");
    }
}

// --- images -------------------------------------------------------------------------------------

/// A PNG whose header claims `w`×`h` (bit depth, colour type) over a few bytes of pixel data.
fn png_header(w: u32, h: u32, depth: u8, colour: u8) -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let start = out.len();
        out.extend(kind);
        out.extend(data);
        out.extend(crc32fast::hash(&out[start..]).to_be_bytes());
    }
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([depth, colour, 0, 0, 0]);
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    chunk(&mut out, b"IHDR", &ihdr);
    // A stored (uncompressed) zlib stream of 4 zero bytes.
    chunk(
        &mut out,
        b"IDAT",
        &[
            0x78, 0x01, 0x01, 0x04, 0x00, 0xfb, 0xff, 0, 0, 0, 0, 0, 0, 0, 1,
        ],
    );
    chunk(&mut out, b"IEND", &[]);
    out
}

#[test]
fn bad_images_are_decode_errors_not_aborts() {
    let cases: [(u32, u32, u8, u8, &str); 5] = [
        // Decoding would need more than the decoder's 512 MiB limit: refused before allocating.
        (
            20_000,
            20_000,
            8,
            2,
            "Memory limit exceeded: the image is 20000×20000 pixels",
        ),
        (
            100_000,
            100_000,
            16,
            6,
            "100000×100000 pixels, over the decoder's 512 MiB limit",
        ),
        // Within the limit, but the data stops short.
        (20_000, 20_000, 8, 0, "not have enough data"),
        (0, 10, 8, 0, "Invalid image dimensions"),
        (10, 0, 8, 0, "Invalid image dimensions"),
    ];
    for (w, h, depth, colour, fragment) in cases {
        let r = GrayImage::decode(&png_header(w, h, depth, colour));
        assert!(
            matches!(r, Err(ImageError::Decode { .. })),
            "{w}x{h}: {r:?}"
        );
        message(r, &["from memory", fragment]);
    }
    // Zero-sized and inconsistent raw buffers.
    message(GrayImage::from_raw(0, 3, 1, PixelData::U8(&[])), &["empty"]);
    message(
        GrayImage::from_raw(4, 3, 4, PixelData::U16(&[0; 47])),
        &["expected 48"],
    );
    message(
        GrayImage::from_raw(1, 1, 1, PixelData::F32(&[f32::NAN])),
        &["NaN"],
    );
}

#[test]
fn patch_centres_must_be_finite() {
    let img = GrayImage::new(8, 8, vec![0.5; 64]).unwrap();
    let r = extract_patches(&img, &[[1.0, 2.0], [f64::NEG_INFINITY, 0.0]]);
    assert!(
        matches!(r, Err(ImageError::NonFinite { row: 1, .. })),
        "{r:?}"
    );
    // Far outside the image is fine: edges are replicated.
    let p = extract_patches(&img, &[[-1e6, 1e9]]).unwrap();
    assert!(p.as_slice().iter().all(|&v| v == 0.5));
}

// --- models (need ONNX Runtime) -----------------------------------------------------------------

fn root() -> PathBuf {
    affcorr_devtools::repo_root()
}

/// Loads ONNX Runtime for the model tests, or says why they are skipped.
fn ort() -> bool {
    match affcorr_devtools::locate_ort_library(&root()) {
        Some(lib) => affcorr::runner::init_ort(Some(&lib)).is_ok(),
        None => {
            eprintln!("skipped: no ONNX Runtime library (set ORT_DYLIB_PATH)");
            false
        }
    }
}

#[test]
fn missing_corrupt_and_wrong_contract_models_are_typed_errors() {
    if !ort() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let o = ShapeModelOptions {
        threads: Some(1),
        ..Default::default()
    };
    let missing = dir.path().join("missing.onnx");
    let r = ShapeEstimator::load(&missing, &o);
    assert!(matches!(r, Err(RunnerError::ModelOpen { .. })), "{r:?}");
    message(r, &["missing.onnx"]);
    let r = ShapeEstimator::load(dir.path(), &o);
    assert!(matches!(r, Err(RunnerError::ModelOpen { .. })), "{r:?}");
    for (name, bytes) in [
        ("empty.onnx", &b""[..]),
        ("junk.onnx", &b"\x08\x07junk"[..]),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let r = ShapeEstimator::load(&p, &o);
        assert!(
            matches!(
                r,
                Err(RunnerError::ModelLoad { .. } | RunnerError::Contract { .. })
            ),
            "{r:?}"
        );
        message(r, &[name]);
    }
    let wrong = root().join("tests/data/shape/wrong_contract.onnx");
    let r = ShapeEstimator::load(&wrong, &o);
    assert!(
        matches!(
            r,
            Err(RunnerError::Contract {
                contract: "shape-v1",
                ..
            })
        ),
        "{r:?}"
    );

    let echo = ShapeEstimator::load(root().join("tests/data/shape/echo.onnx"), &o).unwrap();
    let img = GrayImage::new(40, 30, vec![0.25; 1200]).unwrap();
    let r = echo.estimate(&img, &img, &[[1.0, 1.0]; 3], &[[1.0, 1.0]; 2]);
    message(r, &["x2", "2 points, but x1 has 3"]);
    let r = echo.estimate(&img, &img, &[[1.0, f64::NAN]], &[[1.0, 1.0]]);
    assert!(
        matches!(
            r,
            Err(RunnerError::Image(ImageError::NonFinite {
                what: "x1",
                row: 0
            }))
        ),
        "{r:?}"
    );
    // No matches: no ACs.
    assert!(
        echo.estimate(&img, &img, &[], &[])
            .unwrap()
            .corrs
            .is_empty()
    );
}

#[test]
fn pipeline_builder_names_what_is_missing_or_invalid() {
    // Argument checks come before any model is loaded.
    let r = Pipeline::builder().max_keypoints(0).build();
    message(r, &["max_keypoints", "at least 1"]);
    let r = Pipeline::builder().max_side(16).build();
    message(r, &["max_side", "minimum of 32"]);
    if !ort() {
        return;
    }
    let r = Pipeline::builder().threads(1).build();
    assert!(
        matches!(
            r,
            Err(PipelineError::InvalidInput {
                what: "backbone_model",
                ..
            })
        ),
        "{r:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    let r = Pipeline::builder()
        .models_dir(dir.path())
        .threads(1)
        .build();
    assert!(
        matches!(r, Err(PipelineError::Runner(RunnerError::ModelOpen { .. }))),
        "{r:?}"
    );
    message(r, &["xfeat_backbone.onnx"]);
    // Images are checked per pair: a missing file names itself.
    let models = root().join("python/affcorr/models");
    if models.join("xfeat_backbone.onnx").is_file() {
        let p = Pipeline::builder()
            .models_dir(&models)
            .threads(1)
            .max_keypoints(64)
            .build()
            .unwrap();
        let r = p.match_pair("nope.png", "nope.png");
        message(r, &["nope.png"]);
        // Over 64 MP at the working resolution: an error naming max_side, not an OOM abort.
        let huge = GrayImage::new(8200, 8200, vec![0.5; 8200 * 8200]).unwrap();
        let small = GrayImage::new(64, 64, vec![0.5; 64 * 64]).unwrap();
        let r = p.match_pair(&small, &huge);
        assert!(
            matches!(
                r,
                Err(PipelineError::InvalidInput {
                    what: "image_b",
                    ..
                })
            ),
            "{r:?}"
        );
        message(r, &["8200×8200", "max_side"]);
    }
}
