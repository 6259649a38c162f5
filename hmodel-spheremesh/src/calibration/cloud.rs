//! Initialization of a calibration from complete point clouds (thesis §3.4, the multi-view
//! case: photogrammetry or multi-camera scans of the hand in a few poses).
//!
//! A scan comes in an unknown orientation and unit, often with the forearm, and the thesis
//! initializes its poses by hand. Here:
//! - [`split_forearm`]: the forearm is cut off at the wrist, found on the scan's cross-section
//!   profile along its long axis (the hand model does not describe the forearm; a depth
//!   sensor's wristband segmentation does the same, thesis §2.3);
//! - [`initialize_cloud_pose`]: a pose hypothesis search on the hand part — the template's
//!   wrist-to-fingers axis laid along the scan's long axis toward the fingers, turned about it
//!   in even steps, fingers flat, half bent or curled, thumb adducted or abducted; each hypothesis fitted for the pose alone on
//!   a small subsample with a Huber d2m, the best few refined on a larger one, the lowest energy
//!   kept;
//! - [`initialize_clouds`]: both on every scan, for the template and its mirror image; the hand
//!   whose hypotheses explain the scans better is the scanned one; its poses then go through
//!   [`refine_digits`], a per-digit coordinate search (one digit's flexion hypotheses at a time,
//!   the rest of the pose held), since a single digit in the wrong valley is a local minimum
//!   that neither the whole-hand hypotheses nor the pose LM leave; then pairs of digits
//!   ([`CloudSearch::digit_pairs`]) the same way.
//!
//! [`calibrate`] then fits shape and poses jointly on the hand parts; [`calibrate_clouds`] runs
//! the whole chain, optionally alternating the per-digit search on the calibrated template with
//! the calibration.

use hand_model::kinematics::Pose;
use hand_model::math::{matrix_to_euler_xyz, principal_axes};
use hand_model::spheremesh::{PosedSphereMesh, SphereMeshTemplate};
use nalgebra::{Matrix3, Vector3};

use super::solve::{calibrate, Calibration, CalibrationConfig, CalibrationError, CalibrationFrame};

/// Settings of the pose hypothesis search.
#[derive(Clone, Debug, PartialEq)]
pub struct CloudSearch {
    /// Points of the scan the best hypotheses are refined on (an even subsample; the coarse
    /// pass uses half as many).
    pub sample: usize,
    /// LM iterations of a refinement (the coarse pass runs half as many).
    pub iterations: usize,
    /// Turns about the scan's long axis tried per direction of the fingers along it.
    pub rolls: usize,
    /// Hypotheses of the coarse pass refined.
    pub refine: usize,
    /// Finger flexions (rad, every non-global `flex` DOF, clamped to its limits).
    pub bends: Vec<f64>,
    /// Thumb abductions (rad, `thumb_cmc_abd`).
    pub thumb_abduction: Vec<f64>,
    /// Huber threshold (mm) of the d2m during the search.
    pub robust: f64,
    /// Flexions (rad) tried per digit by the per-digit search ([`refine_digits`]), the thumb
    /// also at every [`thumb_abduction`](Self::thumb_abduction); empty: no hypotheses (the pose
    /// is still refitted, on half and then on the whole subsample).
    pub digit_bends: Vec<f64>,
    /// Pairs of digits (DOF name prefixes) searched together by [`refine_digits`] after the
    /// single digits, every combination of [`digit_bends`](Self::digit_bends) for the two. By
    /// default ring and pinky, whose flexions go together: on scan 3 of `hand-scans-tkach` both
    /// were in wrong valleys that no single-digit move leaves (25 more fits per scan).
    pub digit_pairs: Vec<[String; 2]>,
    /// Rounds of [`calibrate_clouds`] after the first calibration: the digits searched again
    /// on the calibrated template, then calibrated again. Off by default: on the six real scans
    /// of `hand-scans-tkach` (plain [`CalibrationConfig`] defaults, single-digit search) a
    /// round raised the data energy (232 863 vs 232 181, not kept) at
    /// the cost of a second calibration.
    pub rounds: usize,
}

