//! Local optimisation's threshold schedules (`LoSchedule`) on a plane with a second structure a
//! few pixels off it: a cluster of matches in one region of image 1 whose x2 is the plane's,
//! shifted by 5 px (a nearby surface, a matcher's local misregistration). The widening track's
//! first steps (8× the threshold) take the cluster in and fit a compromise that the narrowing
//! steps keep; the threshold track stays on the plane; `Both` (the homography's default) keeps
//! the better score. Every schedule also recovers the pose and F of a multi-plane scene.

use affcorr_geom::synthetic::{NoiseModel, PlaneScene, gaussian, noisy_correspondences};
use affcorr_geom::{Mat2, Mat3, Vec2};
use affcorr_ransac::{
    Correspondences, EstimatorOptions, LoSchedule, RansacOptions, SampleKind, estimate_homography,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

mod common;
use common::{Noisy, angle_deg, make_data, transfer_error};

/// Share of all matches moved from the outliers into the cluster.
const CLUSTER_SHARE: f64 = 0.2;
/// How far the cluster's x2 lies off the plane's, px.
const CLUSTER_SHIFT: f64 = 5.0;

/// 800 ACs of `scene`'s plane: half outliers, of which `CLUSTER_SHARE` of all matches become
/// the cluster (x1 in the bottom-left 0.3 × 0.3 of the 640×480 image 1, x2 = H x1 shifted by
/// `CLUSTER_SHIFT` px in one random direction, A the plane's); 0.5 px noise, 2% on A.
fn plane_with_cluster(rng: &mut Pcg64, scene: &PlaneScene) -> Correspondences {
    let noise = NoiseModel {
        planes: 1,
        outlier_ratio: 0.5,
        pixel_noise: 0.5,
        affine_noise: 0.02,
    };
    let n = 800;
    let (mut acs, is_inlier) = noisy_correspondences(rng, scene, n, &noise);
    let angle = rng.random_range(0.0..std::f64::consts::TAU);
    let shift = Vec2::new(angle.cos(), angle.sin()) * CLUSTER_SHIFT;
    let wanted = (CLUSTER_SHARE * n as f64) as usize;
    let outliers: Vec<usize> = (0..n).filter(|&i| !is_inlier[i]).take(wanted).collect();
    assert_eq!(outliers.len(), wanted, "too few outliers for the cluster");
    for i in outliers {
        let x1 = Vec2::new(rng.random_range(0.0..192.0), rng.random_range(336.0..480.0));
        let exact = scene.correspondence(&x1).expect("the plane is visible");
        let jitter = Mat2::new(gaussian(rng), gaussian(rng), gaussian(rng), gaussian(rng));
        acs[i].x1 = x1;
        acs[i].x2 = exact.x2 + shift + Vec2::new(gaussian(rng), gaussian(rng)) * 0.5;
        acs[i].a = exact.a + exact.a * jitter * 0.02;
    }
    Correspondences::from_acs(&acs).unwrap()
}

fn options(schedule: LoSchedule, kind: SampleKind, seed: u64) -> EstimatorOptions {
    EstimatorOptions {
        ransac: RansacOptions {
            threshold: 2.0,
            seed,
            lo_schedule: schedule,
            ..Default::default()
        },
        sample: Some(kind),
        ..Default::default()
    }
}

/// Over 6 scenes × 4 seeds × (points, 2-AC samples): how many estimates with `schedule` are
/// more than 1 px (mean transfer error) off the plane.
fn misses(schedule: LoSchedule) -> usize {
    let mut rng = Pcg64::seed_from_u64(49);
    let mut missed = 0;
    for _scene in 0..6 {
        let scene = PlaneScene::random(&mut rng);
        let data = plane_with_cluster(&mut rng, &scene);
        for kind in [SampleKind::Points, SampleKind::Affine] {
            for seed in 0..4 {
                let est = estimate_homography(&data, &options(schedule, kind, seed)).unwrap();
                let err = transfer_error(&est.model, &scene.homography(), 40);
                missed += usize::from(err > 1.0);
            }
        }
    }
    missed
}

#[test]
fn both_tracks_stay_on_the_plane_where_the_widening_track_alone_takes_in_the_cluster() {
    let (widening, both) = (misses(LoSchedule::Widening), misses(LoSchedule::Both));
    // The premise: the widening track alone returns the compromise in most runs (38 of 48 when
    // written; both tracks 7: there the compromise was the local optimum of every raw record).
    assert!(
        widening >= 24,
        "widening missed in {widening} of 48 runs only"
    );
    assert!(both <= 12, "both tracks missed in {both} of 48 runs");
}

#[test]
fn auto_is_both_for_the_homography() {
    let mut rng = Pcg64::seed_from_u64(50);
    let scene = PlaneScene::random(&mut rng);
    let data = plane_with_cluster(&mut rng, &scene);
    for seed in 0..3 {
        let run = |s| estimate_homography(&data, &options(s, SampleKind::Affine, seed)).unwrap();
        let (auto, both) = (run(LoSchedule::Auto), run(LoSchedule::Both));
        assert_eq!(auto.model, both.model);
        assert_eq!(auto.inliers, both.inliers);
    }
}

#[test]
fn every_schedule_recovers_the_pose_and_f_and_is_deterministic() {
    // Three planes at 50% outliers: each schedule, forced on the relative pose and F (whose
    // default is the widening track), finds the truth, and the same seed gives the same model.
    use affcorr_geom::sampson::sampson_point;
    use affcorr_ransac::{estimate_fundamental, estimate_relative_pose};
    let mut rng = Pcg64::seed_from_u64(51);
    for trial in 0..3 {
        let scene = PlaneScene::random(&mut rng);
        let Noisy { data, is_inlier } = make_data(&mut rng, &scene, 3, 1000, 0.5, 0.5, 0.02);
        for schedule in [
            LoSchedule::Widening,
            LoSchedule::Threshold,
            LoSchedule::Both,
        ] {
            let mut o = options(schedule, SampleKind::Affine, trial);
            o.ransac.threshold = 1.5;
            let pose = estimate_relative_pose(&data, &scene.k1, &scene.k2, &o).unwrap();
            let r_err = angle_deg(&(pose.model.pose.r.transpose() * scene.pose.r));
            let t_err = pose.model.pose.t.angle(&scene.pose.t).to_degrees();
            assert!(
                r_err < 0.5 && t_err < 3.0,
                "{schedule:?}: {r_err}°, {t_err}°"
            );
            let again = estimate_relative_pose(&data, &scene.k1, &scene.k2, &o).unwrap();
            assert_eq!(pose.model.pose.r, again.model.pose.r, "{schedule:?}");
            let f = estimate_fundamental(&data, &o).unwrap();
            let inliers: Vec<usize> = (0..data.len()).filter(|&i| is_inlier[i]).collect();
            let mean = |m: &Mat3| {
                inliers
                    .iter()
                    .map(|&i| sampson_point(m, &data.ac(i).points()).sqrt())
                    .sum::<f64>()
                    / inliers.len() as f64
            };
            let (got, truth) = (mean(&f.model), mean(&scene.fundamental()));
            assert!(got < 1.2 * truth + 0.05, "{schedule:?}: {got} vs {truth}");
            assert_eq!(f.model, estimate_fundamental(&data, &o).unwrap().model);
        }
    }
}
