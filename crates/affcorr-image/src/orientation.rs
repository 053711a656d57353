//! The EXIF orientation of an image file: how its stored pixels are turned for display.
//!
//! A camera held in portrait stores a landscape pixel grid and tags the file with the turn that
//! shows it upright (EXIF tag 0x0112, values 1–8; PNG's eXIf chunk carries the same tag). So
//! two photographs of one scene taken in portrait and in landscape are stored a quarter turn
//! apart, which matchers that are not rotation invariant (XFeat, LighterGlue, LightGlue) do not
//! match. The pipeline matches the images turned upright ([`Orientation::turn`]) and reports
//! every coordinate in the **stored** pixel grid, as the file's width and height give it: what
//! COLMAP, PIL and a camera's calibration use, so that intrinsics are shared by all of a
//! camera's images whatever way it was held (docs/design.md §2).
//! [`Orientation::display_warp`] is the exact map between the two grids, so ACs map back with
//! [`crate::ac_from_views`].
//!
//! Only the turn of a tag is applied, never its mirror (tags 2, 4, 5 and 7: a front camera's
//! preview). The stored pixels are the camera's projection of the scene; their mirror image is
//! the projection of no camera, its homographies reverse orientation, and no matcher's
//! descriptors meet a mirrored image. A turn keeps up as up, so the turn of a mirrored tag
//! shows the scene upright and unmirrored.

use crate::warp::AffineWarp;

/// How an image file's stored pixels are turned for display (the EXIF orientation tag).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Orientation {
    /// Shown as stored (EXIF 1, or no tag).
    #[default]
    Upright,
    /// Mirrored left to right (EXIF 2).
    FlipHorizontal,
    /// Turned by 180° (EXIF 3).
    Rotate180,
    /// Mirrored top to bottom (EXIF 4).
    FlipVertical,
    /// Turned by 90° clockwise, then mirrored left to right: the transpose (EXIF 5).
    Transpose,
    /// Turned by 90° clockwise (EXIF 6: a camera held in portrait, turned right).
    Rotate90,
    /// Turned by 270° clockwise, then mirrored left to right (EXIF 7).
    Transverse,
    /// Turned by 270° clockwise, i.e. 90° counter-clockwise (EXIF 8).
    Rotate270,
}

impl Orientation {
    /// The orientation of an EXIF tag value (1–8); `None` for any other value.
    pub fn from_exif(tag: u8) -> Option<Self> {
        Some(match tag {
            1 => Self::Upright,
            2 => Self::FlipHorizontal,
            3 => Self::Rotate180,
            4 => Self::FlipVertical,
            5 => Self::Transpose,
            6 => Self::Rotate90,
            7 => Self::Transverse,
            8 => Self::Rotate270,
            _ => return None,
        })
    }

    /// The EXIF tag value (1–8).
    pub fn exif(self) -> u8 {
        match self {
            Self::Upright => 1,
            Self::FlipHorizontal => 2,
            Self::Rotate180 => 3,
            Self::FlipVertical => 4,
            Self::Transpose => 5,
            Self::Rotate90 => 6,
            Self::Transverse => 7,
            Self::Rotate270 => 8,
        }
    }

    /// Whether the stored pixels are shown as they are.
    pub fn is_upright(self) -> bool {
        self == Self::Upright
    }

    /// The turn of this orientation without its mirror: a mirror left to right keeps up as up,
    /// so the turn alone shows the image upright, as the camera saw it (tag 5, a quarter turn
    /// clockwise and a mirror, is a quarter turn clockwise; tag 2 is upright).
    pub fn turn(self) -> Self {
        match self {
            Self::Upright | Self::FlipHorizontal => Self::Upright,
            Self::Rotate180 | Self::FlipVertical => Self::Rotate180,
            Self::Rotate90 | Self::Transpose => Self::Rotate90,
            Self::Rotate270 | Self::Transverse => Self::Rotate270,
        }
    }

    /// Whether the image is shown with its width and height exchanged (the quarter turns and
    /// the two diagonal mirrors).
    pub fn swaps_axes(self) -> bool {
        matches!(
            self,
            Self::Transpose | Self::Rotate90 | Self::Transverse | Self::Rotate270
        )
    }

