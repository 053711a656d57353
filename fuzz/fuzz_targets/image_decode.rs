//! Image decoding from arbitrary bytes (`GrayImage::decode`: PNG, JPEG, anything else), and
//! raw buffers of arbitrary size and channel count (`GrayImage::from_raw`): no panic, no abort,
//! no hang, no runaway allocation (libFuzzer's -rss_limit_mb); a decoded image has
//! width × height finite values, in [0, 1] for integer samples.
#![no_main]

use affcorr_image::{GrayImage, PixelData};
use libfuzzer_sys::fuzz_target;

fn check(img: &GrayImage, unit: bool) {
    assert!(img.width() > 0 && img.height() > 0, "empty image accepted");
    assert_eq!(img.data().len(), img.width() * img.height());
    for &v in img.data() {
        assert!(v.is_finite(), "non-finite pixel {v}");
        if unit {
            // BT.601 weights sum to 1 up to f32 rounding.
            assert!((0.0..=1.0 + 1e-6).contains(&v), "pixel {v} outside [0, 1]");
        }
    }
}

fuzz_target!(|data: &[u8]| {
    // Most inputs are encoded files; a leading 0xFF 0x00 marks a raw buffer instead (an
    // encoded PNG or JPEG never starts so).
    if let [0xFF, 0x00, w, h, c, kind, rest @ ..] = data {
        let (w, h, c) = (usize::from(*w), usize::from(*h), usize::from(*c % 6));
        let res = match kind % 3 {
            0 => GrayImage::from_raw(w, h, c, PixelData::U8(rest)),
            1 => {
                let s: Vec<u16> = rest
                    .chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect();
                GrayImage::from_raw(w, h, c, PixelData::U16(&s))
            }
            _ => {
                let s: Vec<f32> = rest
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .collect();
                GrayImage::from_raw(w, h, c, PixelData::F32(&s))
            }
        };
        if let Ok(img) = res {
            check(&img, kind % 3 != 2);
        }
        return;
    }
    if let Ok(img) = GrayImage::decode(data) {
        check(&img, true);
    }
});
