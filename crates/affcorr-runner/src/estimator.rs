//! Images and matched points in, affine correspondences out (docs/design.md §2, §6).
//!
//! For each match x1 ↔ x2, a 32×32 patch is cut around x1 in image A and around x2 in image B
//! ([`affcorr_image::patches`]); the shape network gives each patch an orientation O and a scale S and
//! the pair a residual shape A″ ([`crate::shape`]); the AC's affine map is
//!
//! ```text
//! A = S_AB · R(O_AB) · A′(A″),   O_AB = O_B − O_A,   S_AB = S_B / S_A,
//! ```
//!
//! with R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]] and A′ = det-normalise([[1+x0, 0], [x1, 1+x2]])
//! ([`affcorr_geom::affine::synthesize`]). The rows are `[x1, y1, x2, y2, a11, a12, a21, a22]`.

use std::path::Path;

use crate::error::{Result, RunnerError};
use crate::shape::{ShapeModel, ShapeModelOptions, ShapePrediction};
use affcorr_image::extract_named;
use affcorr_image::{AffineRefineOptions, GrayImage, affine_confidence, refine_affine};

/// A shape network ready to turn matches into ACs.
#[derive(Debug)]
pub struct ShapeEstimator {
    model: ShapeModel,
}

/// ACs with the per-patch quantities they were built from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ShapeEstimate {
    /// `[x1, y1, x2, y2, a11, a12, a21, a22]` per match.
    pub corrs: Vec<[f64; 8]>,
    /// O of the patch in image A, radians.
    pub orientation_a: Vec<f64>,
    /// O of the patch in image B, radians.
    pub orientation_b: Vec<f64>,
    /// S of the patch in image A.
    pub scale_a: Vec<f64>,
    /// S of the patch in image B.
    pub scale_b: Vec<f64>,
    /// A″ of each pair.
    pub residual_shape: Vec<[f64; 3]>,
    /// The network's uncertainty about each pair ([`ShapePrediction::spread`]).
    pub spread: Vec<affcorr_image::NetworkSpread>,
    /// The confidence of each AC from the network's spread and the neighbouring ACs
    /// ([`affcorr_image::confidence`], model `Network`); [`ShapeEstimator::estimate_refined`]
    /// replaces it with the refined ACs' confidence.
    pub confidence: affcorr_image::AcConfidence,
    /// The refinement's report, from [`ShapeEstimator::estimate_refined`].
    pub refinement: Option<affcorr_image::AffineRefinement>,
}

impl ShapeEstimator {
    /// Wraps a loaded model.
    pub fn new(model: ShapeModel) -> Self {
        Self { model }
    }

    /// Loads a model file ([`ShapeModel::load_with`]).
    pub fn load(path: impl AsRef<Path>, options: &ShapeModelOptions) -> Result<Self> {
        ShapeModel::load_with(path, options).map(Self::new)
    }

    /// The model.
    pub fn model(&self) -> &ShapeModel {
        &self.model
    }

    /// The ACs of the matches `x1[i]` (in `image_a`) ↔ `x2[i]` (in `image_b`), pixels.
    ///
    /// Errors: `x1` and `x2` of different lengths, a non-finite point (naming the row), or a
    /// model problem.
    pub fn estimate(
        &self,
        image_a: &GrayImage,
        image_b: &GrayImage,
        x1: &[[f64; 2]],
        x2: &[[f64; 2]],
    ) -> Result<ShapeEstimate> {
        if x1.len() != x2.len() {
            return Err(RunnerError::invalid(
                "x2",
                format!("{} points, but x1 has {}", x2.len(), x1.len()),
            ));
        }
        let patch_a = extract_named(image_a, x1, "x1")?;
        let patch_b = extract_named(image_b, x2, "x2")?;
        let prediction = self.model.predict(&patch_a, &patch_b)?;
        assemble(prediction, x1, x2)
    }

    /// [`Self::estimate`], then the affine Lucas–Kanade refinement of the ACs against the images
    /// ([`affcorr_image::refine_affine`] with `options`): `corrs` are the refined rows (the
    /// network's where the refinement failed, with a low confidence), `refinement` its report,
    /// and `confidence` from the network's spread, the refinement and the neighbours.
    pub fn estimate_refined(
        &self,
        image_a: &GrayImage,
        image_b: &GrayImage,
        x1: &[[f64; 2]],
        x2: &[[f64; 2]],
        options: &AffineRefineOptions,
    ) -> Result<ShapeEstimate> {
        let mut e = self.estimate(image_a, image_b, x1, x2)?;
        let r = refine_affine(image_a, image_b, &e.corrs, options)?;
        e.confidence = affine_confidence(&r.corrs, Some(&e.spread), Some(&r))?;
        e.corrs = r.corrs.clone();
        e.refinement = Some(r);
        Ok(e)
    }
}

/// ACs from a prediction and the points it was made at.
fn assemble(p: ShapePrediction, x1: &[[f64; 2]], x2: &[[f64; 2]]) -> Result<ShapeEstimate> {
    let corrs: Vec<[f64; 8]> = p
        .affine()?
        .iter()
        .zip(x1.iter().zip(x2))
        .map(|(a, (p1, p2))| [p1[0], p1[1], p2[0], p2[1], a[0], a[1], a[2], a[3]])
        .collect();
    let spread = p.spread();
    let confidence = affine_confidence(&corrs, Some(&spread), None)?;
    Ok(ShapeEstimate {
        corrs,
        spread,
        confidence,
        refinement: None,
        orientation_a: p.orientation_a,
        orientation_b: p.orientation_b,
        scale_a: p.scale_a,
        scale_b: p.scale_b,
        residual_shape: p.residual_shape,
    })
}
