//! Seeded estimation is bit-identical across runs and across rayon thread counts
//! (docs/reliability.md, "Determinism").
//!
//! Why it holds: each estimate runs on one thread with its own seeded PCG streams (sampling and
//! the SPRT's order), and the `_batch` forms only distribute whole pairs over rayon's workers,
//! collecting results by index; the batched Sampson distances compute each row independently.
//! So the thread count decides only where a pair runs, never what it computes.

use affcorr_geom::Mat3;
use affcorr_geom::camera::Intrinsics;
use affcorr_geom::sampson::sampson_affine_batch;
use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_geom::types::AcRow;
use affcorr_ransac::problems::relpose::PoseModel;
use affcorr_ransac::{
    Correspondences, Estimate, EstimatorOptions, RansacOptions, SampleKind, SamplerKind,
    ScoringKind, estimate_fundamental, estimate_fundamental_batch, estimate_homography,
    estimate_homography_batch, estimate_relative_pose, estimate_relative_pose_batch,
};
use rand::SeedableRng;
use rand_pcg::Pcg64;

const THREADS: [usize; 3] = [1, 2, 4];
/// Correspondences per scene.
const N: usize = 120;

/// Everything an estimate reports, as bits: equal fingerprints mean bit-identical results.
fn fingerprint<M>(
    e: &affcorr_ransac::Result<Estimate<M>>,
    model: impl Fn(&M) -> Vec<u64>,
) -> Vec<u64> {
    let e = e.as_ref().expect("estimation succeeds on these scenes");
    let mut v = model(&e.model);
    v.extend(e.inliers.iter().map(|&b| u64::from(b)));
    v.extend([
        e.num_inliers as u64,
        e.score.to_bits(),
        e.iterations as u64,
        e.lo_runs as u64,
        e.refinements as u64,
        e.residual_evaluations,
        e.sprt_rejections as u64,
    ]);
    v
}

fn mat_bits(m: &Mat3) -> Vec<u64> {
    m.iter().map(|v| v.to_bits()).collect()
}

fn pose_bits(m: &PoseModel) -> Vec<u64> {
    let mut v = mat_bits(&m.pose.r);
    v.extend(m.pose.t.iter().map(|x| x.to_bits()));
    v.extend(mat_bits(&m.essential));
    v.extend(mat_bits(&m.fundamental));
    v
}

struct Pair {
    rows: Vec<AcRow>,
    data: Correspondences,
    k1: Intrinsics,
    k2: Intrinsics,
}

/// Scenes with noise and 40% outliers; `planes` 1 for H, 3 for F and pose.
fn pairs(count: usize, planes: usize) -> Vec<Pair> {
    (0..count as u64)
        .map(|s| {
            let mut rng = Pcg64::seed_from_u64(1000 + s);
            let scene = PlaneScene::random(&mut rng);
            let noise = NoiseModel {
                planes,
                outlier_ratio: 0.4,
                pixel_noise: 0.5,
                affine_noise: 0.02,
            };
            let (acs, _) = noisy_correspondences(&mut rng, &scene, N, &noise);
            let rows: Vec<AcRow> = acs.iter().map(|a| a.to_row()).collect();
            Pair {
                data: Correspondences::from_ac_rows(&rows).unwrap(),
                rows,
                k1: scene.k1,
                k2: scene.k2,
            }
        })
        .collect()
}

/// The option sets exercised: AC samples with the defaults plus an affine weight in scoring
/// (MAGSAC++ for F and pose, SPRT on), and point samples with PROSAC, MSAC and no SPRT.
fn option_sets(n: usize) -> Vec<EstimatorOptions> {
    let ransac = RansacOptions {
        threshold: 2.0,
        seed: 7,
        ..Default::default()
    };
    vec![
        EstimatorOptions {
            ransac: ransac.clone(),
            affine_weight: Some(0.5),
            ..Default::default()
        },
        EstimatorOptions {
            ransac: RansacOptions {
                sprt: false,
                seed: 99,
                ..ransac
            },
            sample: Some(SampleKind::Points),
            sampler: SamplerKind::Prosac,
            quality: Some((0..n).map(|i| ((i * 7919) % 1000) as f64).collect()),
            scoring: ScoringKind::Msac,
            ..Default::default()
        },
    ]
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
        .install(f)
}

