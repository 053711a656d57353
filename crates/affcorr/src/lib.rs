//! affcorr: affine correspondences (ACs) for homography, fundamental-matrix and relative-pose
//! estimation.
//!
//! An AC is a point match `x1 ↔ x2` that also carries the local affine map `A = ∂x2/∂x1`
//! between the two images. Two ACs determine a relative pose where points need five, so robust
//! estimation from ACs needs far fewer iterations. Add only `affcorr` to your `Cargo.toml`; this
//! crate re-exports the workspace's crates as modules.
//!
//! # Modules: which one you need
//!
//! | module | what it is for | feature |
//! |---|---|---|
//! | [`geom`] | the conventions (docs/design.md §2) and everything that is pure geometry: the AC type and the `(N, 8)` layout, `A = s·R(θ)·A′(A″)` synthesis and decomposition, kornia LAFs, ACs a homography induces, normalised coordinates, Sampson distances with gradients, E/F/pose utilities, exact synthetic scenes | always |
//! | [`solvers`] | minimal and non-minimal solvers: H from 4 points / 2 ACs / 1 AC + F, F from 7 points / 8 points / 3 ACs, E from 5 points / 2 ACs / 8 points, relative poses; allocation-free, writing into your buffer | always |
//! | [`ransac`] | robust estimation: [`ransac::estimate_homography`], [`ransac::estimate_fundamental`], [`ransac::estimate_relative_pose`] and their parallel `_batch` forms, with PROSAC, MSAC / MAGSAC++, SPRT, local optimisation and a final refinement; [`ransac::planar_twin`], the other motion of a pose whose inliers lie on one plane | always |
//! | [`image`] | gray and colour images, PNG/JPEG decoding, resizing, 32×32 patches, the affine Lucas–Kanade refinement of ACs | `image` |
//! | [`runner`] | the ONNX networks through ONNX Runtime: the XFeat matchers, dense `dense-warp-v1` matchers (DKM, RoMa exports) and the shape network (images + matches → ACs) | `onnx` |
//! | [`pipeline`] | [`Pipeline`]: two images → matches → ACs → H, F or relative pose, timed per stage, with one set of [`pipeline::defaults`] | `pipeline` |
//!
//! # Cargo features
//!
//! - `pipeline` (default): the end-to-end [`Pipeline`]; implies `onnx`.
//! - `onnx`: the networks ([`runner`]); loads the ONNX Runtime library at run time
//!   (`ORT_DYLIB_PATH`, or the `onnxruntime` Python wheel's); implies `image`.
//! - `image`: images, decoding and patches ([`image`]).
//!
//! Geometry, solvers and robust estimation alone, without ONNX Runtime or image decoding:
//!
//! ```toml
//! [dependencies]
//! affcorr = { version = "0.1", default-features = false }
//! ```
//!
//! # Conventions
//!
//! Pixels have x right, y down and pixel centres at integers (OpenCV's). An AC row is
//! `[x1, y1, x2, y2, a11, a12, a21, a22]` ([`geom::types::AcRow`], GC-RANSAC's layout), points
//! alone `[x1, y1, x2, y2]`. `p2ᵀ F p1 = 0`; the motion is `X2 = R X1 + t` and `E = [t]× R`;
//! angles are radians. Models come back with unit Frobenius norm.
//!
//! # Worked examples
//!
//! Each estimator takes [`ransac::Correspondences`] (from AC rows, or point rows) and
//! [`ransac::EstimatorOptions`], and returns a [`ransac::Estimate`]: the model, the inlier
//! mask and the loop's counters, like PoseLib's `(model, info)`. ACs are sampled two at a time
//! (three for F) when the data carry them.
//!
//! ## Homography
//!
//! ```
//! use affcorr::geom::homography::correspondences_from_homography;
//! use affcorr::geom::Mat3;
//! use affcorr::ransac::{Correspondences, EstimatorOptions, estimate_homography};
//!
//! // The ACs that a homography induces on a grid of image 1, then 10 of them spoilt.
//! let h = Mat3::new(0.76, -0.30, 225.7, 0.33, 1.01, -77.0, 3.5e-4, -1.4e-5, 1.0);
//! let x1: Vec<[f64; 2]> = (0..60).map(|i| [40.0 + 9.0 * i as f64, 60.0 + 7.0 * (i % 9) as f64]).collect();
//! let mut rows = vec![[0.0; 8]; x1.len()];
//! correspondences_from_homography(&h, &x1, &mut rows)?;
//! for r in rows.iter_mut().step_by(6) {
//!     r[2] += 80.0; // outliers
//! }
//! let data = Correspondences::from_ac_rows(&rows)?;
//!
//! let mut opts = EstimatorOptions::default();
//! opts.ransac.threshold = 2.0; // pixels
//! let est = estimate_homography(&data, &opts)?;
//!
//! assert_eq!(est.num_inliers, 50);
//! assert!(!est.inliers[0] && est.inliers[1]);
//! let (hh, h) = (est.model / est.model[(2, 2)], h / h[(2, 2)]);
//! assert!((hh - h).norm() < 1e-6 * h.norm());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Fundamental matrix
//!
//! ```
//! use affcorr::geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
//! use affcorr::geom::sampson::sampson_point;
//! use affcorr::ransac::{Correspondences, EstimatorOptions, estimate_fundamental};
//! use rand::{SeedableRng, rngs::StdRng};
//!
//! // Two cameras looking at three planes; 400 ACs, 30% outliers, 0.5 px noise on x2.
//! let mut rng = StdRng::seed_from_u64(7);
//! let scene = PlaneScene::random(&mut rng);
//! let noise = NoiseModel { planes: 3, outlier_ratio: 0.3, pixel_noise: 0.5, affine_noise: 0.01 };
//! let (acs, truth) = noisy_correspondences(&mut rng, &scene, 400, &noise);
//!
//! let mut opts = EstimatorOptions::default();
//! opts.ransac.threshold = 1.0;
//! opts.ransac.seed = 3;
//! let est = estimate_fundamental(&Correspondences::from_acs(&acs)?, &opts)?;
//!
//! // p2ᵀ F p1 = 0: the true inliers are within a pixel of the estimated F.
//! let inliers = acs.iter().zip(&truth).filter(|(_, t)| **t).map(|(ac, _)| ac.points());
//! let d: Vec<f64> = inliers.map(|c| sampson_point(&est.model, &c)).collect();
//! let mean = d.iter().sum::<f64>() / d.len() as f64;
//! assert!(mean < 1.0, "mean Sampson distance {mean}");
//! assert!(est.num_inliers > 250);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Relative pose
//!
//! ```
//! use affcorr::geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
//! use affcorr::ransac::{Correspondences, EstimatorOptions, estimate_relative_pose};
//! use rand::{SeedableRng, rngs::StdRng};
//!
//! let mut rng = StdRng::seed_from_u64(11);
//! let scene = PlaneScene::random(&mut rng);
//! let noise = NoiseModel { planes: 3, outlier_ratio: 0.3, pixel_noise: 0.5, affine_noise: 0.01 };
//! let (acs, _) = noisy_correspondences(&mut rng, &scene, 400, &noise);
//!
//! // Pixels in, intrinsics alongside; the threshold is in pixels.
//! let mut opts = EstimatorOptions::default();
//! opts.ransac.threshold = 1.0;
//! let data = Correspondences::from_acs(&acs)?;
//! let est = estimate_relative_pose(&data, &scene.k1, &scene.k2, &opts)?;
//!
//! // X2 = R X1 + t with |t| = 1: rotation error in degrees, translation direction error.
//! let (r, t) = (est.model.pose.r, est.model.pose.t);
//! let cos = (((r.transpose() * scene.pose.r).trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
//! assert!(cos.acos().to_degrees() < 0.5);
//! assert!(t.dot(&scene.pose.t.normalize()) > 0.99);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! When the inliers lie on one plane (`planes: 1`), a second motion explains them as well,
//! points and A alike; [`ransac::planar_twin`] says so and returns it (docs/estimation.md).
//!
//! ## A minimal solver
//!
//! Solvers write candidate models into a caller-owned buffer and return how many they wrote;
//! a degenerate sample gives none.
//!
//! ```
//! use affcorr::geom::homography::ac_from_homography;
//! use affcorr::geom::{Mat3, Vec2};
//! use affcorr::solvers::homography::homography_2ac;
//!
//! let h = Mat3::new(1.1, 0.1, 5.0, -0.05, 0.9, 3.0, 1e-4, 2e-4, 1.0);
//! let acs = [
//!     ac_from_homography(&h, &Vec2::new(10.0, 20.0), 0)?,
//!     ac_from_homography(&h, &Vec2::new(300.0, 150.0), 1)?,
//! ];
//! let mut out = [Mat3::zeros(); 1];
//! assert_eq!(homography_2ac(&acs, &mut out), 1);
//! assert!((out[0] / out[0][(2, 2)] - h).norm() < 1e-9);
//! # Ok::<(), affcorr::geom::GeomError>(())
//! ```
//!
//! ## The affine map's shape
//!
//! ```
//! use affcorr::geom::affine::{AffineShape, decompose, synthesize};
//!
//! let a = synthesize(&AffineShape { orientation: 0.3, scale: 2.0, residual_shape: [0.1, 0.2, 0.0] }, 0)?;
//! let shape = decompose(&a, 0)?;
//! assert!((shape.orientation - 0.3).abs() < 1e-12 && (shape.scale - 2.0).abs() < 1e-12);
//! # Ok::<(), affcorr::geom::GeomError>(())
//! ```
//!
//! ## Images to a homography (feature `pipeline`)
//!
//! Needs the ONNX models (`python/affcorr/models` in the repository) and the ONNX Runtime
//! library, so it is compiled but not run here.
//!
//! ```no_run
//! # #[cfg(feature = "pipeline")] {
//! use affcorr::{Geometry, Pipeline, runner::init_ort};
//!
//! init_ort(None)?; // ORT_DYLIB_PATH, or the onnxruntime wheel's library
//! let pipeline = Pipeline::builder().models_dir("python/affcorr/models").build()?;
//! let (a, b) = ("data/graffiti/graf1.png", "data/graffiti/graf3.png");
//! let h = pipeline.homography(a, b, &Geometry::Homography.default_options())?;
//! println!("H = {}, {} inliers of {}", h.estimate.model, h.estimate.num_inliers, h.matches.corrs.len());
//! # }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Errors are typed per crate ([`geom::GeomError`], [`solvers`]' solvers return counts,
//! [`ransac::RansacError`], and with the features `image::ImageError`, `runner::RunnerError`,
//! `PipelineError`) and name the bad argument or row.

#[doc(inline)]
pub use affcorr_geom as geom;
#[cfg(feature = "image")]
#[doc(inline)]
pub use affcorr_image as image;
#[cfg(feature = "pipeline")]
#[doc(inline)]
pub use affcorr_pipeline as pipeline;
#[doc(inline)]
pub use affcorr_ransac as ransac;
#[cfg(feature = "onnx")]
#[doc(inline)]
pub use affcorr_runner as runner;
#[doc(inline)]
pub use affcorr_solvers as solvers;

#[cfg(feature = "pipeline")]
#[doc(inline)]
pub use affcorr_pipeline::{
    Estimated, Geometry, ImageSource, Matcher, Matches, Pipeline, PipelineBuilder, PipelineError,
    Timings,
};
