//! The view cascade's driver (see [`crate::views`], which holds its parts: the views, the
//! screen, the work meter and the verification): the loop that runs the steps after a plain
//! pass that failed (or verified weakly), screens the groups, matches the views, keeps the
//! best and stops at a verified view or at the budget; and the store of the views' features,
//! each warped image extracted once per pair and charged once to the work meter.

use std::collections::{HashMap, HashSet, VecDeque};
use std::rc::Rc;
use std::time::{Duration, Instant};

use affcorr_image::{AffineWarp, GrayImage, ac_from_views, warp_image};
use affcorr_runner::{ImageFeatures, PointMatcher};

use super::{MIN_WORKING_SIDE, Pipeline, WorkMatches};
use crate::error::Result;
use crate::result::Timings;
use crate::views::{
    CONFIDENT_VIEW, ImageWarp, REFINE_BELOW, RIVAL_MARGIN, Step, ViewMode, ViewReport, ViewSpec,
    ViewWarps, WorkMeter, cascade_steps, guided_view, planar_rival, planar_support,
    refinement_view, rival_views, rivalled_by_rotations, screen, screen_run, screen_warps,
    uncertain, verify, weak_yield,
};

/// A warped image of the cascade: the image (0: A, 1: B), the warp's bits and the view's size.
type WarpKey = (usize, [u64; 6], usize, usize);

/// The key of image `image`'s warp `w` in a view (`None`: the image as it is).
fn warp_key(image: usize, w: &ImageWarp) -> Option<WarpKey> {
    w.map(|(warp, vw, vh)| {
        let [a, b, c, d] = warp.m.map(f64::to_bits);
        let [e, f] = warp.c.map(f64::to_bits);
        (image, [a, b, c, d, e, f], vw, vh)
    })
}

/// Whether a view's warped image is too small for the matchers (a side under
/// [`MIN_WORKING_SIDE`]): such a view is skipped, neither side extracted.
fn too_small(w: &ImageWarp) -> bool {
    w.is_some_and(|(_, vw, vh)| vw.min(vh) < MIN_WORKING_SIDE)
}

/// A view waiting to run, with its screen (`None`: not ranked in a screened group).
type Queued = (ViewSpec, Option<usize>);

/// At most this many views guided by the ACs of earlier views, per pair.
const MAX_GUIDED_VIEWS: usize = 3;

impl Pipeline {
    /// The matcher's features of both sides of a view with `warps` (A's, B's): the plain
    /// pass's for a side the view leaves as it is, else those of its warp, extracted once per
    /// pair (`store`); `None` when a warp is too small for the matcher. An extraction here is
    /// timed into `timings`; the matching of a view subtracts its features' extraction times.
    fn view_features(
        &self,
        store: &mut ViewFeatures<'_>,
        warps: &ViewWarps,
        timings: &mut Timings,
    ) -> Result<Option<[Rc<ImageFeatures>; 2]>> {
        store.pair(&self.matcher, false, warps, timings)
    }

    /// The features that screen a view ([`crate::views::screen`]): the screener's where the
    /// pipeline has one, else the matcher's ([`Self::view_features`]).
    fn screen_features(
        &self,
        store: &mut ViewFeatures<'_>,
        warps: &ViewWarps,
        timings: &mut Timings,
    ) -> Result<Option<[Rc<ImageFeatures>; 2]>> {
        match &self.screener {
            Some(screener) => store.pair(screener, true, warps, timings),
            None => self.view_features(store, warps, timings),
        }
    }

    /// Screens `group` ([`screen`]) on images of `sizes`, shrunk ([`screen_warps`]) when
    /// `shrink`: extracts each of its warped images once (adding the work of the
    /// extractions, in plain passes, to `extraction`) and scores its views, in the group's
    /// order. `None` when no view could follow the screen within the budget: the cascade
    /// stops there, as it would after the screen, without paying for it; before the
    /// extractions when they alone would reach the budget (they are most of a group's cost),
    /// after them when the screens would.
    #[allow(clippy::too_many_arguments)]
    fn screen_group(
        &self,
        group: Vec<ViewSpec>,
        shrink: bool,
        store: &mut ViewFeatures<'_>,
        sizes: ((usize, usize), (usize, usize)),
        start: Instant,
        extraction: &mut f64,
        timings: &mut Timings,
    ) -> Result<Option<Vec<Queued>>> {
        let o = &self.views;
        let screened_warps: Vec<ViewWarps> = group
            .iter()
            .map(|v| {
                let warps = v.warps(sizes.0, sizes.1);
                if shrink {
                    screen_warps(&warps, sizes.0, sizes.1)
                } else {
                    warps
                }
            })
            .collect();
        let extracted = store.after_extraction(&screened_warps);
        if !o.within_budget(start.elapsed(), &extracted) {
            return Ok(None);
        }
        let before = store.meter.spent;
        let mut features = Vec::with_capacity(group.len());
        for (v, warps) in group.into_iter().zip(&screened_warps) {
            if let Some(f) = self.screen_features(store, warps, timings)? {
                features.push((v, f));
            }
        }
        debug_assert_eq!(store.meter, extracted);
        *extraction += store.meter.in_passes(store.meter.spent - before);
        let mut screened = store.meter.clone();
        for (_, [fa, fb]) in &features {
            screened.screen((fa.len(), fb.len()));
        }
        if !o.within_budget(start.elapsed(), &screened) {
            return Ok(None);
        }
        store.meter = screened;
        let scored = features
            .into_iter()
            .map(|(v, [fa, fb])| Ok((v, Some(screen(&fa, &fb)?))))
            .collect::<Result<Vec<_>>>()?;
        Ok(Some(scored))
    }

