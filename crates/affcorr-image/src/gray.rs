//! Images as the networks see them: grayscale `f32` in [0, 1], row-major H×W (docs/design.md §2).
//!
//! - Decoding (PNG, JPEG) through the `image` crate; 8-bit samples are divided by 255 and
//!   16-bit samples by 65535, float samples are taken as they are.
//! - Colour to gray: luma = 0.299 R + 0.587 G + 0.114 B (ITU-R BT.601, as OpenCV and PIL).
//!   Alpha is ignored (not premultiplied, not composited).
//! - Unreadable, truncated or corrupt files (including JPEGs cut short, which the decoder
//!   itself would fill with grey) are [`ImageError::Open`] /
//!   [`ImageError::Decode`]; bad raw buffers are [`ImageError::Buffer`].
//! - Pixels are returned as the file stores them; its EXIF orientation is read beside them
//!   ([`open_dynamic`], [`crate::Orientation`]), never applied here.

use std::io::Cursor;
use std::path::Path;

use image::{DynamicImage, ImageDecoder, ImageReader};

use crate::error::{ImageError, Result};
use crate::orientation::Orientation;

/// The BT.601 luma weights of R, G and B.
pub const LUMA_WEIGHTS: [f32; 3] = [0.299, 0.587, 0.114];

/// A grayscale image: `data[y * width + x]` is the value of the pixel centred at (x, y).
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

/// Borrowed interleaved pixel samples for [`GrayImage::from_raw`].
#[derive(Debug, Clone, Copy)]
pub enum PixelData<'a> {
    /// 8-bit samples, divided by 255.
    U8(&'a [u8]),
    /// 16-bit samples, divided by 65535.
    U16(&'a [u16]),
    /// Float samples, expected in [0, 1], used as they are (must be finite).
    F32(&'a [f32]),
}

impl PixelData<'_> {
    fn len(&self) -> usize {
        match self {
            Self::U8(d) => d.len(),
            Self::U16(d) => d.len(),
            Self::F32(d) => d.len(),
        }
    }
}

impl GrayImage {
    /// An image from row-major gray values (`data.len() == width * height`, both > 0, all
    /// finite).
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Result<Self> {
        check_size(width, height, 1, data.len())?;
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(non_finite_pixel(i, width));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// An image from interleaved samples with `channels` per pixel: 1 gray, 2 gray + alpha,
    /// 3 RGB, 4 RGBA.
    ///
    /// ```
    /// use affcorr_image::{GrayImage, PixelData};
    /// // One white and one pure-red RGB pixel.
    /// let img = GrayImage::from_raw(2, 1, 3, PixelData::U8(&[255, 255, 255, 255, 0, 0])).unwrap();
    /// assert!((img.get(0, 0) - 1.0).abs() < 1e-6 && (img.get(1, 0) - 0.299).abs() < 1e-6);
    /// ```
    pub fn from_raw(
        width: usize,
        height: usize,
        channels: usize,
        pixels: PixelData<'_>,
    ) -> Result<Self> {
        if !(1..=4).contains(&channels) {
            return Err(ImageError::Buffer {
                reason: format!(
                    "{channels} channels per pixel; expected 1 (gray), 2 (gray + alpha), 3 (RGB) \
                     or 4 (RGBA)"
                ),
            });
        }
        check_size(width, height, channels, pixels.len())?;
        let data = match pixels {
            PixelData::U8(d) => to_gray(d, channels, |v| f32::from(v) / 255.0),
            PixelData::U16(d) => to_gray(d, channels, |v| f32::from(v) / 65535.0),
            PixelData::F32(d) => {
                if let Some(i) = d.iter().position(|v| !v.is_finite()) {
                    return Err(non_finite_pixel(i / channels, width));
                }
                to_gray(d, channels, |v| v)
            }
        };
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Reads and decodes an image file (PNG or JPEG, recognised by content), its pixels as
    /// stored (an EXIF orientation is not applied).
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let (img, name, _) = open_dynamic(path.as_ref())?;
        gray_from_dynamic(&img, &name)
    }

    /// Decodes an encoded image (PNG or JPEG) held in memory, its pixels as stored.
    pub fn decode(bytes: &[u8]) -> Result<Self> {
        decode(bytes, "from memory")
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The row-major values, `height * width` of them.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The value of pixel (x, y); panics when out of range.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) out of range"
        );
        self.data[y * self.width + x]
    }

    /// The values, consuming the image.
    pub fn into_data(self) -> Vec<f32> {
        self.data
    }
}

