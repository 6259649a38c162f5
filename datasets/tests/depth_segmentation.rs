//! Issue "depth-only segmentation": `segment_depth_only` must match the hand across motions,
//! subjects, sensor models and backgrounds, without a color image (sequences from other
//! renderers), so that the Ch. 2 tracker with `--segmentation depth` is close to the wristband run.
//!
//! Measure: per frame, precision and recall of the mask against the synthesizer's `Hand` label.
//! - Recall counts `Hand` pixels that have a depth in range (structured light drops some).
//! - Precision counts as correct the `Hand` pixels and the forearm (and band) pixels within
//!   [`WRIST_SLACK_MM`] of the wrist joint in 3D: the sphere-mesh hand has wrist spheres reaching
//!   ≈ 50 mm below the wrist joint along the forearm, so a cut at the wrist crease is as good for
//!   the tracker as one exactly at the `Hand` label's end.
//!
//! Run `cargo test --release -p datasets --test depth_segmentation -- --nocapture` for the table.

use std::time::Instant;

use datasets::noise::SensorModel;
use datasets::synth::{Part, SceneConfig, Synthesizer};
use datasets::{subject_by_name, MotionLibrary};
use hand_model::spheremesh::default_right_hand;
use nalgebra::Vector3;
use sensor_io::preprocess::{segment_depth_only, DepthOnlyParams, HandSegment, SegmentScratch};
use sensor_io::Camera;

/// Forearm pixels this close (mm, 3D) to the wrist joint count as hand for precision.
const WRIST_SLACK_MM: f64 = 45.0;
/// Frames sampled per (motion, subject, noise) sequence.
const FRAMES_PER_SEQUENCE: usize = 6;

const MOTIONS: [&str; 5] = ["teaser", "fist", "rotation_fast", "occlusion", "pinch"];
const SUBJECTS: [&str; 4] = ["default", "large", "small", "random"];
const NOISES: [&str; 3] = ["none", "tof", "structured"];

