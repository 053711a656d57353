//! Throughput of the shape-network runner, in patch pairs per second (docs/design.md §6).
//!
//! - `shape/extract/t2/512`: cutting 512 patch pairs (two 32×32 bilinear patches each) from two
//!   1024×768 images, in a rayon pool of 2 threads.
//! - `shape/infer/t2/512`: one batch of 512 pairs through the shape network with 2 ONNX Runtime
//!   intra-op threads (decoding included).
//! - `shape/estimate/t2/512`: both, plus AC synthesis (`ShapeEstimator::estimate`).
//!
//! The model is `python/affcorr/models/shape.onnx` (or `$AFFCORR_SHAPE_MODEL`); ONNX Runtime comes
//! from `$ORT_DYLIB_PATH`, else from the repository's `.venv` (the `onnxruntime` wheel):
//!
//! ```text
//! ORT_DYLIB_PATH=$(realpath .venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so.*) \
//!     cargo bench -p affcorr-benches --bench shape
//! ```

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use affcorr::image::{GrayImage, extract_patches};
use affcorr::runner::{ShapeEstimator, ShapeModel, ShapeModelOptions, init_ort};
use criterion::{Criterion, Throughput};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const PAIRS: usize = 512;
const THREADS: usize = 2;

fn root() -> PathBuf {
    affcorr_devtools::repo_root()
}

/// `$ORT_DYLIB_PATH`, else the onnxruntime wheel's library under `.venv`.
fn ort_library() -> PathBuf {
    affcorr_devtools::ort_library()
}

/// A smooth random image (a sum of a few sinusoids plus noise), `w × h`.
fn image(w: usize, h: usize, rng: &mut Pcg64) -> GrayImage {
    let waves: Vec<[f32; 4]> = (0..6)
        .map(|_| {
            [
                rng.random_range(0.01..0.2),
                rng.random_range(0.01..0.2),
                rng.random_range(0.0..6.3),
                rng.random_range(0.05..0.15),
            ]
        })
        .collect();
    let data = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let v: f32 = waves
                .iter()
                .map(|[fx, fy, p, a]| a * (fx * x + fy * y + p).sin())
                .sum();
            (0.5 + v + rng.random_range(-0.02..0.02)).clamp(0.0, 1.0)
        })
        .collect();
    GrayImage::new(w, h, data).unwrap()
}

fn bench(c: &mut Criterion) {
    init_ort(Some(&ort_library())).expect("ONNX Runtime");
    let model_path = std::env::var_os("AFFCORR_SHAPE_MODEL")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("python/affcorr/models/shape.onnx"));
    let options = ShapeModelOptions {
        threads: Some(THREADS),
        batch_size: PAIRS,
    };
    let mut rng = Pcg64::seed_from_u64(1);
    let (w, h) = (1024, 768);
    let (img_a, img_b) = (image(w, h, &mut rng), image(w, h, &mut rng));
    let x1: Vec<[f64; 2]> = (0..PAIRS)
        .map(|_| {
            [
                rng.random_range(0.0..w as f64),
                rng.random_range(0.0..h as f64),
            ]
        })
        .collect();
    let x2: Vec<[f64; 2]> = x1
        .iter()
        .map(|p| {
            [
                p[0] + rng.random_range(-20.0..20.0),
                p[1] + rng.random_range(-20.0..20.0),
            ]
        })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(THREADS)
        .build()
        .expect("rayon pool");

    let mut group = c.benchmark_group("shape");
    group.sample_size(20);
    group.warm_up_time(Duration::from_secs(2));
    group.measurement_time(Duration::from_secs(5));
    group.throughput(Throughput::Elements(PAIRS as u64));

    group.bench_function(format!("extract/t{THREADS}/{PAIRS}"), |b| {
        b.iter(|| {
            pool.install(|| {
                let pa = extract_patches(black_box(&img_a), black_box(&x1)).unwrap();
                let pb = extract_patches(black_box(&img_b), black_box(&x2)).unwrap();
                (pa, pb)
            })
        })
    });

    let model = ShapeModel::load_with(&model_path, &options).expect("shape model");
    let pa = extract_patches(&img_a, &x1).unwrap();
    let pb = extract_patches(&img_b, &x2).unwrap();
    group.bench_function(format!("infer/t{THREADS}/{PAIRS}"), |b| {
        b.iter(|| model.predict(black_box(&pa), black_box(&pb)).unwrap())
    });

    let estimator = ShapeEstimator::new(model);
    group.bench_function(format!("estimate/t{THREADS}/{PAIRS}"), |b| {
        b.iter(|| pool.install(|| estimator.estimate(&img_a, &img_b, &x1, &x2).unwrap()))
    });
    group.finish();
}

criterion::criterion_group!(benches, bench);
criterion::criterion_main!(benches);
