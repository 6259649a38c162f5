//! Issue 8 item 5: `hands calibrate --guide` names the least-certain shape parameters, suggests
//! a corpus pose with an above-median expected gain, writes the online estimate and a rendering
//! of the suggestion.

mod common;
use common::hands;

#[test]
fn guide_suggests_an_informative_pose() {
    let d = std::env::temp_dir().join(format!("hands-guide-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp");
    let seq = d.join("seq.mcap");
    let s = |p: &std::path::Path| p.to_str().expect("utf8").to_string();
    let (ok, text) = hands(&[
        "synth",
        "--motion",
        "teaser",
        "--subject",
        "random",
        "--seed",
        "5",
        "--frames",
        "20",
        "--out",
        &s(&seq),
    ]);
    assert!(ok, "{text}");
    let out = d.join("me.json");
    let (ok, text) = hands(&["calibrate", &s(&seq), "--guide", "--out", &s(&out)]);
    println!("{text}");
    assert!(ok, "{text}");
    let listed = text
        .lines()
        .skip_while(|l| !l.contains("least certain"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .count();
    assert_eq!(listed, 5, "{text}");
    // "suggested next pose: … (expected gain G, median over the corpus M)"
    let line = text
        .lines()
        .find(|l| l.starts_with("suggested next pose"))
        .expect("suggestion");
    let numbers: Vec<f64> = line
        .split([' ', ',', ')'])
        .filter_map(|w| w.parse().ok())
        .collect();
    let (gain, median) = (numbers[numbers.len() - 2], numbers[numbers.len() - 1]);
    assert!(gain > median, "{line}");
    assert!(out.exists() && d.join("me.guide.png").exists());
}
