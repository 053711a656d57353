//! 32×32 patches at sub-pixel centres, cut by bilinear sampling (docs/design.md §6).
//!
//! Pixel (r, c) of the patch around (x, y) is the image read at
//!
//! ```text
//! (u, v) = (x − 15.5 + c, y − 15.5 + r),   r, c = 0..31,
//! ```
//!
//! so the patch centre, between its pixels 15 and 16, is (x, y). Pixel centres lie at integer
//! coordinates, x to the right and y down (docs/design.md §2). The image is read bilinearly,
//!
//! ```text
//! I(u, v) = (1−fx)(1−fy) I[y0, x0] + fx (1−fy) I[y0, x0+1] + (1−fx) fy I[y0+1, x0] + fx fy I[y0+1, x0+1]
//! ```
//!
//! with x0 = ⌊u⌋, fx = u − x0 (same for v), and reads outside the image replicate the border
//! (equivalently: u is clamped to [0, W−1] and v to [0, H−1] first). This is
//! `scipy.ndimage.map_coordinates(order=1, mode="nearest")`.
//!
//! The output is contiguous `(N, 1, 32, 32)` `f32`, the shape network's input.

use rayon::prelude::*;

use crate::error::{ImageError, Result};
use crate::gray::GrayImage;

/// Side of a patch in pixels.
pub const PATCH_SIZE: usize = 32;
/// Values per patch.
pub const PATCH_LEN: usize = PATCH_SIZE * PATCH_SIZE;
/// Offset of a patch's first pixel from its centre: (32 − 1) / 2.
pub const PATCH_HALF: f64 = 15.5;

/// Batches at least this large are cut in parallel.
const PARALLEL_MIN: usize = 64;

/// `N` patches, row-major `(N, 1, 32, 32)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Patches {
    data: Vec<f32>,
}

impl Patches {
    /// Wraps `(N, 1, 32, 32)` data (`data.len()` a multiple of 1024, all finite).
    pub fn from_vec(data: Vec<f32>) -> Result<Self> {
        if !data.len().is_multiple_of(PATCH_LEN) {
            return Err(ImageError::invalid(
                "patches",
                format!(
                    "{} values is not a whole number of 1×32×32 patches",
                    data.len()
                ),
            ));
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(ImageError::NonFinite {
                what: "patches",
                row: i / PATCH_LEN,
            });
        }
        Ok(Self { data })
    }

    /// The number of patches.
    pub fn len(&self) -> usize {
        self.data.len() / PATCH_LEN
    }

    /// Whether there are no patches.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// All values, `(N, 1, 32, 32)` row-major.
    pub fn as_slice(&self) -> &[f32] {
        &self.data
    }

    /// Patch `i`, 32×32 row-major.
    pub fn patch(&self, i: usize) -> &[f32] {
        &self.data[i * PATCH_LEN..(i + 1) * PATCH_LEN]
    }

    /// The values, consuming the patches.
    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }
}

/// Cuts one patch per centre (x, y) from `image`; see the module docs for the sampling.
///
/// ```
/// use affcorr_image::{GrayImage, extract_patches};
/// // I(x, y) = x: bilinear sampling reproduces it exactly away from the border.
/// let (w, h) = (64, 48);
/// let img = GrayImage::new(w, h, (0..w * h).map(|i| (i % w) as f32).collect()).unwrap();
/// let p = extract_patches(&img, &[[30.25, 20.0]]).unwrap();
/// assert!((p.patch(0)[0] - (30.25 - 15.5) as f32).abs() < 1e-5); // r = c = 0
/// assert!((p.patch(0)[31] - (30.25 + 15.5) as f32).abs() < 1e-5); // c = 31
/// ```
pub fn extract_patches(image: &GrayImage, centres: &[[f64; 2]]) -> Result<Patches> {
    extract_named(image, centres, "centres")
}

/// [`extract_patches`] with the argument name used in errors.
pub fn extract_named(
    image: &GrayImage,
    centres: &[[f64; 2]],
    what: &'static str,
) -> Result<Patches> {
    if let Some(row) = centres
        .iter()
        .position(|c| !(c[0].is_finite() && c[1].is_finite()))
    {
        return Err(ImageError::NonFinite { what, row });
    }
    let mut data = vec![0.0f32; centres.len() * PATCH_LEN];
    let cut = |(out, c): (&mut [f32], &[f64; 2])| cut_patch(image, c[0], c[1], out);
    if centres.len() >= PARALLEL_MIN {
        data.par_chunks_mut(PATCH_LEN).zip(centres).for_each(cut);
    } else {
        data.chunks_mut(PATCH_LEN).zip(centres).for_each(cut);
    }
    Ok(Patches { data })
}