impl Default for CloudSearch {
    fn default() -> Self {
        Self {
            sample: 1000,
            iterations: 14,
            rolls: 8,
            refine: 4,
            bends: vec![0.0, 0.6, 1.2],
            thumb_abduction: vec![-0.4, 0.0, 0.7],
            robust: 3.0,
            digit_bends: vec![0.0, 0.4, 0.8, 1.2, 1.6],
            digit_pairs: vec![["ring".into(), "pinky".into()]],
            rounds: 0,
        }
    }
}

/// The pose chosen for one scan.
#[derive(Clone, Debug)]
pub struct CloudPose {
    /// The fitted pose.
    pub pose: Pose,
    /// Its energy on the subsample (d2m, Huber).
    pub energy: f64,
}

/// The initialization of a multi-scan calibration.
#[derive(Clone, Debug)]
pub struct CloudInit {
    /// The template of the scanned hand (the given one or its mirror image), scaled
    /// anisotropically to the scans.
    pub template: SphereMeshTemplate,
    /// Whether the mirror image was chosen.
    pub mirrored: bool,
    /// Per scan its pose.
    pub poses: Vec<CloudPose>,
    /// Per scan its hand part ([`split_forearm`]), as a calibration frame.
    pub frames: Vec<CalibrationFrame>,
    /// Sum of the hypothesis energies of the chosen hand and of the other one.
    pub energies: [f64; 2],
}

/// Set the six global DOFs of `pose` so that the model is turned by `r` (model → data frame)
/// and the centroid of the template's *rest* sphere centers lands on `target`; the
/// articulation of `pose` is kept.
pub fn place_pose(
    template: &SphereMeshTemplate,
    pose: &mut Pose,
    r: &Matrix3<f64>,
    target: &Vector3<f64>,
) {
    let sk = &template.skeleton;
    let rest = PosedSphereMesh::new(template, &Pose::zeros(sk));
    let c = rest.spheres.iter().map(|s| s.center).sum::<Vector3<f64>>() / rest.spheres.len() as f64;
    let t = target - r * c;
    let [a, b, g] = matrix_to_euler_xyz(r);
    for (name, v) in [
        ("global_rx", a),
        ("global_ry", b),
        ("global_rz", g),
        ("global_tx", t.x),
        ("global_ty", t.y),
        ("global_tz", t.z),
    ] {
        // Every template has the six global DOFs.
        let _ = pose.set(sk, name, v);
    }
}

/// The pose with every finger `flex` DOF at `bend` and `thumb_cmc_abd` at `thumb` (clamped to
/// the joint limits).
fn bent(template: &SphereMeshTemplate, bend: f64, thumb: f64) -> Pose {
    let sk = &template.skeleton;
    let mut p = Pose::zeros(sk);
    for d in sk.dofs() {
        if d.name.contains("flex") && !d.name.starts_with("global") {
            // The name comes from the skeleton itself.
            let _ = p.set(sk, &d.name, bend);
        }
    }
    // A template without the DOF keeps its thumb.
    let _ = p.set(sk, "thumb_cmc_abd", thumb);
    p.clamp_to_limits(sk);
    p
}

/// Every `k`-th point, about `n` of them.
fn subsample(points: &[Vector3<f64>], n: usize) -> Vec<Vector3<f64>> {
    let step = (points.len() / n.max(1)).max(1);
    points.iter().step_by(step).copied().collect()
}

/// A scan split at the wrist ([`split_forearm`]).
#[derive(Clone, Debug)]
pub struct ForearmSplit {
    /// The points of the hand side (with a stretch of forearm as long as the template's wrist
    /// segment).
    pub hand: Vec<Vector3<f64>>,
    /// Points removed as forearm.
    pub removed: usize,
    /// Unit vector along the scan's long axis, from the wrist toward the fingers.
    pub toward_fingers: Vector3<f64>,
}

/// Bins of the cross-section profile along the long axis.
const PROFILE_BINS: usize = 48;

