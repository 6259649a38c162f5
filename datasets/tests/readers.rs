//! Issue 7, dataset readers: each reader on the real files of `../shared/reference` (printing that
//! it skipped when they are absent) and on tiny fixtures written here in the same formats,
//! including truncated and corrupt files, which must be refused with the file (and line) named.

use std::path::{Path, PathBuf};

use datasets::dexter::{
    is_annotated, read_ground_truth, read_htrack_output, DEXTER_POINTS, DEXTER_SEQUENCES,
    HTRACK_JOINTS,
};
use datasets::handy::{HandySequence, HANDY_MARKERS};
use datasets::nyu::{depth_path, read_depth, read_uvd_labels, read_xyz_labels, NYU_JOINTS};
use datasets::reference::reference_path;
use sensor_io::io::{write_color_png, write_depth_png};
use sensor_io::{ColorImage, DepthImage};

fn fixture_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("readers-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn nyu_labels_and_predictions_on_the_real_files() {
    let Some(dir) = reference_path("nyu") else {
        return;
    };
    let truth = read_uvd_labels(&dir.join("nyu_test_groundtruth_label_14joints_uvd.txt")).unwrap();
    assert_eq!(truth.len(), 8252);
    let mut preds = 0;
    for entry in std::fs::read_dir(dir.join("predictions")).unwrap() {
        let p = entry.unwrap().path();
        let frames = read_uvd_labels(&p).unwrap();
        assert_eq!(frames.len(), truth.len(), "{}", p.display());
        preds += 1;
    }
    assert!(preds >= 2);
    // Frame 1 of the labels against the real depth frame: the labels' depths match the decoded
    // sensor depth at their pixels (the (G << 8) | B decoding is right; the joints lie inside
    // the hand, so the surface is a little nearer than most of them).
    let depth = read_depth(&depth_path(&dir, 1, 1)).unwrap();
    assert_eq!((depth.width, depth.height), (640, 480));
    let mut gaps: Vec<f64> = truth[0]
        .iter()
        .map(|&[u, v, d]| (depth.get(u.round() as u32, v.round() as u32) as f64 - d).abs())
        .collect();
    gaps.sort_by(f64::total_cmp);
    let median_gap = gaps[NYU_JOINTS / 2];
    println!("NYU frame 1: median |sensor − label| depth over the 14 joints {median_gap:.1} mm");
    assert!(median_gap < 25.0);
    // In the camera frame the hand spans a hand's size.
    let xyz = read_xyz_labels(&dir.join("nyu_test_groundtruth_label_14joints_uvd.txt")).unwrap();
    let span = xyz[0]
        .iter()
        .flat_map(|a| {
            xyz[0]
                .iter()
                .map(move |b| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>())
        })
        .fold(0.0f64, f64::max)
        .sqrt();
    assert!((100.0..250.0).contains(&span), "hand span {span} mm");
}

#[test]
fn dexter_files_on_the_real_files() {
    let Some(dir) = reference_path("dexter1") else {
        return;
    };
    let (mut frames, mut annotated) = (0, 0);
    for seq in DEXTER_SEQUENCES {
        let gt = read_ground_truth(&dir.join(format!("groundtruth/{seq}.txt"))).unwrap();
        let out = read_htrack_output(&dir.join(format!("htrack/{seq}.txt"))).unwrap();
        let reinit = read_htrack_output(&dir.join(format!("htrack_reinit/{seq}.txt"))).unwrap();
        assert!(out.len() <= gt.len() && out.len() + 3 >= gt.len(), "{seq}");
        assert_eq!(reinit.len(), out.len(), "{seq}");
        frames += out.len();
        annotated += gt[..out.len()].iter().filter(|f| is_annotated(f)).count();
    }
    println!("Dexter-1: {frames} htrack frames, {annotated} annotated");
    assert_eq!(frames, 3155);
    assert_eq!(annotated, 2919);
}