/// One patch into `out` (1024 values). All patch pixels share the fractional offsets, so when
/// the patch's footprint lies inside the image the weights are computed once; otherwise every
/// read clamps its coordinates.
fn cut_patch(image: &GrayImage, x: f64, y: f64, out: &mut [f32]) {
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let (u0, v0) = (x - PATCH_HALF, y - PATCH_HALF);
    let (xf, yf) = (u0.floor(), v0.floor());
    let last = (PATCH_SIZE - 1) as f64;
    // Inside when x0 ≥ 0, x0 + 31 + 1 ≤ W − 1 (and the same for y): no read needs clamping.
    let inside = xf >= 0.0 && yf >= 0.0 && xf + last + 1.0 < w as f64 && yf + last + 1.0 < h as f64;
    if inside {
        let (x0, y0) = (xf as usize, yf as usize);
        let (fx, fy) = (u0 - xf, v0 - yf);
        let w00 = ((1.0 - fx) * (1.0 - fy)) as f32;
        let w01 = (fx * (1.0 - fy)) as f32;
        let w10 = ((1.0 - fx) * fy) as f32;
        let w11 = (fx * fy) as f32;
        for (r, out_row) in out.chunks_exact_mut(PATCH_SIZE).enumerate() {
            let top = &data[(y0 + r) * w + x0..(y0 + r) * w + x0 + PATCH_SIZE + 1];
            let bottom = &data[(y0 + r + 1) * w + x0..(y0 + r + 1) * w + x0 + PATCH_SIZE + 1];
            for c in 0..PATCH_SIZE {
                out_row[c] =
                    w00 * top[c] + w01 * top[c + 1] + w10 * bottom[c] + w11 * bottom[c + 1];
            }
        }
        return;
    }
    let (wmax, hmax) = ((w - 1) as f64, (h - 1) as f64);
    // Per column: clamped x0, x1 and fx; per row the same for y.
    let mut cols = [(0usize, 0usize, 0.0f64); PATCH_SIZE];
    for (c, col) in cols.iter_mut().enumerate() {
        *col = axis(u0 + c as f64, wmax);
    }
    for (r, out_row) in out.chunks_exact_mut(PATCH_SIZE).enumerate() {
        let (y0, y1, fy) = axis(v0 + r as f64, hmax);
        let (top, bottom) = (&data[y0 * w..(y0 + 1) * w], &data[y1 * w..(y1 + 1) * w]);
        for (o, &(x0, x1, fx)) in out_row.iter_mut().zip(&cols) {
            let t = (1.0 - fx) * top[x0] as f64 + fx * top[x1] as f64;
            let b = (1.0 - fx) * bottom[x0] as f64 + fx * bottom[x1] as f64;
            *o = ((1.0 - fy) * t + fy * b) as f32;
        }
    }
}

/// The two neighbours and the weight of the second for coordinate `u` clamped to [0, max].
#[inline]
fn axis(u: f64, max: f64) -> (usize, usize, f64) {
    let u = u.clamp(0.0, max);
    let f = u.floor();
    let i0 = f as usize;
    let i1 = if f < max { i0 + 1 } else { i0 };
    (i0, i1, u - f)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> GrayImage {
        GrayImage::new(
            w,
            h,
            (0..w * h)
                .map(|i| 0.01 * (i % w) as f32 + 0.02 * (i / w) as f32)
                .collect(),
        )
        .unwrap()
    }

    #[test]
    fn both_paths_agree_where_they_meet() {
        // A centre just inside (fast path) and the same patch forced through the clamping path
        // must give the same values.
        let img = ramp(40, 40);
        let (x, y) = (16.3, 17.8);
        let mut fast = vec![0.0; PATCH_LEN];
        cut_patch(&img, x, y, &mut fast);
        let mut slow = vec![0.0; PATCH_LEN];
        let (u0, v0) = (x - PATCH_HALF, y - PATCH_HALF);
        for r in 0..PATCH_SIZE {
            let (y0, y1, fy) = axis(v0 + r as f64, 39.0);
            for c in 0..PATCH_SIZE {
                let (x0, x1, fx) = axis(u0 + c as f64, 39.0);
                let g = |xx: usize, yy: usize| img.get(xx, yy) as f64;
                slow[r * PATCH_SIZE + c] = ((1.0 - fy) * ((1.0 - fx) * g(x0, y0) + fx * g(x1, y0))
                    + fy * ((1.0 - fx) * g(x0, y1) + fx * g(x1, y1)))
                    as f32;
            }
        }
        for (a, b) in fast.iter().zip(&slow) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn one_pixel_image_is_constant() {
        let img = GrayImage::new(1, 1, vec![0.25]).unwrap();
        let p = extract_patches(&img, &[[0.0, 0.0], [-100.5, 7.25]]).unwrap();
        assert!(p.as_slice().iter().all(|&v| v == 0.25));
    }
}