/// Cut the forearm off a complete scan of a hand, from the scan's shape alone (no model, any
/// unit). Along the long axis, the cross-section radius (RMS distance of a slice's points to
/// the slice's centroid, 48 slices) is a forearm's plateau at one end and the hand's wider or
/// varying profile at the other: the end whose slices are narrower and steadier is the
/// forearm's. The wrist
/// is the narrowest slice in the first 60 % of the way from the widest slice toward that end;
/// points beyond the wrist by more than 0.2 × the wrist-to-hand-end length (the
/// template's wrist segment reaches 46 mm below the crease, about 0.2 of a hand's length) are
/// removed. A scan without a forearm loses at most a stretch of its wrist.
pub fn split_forearm(points: &[Vector3<f64>]) -> Option<ForearmSplit> {
    let (c, axes) = principal_axes(points)?;
    let a0: Vector3<f64> = axes.column(0).into_owned();
    let t: Vec<f64> = points.iter().map(|p| (p - c).dot(&a0)).collect();
    let (lo, hi) = t
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        });
    let width = (hi - lo) / PROFILE_BINS as f64;
    if width.is_nan() || width <= 0.0 {
        return None;
    }
    let bin = |x: f64| (((x - lo) / width) as usize).min(PROFILE_BINS - 1);
    let mut sums = [(0usize, Vector3::zeros()); PROFILE_BINS];
    for (p, &x) in points.iter().zip(&t) {
        let b = &mut sums[bin(x)];
        b.0 += 1;
        b.1 += p;
    }
    let mut spread = [0.0; PROFILE_BINS];
    for (p, &x) in points.iter().zip(&t) {
        let (n, sum) = sums[bin(x)];
        let d = p - sum / n as f64;
        spread[bin(x)] += (d - a0 * d.dot(&a0)).norm_squared() / n as f64;
    }
    // Three-bin moving average of the RMS radius.
    let radius: Vec<f64> = (0..PROFILE_BINS)
        .map(|k| {
            let r = k.saturating_sub(1)..(k + 2).min(PROFILE_BINS);
            let n = r.len() as f64;
            r.map(|j| spread[j].sqrt()).sum::<f64>() / n
        })
        .collect();
    // The forearm's end is the narrower and steadier one (slices 3..15 from each end: past a
    // scan's rounded edge, short of the palm): score = mean radius × (1 + 4 × its coefficient
    // of variation), since a pointing finger is narrow too, but not steady.
    let end_stats = |bins: std::ops::Range<usize>| {
        let v: Vec<f64> = bins.map(|k| radius[k]).collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        mean + 4.0 * sd
    };
    let low = end_stats(3..15);
    let high = end_stats(PROFILE_BINS - 15..PROFILE_BINS - 3);
    let forearm_low = low < high;
    let toward_fingers = if forearm_low { a0 } else { -a0 };
    let widest = (0..PROFILE_BINS).max_by(|&a, &b| radius[a].total_cmp(&radius[b]))?;
    // The wrist: the narrowest slice in the first 60 % of the way from the widest slice to the
    // forearm's end (the rest may be the scan's tapering edge).
    let window: Vec<usize> = if forearm_low {
        (widest - (widest * 3 / 5)..widest).collect()
    } else {
        (widest + 1..=widest + (PROFILE_BINS - 1 - widest) * 3 / 5).collect()
    };
    let Some(wrist) = window
        .into_iter()
        .min_by(|&a, &b| radius[a].total_cmp(&radius[b]))
    else {
        return Some(ForearmSplit {
            hand: points.to_vec(),
            removed: 0,
            toward_fingers,
        });
    };
    let tw = lo + (wrist as f64 + 0.5) * width;
    let (hand_end, sign) = if forearm_low { (hi, -1.0) } else { (lo, 1.0) };
    let cut = tw + sign * 0.2 * (tw - hand_end).abs();
    let hand: Vec<Vector3<f64>> = points
        .iter()
        .zip(&t)
        .filter(|(_, &x)| sign * (x - cut) <= 0.0)
        .map(|(p, _)| *p)
        .collect();
    Some(ForearmSplit {
        removed: points.len() - hand.len(),
        hand,
        toward_fingers,
    })
}