fn check_size(width: usize, height: usize, channels: usize, len: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(ImageError::Buffer {
            reason: format!("the image is empty ({width}×{height})"),
        });
    }
    let expected = width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .ok_or_else(|| ImageError::Buffer {
            reason: format!("{width}×{height}×{channels} overflows"),
        })?;
    if len != expected {
        return Err(ImageError::Buffer {
            reason: format!(
                "{len} samples for a {width}×{height} image with {channels} channel(s); expected \
                 {expected}"
            ),
        });
    }
    Ok(())
}

fn non_finite_pixel(i: usize, width: usize) -> ImageError {
    ImageError::Buffer {
        reason: format!(
            "pixel (x = {}, y = {}) is NaN or infinite",
            i % width,
            i / width
        ),
    }
}

/// Interleaved samples to gray: the value itself (1–2 channels) or the BT.601 luma (3–4).
fn to_gray<T: Copy>(samples: &[T], channels: usize, scale: impl Fn(T) -> f32) -> Vec<f32> {
    let [wr, wg, wb] = LUMA_WEIGHTS;
    match channels {
        1 => samples.iter().map(|&v| scale(v)).collect(),
        2 => samples.chunks_exact(2).map(|p| scale(p[0])).collect(),
        _ => samples
            .chunks_exact(channels)
            .map(|p| wr * scale(p[0]) + wg * scale(p[1]) + wb * scale(p[2]))
            .collect(),
    }
}

/// Whether a JPEG stream has an EOI marker (FF D9) after its last SOS marker (FF DA).
fn jpeg_complete(bytes: &[u8]) -> bool {
    let last_sos = bytes.windows(2).rposition(|w| w == [0xFF, 0xDA]);
    let last_eoi = bytes.windows(2).rposition(|w| w == [0xFF, 0xD9]);
    matches!((last_sos, last_eoi), (Some(s), Some(e)) if e > s)
}

fn decode(bytes: &[u8], source_name: &str) -> Result<GrayImage> {
    gray_from_dynamic(&decode_dynamic(bytes, source_name)?.0, source_name)
}

/// Reads and decodes an image file in the decoder's pixel type, as stored, with the checks of
/// [`GrayImage::open`] (for the dense matcher, which wants the colour too); also returns the
/// name errors use for it and the file's EXIF orientation (upright without one).
pub fn open_dynamic(path: &Path) -> Result<(DynamicImage, String, Orientation)> {
    let name = format!("`{}`", path.display());
    let bytes = read_image_file(path, &name)?;
    let (img, orientation) = decode_dynamic(&bytes, &name)?;
    Ok((img, name, orientation))
}

/// [`open_dynamic`], turned upright by the turn of the file's EXIF orientation
/// ([`Orientation::turn`]: its mirror is never applied) when `upright`; the orientation
/// returned is the turn applied (upright without `upright`).
pub fn open_oriented(path: &Path, upright: bool) -> Result<(DynamicImage, String, Orientation)> {
    let (mut img, name, orientation) = open_dynamic(path)?;
    if !upright {
        return Ok((img, name, Orientation::Upright));
    }
    let turn = orientation.turn();
    turn.apply(&mut img);
    Ok((img, name, turn))
}

/// The largest image file read: 256 MiB. The decoder's own limit (512 MiB of pixels) bounds
/// what a small file may declare; this bounds what is read before decoding, so a huge file, or
/// a device such as `/dev/zero`, is refused instead of filling memory.
pub const MAX_IMAGE_FILE_BYTES: u64 = 256 << 20;

/// PNG's signature and JPEG's start-of-image marker: what a file must begin with.
const SIGNATURES: [&[u8]; 2] = [b"\x89PNG\r\n\x1a\n", &[0xFF, 0xD8, 0xFF]];