/// Quality of one segmented frame.
#[derive(Clone, Debug)]
struct FrameQuality {
    label: String,
    precision: f64,
    recall: f64,
    micros: f64,
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Segments sampled frames of every (motion, subject, noise) combination; the background wall
/// cycles through 1100 mm, none and 650 mm (a close wall) over the (subject, noise) pairs.
fn measure(params: &DepthOnlyParams) -> Vec<FrameQuality> {
    let base = default_right_hand();
    let cam = Camera::sr300_qvga();
    let w = cam.width as usize;
    let mut out = Vec::new();
    let mut seg = HandSegment::default();
    let mut seq = 0usize;
    for motion_name in MOTIONS {
        let mut combo = 0usize;
        let motion = MotionLibrary::by_name_for(motion_name, 7, &base.skeleton).expect("motion");
        let n = motion.num_frames(60.0);
        for subject_name in SUBJECTS {
            let subject = subject_by_name(subject_name, 11).expect("subject");
            for noise in NOISES {
                let wall_mm = [Some(1100.0), None, Some(650.0)][(combo + combo / 3) % 3];
                combo += 1;
                seq += 1;
                let config = SceneConfig {
                    sensor: SensorModel::by_name(noise).expect("noise"),
                    wall_mm,
                    seed: seq as u64,
                    ..Default::default()
                };
                let mut synth = Synthesizer::new(&base, &subject.beta, config).expect("synth");
                // One per sequence: it carries the previous frame's palm as a hint.
                let mut scratch = SegmentScratch::default();
                for k in 0..FRAMES_PER_SEQUENCE {
                    let frame = (k * n + n / 2) / FRAMES_PER_SEQUENCE;
                    let t = frame as f64 / 60.0;
                    let f = synth
                        .render(frame as u64, t, &motion.pose_at(t))
                        .expect("render");
                    let depth = &f.frame.depth;
                    let valid = |i: usize| {
                        let d = depth.data[i];
                        d >= params.near && d <= params.far
                    };
                    let hand_px = (0..depth.data.len())
                        .filter(|&i| f.parts[i] == Part::Hand && valid(i))
                        .count();
                    if hand_px < 300 {
                        continue; // the hand is (mostly) out of view
                    }
                    let t0 = Instant::now();
                    segment_depth_only(depth, &cam, params, &mut seg, &mut scratch);
                    let micros = t0.elapsed().as_secs_f64() * 1e6;
                    let wrist = Vector3::from(f.truth.keypoints[0]);
                    let (mut tp, mut ok, mut n_mask) = (0usize, 0usize, 0usize);
                    for (i, &m) in seg.mask.data.iter().enumerate() {
                        if m == 0 {
                            continue;
                        }
                        n_mask += 1;
                        match f.parts[i] {
                            Part::Hand => {
                                tp += 1;
                                ok += 1;
                            }
                            Part::Forearm | Part::Wristband => {
                                let p = cam.backproject(
                                    (i % w) as f64,
                                    (i / w) as f64,
                                    depth.data[i] as f64,
                                );
                                if (p - wrist).norm() <= WRIST_SLACK_MM {
                                    ok += 1;
                                }
                            }
                            Part::Background => {}
                        }
                    }
                    let precision = if n_mask == 0 {
                        0.0
                    } else {
                        ok as f64 / n_mask as f64
                    };
                    let recall = tp as f64 / hand_px as f64;
                    if let Ok(dir) = std::env::var("HANDS_SEG_DUMP") {
                        if precision.min(recall) < 0.8 {
                            dump(
                                &dir,
                                &format!("{motion_name}_{subject_name}_{noise}_{frame}"),
                                &f,
                                &seg,
                                &cam,
                                wrist,
                            );
                        }
                    }
                    out.push(FrameQuality {
                        label: format!(
                            "{motion_name}/{subject_name}/{noise}/wall {wall_mm:?} frame {frame}"
                        ),
                        precision,
                        recall,
                        micros,
                    });
                }
            }
        }
    }
    out
}

/// Debug picture (`HANDS_SEG_DUMP=dir`): green kept hand, red missed hand, cyan kept forearm
/// near the wrist, blue kept forearm beyond, yellow kept background, gray levels the depth.
fn dump(
    dir: &str,
    name: &str,
    f: &datasets::synth::SynthFrame,
    seg: &HandSegment,
    cam: &Camera,
    wrist: Vector3<f64>,
) {
    let (w, h) = (cam.width, cam.height);
    let mut img = image::RgbImage::new(w, h);
    for (i, px) in img.pixels_mut().enumerate() {
        let d = f.frame.depth.data[i] as f64;
        let g = if d == 0.0 {
            0
        } else {
            (255.0 - (d - 200.0) * 0.2).clamp(40.0, 255.0) as u8
        };
        let m = seg.mask.data[i] != 0;
        let p = cam.backproject((i % w as usize) as f64, (i / w as usize) as f64, d);
        *px = image::Rgb(match (f.parts[i], m) {
            (Part::Hand, true) => [0, g, 0],
            (Part::Hand, false) if d > 0.0 => [g, 0, 0],
            (Part::Forearm | Part::Wristband, true) if (p - wrist).norm() <= WRIST_SLACK_MM => {
                [0, g, g]
            }
            (Part::Forearm | Part::Wristband, true) => [0, 0, g],
            (Part::Background, true) => [g, g, 0],
            _ => [g / 2, g / 2, g / 2],
        });
    }
    if let Some(c) = seg.palm_center {
        let q = cam.project(&c);
        for du in -2i32..=2 {
            let (u, v) = (
                (q.x as i32 + du).clamp(0, w as i32 - 1),
                (q.y as i32).clamp(0, h as i32 - 1),
            );
            img.put_pixel(u as u32, v as u32, image::Rgb([255, 0, 255]));
        }
    }
    let _ = std::fs::create_dir_all(dir);
    img.save(format!("{dir}/{name}.png")).expect("save dump");
}

fn summarize(q: &[FrameQuality], name: &str) -> (f64, f64, f64, f64) {
    let mut p: Vec<f64> = q.iter().map(|f| f.precision).collect();
    let mut r: Vec<f64> = q.iter().map(|f| f.recall).collect();
    let (pm, p10) = (quantile(&mut p, 0.5), quantile(&mut p, 0.1));
    let (rm, r10) = (quantile(&mut r, 0.5), quantile(&mut r, 0.1));
    eprintln!(
        "{name:>14}: {:4} frames, precision median {pm:.3} p10 {p10:.3}, recall median {rm:.3} p10 {r10:.3}",
        q.len()
    );
    (pm, p10, rm, r10)
}

#[test]
fn depth_only_segmentation_matches_the_hand() {
    let q = measure(&DepthOnlyParams::default());
    let mut us: Vec<f64> = q.iter().map(|f| f.micros).collect();
    let median_us = quantile(&mut us, 0.5);
    for group in MOTIONS.iter().chain(&SUBJECTS).chain(&NOISES) {
        let sel: Vec<FrameQuality> = q
            .iter()
            .filter(|f| f.label.split('/').any(|s| s == *group))
            .cloned()
            .collect();
        let (pm, _, rm, _) = summarize(&sel, group);
        // Measured (this commit): every group ≥ 0.977 median precision, ≥ 0.955 median recall.
        assert!(pm >= 0.93, "{group}: median precision {pm:.3}");
        assert!(rm >= 0.92, "{group}: median recall {rm:.3}");
    }
    let (pm, p10, rm, r10) = summarize(&q, "all");
    let mut worst: Vec<&FrameQuality> = q.iter().collect();
    worst.sort_by(|a, b| (a.precision.min(a.recall)).total_cmp(&b.precision.min(b.recall)));
    for f in worst.iter().take(15) {
        eprintln!(
            "  worst: {} precision {:.3} recall {:.3}",
            f.label, f.precision, f.recall
        );
    }
    eprintln!(
        "median {median_us:.0} µs per QVGA frame (max {:.0})",
        us.last().copied().unwrap_or(0.0)
    );
    assert!(q.len() > 300, "only {} frames measured", q.len());
    // Measured (this commit): precision median 0.989, p10 0.935; recall median 0.977, p10 0.907
    // (before: precision 1.000 / 0.736, recall 0.880 / 0.673 — fingers or fists cut off as the
    // "forearm", wrists cut short). Session 15 (the growth repeated for a lone thumb tip and
    // around the palm, occluded fingers added, holes filled for the palm circle, the previous
    // frame's palm as a hint): precision median 0.976 → 0.980, p10 0.883 → 0.938; recall median
    // 0.997 → 0.999, p10 0.910 → 0.946; the worst frame's min(precision, recall) 0.024 → 0.676.
    assert!(
        pm >= 0.96 && p10 >= 0.90,
        "precision median {pm:.3}, p10 {p10:.3}"
    );
    assert!(
        rm >= 0.95 && r10 >= 0.92,
        "recall median {rm:.3}, p10 {r10:.3}"
    );
    let worst_min = worst.first().map_or(0.0, |f| f.precision.min(f.recall));
    assert!(worst_min >= 0.5, "worst frame: {worst_min:.3}");
}

#[test]
#[ignore = "parameter sweep, prints a table"]
fn sweep() {
    for radius in [220.0, 300.0] {
        for cut_range in [[60.0, 110.0], [80.0, 110.0], [80.0, 130.0], [95.0, 130.0]] {
            for cut_palm_radii in [2.4, 2.8] {
                let p = DepthOnlyParams {
                    radius,
                    cut_range,
                    cut_palm_radii,
                    ..Default::default()
                };
                eprint!("r {radius} cut {cut_range:?} × {cut_palm_radii}: ");
                let _ = summarize(&measure(&p), "all");
            }
        }
    }
}