    /// The view cascade (see [`crate::views`]) after the plain pass `plain`: the matches of the
    /// first view that verifies (or, in full mode, of the view with the most inliers), in the
    /// working images' pixels, and a report per view. The stages of the synthetic views are
    /// timed into `timings` too.
    pub(super) fn view_cascade(
        &self,
        plain: WorkMatches,
        [(work_a, features_a), (work_b, features_b)]: [(&GrayImage, &ImageFeatures); 2],
        timings: &mut Timings,
    ) -> Result<(WorkMatches, Vec<ViewReport>)> {
        let o = &self.views;
        let start = Instant::now();
        // The plain pass's work: both extractions, their matching and its ACs.
        let mut meter = WorkMeter::new(
            work_a.width() * work_a.height() + work_b.width() * work_b.height(),
            (features_a.len(), features_b.len()),
            plain.corrs.len(),
        );
        let passes = |inliers: usize, n: usize| {
            inliers >= o.min_inliers && inliers as f64 >= o.min_inlier_ratio * n as f64
        };
        let (inliers, mask) = verify(&plain.corrs, self.verify_weight())?;
        meter.verification();
        let verified = passes(inliers, plain.corrs.len());
        let mut reports = vec![ViewReport {
            view: ViewSpec::PLAIN,
            matches: plain.corrs.len(),
            inliers,
            verified,
            screen: None,
            time: start.elapsed(),
            work: 1.0,
            started: 0.0,
            screen_extraction: 0.0,
            used: false,
        }];
        // The meter's reading at the last report (the plain pass's verification is the plain
        // pass's): a view's work is what was spent since.
        let mut reported = meter.spent;
        // A weak verification (few of the matches agree) may be a repetitive pattern matched
        // at the wrong rotation: the rotated views are its rivals (see `defaults::weak_ratio`).
        // So may one verified by few inliers (`views::WEAK_YIELD`), or by matches the
        // matcher is unsure of (`views::uncertain`).
        let weak = verified
            && ((inliers as f64)
                < crate::defaults::weak_ratio(self.matcher()) * plain.corrs.len() as f64
                || weak_yield(inliers, self.max_keypoints())
                || uncertain(
                    &plain.certainty,
                    crate::defaults::rival_certainty(self.matcher()),
                ));
        if verified && !weak && o.mode == ViewMode::Auto {
            reports[0].used = true;
            return Ok((plain, reports));
        }
        let mut rival_floor = if weak && o.mode == ViewMode::Auto {
            (RIVAL_MARGIN * inliers as f64).ceil() as usize
        } else {
            0
        };
        tracing::info!(
            matches = plain.corrs.len(),
            inliers,
            weak,
            "the plain pair does not verify (or only weakly): trying synthetic views"
        );
        let inlier_acs: Vec<[f64; 8]> = plain
            .corrs
            .iter()
            .zip(&mask)
            .filter(|(_, m)| **m)
            .map(|(r, _)| *r)
            .collect();
        let mut queue: VecDeque<Queued> = VecDeque::new();
        // A weak plain pass verified by so few inliers that a synthetic view would not end the
        // cascade on them (`views::CONFIDENT_VIEW`) is judged as such a view: kept, and every
        // view rivals it, not only the rotations. A steep tilt verifies like this, with a
        // dozen or two matches in a corner of the overlap. Its AC-guided view comes right
        // after the rotations, which rival it first: a repetitive pattern matched at the
        // wrong rotation guides to a wrong view that verifies too (views_pose lost chessboard
        // and stereo pairs at 90–180° with the guide first). A failed plain pass's guide
        // comes first. A weak pass with more inliers is rivalled by the rotations and then
        // by its guide too: a tilt of 70° verifies the plain pass with a few dozen matches
        // in a band of the overlap, and the view that undoes their map finds the plane
        // (benches/results/eval/extreme_varied.md).
        let mut rivals_only = rival_floor > 0 && inliers >= CONFIDENT_VIEW * o.min_inliers;
        let mut steps: VecDeque<Step> = if rivals_only {
            VecDeque::from([Step::Screened(rival_views())])
        } else {
            cascade_steps().into()
        };
        if let Some(g) = guided_view(&inlier_acs) {
            steps.insert(usize::from(weak), Step::View(g));
        }
        // The views of screened groups past their best: tried once every step has run.
        let mut deferred: Vec<(f64, ViewSpec, Option<usize>)> = Vec::new();
        let (mut best, mut best_inliers) = (plain, if verified { inliers } else { 0 });
        // The kept pass's `views::planar_support`, once a rival needs it.
        let mut best_planar: Option<usize> = None;
        let mut best_index = 0;
        // A view whose matches partly agree (too few to verify) guides the next one: the
        // dominant map of its agreeing ACs, in the original images, is undone first.
        let (mut guide_inliers, mut guided) = (inlier_acs.len(), 0);
        let mut tried = 0;
        // A verified view's refinement is queued: the cascade stops after it.
        let mut refining = false;
        let sizes = (
            (work_a.width(), work_a.height()),
            (work_b.width(), work_b.height()),
        );
        // Views share warps (the tilts of A against B's rotations, the tiles against one zoom
        // of the other image): each warped image's features are extracted once per pair.
        let mut store = ViewFeatures {
            images: [work_a, work_b],
            matcher: FeatureStore {
                plain: [
                    Some(Rc::new(features_a.clone())),
                    Some(Rc::new(features_b.clone())),
                ],
                warped: HashMap::new(),
            },
            screen: FeatureStore::default(),
            charged: HashSet::new(),
            meter,
        };
        // The time a group's screen took, counted in the first view it runs.
        let mut screen_time = Duration::ZERO;
        // The extractions of the screens since the last view, reported with the next one.
        let mut screen_extraction = 0.0;
        loop {
            if tried >= o.max_views || !o.within_budget(start.elapsed(), &store.meter) {
                break;
            }
            let (view, screen_score) = if let Some(v) = queue.pop_front() {
                v
            } else if let Some(step) = steps.pop_front() {
                let ranked_only = matches!(step, Step::Ranked(_));
                match step {
                    Step::View(v) => (v, None),
                    Step::Screened(group) | Step::Ranked(group) => {
                        let t = Instant::now();
                        // Shrunk while nothing is kept. The rivals of a kept pass or view
                        // are screened at full size: a pattern that repeats under quarter
                        // turns separates them by few inliers, and the screen decides which
                        // run (docs/pipeline.md, "Views": shrunk, views_pose's chessboards
                        // lost more pairs than they gained).
                        let Some(mut scored) = self.screen_group(
                            group,
                            rival_floor == 0,
                            &mut store,
                            sizes,
                            start,
                            &mut screen_extraction,
                            timings,
                        )?
                        else {
                            break; // no view could follow the screen within the budget
                        };
                        // Best first (stable: ties keep the steps' order).
                        scored.sort_by_key(|(_, s)| std::cmp::Reverse(*s));
                        let scores: Vec<usize> = scored.iter().filter_map(|v| v.1).collect();
                        // A ranked group runs whole, best-screened first.
                        let run = if ranked_only {
                            scored.len()
                        } else {
                            screen_run(&scores)
                        };
                        let rest = scored.split_off(run);
                        queue.extend(scored);
                        // Deferred views wait ranked by their screen over their group's noise;
                        // a weakly verified pair's rivals that do not stand out are dropped:
                        // they only check the plain pass, which is kept.
                        let noise = scores.get(scores.len() / 2).map_or(1, |&n| n.max(1));
                        deferred.extend(
                            rest.into_iter()
                                .filter(|_| !rivals_only)
                                .map(|(v, s)| (s.unwrap_or(0) as f64 / noise as f64, v, s)),
                        );
                        screen_time += t.elapsed();
                        continue;
                    }
                }
            } else if !deferred.is_empty() {
                // Best first across the groups (stable: ties keep the steps' order).
                deferred.sort_by(|a, b| b.0.total_cmp(&a.0));
                queue.extend(deferred.drain(..).map(|(_, v, s)| (v, s)));
                continue;
            } else {
                break;
            };
            tried += 1;
            let started = store.meter.passes();
            let t = Instant::now();
            let warps = view.warps(sizes.0, sizes.1);
            let [a_warp, b_warp] = warps;
            let Some([fa, fb]) = self.view_features(&mut store, &warps, timings)? else {
                // A view too small for the matcher is skipped, not an error of the pair.
                continue;
            };
            let mut raw = self.matcher.match_features(&fa, &fb)?;
            // The features were timed where they were extracted (the plain pass, this view's
            // warp or an earlier view's): only the matching is this view's.
            for f in [&fa, &fb] {
                raw.timings.preprocess -= f.timings.preprocess;
                raw.timings.network -= f.timings.network;
                raw.timings.detection -= f.timings.detection;
            }
            let warped = |img: &GrayImage, w: &ImageWarp| {
                w.map(|(warp, vw, vh)| warp_image(img, &warp, vw, vh))
                    .transpose()
            };
            let (va, vb) = (warped(work_a, &a_warp)?, warped(work_b, &b_warp)?);
            let (va, vb) = (va.as_ref().unwrap_or(work_a), vb.as_ref().unwrap_or(work_b));
            let m = self.match_working(va, vb, raw, timings)?;
            store.meter.matching((fa.len(), fb.len()), m.corrs.len());
            let (wa, wb) = (
                a_warp.map_or(AffineWarp::IDENTITY, |w| w.0),
                b_warp.map_or(AffineWarp::IDENTITY, |w| w.0),
            );
            let corrs: Vec<[f64; 8]> = m
                .corrs
                .iter()
                .filter_map(|row| ac_from_views(row, &wa, &wb))
                .collect();
            let (inliers, mask) = verify(&corrs, self.verify_weight())?;
            store.meter.verification();
            let verified = passes(inliers, corrs.len());
            let agreeing: Vec<[f64; 8]> = corrs
                .iter()
                .zip(&mask)
                .filter(|(_, m)| **m)
                .map(|(r, _)| *r)
                .collect();
            if !verified
                && inliers > guide_inliers
                && guided < MAX_GUIDED_VIEWS
                && let Some(g) = guided_view(&agreeing)
            {
                queue.push_front((g, None));
                (guide_inliers, guided) = (inliers, guided + 1);
            }
            tracing::debug!(
                view = %view.label(),
                matches = corrs.len(),
                inliers,
                verified,
                "view cascade"
            );
            reports.push(ViewReport {
                view,
                matches: corrs.len(),
                inliers,
                verified,
                screen: screen_score,
                time: t.elapsed() + std::mem::take(&mut screen_time),
                work: store.meter.in_passes(store.meter.spent - reported),
                started,
                screen_extraction: std::mem::take(&mut screen_extraction),
                used: false,
            });
            reported = store.meter.spent;
            // Short of the rival margin, a view that outnumbers the kept pass wins by one plane's
            // support instead (`views::planar_rival`); the kept pass's is computed once.
            let outnumbers = verified && inliers > best_inliers;
            let better = outnumbers
                && (inliers >= rival_floor || {
                    let kept = match best_planar {
                        Some(k) => k,
                        None => *best_planar.insert(planar_support(&best.corrs)?),
                    };
                    planar_rival(planar_support(&corrs)?, kept)
                });
            if better {
                best_index = reports.len() - 1;
                best_inliers = inliers;
                best = WorkMatches { corrs, ..m };
                best_planar = None;
            }
            if o.mode == ViewMode::Auto && (better || refining) {
                // Few inliers (in number, or for the keypoint budget, as `views::WEAK_YIELD`
                // judges the plain pass): the view that undoes their map exactly may find many
                // more.
                let few = inliers < REFINE_BELOW * o.min_inliers
                    || weak_yield(inliers, self.max_keypoints());
                if better
                    && !refining
                    && few
                    && let Some(r) = refinement_view(&view, &agreeing)
                {
                    queue.push_front((r, None));
                    refining = true;
                    continue;
                }
                refining = false;
                if best_inliers >= CONFIDENT_VIEW * o.min_inliers {
                    if !rivalled_by_rotations(steps.front(), best_inliers, self.max_keypoints()) {
                        break;
                    }
                    // Verified weakly before the rotations ran: they rival it, and only they
                    // (their views that do not stand out dropped, as for a weak plain pass).
                    steps.truncate(1);
                    rivals_only = true;
                }
                // A weak proof (`views::CONFIDENT_VIEW`): kept, and rivalled by the views left.
                rival_floor = rival_floor.max((RIVAL_MARGIN * best_inliers as f64).ceil() as usize);
            }
        }
        // Work spent after the last view (a group's extractions whose screens would have
        // reached the budget; a screen the time budget cut short) is the last view's, the
        // plain pass's when no view ran: the views' work sums to the pair's.
        if let Some(last) = reports.last_mut() {
            last.work += store.meter.in_passes(store.meter.spent - reported);
        }
        reports[best_index].used = true;
        tracing::debug!(
            views = reports.len() - 1,
            plain_passes = store.meter.passes(),
            "view cascade's work"
        );
        Ok((best, reports))
    }
}

