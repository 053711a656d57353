//! Colour images, for the matchers that see colour (dense matchers such as DKM and RoMa).

use std::path::Path;

use image::DynamicImage;

use crate::error::{ImageError, Result};
use crate::gray::GrayImage;

/// An RGB image with samples in [0, 1], interleaved row-major (`data[3 (y W + x) + c]`).
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl RgbImage {
    /// An image from interleaved RGB samples (`data.len() == 3 · width · height`, both > 0,
    /// all finite).
    pub fn new(width: usize, height: usize, data: Vec<f32>) -> Result<Self> {
        let expected = width.checked_mul(height).and_then(|n| n.checked_mul(3));
        if width == 0 || height == 0 || expected != Some(data.len()) {
            return Err(ImageError::Buffer {
                reason: format!(
                    "{} samples for a {width}×{height} RGB image; expected 3 per pixel and a \
                     non-empty image",
                    data.len()
                ),
            });
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(ImageError::Buffer {
                reason: format!(
                    "pixel (x = {}, y = {}) is NaN or infinite",
                    (i / 3) % width,
                    i / 3 / width
                ),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// A gray image with R = G = B (for dense matchers given gray input).
    pub fn from_gray(img: &GrayImage) -> Self {
        Self {
            width: img.width(),
            height: img.height(),
            data: img.data().iter().flat_map(|&v| [v, v, v]).collect(),
        }
    }

    /// The BT.601 luma, as [`GrayImage::open`] computes it for colour files.
    pub fn to_gray(&self) -> Result<GrayImage> {
        GrayImage::from_raw(
            self.width,
            self.height,
            3,
            crate::gray::PixelData::F32(&self.data),
        )
    }

    /// Reads and decodes a PNG or JPEG file in colour (gray files give R = G = B; alpha is
    /// ignored), its pixels as stored, with [`GrayImage::open`]'s errors.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let (img, _, _) = crate::gray::open_dynamic(path.as_ref())?;
        Ok(Self::from_dynamic(&img))
    }

    /// The colour samples of a decoded image (gray gives R = G = B; alpha is dropped).
    pub fn from_dynamic(img: &DynamicImage) -> Self {
        let rgb = img.to_rgb32f();
        Self {
            width: rgb.width() as usize,
            height: rgb.height() as usize,
            data: rgb.into_raw(),
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The interleaved samples.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The image resized to `width` × `height` as planar (3, H, W) samples, the network's
    /// layout. Triangle filter: antialiased when shrinking (its support widens by the factor),
    /// bilinear when enlarging.
    pub fn to_planar(&self, width: usize, height: usize) -> Vec<f32> {
        let resized;
        let src: &[f32] = if (width, height) == (self.width, self.height) {
            &self.data
        } else {
            let buf = image::Rgb32FImage::from_raw(
                self.width as u32,
                self.height as u32,
                self.data.clone(),
            )
            .expect("sizes match");
            resized = image::imageops::resize(
                &buf,
                width as u32,
                height as u32,
                image::imageops::FilterType::Triangle,
            )
            .into_raw();
            &resized
        };
        let n = width * height;
        let mut out = vec![0f32; 3 * n];
        for (p, px) in src.chunks_exact(3).enumerate() {
            for c in 0..3 {
                out[c * n + p] = px[c];
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_images_resize_to_planar_and_convert_to_luma() {
        // 2×1: red, white.
        let img = RgbImage::new(2, 1, vec![1.0, 0.0, 0.0, 1.0, 1.0, 1.0]).unwrap();
        assert_eq!(img.to_planar(2, 1), vec![1.0, 1.0, 0.0, 1.0, 0.0, 1.0]);
        let g = img.to_gray().unwrap();
        assert!((g.get(0, 0) - 0.299).abs() < 1e-6 && (g.get(1, 0) - 1.0).abs() < 1e-6);
        // A constant image stays constant when resized.
        let flat = RgbImage::new(4, 4, [0.2f32, 0.4, 0.6].repeat(16)).unwrap();
        let p = flat.to_planar(2, 3);
        assert_eq!(p.len(), 18);
        for (c, want) in [0.2f32, 0.4, 0.6].iter().enumerate() {
            assert!(
                p[c * 6..(c + 1) * 6]
                    .iter()
                    .all(|v| (v - want).abs() < 1e-6)
            );
        }
        assert!(RgbImage::new(2, 2, vec![0.0; 11]).is_err());
        assert!(RgbImage::new(1, 1, vec![0.0, f32::NAN, 0.0]).is_err());
        let gray = GrayImage::new(1, 1, vec![0.5]).unwrap();
        assert_eq!(RgbImage::from_gray(&gray).data(), &[0.5, 0.5, 0.5]);
    }
}
