//! Loss detection and re-initialization hypotheses shared by the trackers (thesis §2.4, §3.6
//! "Generative tracker"; ANCHOR-FACTS §5.7).
//!
//! htrack's `TrackingMonitor` fed a logistic of push/pull errors into a 10-frame window, hmodel
//! and honline thresholded the pull error at 6 mm; both then re-initialized with Qian et al.'s
//! detector. Here a frame *fails* when, after the solve, the mean distance of the sensor points
//! to the model exceeds [`LossParams::max_mean_distance`] or more than
//! [`LossParams::max_unexplained`] of them lie farther than
//! [`LossParams::unexplained_distance`]; tracking is *lost* after [`LossParams::window`]
//! consecutive failed frames. The re-initializer of each tracker solves from a few hypotheses
//! ([`placement_directions`]), and from backups ([`PLACEMENT_ROLLS`]) when those place the
//! hand poorly ([`FrameStats::is_poor_placement`]), and keeps the best by
//! [`FrameStats::score`].

use std::f64::consts::FRAC_PI_2;

use nalgebra::{Matrix2, SymmetricEigen, Vector2, Vector3};

use super::frame_loop::Hypothesis;
use crate::kinematics::{Pose, Skeleton};
use crate::math::{euler_xyz_to_matrix, matrix_to_euler_xyz};
use serde::{Deserialize, Serialize};

/// When a frame counts as failed and tracking as lost (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossParams {
    /// A frame fails above this mean point-to-model distance (mm; hmodel's pull threshold 6).
    pub max_mean_distance: f64,
    /// Points farther than this from the model are unexplained (mm).
    pub unexplained_distance: f64,
    /// A frame fails above this fraction of unexplained points.
    pub max_unexplained: f64,
    /// Consecutive failed frames before re-initialization (htrack: 10).
    pub window: usize,
    /// Fewer sensor points than this: the frame has no hand (`no_hand`).
    pub min_points: usize,
    /// Raise the two distance thresholds to the measured depth noise σ̂ where it exceeds them
    /// ([`LossParams::for_noise`]).
    pub noise_scaled: bool,
}

impl Default for LossParams {
    fn default() -> Self {
        Self {
            max_mean_distance: 6.0,
            unexplained_distance: 15.0,
            max_unexplained: 0.15,
            window: 3,
            min_points: 50,
            noise_scaled: true,
        }
    }
}

/// [`LossParams::for_noise`]: the mean point-to-model distance may reach this many σ̂.
pub const NOISE_MEAN_DISTANCE: f64 = 1.0;
/// [`LossParams::for_noise`]: a point is unexplained beyond this many σ̂ from the model.
pub const NOISE_UNEXPLAINED: f64 = 2.5;

impl LossParams {
    /// These settings for a sensor of depth noise `sigma` (σ̂, mm; `None`: not measured). With
    /// [`LossParams::noise_scaled`] a frame fails only above a mean distance of
    /// `max(max_mean_distance, NOISE_MEAN_DISTANCE·σ̂)` or with more than `max_unexplained` of
    /// its points beyond `max(unexplained_distance, NOISE_UNEXPLAINED·σ̂)`.
    ///
    /// The fixed thresholds are hmodel's, for a sensor of a few millimetres of noise. A hand
    /// tracked at its true pose is on average ≈ 0.62 σ from its points (measured on the teaser
    /// with Gaussian depth noise added: 3.2 / 4.3 / 6.0 mm at σ = 5 / 7 / 10 mm), so from
    /// σ ≈ 10 mm every frame failed. The trackers then re-initialized every third frame and
    /// online calibration learned from no frame. Up to σ̂ = 6 mm (the ToF model's ≈ 5 mm
    /// included) nothing changes.
    pub fn for_noise(&self, sigma: Option<f64>) -> Self {
        let Some(sigma) = sigma.filter(|s| self.noise_scaled && s.is_finite() && *s > 0.0) else {
            return self.clone();
        };
        Self {
            max_mean_distance: self.max_mean_distance.max(NOISE_MEAN_DISTANCE * sigma),
            unexplained_distance: self.unexplained_distance.max(NOISE_UNEXPLAINED * sigma),
            ..self.clone()
        }
    }
}

