//! Synthetic depth sequences with exact ground truth (issue 3): the sphere-mesh hand plus a
//! forearm wearing a blue wristband, ray cast by the CPU renderer of `hand-model` (thesis
//! §3.3.2), optionally in front of a wall, turned into sensor depth by a [`SensorModel`], with an
//! RGB image (skin, band, wall) and the ground-truth pose, shape and 21 keypoints per frame.

use hand_model::kinematics::Pose;
use hand_model::render::{DepthRender, DepthRenderer, Intrinsics, NO_ELEMENT};
use hand_model::shape::{Element, Sphere};
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use nalgebra::Vector3;
use sensor_io::record::HandRecord;
use sensor_io::{Camera, ColorImage, DepthImage, Frame};

use crate::noise::{apply_sensor_model, SensorModel};

/// Scene settings of a synthetic sequence.
#[derive(Clone, Debug)]
pub struct SceneConfig {
    /// The sensor's camera.
    pub camera: Camera,
    /// Depth sensor model.
    pub sensor: SensorModel,
    /// Distance of a background wall (mm), `None` for empty background.
    pub wall_mm: Option<f64>,
    /// Render the forearm (with the wristband).
    pub forearm: bool,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            camera: Camera::sr300_qvga(),
            sensor: SensorModel::NoiseFree,
            wall_mm: Some(1100.0),
            forearm: true,
            seed: 7,
        }
    }
}

/// Per-pixel part labels of a rendered frame.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Part {
    /// Nothing (or the wall).
    Background = 0,
    /// The hand model.
    Hand = 1,
    /// The forearm.
    Forearm = 2,
    /// The wristband on the forearm.
    Wristband = 3,
}

/// One synthesized frame: the sensor frame, its ground truth and per-pixel part labels.
#[derive(Clone, Debug)]
pub struct SynthFrame {
    /// Depth (with sensor noise) and RGB.
    pub frame: Frame,
    /// Ground truth: pose, shape, keypoints.
    pub truth: HandRecord,
    /// Part label per pixel (before noise dropouts).
    pub parts: Vec<Part>,
    /// Ground-truth keypoints projected to pixels.
    pub keypoints_px: Vec<[f64; 2]>,
}

/// Renders frames of one subject; buffers are reused between frames.
pub struct Synthesizer {
    template: SphereMeshTemplate,
    basis: Option<ShapeBasis>,
    beta: Vec<f64>,
    config: SceneConfig,
    intrinsics: Intrinsics,
    renderer: DepthRenderer,
    render: DepthRender,
    posed: PosedSphereMesh,
    spheres: Vec<Sphere>,
    elements: Vec<Element>,
    thin: Vec<bool>,
    hand_elements: usize,
    wrist_bone: Option<usize>,
    forearm_base: Option<[usize; 2]>,
}

/// Forearm in the wrist bone's frame for a template without named wrist spheres: a pill from
/// the wrist to mid-forearm (mm).
const FOREARM: [([f64; 3], f64); 2] = [([0.0, -40.0, 0.0], 21.0), ([0.0, -250.0, 3.0], 27.0)];
/// The subject's own wrist spheres the forearm continues from (DESIGN.md template names).
const WRIST_BASE: [&str; 2] = ["wrist_bottom_left", "wrist_bottom_right"];
/// Far end of the subject-following forearm: offset from each wrist base sphere in the wrist
/// bone's frame (mm) and radius growth. A real forearm continues the wrist's cross-section and
/// widens gently toward the elbow; a fixed-size forearm is thicker than a thin subject's wrist
/// right above the band, which no hand model can explain (measured: it moved the calibrated
/// wrist of thin subjects 1.5–3 mm sideways).
const FOREARM_REACH: [f64; 3] = [0.0, -200.0, 3.0];
const FOREARM_GROWTH: f64 = 1.15;
/// Wristband span along the wrist bone's y axis (mm).
const BAND: [f64; 2] = [-85.0, -50.0];
const SKIN: [f64; 3] = [222.0, 170.0, 138.0];
const BAND_RGB: [f64; 3] = [30.0, 60.0, 200.0];

impl Synthesizer {
    /// A synthesizer for `template` reshaped to `beta` (honline β of [`ShapeBasis::honline`];
    /// empty = the template's own shape).
    pub fn new(
        template: &SphereMeshTemplate,
        beta: &[f64],
        config: SceneConfig,
    ) -> hand_model::Result<Self> {
        let basis = ShapeBasis::honline(template).ok();
        let (shaped, beta) = match (&basis, beta.is_empty()) {
            (Some(b), false) => (b.apply(template, beta)?, beta.to_vec()),
            (Some(b), true) => (template.clone(), b.template_values()),
            (None, _) => (template.clone(), vec![]),
        };
        let c = &config.camera;
        let intrinsics = Intrinsics {
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
            width: c.width,
            height: c.height,
        };
        intrinsics.validate()?;
        let mut elements: Vec<Element> = shaped.elements.iter().map(|e| e.element).collect();
        let thin = shaped
            .elements
            .iter()
            .map(|e| shaped.skeleton.bones()[e.bone].name.ends_with("_3"))
            .collect();
        let hand_elements = elements.len();
        let n = shaped.spheres.len() as u32;
        let forearm_base = match WRIST_BASE.map(|name| shaped.sphere_index(name)) {
            [Some(l), Some(r)] => Some([l, r]),
            _ => None,
        };
        if config.forearm {
            match forearm_base {
                Some([l, r]) => {
                    let (l, r) = (l as u32, r as u32);
                    elements.push(Element::Wedge([l, r, n]));
                    elements.push(Element::Wedge([r, n + 1, n]));
                }
                None => elements.push(Element::Pill([n, n + 1])),
            }
        }
        let wrist_bone = shaped.skeleton.bone_index("wrist");
        Ok(Self {
            template: shaped,
            basis,
            beta,
            config,
            intrinsics,
            renderer: DepthRenderer::new(),
            render: DepthRender::default(),
            posed: PosedSphereMesh::default(),
            spheres: Vec::new(),
            elements,
            thin,
            hand_elements,
            wrist_bone,
            forearm_base,
        })
    }

