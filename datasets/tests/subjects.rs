//! Tests of the synthetic subjects.

use datasets::subjects::{
    hand_length, subject_by_name, Subject, DEFAULT_PERTURBATION, HAND_LENGTH_RANGE, LATENT_RANGES,
};
use datasets::DatasetError;
use hand_model::spheremesh::{default_right_hand, ShapeBasis};

fn in_adult_range(len: f64) -> bool {
    (HAND_LENGTH_RANGE[0]..=HAND_LENGTH_RANGE[1]).contains(&len)
}

#[test]
fn every_named_subject_applies_and_is_adult_sized() {
    let t = default_right_hand();
    let basis = ShapeBasis::honline(&t).unwrap();
    for name in Subject::names() {
        let s = Subject::named(name).unwrap();
        assert_eq!(s.name, *name);
        assert_eq!(s.beta.len(), basis.len());
        let shaped = s.template().unwrap();
        let len = hand_length(&shaped);
        println!("{name}: hand length {len:.1} mm");
        assert!(in_adult_range(len), "{name}: {len}");
        assert!((s.hand_length().unwrap() - len).abs() < 1e-12);
        for (b, p) in s.beta.iter().zip(&basis.params) {
            if let Some([lo, hi]) = p.limits {
                assert!((lo..=hi).contains(b), "{name}: {} = {b}", p.name);
            }
        }
        let named = s.shape_named().unwrap();
        assert_eq!(named.len(), basis.len());
        assert_eq!(named[0].0, basis.params[0].name);
    }
    // The default subject is the template itself.
    let d = Subject::named("default").unwrap();
    assert_eq!(d.beta, basis.template_values());
    // Relations that the names promise.
    let len = |n: &str| Subject::named(n).unwrap().hand_length().unwrap();
    assert!(len("small") < len("default") && len("default") < len("large"));
    assert!(len("short_fingers") < len("default") && len("default") < len("long_fingers"));
    let beta = |n: &str, p: &str| {
        let s = Subject::named(n).unwrap();
        let i = basis.params.iter().position(|q| q.name == p).unwrap();
        s.beta[i]
    };
    assert!(beta("wide_palm", "pinky_base_x") > beta("default", "pinky_base_x"));
    assert!(beta("thick", "index_bottom_radius") > beta("default", "index_bottom_radius"));
    assert!(beta("long_fingers", "palm_index_radius") == beta("default", "palm_index_radius"));
}

#[test]
fn random_subjects_are_deterministic_in_range_and_valid() {
    let t = default_right_hand();
    let basis = ShapeBasis::honline(&t).unwrap();
    let tv = basis.template_values();
    let mut lengths = vec![];
    for seed in 0..40 {
        let a = Subject::random(seed, DEFAULT_PERTURBATION).unwrap();
        let b = Subject::random(seed, DEFAULT_PERTURBATION).unwrap();
        assert_eq!(a, b, "seed {seed}");
        assert_eq!(a.name, format!("random-{seed}"));
        let shaped = a.template().unwrap();
        let len = hand_length(&shaped);
        assert!(in_adult_range(len), "seed {seed}: {len}");
        lengths.push(len);
        // Every entry within latent range × perturbation of the template value, and the bounds.
        let lo_s = LATENT_RANGES.iter().map(|r| r[0]).fold(f64::MAX, f64::min);
        let hi_s = LATENT_RANGES.iter().map(|r| r[1]).fold(0.0, f64::max);
        for ((v, p), t0) in a.beta.iter().zip(&basis.params).zip(&tv) {
            let (x, y) = (
                t0 * lo_s * (1.0 - DEFAULT_PERTURBATION),
                t0 * hi_s * (1.0 + DEFAULT_PERTURBATION),
            );
            let (lo, hi) = if x <= y { (x, y) } else { (y, x) };
            assert!(
                *v >= lo - 1e-9 && *v <= hi + 1e-9,
                "seed {seed}: {} = {v}",
                p.name
            );
            if let Some([l, h]) = p.limits {
                assert!((l..=h).contains(v), "seed {seed}: {} = {v}", p.name);
            }
        }
    }
    assert_ne!(
        Subject::random(1, DEFAULT_PERTURBATION).unwrap().beta,
        Subject::random(2, DEFAULT_PERTURBATION).unwrap().beta
    );
    // The draws do spread over the range.
    let (mn, mx) = lengths
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &l| (a.min(l), b.max(l)));
    println!("random hand lengths: {mn:.1}–{mx:.1} mm");
    assert!(mx - mn > 20.0);
    // No perturbation: a pure latent scaling.
    let s = Subject::random(5, 0.0).unwrap();
    let r: Vec<f64> = s
        .beta
        .iter()
        .zip(&tv)
        .zip(&basis.params)
        .filter(|((_, t0), p)| t0.abs() > 1e-9 && p.kind.latent_axis() == 0 && p.limits.is_some())
        .map(|((b, t0), _)| b / t0)
        .collect();
    assert!(r.iter().all(|x| (x - r[0]).abs() < 1e-12));
}

#[test]
fn bad_arguments_are_errors() {
    for p in [-0.1, f64::NAN, f64::INFINITY, 0.9] {
        assert!(Subject::random(0, p).is_err(), "{p}");
    }
    let err = subject_by_name("giant", 0).unwrap_err();
    assert!(matches!(err, DatasetError::UnknownSubject { .. }));
    let msg = err.to_string();
    assert!(msg.contains("giant") && msg.contains("small") && msg.contains("random"));
    assert_eq!(
        subject_by_name("random", 9).unwrap(),
        Subject::random(9, DEFAULT_PERTURBATION).unwrap()
    );
    assert_eq!(
        subject_by_name("large", 9).unwrap(),
        Subject::named("large").unwrap()
    );
    let bad = Subject {
        name: "bad".into(),
        beta: vec![1.0; 3],
    };
    assert!(bad.template().is_err());
    assert!(bad.shape_named().is_err());
}