/// How one frame went.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Mean distance of the sensor points to the model (mm) at the returned pose.
    pub mean_distance: f64,
    /// Fraction of sensor points farther than [`LossParams::unexplained_distance`].
    pub unexplained: f64,
    /// The model's area outside the sensor silhouette over the silhouette's area (0 where the
    /// tracker does not measure it): what the point distances cannot see — a model that covers
    /// every point and sticks out of the silhouette (with 100 points, the hand turned upside
    /// down over its palm explained them within 6 mm).
    pub outside: f64,
    /// Whether the frame failed by [`LossParams`].
    pub failed: bool,
}

impl FrameStats {
    /// The statistics of one frame from the point-to-model distance of each sensor point
    /// (`None` or non-finite: the point has no correspondence and counts as unexplained).
    pub fn from_distances(distances: impl Iterator<Item = Option<f64>>, p: &LossParams) -> Self {
        let (mut sum, mut n, mut far, mut total) = (0.0, 0usize, 0usize, 0usize);
        for d in distances {
            total += 1;
            let d = d.filter(|d| d.is_finite()).unwrap_or(f64::INFINITY);
            if d.is_finite() {
                sum += d;
                n += 1;
            }
            if d > p.unexplained_distance {
                far += 1;
            }
        }
        let mean = if n > 0 { sum / n as f64 } else { f64::INFINITY };
        let unexplained = far as f64 / total.max(1) as f64;
        Self {
            mean_distance: if mean.is_finite() { mean } else { 1e9 },
            unexplained,
            outside: 0.0,
            failed: !(mean <= p.max_mean_distance && unexplained <= p.max_unexplained),
        }
    }

    /// These statistics with the model's area outside the sensor silhouette, as a fraction of
    /// the silhouette's area ([`FrameStats::outside`], non-finite or negative: counted as 1).
    /// It ranks re-initialization hypotheses ([`FrameStats::score`]) but does not fail a frame:
    /// tracked library sequences left up to 0.21 outside (a template thicker than the hand,
    /// structured-light silhouettes), a hand turned upside down over sparse points 0.1.
    pub fn with_outside(mut self, outside: f64) -> Self {
        self.outside = if outside >= 0.0 && outside.is_finite() {
            outside
        } else {
            1.0
        };
        self
    }

    /// Whether a fitted re-initialization hypothesis is a poor placement: the frame fails
    /// ([`FrameStats::failed`]) or the model covers more than [`POOR_PLACEMENT_OUTSIDE`] of the
    /// silhouette's area outside it.
    pub fn is_poor_placement(&self) -> bool {
        self.failed || self.outside > POOR_PLACEMENT_OUTSIDE
    }

    /// Score of a fitted hypothesis (lower is better): mean distance plus a penalty per
    /// unexplained point and per share of model area outside the silhouette.
    pub fn score(&self) -> f64 {
        self.mean_distance + 100.0 * (self.unexplained + self.outside)
    }
}

/// Rolls of the hand about its finger axis that re-initialization may try at each placement
/// direction, and whether each is a backup ([`super::Hypothesis::backup`]): the palm toward
/// the camera, then, should that be a poor placement, edge-on with either side toward it.
///
/// A hand first seen edge-on (the occlusion motion turned 88° away, ToF, tracked from its
/// 150th frame) was placed palm-on, left 35–49 % of the model outside the silhouette and stayed
/// 80–98 mm off for 45 frames. Tried as equals, the edge-on placements won on fists and claws
/// instead: the open mean pose fits a fist badly either way, and edge-on it covers less of the
/// silhouette's outside (the real scans' fist, the hand's own model: 10.2 → 65.4 mm).
pub const PLACEMENT_ROLLS: [(f64, bool); 3] = [(0.0, false), (FRAC_PI_2, true), (-FRAC_PI_2, true)];

/// A placement leaving more than this share of the silhouette's area covered by the model
/// outside it is poor ([`FrameStats::is_poor_placement`]). A fist placed palm-on as the open
/// mean pose leaves 0.12–0.18 (where the edge-on starts must not be tried, see
/// [`PLACEMENT_ROLLS`]), a hand seen edge-on and placed palm-on 0.36–0.49. At 0.3 a tight fist
/// turned 61° (palm-on 0.21; ToF `rotating_fist` from its 105th frame) kept its palm-on
/// placement and tracked 26.34 mm off; at 0.2, 2.43 mm. On 74 ToF cold starts 0.2 changed two
/// more (random subjects from frame 100: 6.47 → 5.91 and 6.44 → 7.35 mm), and of the real
/// scans only the fist under structured light, lost either way (default template fingertips
/// 62.77 → 42.22 mm); the library's sequences and 30 random-subject runs not at all.
pub const POOR_PLACEMENT_OUTSIDE: f64 = 0.2;

