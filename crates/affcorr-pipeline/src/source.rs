//! The image arguments of the pipeline: decoded gray or colour buffers, or files to decode.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use affcorr_image::gray::{gray_from_dynamic, open_dynamic};
use affcorr_image::{GrayImage, ImageError, RgbImage};

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
    /// The gray image (decoded from a file, or the luma of a colour one).
    pub fn load(self) -> Result<Cow<'a, GrayImage>, ImageError> {
        match self {
            Self::Image(img) => Ok(Cow::Borrowed(img)),
            Self::Rgb(img) => img.to_gray().map(Cow::Owned),
            Self::Path(p) => GrayImage::open(p).map(Cow::Owned),
        }
    }

    /// The gray image and the colour one a dense matcher takes, decoded once (a gray image
    /// gives R = G = B).
    pub fn load_with_colour(self) -> Result<(Cow<'a, GrayImage>, RgbImage), ImageError> {
        match self {
            Self::Image(img) => Ok((Cow::Borrowed(img), RgbImage::from_gray(img))),
            Self::Rgb(img) => Ok((Cow::Owned(img.to_gray()?), img.clone())),
            Self::Path(p) => {
                let (img, name) = open_dynamic(p)?;
                let gray = gray_from_dynamic(&img, &name)?;
                Ok((Cow::Owned(gray), RgbImage::from_dynamic(&img)))
            }
        }
    }
}