/// The pose of `base` that best explains one complete scan (see the module docs). Errors: a
/// scan of fewer than 50 points or with a non-finite point, a template the calibration cannot
/// pose.
pub fn initialize_cloud_pose(
    base: &SphereMeshTemplate,
    points: &[Vector3<f64>],
    search: &CloudSearch,
) -> Result<CloudPose, CalibrationError> {
    let split = split_forearm(points)
        .ok_or_else(|| CalibrationError::Input("a scan has fewer than 3 distinct points".into()))?;
    let coarse = CalibrationFrame::cloud(subsample(&split.hand, search.sample / 2));
    let fine = CalibrationFrame::cloud(subsample(&split.hand, search.sample));
    let Some((c, axes)) = principal_axes(&fine.points) else {
        return Err(CalibrationError::Input(
            "a scan has fewer than 3 points".into(),
        ));
    };
    let fit = |frame: &CalibrationFrame, pose: Pose, iterations| {
        fit_pose(base, frame, pose, iterations, search.robust)
    };
    let mut coarse_fits: Vec<(f64, Pose)> = Vec::new();
    let y = split.toward_fingers;
    {
        let side = axes.column(1) - y * y.dot(&axes.column(1));
        let e1 = side
            .try_normalize(1e-9)
            .unwrap_or_else(|| y.cross(&Vector3::x()).normalize());
        let e2 = y.cross(&e1);
        for roll in 0..search.rolls {
            let phi = roll as f64 * std::f64::consts::TAU / search.rolls as f64;
            let x = e1 * phi.cos() + e2 * phi.sin();
            let r = Matrix3::from_columns(&[x, y, x.cross(&y)]);
            for &bend in &search.bends {
                for &thumb in &search.thumb_abduction {
                    let mut pose = bent(base, bend, thumb);
                    place_pose(base, &mut pose, &r, &c);
                    coarse_fits.push(fit(&coarse, pose, search.iterations / 2)?);
                }
            }
        }
    }
    coarse_fits.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut best: Option<CloudPose> = None;
    for (_, pose) in coarse_fits.into_iter().take(search.refine) {
        let (energy, pose) = fit(&fine, pose, search.iterations)?;
        if best.as_ref().is_none_or(|b| energy < b.energy) {
            best = Some(CloudPose { pose, energy });
        }
    }
    // At least one rotation, shift and bend was tried.
    best.ok_or_else(|| CalibrationError::Input("no pose hypothesis (empty search)".into()))
}

/// The pose-only LM fit of `template` to one cloud frame from `pose` (Huber d2m with threshold
/// `robust` mm, `iterations` steps at most): its energy and the pose.
fn fit_pose(
    template: &SphereMeshTemplate,
    frame: &CalibrationFrame,
    pose: Pose,
    iterations: usize,
    robust: f64,
) -> Result<(f64, Pose), CalibrationError> {
    let config = CalibrationConfig {
        fit_shape: false,
        iterations,
        robust,
        ..CalibrationConfig::default()
    };
    let fit = calibrate(template, std::slice::from_ref(frame), &[pose], &config)?;
    let energy = fit.best_energy();
    let pose = fit
        .poses
        .into_iter()
        .next()
        .ok_or_else(|| CalibrationError::Input("the pose fit returned no pose".into()))?;
    Ok((energy, pose))
}

/// The articulation DOFs by digit (the DOF name's prefix before its first `_`, `thumb`,
/// `index`, ...), in skeleton order; global and wrist DOFs belong to none.
fn digits(template: &SphereMeshTemplate) -> Vec<(String, Vec<usize>)> {
    let mut out: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, d) in template.skeleton.dofs().iter().enumerate() {
        let prefix = d.name.split('_').next().unwrap_or("");
        if prefix.is_empty() || prefix == "global" || prefix == "wrist" {
            continue;
        }
        match out.iter_mut().find(|(p, _)| p == prefix) {
            Some((_, dofs)) => dofs.push(i),
            None => out.push((prefix.to_string(), vec![i])),
        }
    }
    out
}

