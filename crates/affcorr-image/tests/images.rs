//! Image decoding: every PNG/JPEG pixel layout to gray in [0, 1], and typed errors for bad files
//! and buffers. Images are written with the `image` crate's encoders in a temporary directory.

use std::path::Path;

use affcorr_image::{GrayImage, ImageError, PixelData};
use image::{ImageBuffer, Luma, LumaA, Rgb, Rgba};

const W: u32 = 7;
const H: u32 = 5;

/// A deterministic sample value in 0..=max at (x, y, channel).
fn sample(x: u32, y: u32, c: u32, max: u32) -> u32 {
    (x * 37 + y * 101 + c * 53 + x * y * 7) * (max / 255 + 1) % (max + 1)
}

fn luma(r: f64, g: f64, b: f64) -> f64 {
    0.299 * r + 0.587 * g + 0.114 * b
}

fn assert_close(img: &GrayImage, expected: impl Fn(u32, u32) -> f64, tol: f64) {
    assert_eq!((img.width(), img.height()), (W as usize, H as usize));
    for y in 0..H {
        for x in 0..W {
            let got = img.get(x as usize, y as usize) as f64;
            let want = expected(x, y);
            assert!((got - want).abs() <= tol, "({x}, {y}): {got} vs {want}");
        }
    }
}

fn save<P: image::Pixel<Subpixel = S> + image::PixelWithColorType, S: image::Primitive>(
    buf: &ImageBuffer<P, Vec<S>>,
    path: &Path,
) where
    [S]: image::EncodableLayout,
{
    buf.save(path).unwrap();
}

#[test]
fn png_8_bit_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let s = |x, y, c| sample(x, y, c, 255) as u8;
    let v = |x, y, c| sample(x, y, c, 255) as f64 / 255.0;

    let p = dir.path().join("l8.png");
    save(&ImageBuffer::from_fn(W, H, |x, y| Luma([s(x, y, 0)])), &p);
    assert_close(&GrayImage::open(&p).unwrap(), |x, y| v(x, y, 0), 1e-7);

    let p = dir.path().join("la8.png");
    save(
        &ImageBuffer::from_fn(W, H, |x, y| LumaA([s(x, y, 0), s(x, y, 1)])),
        &p,
    );
    assert_close(&GrayImage::open(&p).unwrap(), |x, y| v(x, y, 0), 1e-7);

    let p = dir.path().join("rgb8.png");
    save(
        &ImageBuffer::from_fn(W, H, |x, y| Rgb([s(x, y, 0), s(x, y, 1), s(x, y, 2)])),
        &p,
    );
    let want = |x, y| luma(v(x, y, 0), v(x, y, 1), v(x, y, 2));
    assert_close(&GrayImage::open(&p).unwrap(), want, 1e-6);

    // Alpha is ignored, even where it is 0.
    let p = dir.path().join("rgba8.png");
    let rgba = |x, y| {
        Rgba([
            s(x, y, 0),
            s(x, y, 1),
            s(x, y, 2),
            if x == 0 { 0 } else { s(x, y, 3) },
        ])
    };
    save(&ImageBuffer::from_fn(W, H, rgba), &p);
    assert_close(&GrayImage::open(&p).unwrap(), want, 1e-6);
}

#[test]
fn png_16_bit_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let s = |x, y, c| sample(x, y, c, 65535) as u16;
    let v = |x, y, c| sample(x, y, c, 65535) as f64 / 65535.0;
    // 16-bit precision survives: values differ from their 8-bit rounding.
    assert!((0..W).any(|x| (v(x, 1, 0) * 255.0).fract().abs() > 0.1));

    let p = dir.path().join("l16.png");
    save(&ImageBuffer::from_fn(W, H, |x, y| Luma([s(x, y, 0)])), &p);
    assert_close(&GrayImage::open(&p).unwrap(), |x, y| v(x, y, 0), 1e-7);

    let p = dir.path().join("la16.png");
    save(
        &ImageBuffer::from_fn(W, H, |x, y| LumaA([s(x, y, 0), s(x, y, 1)])),
        &p,
    );
    assert_close(&GrayImage::open(&p).unwrap(), |x, y| v(x, y, 0), 1e-7);

    let want = |x, y| luma(v(x, y, 0), v(x, y, 1), v(x, y, 2));
    let p = dir.path().join("rgb16.png");
    save(
        &ImageBuffer::from_fn(W, H, |x, y| Rgb([s(x, y, 0), s(x, y, 1), s(x, y, 2)])),
        &p,
    );
    assert_close(&GrayImage::open(&p).unwrap(), want, 1e-6);

    let p = dir.path().join("rgba16.png");
    let rgba = |x, y| Rgba([s(x, y, 0), s(x, y, 1), s(x, y, 2), s(x, y, 3)]);
    save(&ImageBuffer::from_fn(W, H, rgba), &p);
    assert_close(&GrayImage::open(&p).unwrap(), want, 1e-6);
}

