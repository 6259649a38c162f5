//! Depth-sensor models applied to an exact rendered depth (issue 3, "Sensor models"; thesis
//! §2.2 "Acquisition device", Fig. 2.2): noise-free, time-of-flight, structured light, and plain
//! quantization. Each model turns exact depths (f32 mm, 0 = background) into a `u16` depth image.
//!
//! The parameters are chosen from the sensors' published behaviour rather than fitted to any
//! recording: ToF depth noise of a few mm at arm's length growing with depth², mixed ("flying")
//! pixels across depth edges and a complete silhouette (Creative/SoftKinetic, Fig. 2.2 right);
//! structured light with smooth, disparity-quantized depth but holes at grazing angles, in the
//! projector's shadow and on thin parts (PrimeSense/RealSense, Fig. 2.2 left).

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sensor_io::{Camera, DepthImage};

/// The sensor model of a synthetic sequence.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum SensorModel {
    /// Exact depth rounded to the millimetre.
    NoiseFree,
    /// Disparity quantization of a structured-light sensor, no noise.
    Quantized,
    /// Time of flight: `σ(z) = σ0 + k·z²` Gaussian noise, flying pixels at depth edges.
    TimeOfFlight {
        /// Noise at zero depth (mm).
        sigma0: f64,
        /// Growth with depth² (mm per mm²).
        k: f64,
    },
    /// Structured light: small noise, disparity quantization, dropouts at grazing angles, in
    /// the projector shadow and on thin parts.
    StructuredLight {
        /// Noise (mm) before quantization.
        sigma: f64,
        /// Grazing angle (rad from the viewing ray) beyond which pixels drop out.
        grazing: f64,
    },
}

impl SensorModel {
    /// A model by name: `none`, `quantized`, `tof`, `structured`.
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "none" | "noise-free" | "clean" => Some(SensorModel::NoiseFree),
            "quantized" | "quantization" => Some(SensorModel::Quantized),
            // 1 mm + 2.5e-5·z²: ≈ 5 mm at 400 mm, ≈ 7 mm at 500 mm.
            "tof" | "time-of-flight" => Some(SensorModel::TimeOfFlight {
                sigma0: 1.0,
                k: 2.5e-5,
            }),
            "structured" | "structured-light" | "sl" => Some(SensorModel::StructuredLight {
                sigma: 0.5,
                grazing: 75f64.to_radians(),
            }),
            _ => None,
        }
    }

    /// The names accepted by [`SensorModel::by_name`].
    pub fn names() -> &'static [&'static str] {
        &["none", "quantized", "tof", "structured"]
    }
}

/// Baseline (mm) and sub-pixel disparity resolution of the structured-light model
/// (a RealSense-like 50 mm baseline with 1/8-pixel disparity).
const BASELINE_MM: f64 = 50.0;
const SUBPIXEL: f64 = 1.0 / 8.0;

fn quantize_disparity(z: f64, f: f64) -> f64 {
    let d = f * BASELINE_MM / z;
    let dq = (d / SUBPIXEL).round() * SUBPIXEL;
    if dq <= 0.0 {
        z
    } else {
        f * BASELINE_MM / dq
    }
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    // Box–Muller: keeps the dependency list short (no rand_distr).
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Apply a sensor model to exact depths `depth` (mm, 0 = miss) with per-pixel outward normals
/// `normals` (camera frame; zero where unknown) and per-pixel thin-part flags `thin` (e.g. distal
/// phalanges). Deterministic for a given `seed`.
pub fn apply_sensor_model(
    model: SensorModel,
    camera: &Camera,
    depth: &[f32],
    normals: &[Vector3<f32>],
    thin: &[bool],
    seed: u64,
    out: &mut DepthImage,
) {
    let (w, h) = (camera.width as usize, camera.height as usize);
    out.width = camera.width;
    out.height = camera.height;
    out.data.clear();
    out.data.resize(w * h, 0);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let to_u16 = |z: f64| {
        if z.is_finite() && z > 0.5 {
            z.round().min(65535.0) as u16
        } else {
            0
        }
    };
    match model {
        SensorModel::NoiseFree => {
            for (o, &z) in out.data.iter_mut().zip(depth) {
                *o = to_u16(z as f64);
            }
        }
        SensorModel::Quantized => {
            for (o, &z) in out.data.iter_mut().zip(depth) {
                *o = if z > 0.0 {
                    to_u16(quantize_disparity(z as f64, camera.fx))
                } else {
                    0
                };
            }
        }
        SensorModel::TimeOfFlight { sigma0, k } => {
            for i in 0..w * h {
                let z = depth[i] as f64;
                let (u, v) = (i % w, i / w);
                // Flying pixels: a pixel on a depth edge mixes foreground and background returns.
                let mut edge_other = None;
                for (du, dv) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (x, y) = (u as i64 + du, v as i64 + dv);
                    if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                        continue;
                    }
                    let zn = depth[y as usize * w + x as usize] as f64;
                    if z > 0.0 && zn > z + 30.0 {
                        edge_other = Some(zn);
                    }
                }
                let mut zz = z;
                if let Some(zb) = edge_other {
                    if rng.random_bool(0.5) {
                        let a: f64 = rng.random_range(0.1..0.9);
                        zz = z * (1.0 - a) + zb * a;
                    }
                }
                if zz > 0.0 {
                    zz += (sigma0 + k * zz * zz) * gauss(&mut rng);
                }
                out.data[i] = to_u16(zz);
            }
        }
        SensorModel::StructuredLight { sigma, grazing } => {
            let cos_limit = grazing.cos();
            // The projector sits to the camera's left (−x): background pixels just right of a
            // nearer surface receive no pattern (shadow); the band width follows the disparity gap.
            for v in 0..h {
                let mut nearest_disp = 0.0f64; // largest disparity seen to the left so far, decayed per pixel
                for u in 0..w {
                    let i = v * w + u;
                    let z = depth[i] as f64;
                    nearest_disp -= 1.0;
                    if z <= 0.0 {
                        continue;
                    }
                    let disp = camera.fx * BASELINE_MM / z;
                    let shadowed = nearest_disp > disp + 1.0;
                    nearest_disp = nearest_disp.max(disp);
                    let n = normals[i];
                    let ray = camera.backproject(u as f64, v as f64, 1.0).normalize();
                    let facing = if n.norm_squared() > 0.0 {
                        -(n.cast::<f64>().dot(&ray))
                    } else {
                        1.0
                    };
                    let grazing_drop = facing < cos_limit
                        && rng.random_bool(
                            ((cos_limit - facing) / cos_limit.max(1e-3) * 4.0).clamp(0.0, 1.0),
                        );
                    let thin_drop = thin[i] && rng.random_bool(0.15);
                    if shadowed || grazing_drop || thin_drop {
                        continue;
                    }
                    let zz = quantize_disparity(z + sigma * gauss(&mut rng), camera.fx);
                    out.data[i] = to_u16(zz);
                }
            }
        }
    }
}
