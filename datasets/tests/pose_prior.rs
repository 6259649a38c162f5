//! The PCA pose prior (thesis §2.3.2, Eq. 2.5–2.6) scores natural poses as more likely (lower
//! `E_pose`) than unnatural ones — with the project's own prior and with the original htrack
//! prior — and the committed project prior is reproduced by its build command.

use std::path::Path;

use datasets::animbank::{read_animbank, AnimbankPose, Retargeter};
use datasets::motion::{KeyPose, MotionLibrary};
use datasets::prior::{build_project_prior, fit_prior, key_pose_digits, pose_corpus};
use hand_model::kinematics::names::DIGIT_DOFS;
use hand_model::kinematics::{Pose, Skeleton};
use hand_model::solver::terms::{PosePrior, PosePriorParams};
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::default_right_hand;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ANIMBANK: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/reference/pose-corpus-realsense/animbank.pose"
);
const HTRACK: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/reference/htrack-pose-space-pca"
);
const COMMITTED: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../hand-model/data/pose-prior.json"
);

fn animbank() -> Option<Vec<AnimbankPose>> {
    let p = Path::new(ANIMBANK);
    if p.exists() {
        Some(read_animbank(p).expect("animbank parses"))
    } else {
        eprintln!("skipped the recorded poses: {ANIMBANK} absent");
        None
    }
}