/// The global rotation, as `(global_rx, global_ry, global_rz)` ([`euler_xyz_to_matrix`]'s
/// angles), of a hand turned about the optical axis so that its fingers (model +y) point along
/// the image direction `e`, then rolled by `roll` about the fingers: `Rz(a)·Ry(roll)` with
/// `Rz(a)·ŷ = e`. `roll = 0` gives exactly `(0, 0, a)`.
pub fn placement_rotation(e: Vector2<f64>, roll: f64) -> [f64; 3] {
    let a = (-e.x).atan2(e.y);
    if roll == 0.0 {
        return [0.0, 0.0, a];
    }
    matrix_to_euler_xyz(&(euler_xyz_to_matrix(0.0, 0.0, a) * euler_xyz_to_matrix(0.0, roll, 0.0)))
}

/// `pose` with its global rotation set to [`placement_rotation`]`(e, roll)` (its other DOFs
/// kept); `None` when the skeleton lacks a global rotation DOF.
pub fn placed_rotation(
    pose: &Pose,
    skeleton: &Skeleton,
    e: Vector2<f64>,
    roll: f64,
) -> Option<Pose> {
    let mut out = pose.clone();
    for (name, v) in ["global_rx", "global_ry", "global_rz"]
        .iter()
        .zip(placement_rotation(e, roll))
    {
        out.set(skeleton, name, v).ok()?;
    }
    Some(out)
}

/// The least cosine between the fingers' image direction and the forearm's (toward the hand)
/// that a placement may take when the segmentation found the forearm ([`placement_directions`]):
/// about 107°, beyond the wrist's flexion and extension (≈ 80°) seen at any angle.
pub const ARM_MIN_COSINE: f64 = -0.3;

/// The arm's direction is not added to the placements when one of them is within ≈ 8° of it.
const ARM_SAME_COSINE: f64 = 0.99;

/// A forearm whose image direction is shorter than this (its unit 3-D axis mostly along the
/// optical axis) gives no direction to placements.
const ARM_MIN_IMAGE_LENGTH: f64 = 0.3;

/// Where re-initialization hypotheses put the hand: the point cloud's centroid and the image
/// directions the fingers may point to — upright (image −y) and ± the principal image axis of
/// the cloud when it has one. Empty input gives the origin and the upright direction only.
///
/// `arm` is the forearm's axis toward the hand (camera frame, e.g. from the wristband or the
/// depth-only segmentation's forearm cut), when known: the directions pointing back along it
/// (cosine below [`ARM_MIN_COSINE`]) are dropped, and the arm's own image direction is added
/// (unless one of them is within ≈ 8° of it).
/// A hand turned upside down in the image fits a silhouette of crossed or folded fingers about
/// as well as the upright one: without the arm, cold starts on crossed fingers (ToF, `crossing`
/// from frames 150 and 165) were placed with the wrist at the fingertips by the Ch. 2 tracker,
/// 88 mm mean keypoint error (36 and 33 mm with it; the other 72 ToF cold starts and the 34
/// library sequences unchanged, for either tracker). Of the 64 noise-free cold starts two
/// changed by more than 0.1 mm: a fast turn from frame 165, 22.95 → 11.80 mm (sphere-mesh) and
/// 23.35 → 12.48 mm (online calibration), and a fist from frame 60 with online calibration,
/// 1.96 → 14.26 mm.
pub fn placement_directions(
    points: &[Vector3<f64>],
    arm: Option<&Vector3<f64>>,
) -> (Vector3<f64>, Vec<Vector2<f64>>) {
    let n = points.len().max(1) as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p) / n;
    let mut cov = Matrix2::zeros();
    for p in points {
        let d = Vector2::new(p.x - centroid.x, p.y - centroid.y);
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let k = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        0
    } else {
        1
    };
    let axis = eig.eigenvectors.column(k).into_owned();
    let mut dirs = vec![Vector2::new(0.0, -1.0)];
    if axis.iter().all(|v| v.is_finite()) && axis.norm() > 0.5 && points.len() > 1 {
        dirs.push(axis);
        dirs.push(-axis);
    }
    let arm = arm
        .map(|a| Vector2::new(a.x, a.y))
        .filter(|a| a.iter().all(|v| v.is_finite()) && a.norm() >= ARM_MIN_IMAGE_LENGTH);
    if let Some(a) = arm.map(|a| a.normalize()) {
        dirs.retain(|e| e.dot(&a) >= ARM_MIN_COSINE);
        if !dirs.iter().any(|e| e.dot(&a) > ARM_SAME_COSINE) {
            dirs.push(a);
        }
    }
    (centroid, dirs)
}

