//! [`Features`]: one image's features for the pipeline ([`crate::Pipeline::extract`]), computed
//! once and matched with any number of other images ([`crate::Pipeline::match_features`]),
//! with results bit-identical to [`crate::Pipeline::match_pair`]'s.
//!
//! A feature set holds the working image (the shape network's patches and the affine
//! refinement read it; the view cascade warps it), its scale from the original pixels, the
//! turn of a file's EXIF orientation that it was shown upright by (coordinates are reported in
//! the file's stored pixel grid: `affcorr_image::orientation`), and the matcher's keypoints
//! and descriptors ([`ImageFeatures`]). [`Features::to_bytes`] and
//! [`Features::from_bytes`] store it (little-endian, versioned), for a cache on disk.

use std::time::Duration;

use affcorr_image::{AffineWarp, GrayImage, Orientation, RgbImage};
use affcorr_runner::{
    DenseFeatures, FeatureData, ImageFeatures, Matcher, MatcherTimings, SparseFeatures,
};

use crate::error::{PipelineError, Result};

/// One image's features ([`crate::Pipeline::extract`]); cloneable, `Send` and `Sync`.
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    /// The image at the working resolution (after `max_side`), shown upright (`orientation`).
    pub(crate) work: GrayImage,
    /// Working pixels per original pixel, (x, y) of the upright image
    /// ([`affcorr_image::limit_side`]).
    pub(crate) scale: [f64; 2],
    /// How the original image was turned upright before extraction: its file's EXIF
    /// orientation, or upright (arrays, or the pipeline's `exif_orientation` off).
    pub(crate) orientation: Orientation,
    /// (W, H) of the original image as stored (before `orientation`'s turn).
    pub(crate) original_size: (usize, usize),
    /// The matcher's features of the working image.
    pub(crate) matcher: ImageFeatures,
    /// The pipeline's keypoint budget, detection threshold and `max_side` (checked when
    /// matching).
    pub(crate) max_keypoints: usize,
    pub(crate) detection_threshold: Option<f32>,
    pub(crate) max_side: Option<usize>,
    /// Decoding (and downscaling) time.
    pub(crate) decode: Duration,
}

const MAGIC: &[u8; 4] = b"AFCF";
/// 2: the detection threshold after the keypoint budget; 3: the orientation after the original
/// size.
const VERSION: u32 = 3;

impl Features {
    /// The matcher that computed them.
    pub fn matcher(&self) -> Matcher {
        self.matcher.matcher
    }

    /// (W, H) of the original image as stored (as its file's header gives it).
    pub fn image_size(&self) -> (usize, usize) {
        self.original_size
    }

    /// How the image was turned upright before extraction (its file's EXIF orientation;
    /// upright for arrays, or with the pipeline's `exif_orientation` off).
    pub fn orientation(&self) -> Orientation {
        self.orientation
    }

    /// The map from the stored pixels to the upright ones, when the image was turned.
    pub(crate) fn upright_warp(&self) -> Option<AffineWarp> {
        let (w, h) = self.original_size;
        (!self.orientation.is_upright()).then(|| self.orientation.display_warp(w, h).0)
    }

    /// (W, H) at the working resolution.
    pub fn working_size(&self) -> (usize, usize) {
        (self.work.width(), self.work.height())
    }

    /// Working pixels per original pixel, (x, y).
    pub fn scale(&self) -> [f64; 2] {
        self.scale
    }

    /// Keypoints (semi-dense cells) found; 0 for a dense matcher.
    pub fn len(&self) -> usize {
        self.matcher.len()
    }

    /// Whether none was found (always for a dense matcher).
    pub fn is_empty(&self) -> bool {
        self.matcher.is_empty()
    }

