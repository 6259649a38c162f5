//! Issue 7, item 3: published numbers recomputed by our marker-metric code from published
//! per-frame outputs in `../shared/reference` (each test prints that it skipped when the folder is
//! absent):
//! - NYU: mean 3D joint error over the 8252 test frames, V2V-PoseNet 8.42 mm and DeepPrior++
//!   12.24 mm (their papers), plus the fraction-of-frames-under-ε curves of every prediction file
//!   as an SVG in the cargo target tmp dir;
//! - Dexter-1: htrack's mean fingertip error 9.04 mm and median 7.60 mm over 2919 annotated
//!   frames (`dexter1/htrack_errors_all.txt`, Tagliasacchi et al. 2015), and the curves of htrack
//!   with and without re-initialization as an SVG.

use eval::benchmarks::{dexter_score, nyu_file_errors};
use eval::markers::MarkerSummary;
use eval::plot::under_curve_svg;

use datasets::dexter::DEXTER_SEQUENCES;
use datasets::reference::reference_path;

const NYU_TRUTH: &str = "nyu_test_groundtruth_label_14joints_uvd.txt";

#[test]
fn nyu_published_mean_errors_and_curves() {
    let Some(dir) = reference_path("nyu") else {
        return;
    };
    let truth = dir.join(NYU_TRUTH);
    let mut curves = Vec::new();
    let mut files: Vec<_> = std::fs::read_dir(dir.join("predictions"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    for p in &files {
        let errors = nyu_file_errors(p, &truth).unwrap();
        let s = MarkerSummary::new(&errors);
        let name = p.file_stem().unwrap().to_string_lossy().into_owned();
        println!(
            "NYU {name}: {} frames, mean {:.3} mm, median {:.3} mm, mean max {:.3} mm",
            s.frames, s.mean, s.median, s.mean_max
        );
        assert_eq!(s.frames, 8252);
        let published = match name.as_str() {
            "CVPR18_NYU_V2V_PoseNet" => Some(8.42),
            "ICCVW17_NYU_DeepPrior++" => Some(12.24),
            _ => None,
        };
        if let Some(expected) = published {
            assert!(
                (s.mean - expected).abs() < 0.05,
                "{name}: {:.3} mm vs published {expected} mm",
                s.mean
            );
        }
        curves.push((name, errors.iter().map(|e| e.mean).collect::<Vec<f64>>()));
    }
    assert!(curves.len() >= 2, "both published methods are present");
    let svg = under_curve_svg("NYU: mean 3D joint error", &curves, 50.0, 100).unwrap();
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("nyu_under_curves.svg");
    std::fs::write(&out, svg).unwrap();
    println!("wrote {}", out.display());
}

#[test]
fn dexter_htrack_published_fingertip_error() {
    let Some(dir) = reference_path("dexter1") else {
        return;
    };
    let s = dexter_score(&dir, "htrack", &DEXTER_SEQUENCES).unwrap();
    println!(
        "Dexter-1 htrack: {} frames, mean {:.3} mm, median over fingertips {:.3} mm \
         (over frames {:.3} mm)",
        s.frames, s.mean, s.median_tip, s.median_frame
    );
    assert_eq!(s.frames, 2919);
    assert!((s.mean - 9.04).abs() < 0.05, "mean {}", s.mean);
    assert!(
        (s.median_tip - 7.60).abs() < 0.05,
        "median {}",
        s.median_tip
    );
    let r = dexter_score(&dir, "htrack_reinit", &DEXTER_SEQUENCES).unwrap();
    println!(
        "Dexter-1 htrack with re-initialization: {} frames, mean {:.3} mm, median {:.3} mm",
        r.frames, r.mean, r.median_tip
    );
    let curves: Vec<(String, Vec<f64>)> = [("htrack", &s), ("htrack with re-initialization", &r)]
        .iter()
        .map(|(n, sc)| {
            (
                n.to_string(),
                sc.frame_errors.iter().map(|e| e.mean).collect(),
            )
        })
        .collect();
    let svg = under_curve_svg("Dexter-1: mean fingertip error", &curves, 50.0, 100).unwrap();
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("dexter_under_curves.svg");
    std::fs::write(&out, svg).unwrap();
    println!("wrote {}", out.display());
    let e = dexter_score(&dir, "no-such-method", &DEXTER_SEQUENCES).unwrap_err();
    assert!(e.to_string().contains("no-such-method"), "{e}");
}
