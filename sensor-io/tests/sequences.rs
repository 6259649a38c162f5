//! Issue 3: sequence I/O round trips and bad input (missing camera fields, wrong image sizes,
//! truncated files, bad ground-truth lines) give clear errors, never panics.

use std::path::PathBuf;

use sensor_io::io::{create_sequence, open_sequence, write_depth_png};
use sensor_io::record::HandRecord;
use sensor_io::{Camera, ColorImage, DepthImage, Frame};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hands-seq-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn frames(cam: &Camera, n: usize) -> Vec<(Frame, HandRecord)> {
    (0..n)
        .map(|k| {
            let mut depth = DepthImage::zeros(cam.width, cam.height);
            for (i, d) in depth.data.iter_mut().enumerate() {
                *d = ((i * 7 + k * 13) % 3000) as u16;
            }
            let mut color = ColorImage::zeros(cam.width, cam.height);
            color
                .data
                .iter_mut()
                .enumerate()
                .for_each(|(i, c)| *c = (i % 251) as u8);
            let mut rec = HandRecord {
                frame: k as u64,
                timestamp: k as f64 / 60.0,
                ..Default::default()
            };
            rec.pose.insert("index_mcp_flex".into(), 0.1 * k as f64);
            rec.keypoints = vec![[1.0, 2.0, 300.0 + k as f64]; 21];
            (
                Frame {
                    index: k as u64,
                    timestamp: rec.timestamp,
                    depth,
                    color: Some(color),
                },
                rec,
            )
        })
        .collect()
}

#[test]
fn folder_round_trip() {
    let cam = Camera::new("test", 16, 12, 20.0, 21.0, 8.0, 6.0).expect("camera");
    let dir = tmp("folder");
    let input = frames(&cam, 3);
    let mut w = create_sequence(&dir, &cam).expect("create");
    for (f, r) in &input {
        w.write(f, Some(r)).expect("write");
    }
    w.finish().expect("finish");
    let mut r = open_sequence(&dir).expect("open");
    assert_eq!(r.camera(), &cam);
    assert_eq!(r.len(), Some(3));
    for (f, rec) in &input {
        let (g, grec) = r.next_frame().expect("frame").expect("ok");
        assert_eq!(&g.depth, &f.depth);
        assert_eq!(&g.color, &f.color);
        assert_eq!(grec.as_ref(), Some(rec));
    }
    assert!(r.next_frame().is_none());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn folder_bad_inputs_are_named() {
    let cam = Camera::new("test", 16, 12, 20.0, 21.0, 8.0, 6.0).expect("camera");
    let dir = tmp("bad");
    let mut w = create_sequence(&dir, &cam).expect("create");
    for (f, r) in &frames(&cam, 2) {
        w.write(f, Some(r)).expect("write");
    }
    w.finish().expect("finish");
    // Wrong image size.
    write_depth_png(&dir.join("depth/000001.png"), &DepthImage::zeros(8, 8)).expect("w");
    let mut r = open_sequence(&dir).expect("open");
    assert!(r.next_frame().expect("f0").is_ok());
    let err = r.next_frame().expect("f1").expect_err("size");
    assert!(err.to_string().contains("000001.png"), "{err}");
    // Missing camera field.
    std::fs::write(
        dir.join("camera.json"),
        r#"{"width": 16, "height": 12, "fx": 20, "cx": 8, "cy": 6}"#,
    )
    .expect("w");
    let err = open_sequence(&dir).err().expect("missing fy");
    assert!(err.to_string().contains("fy"), "{err}");
    // Corrupt ground truth line.
    std::fs::write(
        dir.join("camera.json"),
        serde_json::to_string(&cam).expect("json"),
    )
    .expect("w");
    std::fs::write(
        dir.join("groundtruth.jsonl"),
        "{\"frame\": 0, \"timestamp\": 0}\n{not json\n",
    )
    .expect("w");
    write_depth_png(&dir.join("depth/000001.png"), &DepthImage::zeros(16, 12)).expect("w");
    let mut r = open_sequence(&dir).expect("open");
    assert!(r.next_frame().expect("f0").is_ok());
    let err = r.next_frame().expect("f1").expect_err("gt");
    assert!(err.to_string().contains("line 2"), "{err}");
    // Not a sequence at all.
    assert!(open_sequence(&dir.join("nope")).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mcap_round_trip_and_corruption() {
    let cam = Camera::new("test", 16, 12, 20.0, 21.0, 8.0, 6.0).expect("camera");
    let dir = tmp("mcap");
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("seq.mcap");
    let input = frames(&cam, 4);
    let mut w = create_sequence(&path, &cam).expect("create");
    for (f, r) in &input {
        w.write(f, Some(r)).expect("write");
    }
    w.finish().expect("finish");
    let mut r = open_sequence(&path).expect("open");
    let c = r.camera();
    assert_eq!(
        (c.width, c.height, c.fx, c.fy, c.cx, c.cy),
        (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
    );
    for (f, rec) in &input {
        let (g, grec) = r.next_frame().expect("frame").expect("ok");
        assert_eq!(&g.depth, &f.depth);
        assert_eq!(&g.color, &f.color);
        assert_eq!(grec.as_ref(), Some(rec));
        assert!((g.timestamp - f.timestamp).abs() < 1e-9);
    }
    assert!(r.next_frame().is_none());
    // Truncated file: an error at open or while reading, never a panic.
    let bytes = std::fs::read(&path).expect("bytes");
    for cut in [8, 100, bytes.len() / 2, bytes.len() - 10] {
        let t = dir.join(format!("cut{cut}.mcap"));
        std::fs::write(&t, &bytes[..cut]).expect("w");
        let outcome = open_sequence(&t).map(|mut r| {
            let mut n = 0;
            while let Some(f) = r.next_frame() {
                if f.is_err() {
                    return Err(());
                }
                n += 1;
            }
            Ok(n)
        });
        match outcome {
            Err(_) | Ok(Err(())) => {}
            Ok(Ok(n)) => assert!(n < input.len(), "a truncated file gave all frames"),
        }
    }
    // Corrupt length fields anywhere (a fuzzing find: a huge record length used to abort the
    // process on allocation): every outcome is an error or fewer frames, never an abort.
    for offset in (8..bytes.len().saturating_sub(8)).step_by(61) {
        let mut b = bytes.clone();
        b[offset..offset + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        let t = dir.join("corrupt.mcap");
        std::fs::write(&t, &b).expect("w");
        if let Ok(mut r) = open_sequence(&t) {
            for _ in 0..input.len() + 1 {
                match r.next_frame() {
                    Some(Ok(_)) => {}
                    _ => break,
                }
            }
        }
    }
    // An attachment record too short for its own header made the `mcap` decoder panic on a
    // slice index (a fuzzing find): the reader reports an error instead.
    let mut evil = b"\x89MCAP0\r\n".to_vec();
    evil.push(0x09);
    evil.extend_from_slice(&33u64.to_le_bytes());
    evil.extend_from_slice(&[0u8; 24]);
    evil.extend_from_slice(&1u64.to_le_bytes());
    evil.push(0);
    std::fs::write(dir.join("evil.mcap"), &evil).expect("w");
    assert!(open_sequence(&dir.join("evil.mcap")).is_err());
    // Garbage.
    std::fs::write(dir.join("junk.mcap"), b"not an mcap file at all").expect("w");
    assert!(open_sequence(&dir.join("junk.mcap")).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
