//! LighterGlue on graffiti 1→3 (800×640, XFeat features of the shipped backbone): the adaptive
//! loop over the pieces (`glue/adaptive/<k>`, depth 0.95 and width 0.95, the default) against
//! the full graph (`glue/full/<k>`, every layer), 2 ONNX Runtime intra-op threads, at 1024 and
//! 2048 keypoints per image (benches/results/lighterglue_adaptive.md has the accuracy of each):
//!
//! ```text
//! ORT_DYLIB_PATH=$(realpath .venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so.*) \
//!     cargo bench -p affcorr-benches --bench glue
//! ```

use std::hint::black_box;
use std::time::Duration;

use affcorr::image::GrayImage;
use affcorr::runner::features::{detect_and_compute, preprocess};
use affcorr::runner::matching::normalize_keypoints_lighterglue;
use affcorr::runner::{
    Backbone, GlueMode, LighterGlue, LighterGlueOptions, SparseFeatures, init_ort,
};
use criterion::Criterion;

const THREADS: usize = 2;

fn features(backbone: &Backbone, name: &str, top_k: usize) -> SparseFeatures {
    let path = affcorr_devtools::repo_root()
        .join("data/graffiti")
        .join(name);
    let img = GrayImage::open(path).unwrap();
    let (w, h) = (img.width(), img.height());
    let cfg = backbone.config();
    let input = preprocess(img.data(), h, w, cfg.input_multiple).unwrap();
    let maps = backbone
        .run(&input.data, input.height, input.width, true)
        .unwrap();
    detect_and_compute(
        &maps,
        top_k,
        cfg.threshold,
        cfg.nms_size,
        (input.rh, input.rw),
        (w, h),
    )
}

fn bench(c: &mut Criterion) {
    init_ort(Some(&affcorr_devtools::ort_library())).expect("ONNX Runtime");
    let models = affcorr_devtools::models_dir();
    let backbone = Backbone::load(models.join("xfeat_backbone.onnx"), Some(THREADS)).unwrap();
    let glue = |mode| {
        let options = LighterGlueOptions {
            mode: Some(mode),
            ..Default::default()
        };
        LighterGlue::load_with(
            models.join("xfeat_lighterglue.onnx"),
            Some(THREADS),
            &options,
        )
        .unwrap()
    };
    let nets = [
        ("full", glue(GlueMode::Full)),
        ("adaptive", glue(GlueMode::Adaptive)),
    ];
    let mut group = c.benchmark_group("glue");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(8));
    for k in [1024, 2048] {
        let a = features(&backbone, "graf1.png", k);
        let b = features(&backbone, "graf3.png", k);
        let k0 = normalize_keypoints_lighterglue(&a.keypoints, a.image_size);
        let k1 = normalize_keypoints_lighterglue(&b.keypoints, b.image_size);
        for (name, net) in &nets {
            group.bench_function(format!("{name}/{k}"), |bench| {
                bench.iter(|| {
                    net.run(
                        black_box(&k0),
                        &a.descriptors,
                        &k1,
                        &b.descriptors,
                        net.min_conf(),
                    )
                    .unwrap()
                })
            });
        }
    }
    group.finish();
}

criterion::criterion_group!(benches, bench);
criterion::criterion_main!(benches);