/// The features of a pair's synthetic views: the working images, the matcher's features and
/// the screener's (each image extracted once per pair by each), and the cascade's work meter
/// that the extractions are charged to.
struct ViewFeatures<'a> {
    images: [&'a GrayImage; 2],
    matcher: FeatureStore,
    /// The screener's, when the pipeline has one ([`Pipeline::screener`]).
    screen: FeatureStore,
    /// The warped images whose extraction the meter has counted. Each counts once, whichever
    /// extractor comes first: the meter counts the default matcher's work (see
    /// `views::WorkMeter`), and a screener's extraction is a small part of a slow matcher's.
    charged: HashSet<WarpKey>,
    meter: WorkMeter,
}

/// One extractor's features of a pair's images: of the working images (`None` until
/// extracted) and of their warps.
#[derive(Default)]
struct FeatureStore {
    plain: [Option<Rc<ImageFeatures>>; 2],
    warped: HashMap<WarpKey, Rc<ImageFeatures>>,
}

impl ViewFeatures<'_> {
    /// `extractor`'s features of both sides of a view with `warps` ([`Self::side`]).
    fn pair(
        &mut self,
        extractor: &PointMatcher,
        screen: bool,
        warps: &ViewWarps,
        timings: &mut Timings,
    ) -> Result<Option<[Rc<ImageFeatures>; 2]>> {
        if warps.iter().any(too_small) {
            return Ok(None);
        }
        let fa = self.side(extractor, screen, 0, &warps[0], timings)?;
        let fb = self.side(extractor, screen, 1, &warps[1], timings)?;
        Ok(Some([fa, fb]))
    }

    /// The meter as a group's screen (its views' images under `warps`) will leave it once it
    /// has extracted the warped images that no extractor has yet: each charged in the order
    /// the screen extracts them, so that the reading is the one the screen leaves.
    fn after_extraction(&self, warps: &[ViewWarps]) -> WorkMeter {
        let mut meter = self.meter.clone();
        let mut new = HashSet::new();
        for warps in warps {
            if warps.iter().any(too_small) {
                continue;
            }
            for (image, w) in warps.iter().enumerate() {
                if let (Some((_, vw, vh)), Some(key)) = (w, warp_key(image, w))
                    && !self.charged.contains(&key)
                    && new.insert(key)
                {
                    meter.extraction(vw * vh);
                }
            }
        }
        meter
    }

    /// `extractor`'s features (the screener's store when `screen`) of image `image` (0: A,
    /// 1: B) under `warp` (not [`too_small`]), extracted on first use. A warped image's first
    /// extraction is charged to the meter; the screener's features of a working image are
    /// not (the plain pass's extractions were).
    fn side(
        &mut self,
        extractor: &PointMatcher,
        screen: bool,
        image: usize,
        warp: &ImageWarp,
        timings: &mut Timings,
    ) -> Result<Rc<ImageFeatures>> {
        let store = if screen {
            &mut self.screen
        } else {
            &mut self.matcher
        };
        let (Some((w, vw, vh)), Some(key)) = (warp, warp_key(image, warp)) else {
            if let Some(f) = &store.plain[image] {
                return Ok(f.clone());
            }
            let f = Rc::new(extract_timed(extractor, self.images[image], timings)?);
            store.plain[image] = Some(f.clone());
            return Ok(f);
        };
        if let Some(hit) = store.warped.get(&key) {
            return Ok(hit.clone());
        }
        let view = warp_image(self.images[image], w, *vw, *vh)?;
        let f = Rc::new(extract_timed(extractor, &view, timings)?);
        if self.charged.insert(key) {
            self.meter.extraction(vw * vh);
        }
        store.warped.insert(key, f.clone());
        Ok(f)
    }
}

/// `extractor`'s features of `image`, their stages timed into `timings`.
fn extract_timed(
    extractor: &PointMatcher,
    image: &GrayImage,
    timings: &mut Timings,
) -> Result<ImageFeatures> {
    let f = extractor.extract(image, None)?;
    timings.decode += f.timings.preprocess;
    timings.matcher += f.timings.network;
    timings.detection += f.timings.detection;
    Ok(f)
}