/// Per-digit coordinate search on one scan's hand part, from `pose`: for each digit in turn
/// (the others held at the best pose so far), every flexion of `search.digit_bends` (all of the
/// digit's `flex` DOFs at once; the thumb also at every `search.thumb_abduction`) is fitted for
/// the whole pose and the lowest energy kept. The pose LM follows the gradient of the d2m,
/// which a digit lying in the wrong valley (curled where the scan's is straight, or folded over
/// the palm the other way) cannot climb out of, while [`initialize_cloud_pose`] only tries
/// whole-hand bends. Hypotheses are screened like the coarse pass of [`initialize_cloud_pose`]
/// (half the points, half the iterations), the current pose refitted the same way so that it
/// competes on equal terms and stays unless a hypothesis explains the scan better; then every
/// pair of `search.digit_pairs` at every combination of two bends; the winner is refined on the
/// full subsample. Errors as [`calibrate`].
pub fn refine_digits(
    template: &SphereMeshTemplate,
    points: &[Vector3<f64>],
    pose: &Pose,
    search: &CloudSearch,
) -> Result<CloudPose, CalibrationError> {
    let coarse = CalibrationFrame::cloud(subsample(points, search.sample / 2));
    let short = search.iterations / 2;
    let (mut energy, mut best) = fit_pose(template, &coarse, pose.clone(), short, search.robust)?;
    let sk = &template.skeleton;
    let digits = digits(template);
    // One setting: all `flex` DOFs of a digit at a bend, its `abd` ones at the abduction when
    // given. A step offers every hypothesis of one digit or pair, tried from the best so far.
    type Setting<'a> = (&'a [usize], f64, Option<f64>);
    let mut steps: Vec<Vec<Vec<Setting>>> = Vec::new();
    for (digit, dofs) in &digits {
        let abductions: Vec<Option<f64>> = if digit == "thumb" {
            search.thumb_abduction.iter().copied().map(Some).collect()
        } else {
            vec![None]
        };
        steps.push(
            search
                .digit_bends
                .iter()
                .flat_map(|&b| {
                    abductions
                        .iter()
                        .map(move |&a| vec![(dofs.as_slice(), b, a)])
                })
                .collect(),
        );
    }
    let find = |name: &str| digits.iter().find(|(d, _)| d == name).map(|(_, v)| v);
    for [a, b] in &search.digit_pairs {
        let (Some(da), Some(db)) = (find(a), find(b)) else {
            continue;
        };
        steps.push(
            search
                .digit_bends
                .iter()
                .flat_map(|&x| {
                    search
                        .digit_bends
                        .iter()
                        .map(move |&y| vec![(da.as_slice(), x, None), (db.as_slice(), y, None)])
                })
                .collect(),
        );
    }
    for step in steps {
        let trials: Vec<Pose> = step
            .iter()
            .map(|settings| {
                let mut p = best.clone();
                for &(dofs, bend, abduction) in settings {
                    for &i in dofs {
                        let name = &sk.dofs()[i].name;
                        if name.contains("flex") {
                            p.values[i] = bend;
                        } else if let (Some(a), true) = (abduction, name.contains("abd")) {
                            p.values[i] = a;
                        }
                    }
                }
                p.clamp_to_limits(sk);
                p
            })
            .collect();
        for p in trials {
            let (e, q) = fit_pose(template, &coarse, p, short, search.robust)?;
            if e < energy {
                (energy, best) = (e, q);
            }
        }
    }
    let fine = CalibrationFrame::cloud(subsample(points, search.sample));
    let (energy, pose) = fit_pose(template, &fine, best, search.iterations, search.robust)?;
    Ok(CloudPose { pose, energy })
}

