//! Synthetic views (`affcorr::image::warp_image`): one 640×480 image under the warps the view
//! cascade uses (each fitted to the view that holds the whole image, as the cascade fits
//! them), in a rayon pool of 2 threads. A warp that shrinks blurs the source first
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
        let (warp, vw, vh) = linear.fitted(w, h);
        group.bench_function(name, |b| {
            b.iter(|| pool.install(|| warp_image(black_box(&image), &warp, vw, vh).unwrap()))
        });
    }
    group.finish();
}

criterion::criterion_group!(benches, bench);
criterion::criterion_main!(benches);