    /// The keypoints in the original image's stored pixels (pixel centres at integers), as the
    /// ACs are: x = (x_work + 0.5)/s − 0.5 per axis, turned back from upright; empty for a
    /// dense matcher.
    pub fn keypoints(&self) -> Vec<[f64; 2]> {
        let [sx, sy] = self.scale;
        let to_stored = self.upright_warp().map(|w| {
            w.inverse()
                .expect("an orientation's warp is a signed permutation")
        });
        self.matcher
            .keypoints()
            .iter()
            .map(|&[x, y]| {
                let p = [
                    (f64::from(x) + 0.5) / sx - 0.5,
                    (f64::from(y) + 0.5) / sy - 0.5,
                ];
                to_stored.map_or(p, |w| w.apply(p))
            })
            .collect()
    }

    /// The detector's scores (sparse matchers; empty otherwise).
    pub fn scores(&self) -> &[f32] {
        match &self.matcher.data {
            FeatureData::Sparse(f) => &f.scores,
            _ => &[],
        }
    }

    /// The descriptors, `len()` × [`Self::descriptor_dim`] (empty for a dense matcher).
    pub fn descriptors(&self) -> &[f32] {
        match &self.matcher.data {
            FeatureData::Sparse(f) => &f.descriptors,
            FeatureData::SemiDense(f) => &f.descriptors,
            FeatureData::Colour(_) => &[],
        }
    }

    /// The descriptor length (0 for a dense matcher).
    pub fn descriptor_dim(&self) -> usize {
        match &self.matcher.data {
            FeatureData::Sparse(f) => f.dim,
            FeatureData::SemiDense(f) => f.dim,
            FeatureData::Colour(_) => 0,
        }
    }

    /// The matcher's features (of the working image).
    pub fn image_features(&self) -> &ImageFeatures {
        &self.matcher
    }

    /// Wall time of decoding and of the matcher's extraction.
    pub fn extraction_time(&self) -> Duration {
        let t = &self.matcher.timings;
        self.decode + t.preprocess + t.network + t.detection
    }

    /// Counts `d` more decoding time (for callers that decode or convert the image
    /// themselves, such as the Python bindings).
    pub fn add_decode_time(&mut self, d: Duration) {
        self.decode += d;
    }

