//! Images for affcorr: decoding, gray and colour buffers, resizing to a working resolution,
//! 32×32 patches, and the affine Lucas–Kanade refinement of ACs against the two images. No
//! ONNX here: the networks are in `affcorr-runner`.
//!
//! - [`gray`]: [`GrayImage`], grayscale `f32` in [0, 1] as the networks see it; PNG/JPEG
//!   decoding with format and truncation checks; raw buffers (u8, u16, f32; 1–4 channels).
//! - [`rgb`]: [`RgbImage`], interleaved colour for the matchers that see colour.
//! - [`resize`]: downscaling to a working resolution and the map of ACs back to the original
//!   pixels.
//! - [`patches`]: bilinear 32×32 patches at sub-pixel centres, `(N, 1, 32, 32)`.
//! - [`affine_refine`]: affine Lucas–Kanade refinement of ACs, coarse to fine.
//! - [`warp`]: synthetic views (rotation, zoom, tilt) and the map of their ACs back.
//! - [`error`]: [`ImageError`], which names what went wrong.
//!
//! Conventions are docs/design.md §2's: pixels (x, y) with x right and y down, pixel centres at
//! integer coordinates, ACs `[x1, y1, x2, y2, a11, a12, a21, a22]` with A = ∂x2/∂x1.
//!
//! ```
//! use affcorr_image::{GrayImage, extract_patches, PATCH_SIZE};
//! let img = GrayImage::new(64, 48, (0..64 * 48).map(|i| (i % 64) as f32 / 63.0).collect())?;
//! let patches = extract_patches(&img, &[[31.5, 20.0]])?;
//! assert_eq!(patches.patch(0).len(), PATCH_SIZE * PATCH_SIZE);
//! # Ok::<(), affcorr_image::ImageError>(())
//! ```

pub mod affine_refine;
pub mod confidence;
pub mod error;
pub mod gray;
pub mod orientation;
pub mod patches;
pub mod resize;
pub mod rgb;
pub mod warp;

pub use affine_refine::{AffineRefineOptions, AffineRefinement, RefineStatus, refine_affine};
pub use confidence::{AcConfidence, ConfidenceModel, NetworkSpread, affine_confidence};
pub use error::{ImageError, Result};
pub use gray::{GrayImage, LUMA_WEIGHTS, PixelData};
pub use orientation::Orientation;
pub use patches::{PATCH_LEN, PATCH_SIZE, Patches, extract_named, extract_patches};
pub use resize::{ac_to_original, limit_side};
pub use rgb::RgbImage;
pub use warp::{AffineWarp, ac_from_views, warp_image};