fn set(skeleton: &Skeleton, digits: &[f64]) -> Vec<f64> {
    let mut pose = Pose::zeros(skeleton);
    for (name, v) in DIGIT_DOFS.iter().zip(digits) {
        pose.values[skeleton.dof_index(name).unwrap()] = *v;
    }
    pose.values
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Fraction of (natural, unnatural) pairs ordered correctly.
fn ordered(natural: &[f64], unnatural: &[f64]) -> f64 {
    let mut good = 0usize;
    for n in natural {
        good += unnatural.iter().filter(|u| n < u).count();
    }
    good as f64 / (natural.len() * unnatural.len()) as f64
}

/// Named sets of 20-vectors of digit angles.
struct Sets {
    natural: Vec<(&'static str, Vec<Vec<f64>>)>,
    unnatural: Vec<(&'static str, Vec<Vec<f64>>)>,
}

fn sets(held_out: &[Vec<f64>], limits: &[[f64; 2]; 20]) -> Sets {
    let key = |names: &[&str]| -> Vec<Vec<f64>> {
        names
            .iter()
            .map(|n| key_pose_digits(KeyPose::by_name(n).unwrap()))
            .collect()
    };
    // Library motions at another seed, sampled between the corpus' 10 Hz grid.
    let mut motions = vec![];
    for name in ["teaser", "pinch", "fist", "random"] {
        let m = MotionLibrary::by_name(name, 3).unwrap();
        for i in 0..40 {
            let t = (i as f64 + 0.37) * m.duration() / 40.0;
            motions.push(m.articulation_at(t).0[2..].to_vec());
        }
    }
    let mut natural = vec![
        (
            "open/fist/pinch/point",
            key(&["open", "fist", "pinch_index", "point"]),
        ),
        ("library motions (seed 3)", motions),
    ];
    if !held_out.is_empty() {
        natural.push(("held-out recorded poses", held_out.to_vec()));
    }
    let lo = |i: usize| limits[i][0];
    let hi = |i: usize| limits[i][1];
    let open = key_pose_digits(KeyPose::Open);
    // Alternating: index and ring fully flexed, middle and pinky hyper-extended (and reverse).
    let alternating = |flexed: [usize; 2], straight: [usize; 2]| {
        let mut a = open.clone();
        for d in flexed {
            for k in 1..4 {
                a[4 + 4 * d + k] = hi(4 + 4 * d + k);
            }
        }
        for d in straight {
            for k in 1..4 {
                a[4 + 4 * d + k] = lo(4 + 4 * d + k);
            }
        }
        a
    };
    // Index fully flexed, the others straight, pinky hyper-abducted.
    let mut index_only = vec![0.0; 20];
    for k in 1..4 {
        index_only[4 + k] = hi(4 + k);
    }
    index_only[16] = lo(16);
    // DIPs flexed with the PIPs straight (the tendon coupling forbids it).
    let mut dip_only = open.clone();
    for d in 0..4 {
        dip_only[4 + 4 * d + 2] = lo(4 + 4 * d + 2);
        dip_only[4 + 4 * d + 3] = hi(4 + 4 * d + 3);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let uniform: Vec<Vec<f64>> = (0..300)
        .map(|_| (0..20).map(|i| rng.random_range(lo(i)..=hi(i))).collect())
        .collect();
    Sets {
        natural,
        unnatural: vec![
            (
                "alternating flexion",
                vec![alternating([0, 2], [1, 3]), alternating([1, 3], [0, 2])],
            ),
            ("index flexed, pinky hyper-abducted", vec![index_only]),
            ("DIPs flexed, PIPs straight", vec![dip_only]),
            ("uniform within limits", uniform),
        ],
    }
}

/// Score every set with `prior` (thesis defaults ω₄ = 10³, ω₅ = 1, 3 + 3 latents), print the
/// medians, and assert the natural sets beat every unnatural one: every natural median below
/// every unnatural median, and most (natural, unnatural) pairs ordered.
fn check(label: &str, prior: &PcaPrior, sets: &Sets, skeleton: &Skeleton) {
    let term = PosePrior::new(skeleton, prior, &PosePriorParams::default()).unwrap();
    let score = |s: &[Vec<f64>]| -> Vec<f64> {
        s.iter()
            .map(|d| term.energy(&set(skeleton, d)).unwrap())
            .collect()
    };
    let natural: Vec<(&str, Vec<f64>)> = sets.natural.iter().map(|(n, s)| (*n, score(s))).collect();
    let unnatural: Vec<(&str, Vec<f64>)> =
        sets.unnatural.iter().map(|(n, s)| (*n, score(s))).collect();
    eprintln!("{label}: E_pose medians");
    for (n, e) in natural.iter().chain(&unnatural) {
        eprintln!("  {n:38} {:>5} poses  median {:9.1}", e.len(), median(e));
    }
    let all_natural: Vec<f64> = natural.iter().flat_map(|(_, e)| e.clone()).collect();
    for (un, ue) in &unnatural {
        let frac = ordered(&all_natural, ue);
        eprintln!("  natural < {un}: {:.1} % of pairs", 100.0 * frac);
        for (nn, ne) in &natural {
            assert!(
                median(ne) < median(ue),
                "{label}: median {nn} {} ≥ median {un} {}",
                median(ne),
                median(ue)
            );
        }
        // Single hand-picked poses: most pairs; the 300 uniform poses: nearly all pairs.
        let min = if ue.len() > 100 { 0.95 } else { 0.7 };
        assert!(frac > min, "{label}: natural < {un} in only {frac}");
    }
}

#[test]
fn natural_poses_score_better_than_unnatural_ones() {
    let template = default_right_hand();
    let skeleton = &template.skeleton;
    let retarget = Retargeter::default_template();
    let recorded = animbank().unwrap_or_default();
    // Hold out every 5th recorded pose: fit on the rest, score the held-out ones.
    let (train, test): (Vec<_>, Vec<_>) =
        recorded.iter().enumerate().partition(|(i, _)| i % 5 != 0);
    let train: Vec<AnimbankPose> = train.into_iter().map(|(_, p)| p.clone()).collect();
    let held_out: Vec<Vec<f64>> = test
        .into_iter()
        .map(|(_, p)| retarget.retarget_clamped(p).to_vec())
        .collect();
    let sets = sets(&held_out, retarget.limits());
    let own = fit_prior(&pose_corpus(&train).unwrap()).unwrap();
    check(
        "project prior (fit without the held-out poses)",
        &own,
        &sets,
        skeleton,
    );
    check(
        "project prior (committed)",
        &PcaPrior::project_default(),
        &sets,
        skeleton,
    );
    if Path::new(HTRACK).is_dir() {
        let htrack = PcaPrior::load_htrack_dir(Path::new(HTRACK)).unwrap();
        check("htrack prior", &htrack, &sets, skeleton);
    } else {
        eprintln!("skipped the htrack prior: {HTRACK} absent");
    }
}

#[test]
fn committed_prior_is_reproducible() {
    let path = Path::new(ANIMBANK);
    if !path.exists() {
        eprintln!("skipped: {ANIMBANK} absent (the committed prior includes the recorded poses)");
        return;
    }
    let (built, description) = build_project_prior(Some(path)).unwrap();
    let committed = PcaPrior::load_json(Path::new(COMMITTED)).unwrap();
    assert_eq!(committed, PcaPrior::project_default());
    let text = std::fs::read_to_string(COMMITTED).unwrap();
    assert!(text.contains(&description), "the description changed");
    let mut worst = 0.0f64;
    for (a, b) in built.groups.iter().zip(&committed.groups) {
        assert_eq!(a.dofs, b.dofs);
        let diffs = a
            .mean
            .iter()
            .zip(&b.mean)
            .chain(a.variances.iter().zip(&b.variances))
            .chain(a.basis.iter().zip(b.basis.iter()));
        for (x, y) in diffs {
            worst = worst.max((x - y).abs());
        }
    }
    eprintln!("rebuilt vs committed: max difference {worst:.2e}");
    assert!(worst < 1e-9, "{worst}");
}