/// Reads an image file: its first bytes must be a PNG or JPEG signature (checked before the
/// rest is read) and it must not exceed [`MAX_IMAGE_FILE_BYTES`].
fn read_image_file(path: &Path, name: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let open_error = |e: std::io::Error| ImageError::Open {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let mut file = std::fs::File::open(path).map_err(open_error)?;
    let mut head = [0u8; 8];
    let mut got = 0;
    while got < head.len() {
        match file.read(&mut head[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(open_error(e)),
        }
    }
    let head = &head[..got];
    if !SIGNATURES.iter().any(|s| head.starts_with(s)) {
        let shown: Vec<String> = head.iter().map(|b| format!("{b:02x}")).collect();
        return Err(decode_error(
            name,
            format!(
                "unrecognised format (PNG and JPEG are supported; the file starts with [{}])",
                shown.join(" ")
            ),
        ));
    }
    let mut bytes = head.to_vec();
    // One byte past the limit tells a file at the limit from one over it.
    file.take(MAX_IMAGE_FILE_BYTES + 1 - head.len() as u64)
        .read_to_end(&mut bytes)
        .map_err(open_error)?;
    if bytes.len() as u64 > MAX_IMAGE_FILE_BYTES {
        return Err(decode_error(
            name,
            format!(
                "the file is over the {} MiB limit on image files",
                MAX_IMAGE_FILE_BYTES >> 20
            ),
        ));
    }
    Ok(bytes)
}

fn decode_error(source_name: &str, reason: String) -> ImageError {
    ImageError::Decode {
        source_name: source_name.to_string(),
        reason,
    }
}

fn decode_dynamic(bytes: &[u8], source_name: &str) -> Result<(DynamicImage, Orientation)> {
    let decode_error = |reason: String| decode_error(source_name, reason);
    let reader = ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| decode_error(e.to_string()))?;
    if reader.format().is_none() {
        return Err(decode_error(
            "unrecognised format (PNG and JPEG are supported)".to_string(),
        ));
    }
    // The JPEG decoder fills a truncated scan with grey instead of failing; a complete file has
    // an end-of-image marker after its last start-of-scan (scan data never contains FF D9).
    if reader.format() == Some(image::ImageFormat::Jpeg) && !jpeg_complete(bytes) {
        return Err(decode_error(
            "truncated JPEG (no end-of-image marker after the last scan)".to_string(),
        ));
    }
    let decoder_error = |e: image::ImageError| match e {
        image::ImageError::Limits(_) => decode_error(too_large(bytes, &e)),
        e => decode_error(e.to_string()),
    };
    let mut decoder = reader.into_decoder().map_err(decoder_error)?;
    // What `ImageReader::decode` does: the decoded buffer is refused before it is allocated
    // when it would exceed the decoder's limit (512 MiB).
    let mut limits = image::Limits::default();
    limits
        .reserve(decoder.total_bytes())
        .map_err(decoder_error)?;
    decoder.set_limits(limits).map_err(decoder_error)?;
    // A damaged EXIF block leaves the pixels as stored, as image viewers do: it does not make
    // the image unreadable.
    let orientation = decoder
        .orientation()
        .map(Orientation::from_image)
        .unwrap_or_default();
    let img = DynamicImage::from_decoder(decoder).map_err(decoder_error)?;
    Ok((img, orientation))
}

/// Names the size of an image refused by the decoder's allocation limit (`image`'s default
/// `Limits`, 512 MiB), which it checks from the header before allocating.
fn too_large(bytes: &[u8], e: &image::ImageError) -> String {
    let dims = ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .ok()
        .and_then(|r| r.into_dimensions().ok());
    match dims {
        Some((w, h)) => {
            format!("{e}: the image is {w}×{h} pixels, over the decoder's 512 MiB limit")
        }
        None => e.to_string(),
    }
}

/// A decoded image to gray (BT.601 luma for colour).
pub fn gray_from_dynamic(img: &DynamicImage, source_name: &str) -> Result<GrayImage> {
    let decode_error = |reason: String| decode_error(source_name, reason);
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (channels, pixels) = match img {
        DynamicImage::ImageLuma8(b) => (1, PixelData::U8(b.as_raw())),
        DynamicImage::ImageLumaA8(b) => (2, PixelData::U8(b.as_raw())),
        DynamicImage::ImageRgb8(b) => (3, PixelData::U8(b.as_raw())),
        DynamicImage::ImageRgba8(b) => (4, PixelData::U8(b.as_raw())),
        DynamicImage::ImageLuma16(b) => (1, PixelData::U16(b.as_raw())),
        DynamicImage::ImageLumaA16(b) => (2, PixelData::U16(b.as_raw())),
        DynamicImage::ImageRgb16(b) => (3, PixelData::U16(b.as_raw())),
        DynamicImage::ImageRgba16(b) => (4, PixelData::U16(b.as_raw())),
        DynamicImage::ImageRgb32F(b) => (3, PixelData::F32(b.as_raw())),
        DynamicImage::ImageRgba32F(b) => (4, PixelData::F32(b.as_raw())),
        other => {
            return Err(decode_error(format!(
                "unsupported pixel type {:?}",
                other.color()
            )));
        }
    };
    GrayImage::from_raw(w, h, channels, pixels).map_err(|e| decode_error(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reason(e: ImageError) -> String {
        e.to_string()
    }

    #[test]
    fn a_file_that_does_not_start_like_an_image_is_refused_from_its_first_bytes() {
        // /dev/zero never ends: read whole, it would fill memory.
        let e = reason(GrayImage::open("/dev/zero").unwrap_err());
        assert!(
            e.contains("unrecognised format") && e.contains("[00 00 00 00 00 00 00 00]"),
            "{e}"
        );
        let dir = std::env::temp_dir().join(format!("affcorr-gray-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text = dir.join("text.png");
        std::fs::write(&text, b"hello").unwrap();
        let e = reason(GrayImage::open(&text).unwrap_err());
        assert!(e.contains("[68 65 6c 6c 6f]"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_file_over_the_size_limit_is_refused_naming_the_limit() {
        let dir = std::env::temp_dir().join(format!("affcorr-big-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let big = dir.join("big.png");
        // A PNG signature, then a sparse hole: 300 MiB on paper, nothing on disk.
        let f = std::fs::File::create(&big).unwrap();
        std::io::Write::write_all(&mut &f, b"\x89PNG\r\n\x1a\n").unwrap();
        f.set_len(300 << 20).unwrap();
        let e = reason(GrayImage::open(&big).unwrap_err());
        assert!(e.contains("over the 256 MiB limit"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
    /// A 6 × 4 gray ramp encoded as `format`.
    fn encoded(format: image::ImageFormat) -> Vec<u8> {
        let img = image::GrayImage::from_fn(6, 4, |x, y| [(40 * y + 10 * x) as u8].into());
        let mut out = Cursor::new(Vec::new());
        DynamicImage::ImageLuma8(img)
            .write_to(&mut out, format)
            .unwrap();
        out.into_inner()
    }

    #[test]
    fn the_exif_orientation_is_read_beside_the_stored_pixels() {
        use affcorr_devtools::with_exif_orientation;
        let dir = std::env::temp_dir().join(format!("affcorr-exif-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for format in [image::ImageFormat::Jpeg, image::ImageFormat::Png] {
            let plain = encoded(format);
            let stored = GrayImage::decode(&plain).unwrap();
            for o in Orientation::ALL {
                let path = dir.join(format!("o{}.{}", o.exif(), format.extensions_str()[0]));
                std::fs::write(&path, with_exif_orientation(&plain, u16::from(o.exif()))).unwrap();
                let (img, _, got) = open_dynamic(&path).unwrap();
                assert_eq!(got, o, "{format:?}");
                // The pixels stay as stored: only the tag differs from the plain file.
                assert_eq!(GrayImage::open(&path).unwrap(), stored, "{format:?} {o:?}");
                assert_eq!((img.width(), img.height()), (6, 4));
            }
            // A value outside 1-8 reads as upright, and the image still decodes.
            let path = dir.join(format!("bad.{}", format.extensions_str()[0]));
            std::fs::write(&path, with_exif_orientation(&plain, 9)).unwrap();
            let (_, _, got) = open_dynamic(&path).unwrap();
            assert_eq!(got, Orientation::Upright, "{format:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_damaged_exif_block_leaves_the_image_readable_and_upright() {
        let plain = encoded(image::ImageFormat::Jpeg);
        // An APP1 "Exif" segment whose TIFF header is garbage.
        let mut bytes = plain[..2].to_vec();
        bytes.extend_from_slice(&[0xFF, 0xE1, 0x00, 0x10]);
        bytes.extend_from_slice(b"Exif\0\0garbage!");
        bytes.extend_from_slice(&plain[2..]);
        let (img, orientation) = decode_dynamic(&bytes, "test").unwrap();
        assert_eq!(orientation, Orientation::Upright);
        assert_eq!((img.width(), img.height()), (6, 4));
    }
}
