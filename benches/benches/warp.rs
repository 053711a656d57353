//! Synthetic views (`affcorr::image::warp_image`): one 640×480 image under the warps the view
//! cascade uses, in a rayon pool of 2 threads. A warp that shrinks blurs the source first
//! (isotropically, then along the shrinking direction: ASIFT's anti-aliasing), and that blur
//! is most of a tilt view's cost.
//!
//! - `warp/rotation`: B turned by 135° (no shrink, no blur);
//! - `warp/tilt2`, `warp/tilt4`: A foreshortened 2× and 4× along 22.5°;
//! - `warp/zoom0.5_tilt4`: the same tilt 4 zoomed by ½ (the tilt-4 groups' zoomed views).
//!
//! ```text
//! cargo bench -p affcorr-benches --bench warp
//! ```

use std::hint::black_box;
use std::time::Duration;

use affcorr::image::{AffineWarp, GrayImage, warp_image};
use criterion::Criterion;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const THREADS: usize = 2;

/// `linear` with the translation and size that hold the whole warped `w` × `h` image.
fn framed(linear: AffineWarp, w: usize, h: usize) -> (AffineWarp, usize, usize) {
    let corners = [
        [0.0, 0.0],
        [w as f64, 0.0],
        [0.0, h as f64],
        [w as f64, h as f64],
    ];
    let m = linear.m;
    let mapped = corners.map(|[x, y]| [m[0] * x + m[1] * y, m[2] * x + m[3] * y]);
    let lo = |k: usize| mapped.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
    let hi = |k: usize| {
        mapped
            .iter()
            .map(|p| p[k])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let warp = AffineWarp {
        m,
        c: [-lo(0), -lo(1)],
    };
    let size = |k: usize| (hi(k) - lo(k)).ceil() as usize;
    (warp, size(0), size(1))
}

fn bench(c: &mut Criterion) {
    let mut rng = Pcg64::seed_from_u64(3);
    let (w, h) = (640, 480);
    let data = (0..w * h).map(|_| rng.random::<f32>()).collect();
    let image = GrayImage::new(w, h, data).unwrap();
    let deg = f64::to_radians;
    let views = [
        ("rotation", AffineWarp::linear(deg(135.0), 1.0, 1.0, 0.0)),
        ("tilt2", AffineWarp::linear(0.0, 1.0, 2.0, deg(22.5))),
        ("tilt4", AffineWarp::linear(0.0, 1.0, 4.0, deg(22.5))),
        (
            "zoom0.5_tilt4",
            AffineWarp::linear(0.0, 0.5, 4.0, deg(22.5)),
        ),
    ];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(THREADS)
        .build()
        .expect("rayon pool");
    let mut group = c.benchmark_group("warp");
    group.sample_size(20);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    for (name, linear) in views {
        let (warp, vw, vh) = framed(linear, w, h);
        group.bench_function(name, |b| {
            b.iter(|| pool.install(|| warp_image(black_box(&image), &warp, vw, vh).unwrap()))
        });
    }
    group.finish();
}

criterion::criterion_group!(benches, bench);
criterion::criterion_main!(benches);
