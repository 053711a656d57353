//! Shape-model loading from arbitrary bytes (`ShapeModel::from_bytes`: ONNX Runtime parses the
//! protobuf, then our `shape-v1` contract check reads the metadata, inputs, outputs and, for
//! symbolic widths, runs the model once): no panic, no abort, no hang. A model that loads must
//! then turn one match into a finite AC or fail with an error.
//!
//! Needs ONNX Runtime: `ORT_DYLIB_PATH` (see README.md). Seeds: the contract fixtures of
//! tests/data/shape (each breaks the contract in one named way), so mutations land in the
//! metadata and graph signatures our checks read.
#![no_main]

use std::sync::OnceLock;

use affcorr_image::GrayImage;
use affcorr_runner::{ShapeEstimator, ShapeModel, ShapeModelOptions};
use libfuzzer_sys::fuzz_target;

fn image() -> &'static GrayImage {
    static IMG: OnceLock<GrayImage> = OnceLock::new();
    IMG.get_or_init(|| {
        let data = (0..64 * 64)
            .map(|i| ((i * 37) % 251) as f32 / 251.0)
            .collect();
        GrayImage::new(64, 64, data).expect("a valid image")
    })
}

fuzz_target!(|data: &[u8]| {
    static INIT: OnceLock<()> = OnceLock::new();
    INIT.get_or_init(|| affcorr_runner::init_ort(None).expect("set ORT_DYLIB_PATH"));
    let options = ShapeModelOptions {
        threads: Some(1),
        batch_size: 4,
    };
    let Ok(model) = ShapeModel::from_bytes(data, &options) else {
        return;
    };
    let est = ShapeEstimator::new(model);
    if let Ok(e) = est.estimate(image(), image(), &[[20.0, 30.5]], &[[40.25, 22.0]]) {
        assert_eq!(e.corrs.len(), 1);
        assert!(
            e.corrs[0].iter().all(|v| v.is_finite()),
            "AC {:?}",
            e.corrs[0]
        );
    }
});