fn jpeg(img: &image::DynamicImage, path: &Path) {
    let mut bytes = Vec::new();
    img.write_with_encoder(image::codecs::jpeg::JpegEncoder::new_with_quality(
        &mut bytes, 95,
    ))
    .unwrap();
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn jpeg_gray_and_colour() {
    // JPEG is lossy: a smooth image comes back within a few grey levels.
    let dir = tempfile::tempdir().unwrap();
    let smooth = |x: u32, y: u32, c: u32| (40 + 20 * x + 15 * y + 30 * c) as u8;
    let p = dir.path().join("gray.jpg");
    jpeg(
        &image::DynamicImage::ImageLuma8(ImageBuffer::from_fn(W, H, |x, y| {
            Luma([smooth(x, y, 0)])
        })),
        &p,
    );
    assert_close(
        &GrayImage::open(&p).unwrap(),
        |x, y| smooth(x, y, 0) as f64 / 255.0,
        6.0 / 255.0,
    );

    let p = dir.path().join("rgb.jpg");
    let rgb = |x, y| Rgb([smooth(x, y, 0), smooth(x, y, 1), smooth(x, y, 2)]);
    jpeg(
        &image::DynamicImage::ImageRgb8(ImageBuffer::from_fn(W, H, rgb)),
        &p,
    );
    let want = |x, y| {
        luma(
            smooth(x, y, 0) as f64,
            smooth(x, y, 1) as f64,
            smooth(x, y, 2) as f64,
        ) / 255.0
    };
    assert_close(&GrayImage::open(&p).unwrap(), want, 6.0 / 255.0);
    // The same bytes decode the same from memory.
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(
        GrayImage::decode(&bytes).unwrap(),
        GrayImage::open(&p).unwrap()
    );
}

#[test]
fn bad_files_are_typed_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();

    let missing = dir.path().join("missing.png");
    let e = GrayImage::open(&missing).unwrap_err();
    assert!(
        matches!(e, ImageError::Open { ref path, .. } if *path == missing),
        "{e:?}"
    );
    assert!(e.to_string().contains("missing.png"));

    let garbage = dir.path().join("garbage.png");
    std::fs::write(&garbage, b"this is not an image at all").unwrap();
    let e = GrayImage::open(&garbage).unwrap_err();
    assert!(matches!(e, ImageError::Decode { .. }), "{e:?}");
    assert!(
        e.to_string().contains("garbage.png") && e.to_string().contains("unrecognised"),
        "{e}"
    );

    let empty = dir.path().join("empty.png");
    std::fs::write(&empty, b"").unwrap();
    assert!(matches!(
        GrayImage::open(&empty),
        Err(ImageError::Decode { .. })
    ));

    // Truncated PNG: the header is fine, the data stops half-way.
    let good = dir.path().join("good.png");
    let big = ImageBuffer::from_fn(64, 64, |x, y| Luma([((x * 7 + y * 13) % 256) as u8]));
    save(&big, &good);
    let bytes = std::fs::read(&good).unwrap();
    let truncated = dir.path().join("truncated.png");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let e = GrayImage::open(&truncated).unwrap_err();
    assert!(matches!(e, ImageError::Decode { .. }), "{e:?}");
    assert!(e.to_string().contains("truncated.png"), "{e}");

    // Truncated JPEG.
    let good = dir.path().join("good.jpg");
    jpeg(&image::DynamicImage::ImageLuma8(big), &good);
    let bytes_jpg = std::fs::read(&good).unwrap();
    let truncated = dir.path().join("truncated.jpg");
    std::fs::write(&truncated, &bytes_jpg[..bytes_jpg.len() / 3]).unwrap();
    let e = GrayImage::open(&truncated).unwrap_err();
    assert!(matches!(e, ImageError::Decode { .. }), "{e:?}");

    // A directory is not an image.
    assert!(matches!(
        GrayImage::open(dir.path()),
        Err(ImageError::Open { .. })
    ));
    // From memory, the source is named as such.
    let e = GrayImage::decode(&bytes[..20]).unwrap_err();
    assert!(e.to_string().contains("from memory"), "{e}");
}

#[test]
fn raw_buffers() {
    let img = GrayImage::from_raw(2, 1, 1, PixelData::U16(&[0, 65535])).unwrap();
    assert_eq!(img.data(), &[0.0, 1.0]);
    let img = GrayImage::from_raw(1, 2, 2, PixelData::U8(&[51, 0, 255, 9])).unwrap();
    assert_eq!(img.data(), &[0.2, 1.0]);
    let img = GrayImage::from_raw(1, 1, 4, PixelData::F32(&[1.0, 0.5, 0.0, 0.3])).unwrap();
    assert!((img.data()[0] - (0.299 + 0.587 * 0.5)).abs() < 1e-7);
    assert_eq!(
        GrayImage::new(2, 2, vec![0.1; 4]).unwrap().data(),
        &[0.1; 4]
    );

    let err = |r: Result<GrayImage, ImageError>| match r {
        Err(e @ ImageError::Buffer { .. }) => e.to_string(),
        other => panic!("expected ImageBuffer, got {other:?}"),
    };
    assert!(err(GrayImage::from_raw(2, 2, 3, PixelData::U8(&[0; 11]))).contains("expected 12"));
    assert!(err(GrayImage::from_raw(0, 2, 1, PixelData::U8(&[]))).contains("empty"));
    assert!(err(GrayImage::from_raw(1, 1, 5, PixelData::U8(&[0; 5]))).contains("5 channels"));
    let nan = err(GrayImage::from_raw(
        2,
        2,
        1,
        PixelData::F32(&[0.0, 0.0, 0.0, f32::NAN]),
    ));
    assert!(nan.contains("x = 1, y = 1"), "{nan}");
    assert!(err(GrayImage::new(3, 1, vec![0.0, f32::INFINITY, 0.0])).contains("x = 1, y = 0"));
    assert!(err(GrayImage::new(3, 1, vec![0.0; 2])).contains("expected 3"));
}
