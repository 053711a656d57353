//! The image arguments of the pipeline: decoded gray or colour buffers, or files to decode.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use affcorr_image::gray::{gray_from_dynamic, open_oriented};
use affcorr_image::{GrayImage, ImageError, Orientation, RgbImage};

/// An image argument: decoded already, or a file to decode (PNG, JPEG).
#[derive(Debug, Clone, Copy)]
pub enum ImageSource<'a> {
    /// A decoded image.
    Image(&'a GrayImage),
    /// A decoded colour image: a dense matcher sees its colour, everything else its BT.601
    /// luma.
    Rgb(&'a RgbImage),
    /// A file path.
    Path(&'a Path),
}

impl<'a> From<&'a RgbImage> for ImageSource<'a> {
    fn from(img: &'a RgbImage) -> Self {
        Self::Rgb(img)
    }
}

impl<'a> From<&'a GrayImage> for ImageSource<'a> {
    fn from(img: &'a GrayImage) -> Self {
        Self::Image(img)
    }
}

impl<'a> From<&'a Path> for ImageSource<'a> {
    fn from(p: &'a Path) -> Self {
        Self::Path(p)
    }
}

impl<'a> From<&'a PathBuf> for ImageSource<'a> {
    fn from(p: &'a PathBuf) -> Self {
        Self::Path(p)
    }
}

impl<'a> From<&'a str> for ImageSource<'a> {
    fn from(p: &'a str) -> Self {
        Self::Path(Path::new(p))
    }
}

impl<'a> ImageSource<'a> {
    /// The gray image (decoded from a file, or the luma of a colour one) and the orientation
    /// it was turned by: with `upright`, a file is turned as its EXIF orientation shows it
    /// (module `affcorr_image::orientation`); otherwise, and for decoded images, it is as
    /// stored and the orientation upright.
    pub fn load(self, upright: bool) -> Result<(Cow<'a, GrayImage>, Orientation), ImageError> {
        match self {
            Self::Image(img) => Ok((Cow::Borrowed(img), Orientation::Upright)),
            Self::Rgb(img) => Ok((Cow::Owned(img.to_gray()?), Orientation::Upright)),
            Self::Path(p) => {
                let (img, name, orientation) = open_oriented(p, upright)?;
                Ok((Cow::Owned(gray_from_dynamic(&img, &name)?), orientation))
            }
        }
    }

    /// [`Self::load`], with the colour image a dense matcher takes, decoded once (a gray image
    /// gives R = G = B).
    pub fn load_with_colour(
        self,
        upright: bool,
    ) -> Result<(Cow<'a, GrayImage>, RgbImage, Orientation), ImageError> {
        match self {
            Self::Image(img) => Ok((
                Cow::Borrowed(img),
                RgbImage::from_gray(img),
                Orientation::Upright,
            )),
            Self::Rgb(img) => Ok((
                Cow::Owned(img.to_gray()?),
                img.clone(),
                Orientation::Upright,
            )),
            Self::Path(p) => {
                let (img, name, orientation) = open_oriented(p, upright)?;
                let gray = gray_from_dynamic(&img, &name)?;
                Ok((Cow::Owned(gray), RgbImage::from_dynamic(&img), orientation))
            }
        }
    }
}