/// The batch results (H pairs, then F, then pose) of every option set.
fn batches(opts: &EstimatorOptions, h: &[Pair], g: &[Pair]) -> Vec<Vec<u64>> {
    let hd: Vec<_> = h.iter().map(|p| p.data.clone()).collect();
    let gd: Vec<_> = g.iter().map(|p| p.data.clone()).collect();
    let gk: Vec<_> = g.iter().map(|p| (p.data.clone(), p.k1, p.k2)).collect();
    let mut out: Vec<_> = estimate_homography_batch(&hd, opts)
        .iter()
        .map(|e| fingerprint(e, mat_bits))
        .collect();
    out.extend(
        estimate_fundamental_batch(&gd, opts)
            .iter()
            .map(|e| fingerprint(e, mat_bits)),
    );
    out.extend(
        estimate_relative_pose_batch(&gk, opts)
            .iter()
            .map(|e| fingerprint(e, pose_bits)),
    );
    out
}

/// The single calls, in the order of [`batches`].
fn singles(opts: &EstimatorOptions, h: &[Pair], g: &[Pair]) -> Vec<Vec<u64>> {
    let mut out: Vec<_> = h
        .iter()
        .map(|p| fingerprint(&estimate_homography(&p.data, opts), mat_bits))
        .collect();
    out.extend(
        g.iter()
            .map(|p| fingerprint(&estimate_fundamental(&p.data, opts), mat_bits)),
    );
    out.extend(g.iter().map(|p| {
        fingerprint(
            &estimate_relative_pose(&p.data, &p.k1, &p.k2, opts),
            pose_bits,
        )
    }));
    out
}

// Debug builds run this: few, small scenes keep it to seconds.
#[test]
fn estimates_are_bit_identical_across_runs_and_thread_counts() {
    let (h, g) = (pairs(2, 1), pairs(2, 3));
    for (k, opts) in option_sets(N).iter().enumerate() {
        let reference = in_pool(THREADS[0], || batches(opts, &h, &g));
        for &t in &THREADS[1..] {
            let other = in_pool(t, || batches(opts, &h, &g));
            for (i, (a, b)) in reference.iter().zip(&other).enumerate() {
                assert_eq!(
                    a, b,
                    "option set {k}, batch result {i}: 1 vs {t} rayon threads"
                );
            }
        }
        // A single call equals its batch result, wherever it runs.
        let single = in_pool(2, || singles(opts, &h, &g));
        for (i, (a, b)) in reference.iter().zip(&single).enumerate() {
            assert_eq!(
                a, b,
                "option set {k}, result {i}: single call differs from the batch"
            );
        }
    }
}

#[test]
fn batched_sampson_distances_do_not_depend_on_the_thread_count() {
    // Several rayon chunks (1024 rows each) so the work really is split.
    let rows: Vec<AcRow> = pairs(25, 3).into_iter().flat_map(|p| p.rows).collect();
    let f = Mat3::new(1e-6, -2e-5, 3e-3, 2.2e-5, 1e-7, -4e-3, -3e-3, 4.1e-3, 1.0);
    let run = |t| {
        in_pool(t, || {
            let mut out = vec![[0.0; 2]; rows.len()];
            sampson_affine_batch(&f, &rows, &mut out).unwrap();
            out.iter()
                .flatten()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        })
    };
    let reference = run(1);
    for t in [2, 4] {
        assert_eq!(
            reference,
            run(t),
            "sampson_affine_batch differs with {t} threads"
        );
    }
}