/// Forearm removal, handedness and poses for a calibration from complete scans (see the
/// module docs); the scans must be in millimetres. Errors: no scan, a scan that
/// [`initialize_cloud_pose`] refuses, a template without a mirror image.
pub fn initialize_clouds(
    base: &SphereMeshTemplate,
    scans: &[Vec<Vector3<f64>>],
    search: &CloudSearch,
) -> Result<CloudInit, CalibrationError> {
    if scans.is_empty() {
        return Err(CalibrationError::Input("no scan".into()));
    }
    let mirror = base.mirrored()?;
    let fit = |t: &SphereMeshTemplate| -> Result<Vec<CloudPose>, CalibrationError> {
        scans
            .iter()
            .map(|s| initialize_cloud_pose(t, s, search))
            .collect()
    };
    let total = |v: &[CloudPose]| v.iter().map(|p| p.energy).sum::<f64>();
    let (given, mirrored) = (fit(base)?, fit(&mirror)?);
    let energies = [total(&given), total(&mirrored)];
    let (template, poses, is_mirror, energies) = if energies[1] < energies[0] {
        (mirror, mirrored, true, [energies[1], energies[0]])
    } else {
        (base.clone(), given, false, energies)
    };
    let frames: Vec<CalibrationFrame> = scans
        .iter()
        .map(|s| {
            // `initialize_cloud_pose` accepted the scan, so it splits.
            let hand = split_forearm(s).map_or_else(|| s.clone(), |h| h.hand);
            CalibrationFrame::cloud(hand)
        })
        .collect();
    let poses = frames
        .iter()
        .zip(&poses)
        .map(|(f, p)| refine_digits(&template, &f.points, &p.pose, search))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(CloudInit {
        template,
        mirrored: is_mirror,
        poses,
        frames,
        energies,
    })
}

/// A calibration from complete scans ([`calibrate_clouds`]).
#[derive(Clone, Debug)]
pub struct CloudCalibration {
    /// The initialization (handedness, hand parts, first poses).
    pub init: CloudInit,
    /// The calibration kept: that of the last round that lowered the data energy.
    pub calibration: Calibration,
    /// Per round (the first calibration, then each of `search.rounds`) its data energy (d2m
    /// + m2d at its best iterate) and whether it was kept.
    pub rounds: Vec<(f64, bool)>,
}

/// The data part (d2m + m2d) of a calibration's lowest-energy iterate (the initial guess when
/// no step was accepted: the data energy of the frames is then not recorded, infinite).
fn data_energy(c: &Calibration) -> f64 {
    c.iterations
        .iter()
        .filter(|r| r.accepted)
        .min_by(|a, b| a.energy.total_cmp(&b.energy))
        .map_or(f64::INFINITY, |r| r.d2m + r.m2d)
}

/// The whole calibration from complete scans in millimetres (thesis §3.4, multi-view case):
/// [`initialize_clouds`], [`calibrate`], then `search.rounds` times an alternation: each scan's
/// digits searched again ([`refine_digits`]) on the calibrated template from its calibrated
/// pose, and a calibration from there. The first poses are found on the uncalibrated template,
/// whose proportions differ from the hand's; a digit hypothesis that lost to a wrong one then
/// may win on the calibrated shape, and the shape stops absorbing that pose error. A round is
/// kept only if it lowers the data energy. `config` is usually [`CalibrationConfig::clouds`].
/// Errors as [`initialize_clouds`] and [`calibrate`].
pub fn calibrate_clouds(
    base: &SphereMeshTemplate,
    scans: &[Vec<Vector3<f64>>],
    search: &CloudSearch,
    config: &CalibrationConfig,
) -> Result<CloudCalibration, CalibrationError> {
    let init = initialize_clouds(base, scans, search)?;
    let poses: Vec<Pose> = init.poses.iter().map(|p| p.pose.clone()).collect();
    let mut best = calibrate(&init.template, &init.frames, &poses, config)?;
    let mut rounds = vec![(data_energy(&best), true)];
    for _ in 0..search.rounds {
        let poses = init
            .frames
            .iter()
            .zip(&best.poses)
            .map(|(f, p)| refine_digits(&best.template, &f.points, p, search).map(|c| c.pose))
            .collect::<Result<Vec<_>, _>>()?;
        let next = calibrate(&best.template, &init.frames, &poses, config)?;
        let energy = data_energy(&next);
        let better = energy
            < rounds
                .iter()
                .filter(|r| r.1)
                .map(|r| r.0)
                .fold(f64::INFINITY, f64::min);
        rounds.push((energy, better));
        if better {
            best = next;
        }
    }
    Ok(CloudCalibration {
        init,
        calibration: best,
        rounds,
    })
}