    /// The reshaped template that is rendered.
    pub fn template(&self) -> &SphereMeshTemplate {
        &self.template
    }

    /// Render frame `index` at time `t` (s) for `pose`.
    pub fn render(&mut self, index: u64, t: f64, pose: &Pose) -> hand_model::Result<SynthFrame> {
        self.posed.update(&self.template, pose);
        self.spheres.clear();
        self.spheres.extend_from_slice(&self.posed.spheres);
        let wrist_g = self.wrist_bone.map(|b| self.posed.skeleton.globals[b]);
        if self.config.forearm {
            let g = wrist_g.unwrap_or_default();
            match self.forearm_base {
                Some(base) => {
                    let reach = g.transform_vector(&Vector3::from(FOREARM_REACH));
                    for b in base {
                        let s = self.posed.spheres[b];
                        self.spheres
                            .push(Sphere::new(s.center + reach, s.radius * FOREARM_GROWTH));
                    }
                }
                None => {
                    for (c, r) in FOREARM {
                        self.spheres
                            .push(Sphere::new(g.transform_point(&Vector3::from(c)), r));
                    }
                }
            }
        }
        self.renderer.render(
            &self.intrinsics,
            &self.spheres,
            &self.elements,
            &mut self.render,
        )?;
        let cam = &self.config.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut depth: Vec<f32> = self.render.depth.clone();
        let mut normals: Vec<Vector3<f32>> = self
            .render
            .normal
            .iter()
            .map(|n| Vector3::new(n[0], n[1], n[2]))
            .collect();
        let mut parts = vec![Part::Background; w * h];
        let mut thin = vec![false; w * h];
        let mut color = ColorImage::zeros(cam.width, cam.height);
        for i in 0..w * h {
            let e = self.render.element[i];
            let (u, v) = ((i % w) as f64, (i / w) as f64);
            if e == NO_ELEMENT {
                if let Some(z) = self.config.wall_mm {
                    depth[i] = z as f32;
                    normals[i] = Vector3::new(0.0, 0.0, -1.0);
                    color.data[3 * i..3 * i + 3].copy_from_slice(&[150, 150, 145]);
                }
                continue;
            }
            let e = e as usize;
            let p = cam.backproject(u, v, depth[i] as f64);
            let n = normals[i].cast::<f64>();
            let shade = (0.35 + 0.65 * (-n.dot(&p.normalize())).max(0.0)).min(1.0);
            let (part, base) = if e < self.hand_elements {
                thin[i] = self.thin[e];
                (Part::Hand, SKIN)
            } else {
                let y = wrist_g.map_or(0.0, |g| g.inverse().transform_point(&p).y);
                if (BAND[0]..=BAND[1]).contains(&y) {
                    (Part::Wristband, BAND_RGB)
                } else {
                    (Part::Forearm, SKIN)
                }
            };
            parts[i] = part;
            for (c, b) in color.data[3 * i..3 * i + 3].iter_mut().zip(base) {
                *c = (b * shade).round().clamp(0.0, 255.0) as u8;
            }
        }
        let mut out = DepthImage::default();
        apply_sensor_model(
            self.config.sensor,
            cam,
            &depth,
            &normals,
            &thin,
            self.config.seed.wrapping_mul(1_000_003).wrapping_add(index),
            &mut out,
        );
        let keypoints = self.posed.keypoints(&self.template);
        let mut truth = HandRecord {
            frame: index,
            timestamp: t,
            ..Default::default()
        };
        for (name, v) in pose.named(&self.template.skeleton) {
            truth.pose.insert(name.to_string(), v);
        }
        if let Some(b) = &self.basis {
            for (name, v) in b.names().zip(&self.beta) {
                truth.shape.insert(name.to_string(), *v);
            }
        }
        truth.keypoints = keypoints.iter().map(|k| [k.x, k.y, k.z]).collect();
        let keypoints_px = keypoints
            .iter()
            .map(|k| {
                if k.z > 1.0 {
                    let p = cam.project(k);
                    [p.x, p.y]
                } else {
                    [f64::NAN, f64::NAN]
                }
            })
            .collect();
        if self.render.hit_count() == 0 {
            truth.flags.push("no_hand".into());
        }
        Ok(SynthFrame {
            frame: Frame {
                index,
                timestamp: t,
                depth: out,
                color: Some(color),
            },
            truth,
            parts,
            keypoints_px,
        })
    }
}
