//! Issue 3, bad input to the preprocessing pipeline: empty frames, frames with nothing
//! hand-like in range, NaN-free output, wrong image sizes.

use sensor_io::preprocess::{
    PreprocessConfig, PreprocessedFrame, Preprocessor, Segmentation, Subsampling,
};
use sensor_io::{Camera, DepthImage, Frame};

fn frame(depth: DepthImage) -> Frame {
    Frame {
        index: 0,
        timestamp: 0.0,
        depth,
        color: None,
    }
}

#[test]
fn empty_and_handless_frames_give_an_empty_hand() {
    let cam = Camera::sr300_qvga();
    let mut out = PreprocessedFrame::default();
    for sub in [Subsampling::Uniform, Subsampling::Farthest] {
        let mut pre = Preprocessor::new(PreprocessConfig {
            subsampling: sub,
            ..Default::default()
        });
        // No valid depth at all.
        pre.process(&frame(DepthImage::zeros(320, 240)), &cam, &mut out)
            .expect("empty frame");
        assert_eq!(out.hand.count, 0);
        assert!(out.points.is_empty());
        // Only a far wall, beyond the working range.
        let mut wall = DepthImage::zeros(320, 240);
        wall.data.iter_mut().for_each(|d| *d = 3000);
        pre.process(&frame(wall), &cam, &mut out).expect("far wall");
        assert_eq!(out.hand.count, 0);
        // Salt noise: isolated pixels are not a hand.
        let mut salt = DepthImage::zeros(320, 240);
        for i in (0..salt.data.len()).step_by(97) {
            salt.data[i] = 400 + (i % 300) as u16;
        }
        pre.process(&frame(salt), &cam, &mut out).expect("salt");
        assert_eq!(out.hand.count, 0, "isolated pixels segmented as a hand");
    }
    // Wristband segmentation without a color image: an empty hand, not an error.
    let mut pre = Preprocessor::new(PreprocessConfig {
        segmentation: Segmentation::Wristband(Default::default()),
        ..Default::default()
    });
    let mut blob = DepthImage::zeros(320, 240);
    for v in 100..140 {
        for u in 140..180 {
            blob.data[v * 320 + u] = 420;
        }
    }
    pre.process(&frame(blob.clone()), &cam, &mut out)
        .expect("no color");
    assert_eq!(out.hand.count, 0);
    // A hand-sized blob is found, with finite points and unit normals.
    let mut pre = Preprocessor::new(PreprocessConfig::default());
    pre.process(&frame(blob), &cam, &mut out).expect("blob");
    assert!(out.hand.count > 1000);
    assert!(out.points.iter().all(|p| p.iter().all(|x| x.is_finite())));
    assert!(out
        .normals
        .iter()
        .all(|n| n.norm() == 0.0 || (n.norm() - 1.0).abs() < 1e-9));
}

#[test]
fn wrong_sizes_are_errors() {
    let cam = Camera::sr300_qvga();
    let mut out = PreprocessedFrame::default();
    let mut pre = Preprocessor::new(PreprocessConfig::default());
    let err = pre
        .process(&frame(DepthImage::zeros(640, 480)), &cam, &mut out)
        .expect_err("size");
    assert!(err.to_string().contains("640"), "{err}");
    let bad = Frame {
        depth: DepthImage {
            width: 320,
            height: 240,
            data: vec![0; 10],
        },
        ..frame(DepthImage::zeros(1, 1))
    };
    assert!(pre.process(&bad, &cam, &mut out).is_err());
}

/// The default smoothing lowers a noisy blob's point noise from a sequence's 31st frame on and
/// leaves the depth image (on which the trackers measure the sensor's noise) as the sensor gave
/// it; `smoothing: None` keeps the raw depth in the points, and so do the first 30 frames.
#[test]
fn smoothing_reaches_the_points_not_the_depth_image() {
    use rand::{Rng, SeedableRng};
    use sensor_io::preprocess::SmoothParams;
    let cam = Camera::sr300_qvga();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut blob = DepthImage::zeros(320, 240);
    for v in 90..150 {
        for u in 130..190 {
            blob.data[v * 320 + u] = 420 + rng.random_range(0..=10);
        }
    }
    let spread = |out: &PreprocessedFrame| {
        let n = out.points.len() as f64;
        let mean = out.points.iter().map(|p| p.z).sum::<f64>() / n;
        (out.points.iter().map(|p| (p.z - mean).powi(2)).sum::<f64>() / n).sqrt()
    };
    let mut out = PreprocessedFrame::default();
    let mut raw = Preprocessor::new(PreprocessConfig {
        smoothing: None,
        ..Default::default()
    });
    raw.process(&frame(blob.clone()), &cam, &mut out)
        .expect("raw");
    let (raw_spread, raw_points) = (spread(&out), out.points.clone());
    let mut smooth = Preprocessor::new(PreprocessConfig::default());
    let after = SmoothParams::default().after_frames;
    for k in 0..=after {
        smooth
            .process(&frame(blob.clone()), &cam, &mut out)
            .expect("smoothed");
        assert_eq!(out.depth.data, blob.data, "the depth image is the sensor's");
        if k < after {
            assert_eq!(out.points, raw_points, "frame {k} is not smoothed yet");
        }
    }
    assert_eq!(out.points.len(), raw_points.len());
    let smoothed = spread(&out);
    assert!(
        smoothed < 0.5 * raw_spread,
        "point depth spread: raw {raw_spread:.2} mm, smoothed {smoothed:.2} mm"
    );
    // Exact depth (a tilted plane, noise well under `min_noise`) is never smoothed.
    let mut exact = blob.clone();
    for (i, d) in exact.data.iter_mut().enumerate() {
        if *d != 0 {
            *d = 400 + (i % 320) as u16 / 4;
        }
    }
    let mut quiet = Preprocessor::new(PreprocessConfig::default());
    let mut first = PreprocessedFrame::default();
    raw.process(&frame(exact.clone()), &cam, &mut first)
        .expect("raw");
    for _ in 0..=after {
        quiet
            .process(&frame(exact.clone()), &cam, &mut out)
            .expect("exact");
    }
    assert_eq!(out.points, first.points);
}