    /// The features as bytes ([`Self::from_bytes`] reads them back, equal but for the times).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer(Vec::with_capacity(
            64 + 4 * (self.work.data().len() + self.descriptors().len() + 3 * self.len()),
        ));
        w.0.extend_from_slice(MAGIC);
        w.u32(VERSION);
        w.str(self.matcher().name());
        w.u64(self.max_keypoints as u64);
        w.f64(self.detection_threshold.map_or(f64::NAN, f64::from));
        w.u64(self.max_side.map_or(0, |s| s as u64));
        w.size(self.original_size);
        w.u32(u32::from(self.orientation.exif()));
        w.f64(self.scale[0]);
        w.f64(self.scale[1]);
        w.size((self.work.width(), self.work.height()));
        w.f32s(self.work.data());
        w.size(self.matcher.image_size);
        match &self.matcher.data {
            FeatureData::Sparse(f) => {
                w.u32(0);
                w.u64(f.dim as u64);
                w.points(&f.keypoints);
                w.f32s(&f.scores);
                w.f32s(&f.descriptors);
                w.size(f.image_size);
            }
            FeatureData::SemiDense(f) => {
                w.u32(1);
                w.u64(f.dim as u64);
                w.points(&f.keypoints);
                w.f32s(&f.inv_scale);
                w.f32s(&f.descriptors);
            }
            FeatureData::Colour(img) => {
                w.u32(2);
                w.size((img.width(), img.height()));
                w.f32s(img.data());
            }
        }
        w.0
    }

    /// Features written by [`Self::to_bytes`]; a truncated, foreign or inconsistent buffer is
    /// an error naming `data`.
    pub fn from_bytes(data: &[u8]) -> Result<Self> {
        let mut r = Reader { data, pos: 0 };
        if r.take(4)? != MAGIC {
            return Err(bad("not affcorr features (no AFCF header)"));
        }
        let version = r.u32()?;
        if version != VERSION {
            return Err(bad(format!(
                "format version {version}, this build reads {VERSION}"
            )));
        }
        let matcher: Matcher = r.str()?.parse().map_err(|_| bad("unknown matcher name"))?;
        let max_keypoints = r.usize()?;
        let threshold = r.f64()?;
        let detection_threshold = (!threshold.is_nan()).then_some(threshold as f32);
        let max_side = match r.usize()? {
            0 => None,
            s => Some(s),
        };
        let original_size = r.size()?;
        let orientation = u8::try_from(r.u32()?)
            .ok()
            .and_then(Orientation::from_exif)
            .ok_or_else(|| bad("unknown orientation"))?;
        let scale = [r.f64()?, r.f64()?];
        let (ww, wh) = r.size()?;
        let work =
            GrayImage::new(ww, wh, r.f32s()?).map_err(|e| bad(format!("working image: {e}")))?;
        let image_size = r.size()?;
        let feature_data = match r.u32()? {
            0 => {
                let dim = r.usize()?;
                let keypoints = r.points()?;
                let scores = r.f32s()?;
                let descriptors = r.f32s()?;
                let size = r.size()?;
                if scores.len() != keypoints.len() || descriptors.len() != keypoints.len() * dim {
                    return Err(bad("inconsistent sparse feature sizes"));
                }
                FeatureData::Sparse(SparseFeatures {
                    keypoints,
                    scores,
                    descriptors,
                    dim,
                    image_size: size,
                })
            }
            1 => {
                let dim = r.usize()?;
                let keypoints = r.points()?;
                let inv_scale = r.f32s()?;
                let descriptors = r.f32s()?;
                if inv_scale.len() != keypoints.len() || descriptors.len() != keypoints.len() * dim
                {
                    return Err(bad("inconsistent semi-dense feature sizes"));
                }
                FeatureData::SemiDense(DenseFeatures {
                    keypoints,
                    inv_scale,
                    descriptors,
                    dim,
                })
            }
            2 => {
                let (w, h) = r.size()?;
                FeatureData::Colour(
                    RgbImage::new(w, h, r.f32s()?)
                        .map_err(|e| bad(format!("colour image: {e}")))?,
                )
            }
            k => return Err(bad(format!("unknown feature kind {k}"))),
        };
        let consistent = matches!(
            (&feature_data, matcher),
            (FeatureData::Colour(_), Matcher::Dense)
                | (FeatureData::SemiDense(_), Matcher::XFeatStar)
                | (
                    FeatureData::Sparse(_),
                    Matcher::XFeatMnn
                        | Matcher::XFeatLighterGlue
                        | Matcher::DiskLightGlue
                        | Matcher::AlikedLightGlue
                )
        );
        if !consistent || r.pos != data.len() {
            return Err(bad("inconsistent or trailing data"));
        }
        Ok(Self {
            work,
            scale,
            orientation,
            original_size,
            matcher: ImageFeatures {
                matcher,
                image_size,
                data: feature_data,
                timings: MatcherTimings::default(),
            },
            max_keypoints,
            detection_threshold,
            max_side,
            decode: Duration::ZERO,
        })
    }
}

fn bad(msg: impl Into<String>) -> PipelineError {
    PipelineError::invalid("data", msg.into())
}

struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn size(&mut self, (w, h): (usize, usize)) {
        self.u64(w as u64);
        self.u64(h as u64);
    }
    fn str(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
    }
    fn f32s(&mut self, v: &[f32]) {
        self.u64(v.len() as u64);
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn points(&mut self, v: &[[f32; 2]]) {
        self.u64(v.len() as u64);
        for p in v {
            self.0.extend_from_slice(&p[0].to_le_bytes());
            self.0.extend_from_slice(&p[1].to_le_bytes());
        }
    }
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| bad("truncated"))?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn usize(&mut self) -> Result<usize> {
        usize::try_from(self.u64()?).map_err(|_| bad("a size over usize"))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn size(&mut self) -> Result<(usize, usize)> {
        Ok((self.usize()?, self.usize()?))
    }
    fn str(&mut self) -> Result<&'a str> {
        let n = self.usize()?;
        std::str::from_utf8(self.take(n)?).map_err(|_| bad("a name that is not UTF-8"))
    }
    fn count(&mut self, item: usize) -> Result<usize> {
        let n = self.usize()?;
        // A count larger than what is left is corruption, not an allocation to attempt.
        if n.saturating_mul(item) > self.data.len() - self.pos {
            return Err(bad("truncated"));
        }
        Ok(n)
    }
    fn f32s(&mut self) -> Result<Vec<f32>> {
        let n = self.count(4)?;
        let bytes = self.take(4 * n)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }
    fn points(&mut self) -> Result<Vec<[f32; 2]>> {
        let n = self.count(8)?;
        let bytes = self.take(8 * n)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|c| {
                [
                    f32::from_le_bytes(c[..4].try_into().expect("4 bytes")),
                    f32::from_le_bytes(c[4..].try_into().expect("4 bytes")),
                ]
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(data: FeatureData, matcher: Matcher) -> Features {
        Features {
            work: GrayImage::new(3, 2, vec![0.0, 0.1, 0.2, 0.3, 0.4, 0.5]).unwrap(),
            scale: [0.5, 0.5],
            orientation: Orientation::Upright,
            original_size: (6, 4),
            matcher: ImageFeatures {
                matcher,
                image_size: (3, 2),
                data,
                timings: MatcherTimings::default(),
            },
            max_keypoints: 10,
            detection_threshold: (matcher != Matcher::Dense).then_some(0.25),
            max_side: Some(3),
            decode: Duration::ZERO,
        }
    }

    #[test]
    fn bytes_round_trip_every_kind_and_reject_damage() {
        let sparse = FeatureData::Sparse(SparseFeatures {
            keypoints: vec![[1.0, 0.5], [2.0, 1.5]],
            scores: vec![0.9, 0.1],
            descriptors: vec![0.1, 0.2, 0.3, 0.4],
            dim: 2,
            image_size: (3, 2),
        });
        let semi = FeatureData::SemiDense(DenseFeatures {
            keypoints: vec![[1.0, 0.5]],
            inv_scale: vec![1.5],
            descriptors: vec![0.5, 0.25],
            dim: 2,
        });
        let colour = FeatureData::Colour(RgbImage::new(1, 1, vec![0.1, 0.2, 0.3]).unwrap());
        for (d, m) in [
            (sparse, Matcher::XFeatLighterGlue),
            (semi, Matcher::XFeatStar),
            (colour, Matcher::Dense),
        ] {
            let f = sample(d, m);
            let bytes = f.to_bytes();
            assert_eq!(Features::from_bytes(&bytes).unwrap(), f);
            for cut in [0, 3, 10, bytes.len() - 1] {
                let e = Features::from_bytes(&bytes[..cut]).unwrap_err().to_string();
                assert!(e.contains("data"), "{e}");
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(Features::from_bytes(&longer).is_err());
        }
        let f = sample(
            FeatureData::Sparse(SparseFeatures {
                keypoints: vec![[1.0, 0.5]],
                scores: vec![1.0],
                descriptors: vec![1.0],
                dim: 1,
                image_size: (3, 2),
            }),
            Matcher::XFeatMnn,
        );
        assert_eq!(f.keypoints(), vec![[2.5, 1.5]]);
        // Stored 4 × 6 and shown turned by 90° clockwise (6 × 4): the shown (x, y) is the stored
        // (y, 6 - 1 - x), so the upright (2.5, 1.5) is stored at (1.5, 2.5); the orientation
        // survives the bytes.
        let turned = Features {
            orientation: Orientation::Rotate90,
            original_size: (4, 6),
            ..f
        };
        assert_eq!(turned.keypoints(), vec![[1.5, 2.5]]);
        let back = Features::from_bytes(&turned.to_bytes()).unwrap();
        assert_eq!(back.orientation(), Orientation::Rotate90);
        assert_eq!(back, turned);
    }
}