/// The re-initialization starts on a frame's points (and its forearm's axis, see
/// [`placement_directions`]): for every roll of [`PLACEMENT_ROLLS`]
/// (a backup or not, as it says) and every direction of [`placement_directions`], the pose
/// `place(e, roll, target)` builds with the fingers along the image direction `e`, rolled by
/// `roll` about them, and the palm on `target`, 10 mm behind the cloud's centroid (inside the
/// hand rather than on its visible surface). Directions where `place` gives `None` are left out.
pub fn placement_hypotheses(
    points: &[Vector3<f64>],
    arm: Option<&Vector3<f64>>,
    place: impl Fn(Vector2<f64>, f64, &Vector3<f64>) -> Option<Pose>,
) -> Vec<Hypothesis> {
    let (centroid, dirs) = placement_directions(points, arm);
    let target = centroid + Vector3::new(0.0, 0.0, 10.0);
    PLACEMENT_ROLLS
        .iter()
        .flat_map(|&roll| dirs.iter().map(move |&e| (e, roll)))
        .filter_map(|(e, (roll, backup))| {
            let pose = place(e, roll, &target)?;
            Some(Hypothesis { pose, backup })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hypotheses_cover_every_direction_and_roll_with_the_palm_behind_the_centroid() {
        let points: Vec<_> = (0..20)
            .map(|i| Vector3::new(3.0 * f64::from(i), 1.0, 400.0 + f64::from(i % 2)))
            .collect();
        let (centroid, dirs) = placement_directions(&points, None);
        assert_eq!(dirs.len(), 3);
        // A "pose" recording what it was built from: e, roll, target.
        let hs = placement_hypotheses(&points, None, |e, roll, target| {
            (e.x != 0.0 || roll >= 0.0).then(|| Pose {
                values: vec![e.x, e.y, roll, target.x, target.y, target.z],
            })
        });
        // Upright (e.x = 0) with the negative roll is refused by `place`: left out.
        assert_eq!(hs.len(), PLACEMENT_ROLLS.len() * dirs.len() - 1);
        for h in &hs {
            let v = &h.pose.values;
            let roll = PLACEMENT_ROLLS.iter().find(|r| r.0 == v[2]).unwrap();
            assert_eq!(h.backup, roll.1);
            assert!(dirs.contains(&Vector2::new(v[0], v[1])));
            assert_eq!(
                [v[3], v[4], v[5]],
                [centroid.x, centroid.y, centroid.z + 10.0]
            );
        }
        assert_eq!(hs.iter().filter(|h| !h.backup).count(), dirs.len());
    }

    #[test]
    fn stats_count_unexplained_and_missing_points() {
        let p = LossParams::default();
        let d = [Some(1.0), Some(3.0), None, Some(20.0)];
        let s = FrameStats::from_distances(d.into_iter(), &p);
        assert!((s.mean_distance - 8.0).abs() < 1e-12);
        assert!((s.unexplained - 0.5).abs() < 1e-12);
        assert!(s.failed);
        let ok = FrameStats::from_distances([Some(1.0); 10].into_iter(), &p);
        assert!(!ok.failed && ok.score() == 1.0);
        let empty = FrameStats::from_distances(std::iter::empty(), &p);
        assert!(empty.failed && empty.mean_distance.is_finite());
    }

    #[test]
    fn thresholds_follow_the_depth_noise_above_their_own() {
        let p = LossParams::default();
        for quiet in [None, Some(f64::NAN), Some(-1.0), Some(0.0), Some(5.0)] {
            assert_eq!(p.for_noise(quiet), p, "{quiet:?}");
        }
        let noisy = p.for_noise(Some(10.0));
        assert_eq!(noisy.max_mean_distance, 10.0);
        assert_eq!(noisy.unexplained_distance, 25.0);
        assert_eq!(
            (noisy.max_unexplained, noisy.window),
            (p.max_unexplained, p.window)
        );
        // Points 7 mm off, as a correct fit under σ = 10 mm leaves them: failed, then not.
        let d = [Some(7.0); 20];
        assert!(FrameStats::from_distances(d.into_iter(), &p).failed);
        assert!(!FrameStats::from_distances(d.into_iter(), &noisy).failed);
        let fixed = LossParams {
            noise_scaled: false,
            ..LossParams::default()
        };
        assert_eq!(fixed.for_noise(Some(10.0)), fixed);
    }

    /// 50 points along image x (0–98 mm), a little spread in y.
    fn cloud_along_x() -> Vec<Vector3<f64>> {
        (0..50)
            .map(|i| Vector3::new(f64::from(i) * 2.0, 0.5 * f64::from(i % 3), 400.0))
            .collect()
    }

    #[test]
    fn directions_follow_the_cloud() {
        let pts = cloud_along_x();
        let (c, dirs) = placement_directions(&pts, None);
        assert!((c.x - 49.0).abs() < 1e-9);
        assert_eq!(dirs.len(), 3);
        assert!(dirs[1].x.abs() > 0.99);
        let (_, one) = placement_directions(&[], None);
        assert_eq!(one, vec![Vector2::new(0.0, -1.0)]);
    }

    /// A cloud along image x with the forearm coming from its −x end: the fingers may not point
    /// back along the arm, and the arm's own direction is tried; an arm along the optical axis
    /// or not finite changes nothing.
    #[test]
    fn the_forearm_rules_out_the_fingers_pointing_back_along_it() {
        let pts = cloud_along_x();
        let (_, free) = placement_directions(&pts, None);
        let arm = Vector3::new(0.8, -0.3, 0.5).normalize();
        let (_, dirs) = placement_directions(&pts, Some(&arm));
        let a = Vector2::new(arm.x, arm.y).normalize();
        assert!(dirs.iter().all(|e| e.dot(&a) >= ARM_MIN_COSINE), "{dirs:?}");
        // Upright and the +x axis stay, −x goes, the arm's direction (21° from +x) comes.
        assert_eq!(dirs.len(), 3, "{dirs:?}");
        assert!(dirs.contains(&free[0]));
        assert!(dirs.iter().any(|e| e.x > 0.99));
        assert!(!dirs.iter().any(|e| e.x < -0.99));
        assert!(dirs.contains(&a));
        // Along +x itself: nothing added next to the +x axis.
        let (_, along) = placement_directions(&pts, Some(&Vector3::new(1.0, 0.0, 0.0)));
        assert_eq!(along.len(), 2, "{along:?}");
        for ignored in [
            Vector3::new(0.1, 0.1, 0.99),
            Vector3::new(f64::NAN, 1.0, 0.0),
        ] {
            assert_eq!(placement_directions(&pts, Some(&ignored)).1, free);
        }
    }

    #[test]
    fn placements_point_the_fingers_and_roll_about_them() {
        use std::f64::consts::PI;
        let dirs: [Vector2<f64>; 3] = [
            Vector2::new(0.0, -1.0),
            Vector2::new(0.6, 0.8),
            Vector2::new(-1.0, 0.0),
        ];
        for e in dirs {
            let a = (-e.x).atan2(e.y);
            assert_eq!(placement_rotation(e, 0.0), [0.0, 0.0, a]);
            for (roll, _) in PLACEMENT_ROLLS {
                let [x, y, z] = placement_rotation(e, roll);
                let r = euler_xyz_to_matrix(x, y, z);
                let fingers = r * Vector3::y();
                assert!(
                    (fingers - Vector3::new(e.x, e.y, 0.0)).norm() < 1e-12,
                    "{e} {roll}"
                );
                // The palm normal (model z) turns by the roll away from the optical axis.
                let normal = r * Vector3::z();
                assert!((normal.z - roll.cos()).abs() < 1e-12, "{e} {roll}");
            }
            // Half a turn about the fingers shows the back of the hand.
            let [x, y, z] = placement_rotation(e, PI);
            assert!(((euler_xyz_to_matrix(x, y, z) * Vector3::z()).z + 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn a_placement_is_poor_when_it_fails_or_covers_much_outside() {
        let p = LossParams::default();
        let good = FrameStats::from_distances([Some(2.0); 10].into_iter(), &p);
        assert!(!good.is_poor_placement());
        assert!(!good
            .clone()
            .with_outside(POOR_PLACEMENT_OUTSIDE)
            .is_poor_placement());
        assert!(good.with_outside(0.45).is_poor_placement());
        let far = FrameStats::from_distances([Some(9.0); 10].into_iter(), &p);
        assert!(far.is_poor_placement());
    }
}
