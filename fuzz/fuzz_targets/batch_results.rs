//! Per-pair batch results (issue 23): a batch of pairs of any size (0 and 1 rows included),
//! with per-pair options and a cancellation flag, set or not. Each pair gets its own result:
//! equal to the single call's (bit for bit) unless the flag was set; a set flag runs no
//! iteration (`NoModel { iterations: 0 }`) or fails the pair's input checks exactly as the
//! single call does. One pair's error never changes another pair's result.
#![no_main]

use affcorr_fuzz::Reader;
use affcorr_geom::types::AcRow;
use affcorr_ransac::options::Cancel;
use affcorr_ransac::{
    BatchOptions, Correspondences, EstimatorOptions, RansacError, estimate_homography,
    estimate_homography_batch,
};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut r = Reader::new(data);
    let cancel = Cancel::new();
    let pairs = 1 + usize::from(r.u8() % 4);
    let mut corrs = Vec::new();
    let mut options = Vec::new();
    for _ in 0..pairs {
        let n = usize::from(r.u8() % 12);
        let rows: Vec<AcRow> = (0..n)
            .map(|_| std::array::from_fn(|_| f64::from(r.u8() as i8) * 4.0 + r.f64().clamp(-1.0, 1.0)))
            .collect();
        let Ok(c) = Correspondences::from_ac_rows(&rows) else { return };
        corrs.push(c);
        let mut o = EstimatorOptions::default();
        o.ransac.threshold = if r.bool() { r.f64() } else { 2.0 };
        o.ransac.max_iterations = usize::from(r.u8());
        o.ransac.seed = r.u64();
        o.ransac.cancel = Some(cancel.clone());
        options.push(o);
    }
    let cancelled = r.bool();
    if cancelled {
        cancel.cancel();
    }
    let batch = estimate_homography_batch(&corrs, BatchOptions::PerPair(&options));
    assert_eq!(batch.len(), pairs);
    for (i, b) in batch.iter().enumerate() {
        let single = estimate_homography(&corrs[i], &options[i]);
        match (b, &single) {
            (Ok(x), Ok(y)) => {
                assert!(!cancelled, "pair {i}: a cancelled estimate found a model");
                assert_eq!(x.model.map(f64::to_bits), y.model.map(f64::to_bits), "pair {i}");
                assert_eq!(x.inliers, y.inliers);
            }
            (Err(RansacError::NoModel { iterations: a }), Err(RansacError::NoModel { iterations: b })) => {
                assert_eq!(a, b, "pair {i}");
                if cancelled {
                    assert_eq!(*a, 0, "pair {i}: iterations after cancellation");
                }
            }
            (Err(x), Err(y)) => assert_eq!(x.to_string(), y.to_string(), "pair {i}"),
            _ => panic!("pair {i}: batch {b:?} but single {single:?}"),
        }
    }
});