#[test]
fn dexter_fixture_truncated_files_name_file_and_line() {
    let dir = fixture_dir("dexter");
    let gt = dir.join("gt.txt");
    let block = "1, 2, 3\n".repeat(DEXTER_POINTS);
    std::fs::write(&gt, format!("{block}\n{block}\n1, 2, 3\n")).unwrap();
    let e = read_ground_truth(&gt).unwrap_err().to_string();
    assert!(e.contains("gt.txt, line 15"), "{e}");
    let out = dir.join("out.txt");
    let row = vec!["1.5"; 3 * HTRACK_JOINTS].join(" ");
    std::fs::write(&out, format!("{row}\n{}\n", &row[..20])).unwrap();
    let e = read_htrack_output(&out).unwrap_err().to_string();
    assert!(e.contains("out.txt, line 2"), "{e}");
    std::fs::write(&out, format!("{row}\n{row}\n")).unwrap();
    assert_eq!(read_htrack_output(&out).unwrap().len(), 2);
}

#[test]
fn handy_fixture_sequence_round_trip() {
    let dir = fixture_dir("handy");
    for k in 0..3u16 {
        let mut d = DepthImage::zeros(320, 240);
        d.data[k as usize] = 400 + k;
        write_depth_png(&dir.join(format!("depth-{k:07}.png")), &d).unwrap();
    }
    // Color as the original recorder wrote it: red in the PNG's blue channel.
    let mut c = ColorImage::zeros(320, 240);
    c.data[..3].copy_from_slice(&[10, 20, 200]);
    write_color_png(&dir.join("color-0000000.png"), &c).unwrap();
    let seq = HandySequence::open(&dir).unwrap();
    assert_eq!(seq.len(), 3);
    let f = seq.read_frame(2).unwrap();
    assert_eq!((f.depth.data[2], f.index), (402, 2));
    assert!(f.color.is_none());
    let c0 = seq.read_frame(0).unwrap().color.unwrap();
    assert_eq!(&c0.data[..3], &[200, 20, 10]);
    assert_eq!(seq.markers(HANDY_MARKERS).unwrap(), None);
    // Markers: 2 frames, count header.
    let values: Vec<String> = (0..2 * 3 * HANDY_MARKERS).map(|i| i.to_string()).collect();
    std::fs::write(
        dir.join("marker_positions.txt"),
        format!("2\n{}\n", values.join(" ")),
    )
    .unwrap();
    let m = seq.markers(HANDY_MARKERS).unwrap().unwrap();
    assert_eq!(
        (m.len(), m[1].len(), m[1][0]),
        (2, HANDY_MARKERS, [75.0, 76.0, 77.0])
    );
    // sequence_length.txt overrides the file count; a corrupt PNG is named.
    std::fs::write(dir.join("sequence_length.txt"), "2\n").unwrap();
    assert_eq!(HandySequence::open(&dir).unwrap().len(), 2);
    std::fs::write(dir.join("depth-0000001.png"), b"\x89PNG\r\n\x1a\n").unwrap();
    let e = seq.read_depth(1).unwrap_err().to_string();
    assert!(e.contains("depth-0000001.png"), "{e}");
    std::fs::write(dir.join("sequence_length.txt"), "two\n").unwrap();
    let e = HandySequence::open(&dir).unwrap_err().to_string();
    assert!(e.contains("sequence_length.txt, line 1"), "{e}");
    let empty = fixture_dir("handy-empty");
    let e = HandySequence::open(&empty).unwrap_err().to_string();
    assert!(e.contains("depth-0000000.png"), "{e}");
}

#[test]
fn nyu_fixture_truncated_labels_name_file_and_line() {
    let dir = fixture_dir("nyu");
    let line = vec!["1.0"; 3 * NYU_JOINTS].join(" ");
    let p = dir.join("labels.txt");
    std::fs::write(&p, format!("{line}\n{line}\n{}", &line[..30])).unwrap();
    let e = read_uvd_labels(&p).unwrap_err().to_string();
    assert!(e.contains("labels.txt, line 3"), "{e}");
    assert!(read_depth(&dir.join("missing.png")).is_err());
}
