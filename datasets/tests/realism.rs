//! Optional realism check against recorded human hand poses (`pose-corpus-realsense`).
//!
//! `animbank.pose` (IntelRealSense/hand_tracking_samples) holds 2336 poses, one per line, each
//! 17 bones × (position xyz in metres, quaternion xyzw). The bone layout is not documented with
//! the file; from the positions we read it as: 0 forearm, 1 palm, 2–4 thumb, 5–7 index, 8–10
//! middle, 11–13 ring, 14–16 pinky (consecutive bones of a chain 15–75 mm apart), and the test
//! checks that reading before comparing anything. Only the PIP flexion range is compared (the
//! relative rotation of consecutive finger bones, free of rest-pose offsets); the other ranges
//! are printed.

use datasets::motion::{MotionLibrary, JOINT_DOFS};

const PATH: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/reference/pose-corpus-realsense/animbank.pose"
);

type Bone = [f64; 7];

fn parse(text: &str) -> Vec<Vec<Bone>> {
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .map(|x| x.parse::<f64>().expect("a number"))
                .collect();
            assert_eq!(v.len(), 17 * 7, "a pose line has 119 numbers");
            v.chunks(7)
                .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5], c[6]])
                .collect()
        })
        .collect()
}

/// Angle of the relative rotation between two unit quaternions (xyzw).
fn rel_angle(a: &Bone, b: &Bone) -> f64 {
    let dot = a[3] * b[3] + a[4] * b[4] + a[5] * b[5] + a[6] * b[6];
    2.0 * dot.abs().min(1.0).acos()
}

fn dist_mm(a: &Bone, b: &Bone) -> f64 {
    1000.0 * ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn library_flexion_ranges_match_recorded_poses() {
    let Ok(text) = std::fs::read_to_string(PATH) else {
        println!("skipped: {PATH} absent");
        return;
    };
    let poses = parse(&text);
    assert_eq!(poses.len(), 2336);
    for p in &poses {
        for b in p {
            let n = (b[3] * b[3] + b[4] * b[4] + b[5] * b[5] + b[6] * b[6]).sqrt();
            assert!((n - 1.0).abs() < 1e-3, "quaternion norm {n}");
        }
    }
    let chains: [[usize; 4]; 5] = [
        [1, 2, 3, 4],
        [1, 5, 6, 7],
        [1, 8, 9, 10],
        [1, 11, 12, 13],
        [1, 14, 15, 16],
    ];
    for p in &poses {
        for c in &chains {
            for w in c[1..].windows(2) {
                let d = dist_mm(&p[w[0]], &p[w[1]]);
                assert!((15.0..=75.0).contains(&d), "bones {w:?} {d} mm apart");
            }
        }
    }
    // PIP: relative rotation of proximal and middle phalanx (fingers only).
    let mut corpus_pip: Vec<f64> = poses
        .iter()
        .flat_map(|p| {
            chains[1..]
                .iter()
                .map(move |c| rel_angle(&p[c[1]], &p[c[2]]))
        })
        .collect();
    let mut corpus_dip: Vec<f64> = poses
        .iter()
        .flat_map(|p| {
            chains[1..]
                .iter()
                .map(move |c| rel_angle(&p[c[2]], &p[c[3]]))
        })
        .collect();
    let corpus_pip_max = percentile(&mut corpus_pip, 1.0);
    println!(
        "corpus PIP: median {:.2}, p95 {:.2}, max {:.2} rad; DIP: median {:.2}, max {:.2} rad",
        percentile(&mut corpus_pip, 0.5),
        percentile(&mut corpus_pip, 0.95),
        corpus_pip_max,
        percentile(&mut corpus_dip, 0.5),
        percentile(&mut corpus_dip, 1.0)
    );
    let pip: Vec<usize> = JOINT_DOFS
        .iter()
        .enumerate()
        .filter(|(_, n)| n.ends_with("_pip_flex"))
        .map(|(i, _)| i)
        .collect();
    let dip: Vec<usize> = JOINT_DOFS
        .iter()
        .enumerate()
        .filter(|(_, n)| n.ends_with("_dip_flex"))
        .map(|(i, _)| i)
        .collect();
    for name in MotionLibrary::names() {
        let m = MotionLibrary::by_name(name, 0).unwrap();
        let (mut lib_pip, mut lib_dip) = (vec![], vec![]);
        for i in 0..m.num_frames(30.0) {
            let a = m.articulation_at(i as f64 / 30.0);
            lib_pip.extend(pip.iter().map(|&j| a.0[j].abs()));
            lib_dip.extend(dip.iter().map(|&j| a.0[j].abs()));
        }
        let lib_pip_max = percentile(&mut lib_pip, 1.0);
        println!(
            "{name}: PIP median {:.2}, max {:.2}; DIP median {:.2}, max {:.2} rad",
            percentile(&mut lib_pip, 0.5),
            lib_pip_max,
            percentile(&mut lib_dip, 0.5),
            percentile(&mut lib_dip, 1.0)
        );
        assert!(
            lib_pip_max <= corpus_pip_max + 0.15,
            "{name}: PIP flexion {lib_pip_max} beyond recorded human range {corpus_pip_max}"
        );
    }
}