    /// The map x_shown = M x_stored + c of an image stored `width` × `height` (pixel centres at
    /// integers, y down), and the size it is shown at. M is a signed permutation, so the map is
    /// exact and the pixels move without resampling: the displayed image is the `image`
    /// crate's `apply_orientation` of the stored one (tested for all eight).
    pub fn display_warp(self, width: usize, height: usize) -> (AffineWarp, usize, usize) {
        // Turning by 90° clockwise takes the stored x axis (right) to the shown y axis (down)
        // and the stored y axis (down) to the shown −x axis (left).
        let m = match self {
            Self::Upright => [1.0, 0.0, 0.0, 1.0],
            Self::FlipHorizontal => [-1.0, 0.0, 0.0, 1.0],
            Self::Rotate180 => [-1.0, 0.0, 0.0, -1.0],
            Self::FlipVertical => [1.0, 0.0, 0.0, -1.0],
            Self::Transpose => [0.0, 1.0, 1.0, 0.0],
            Self::Rotate90 => [0.0, -1.0, 1.0, 0.0],
            Self::Transverse => [0.0, -1.0, -1.0, 0.0],
            Self::Rotate270 => [0.0, 1.0, -1.0, 0.0],
        };
        AffineWarp { m, c: [0.0, 0.0] }.fitted(width, height)
    }

    /// Turns a decoded image as this orientation shows it (the pixels [`Self::display_warp`]
    /// maps them to).
    pub fn apply(self, img: &mut image::DynamicImage) {
        if !self.is_upright() {
            img.apply_orientation(self.to_image());
        }
    }

    pub(crate) fn from_image(o: image::metadata::Orientation) -> Self {
        Self::from_exif(o.to_exif()).unwrap_or_default()
    }

    pub(crate) fn to_image(self) -> image::metadata::Orientation {
        image::metadata::Orientation::from_exif(self.exif())
            .expect("every Orientation has an EXIF value the image crate knows")
    }

    /// Every orientation, in EXIF order.
    pub const ALL: [Self; 8] = [
        Self::Upright,
        Self::FlipHorizontal,
        Self::Rotate180,
        Self::FlipVertical,
        Self::Transpose,
        Self::Rotate90,
        Self::Transverse,
        Self::Rotate270,
    ];
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{DynamicImage, GrayImage as Luma8};

    /// A 5 × 3 image whose every pixel is distinct.
    fn numbered() -> DynamicImage {
        DynamicImage::ImageLuma8(Luma8::from_fn(5, 3, |x, y| [(10 * y + x) as u8].into()))
    }

    #[test]
    fn the_display_warp_moves_each_pixel_where_the_image_crate_shows_it() {
        let stored = numbered().to_luma8();
        for o in Orientation::ALL {
            let mut shown = numbered();
            o.apply(&mut shown);
            let shown = shown.to_luma8();
            let (warp, w, h) = o.display_warp(5, 3);
            assert_eq!(
                (w, h),
                (shown.width() as usize, shown.height() as usize),
                "{o:?}"
            );
            assert_eq!(o.swaps_axes(), (w, h) == (3, 5), "{o:?}");
            for (x, y, p) in stored.enumerate_pixels() {
                let [u, v] = warp.apply([f64::from(x), f64::from(y)]);
                assert_eq!(u.fract(), 0.0, "{o:?}");
                assert_eq!(
                    shown.get_pixel(u as u32, v as u32),
                    p,
                    "{o:?} at ({x}, {y})"
                );
            }
        }
    }

    #[test]
    fn exif_values_round_trip_and_others_are_refused() {
        for (k, o) in Orientation::ALL.iter().enumerate() {
            assert_eq!(o.exif() as usize, k + 1);
            assert_eq!(Orientation::from_exif(o.exif()), Some(*o));
            assert_eq!(Orientation::from_image(o.to_image()), *o);
        }
        assert_eq!(Orientation::from_exif(0), None);
        assert_eq!(Orientation::from_exif(9), None);
        assert!(Orientation::default().is_upright() && !Orientation::Rotate90.is_upright());
    }

    #[test]
    fn a_turn_is_the_orientation_less_a_left_right_mirror() {
        for o in Orientation::ALL {
            let t = o.turn();
            assert_eq!(t.turn(), t);
            let (m, ..) = t.display_warp(5, 3);
            // A turn: a rotation (determinant +1)...
            assert_eq!(m.m[0] * m.m[3] - m.m[1] * m.m[2], 1.0, "{o:?}");
            // ... equal to the orientation where that is one, else to it followed by a mirror
            // left to right (x -> -x).
            let (full, ..) = o.display_warp(5, 3);
            let det = full.m[0] * full.m[3] - full.m[1] * full.m[2];
            let mirrored = [-full.m[0], -full.m[1], full.m[2], full.m[3]];
            assert_eq!(if det > 0.0 { full.m } else { mirrored }, m.m, "{o:?}");
        }
    }
}
