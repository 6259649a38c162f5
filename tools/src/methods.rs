//! Tracking methods behind one trait, found by name: `hands track`, `eval`, `compare` and
//! `demo` ask this registry for "cylinders", "spheremesh", … and never name a tracker type, so
//! a later method (online calibration, lifted correspondences) is one more entry of
//! [`METHODS`] and appears everywhere at once.
//!
//! A [`Method`] builds its [`MethodModel`] of a subject (given as a sphere-mesh template, the
//! project's common shape description); the model builds trackers ([`FrameTracker`]) and
//! renderers ([`ModelRenderer`]: the model at any recorded pose, what the algorithm-agnostic
//! metrics of `hands eval` need).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{bail, Result};
use hand_model::cylinder::{CylinderModel, CylinderRaster};
use hand_model::kinematics::{Pose, PosedSkeleton, Skeleton};
use hand_model::render::{DepthRenderer, PixelHit};
use hand_model::shape::Element;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::M2dMode;
use honline_calib::{Estimator, OnlineConfig};
use sensor_io::Camera;

use crate::config::read_config;
use crate::trackers::{CylinderTracker, FrameTracker, OnlineTracker, SphereMeshTracker};

/// A tracking method as the commands see it.
pub trait Method: Sync {
    /// The name users type (`--model`, `--methods`).
    fn name(&self) -> &'static str;
    /// One line for tables and `--help`.
    fn summary(&self) -> &'static str;
    /// The energy terms that [`TrackSettings::disabled`] may name (the `--no-<term>` switches).
    fn terms(&self) -> &'static [&'static str];
    /// This method's model of the subject whose sphere-mesh template is `template`.
    fn model(&self, template: &SphereMeshTemplate) -> Result<Box<dyn MethodModel>>;
}

/// A method's model of one subject: it tracks, and it renders any pose of its skeleton.
pub trait MethodModel {
    /// The skeleton whose DOF names the method's records use.
    fn skeleton(&self) -> &Skeleton;
    /// A tracker of this model with `settings`.
    fn tracker<'a>(
        &'a self,
        prior: Option<&'a PcaPrior>,
        settings: &TrackSettings,
    ) -> Result<Box<dyn FrameTracker + 'a>>;
    /// A renderer of this model at arbitrary poses.
    fn renderer(&self) -> Box<dyn ModelRenderer + '_>;
}

/// Tracker settings common to the methods: the JSON config file, then the switches.
#[derive(Clone, Debug)]
pub struct TrackSettings {
    /// Tracker settings as JSON (any subset of the method's tracker config, at any depth; the
    /// rest keep the method's defaults).
    pub config: Option<PathBuf>,
    /// Front-facing correspondences (Fig. 2.6, 3.9).
    pub front_facing: bool,
    /// A rigid-only first iteration (Fig. 2.17).
    pub rigid_first: bool,
    /// Energy terms to disable, among [`Method::terms`].
    pub disabled: Vec<&'static str>,
    /// Sphere-mesh E_m2d mode: `render` or `centers`.
    pub m2d: Option<String>,
    /// Along-ray correspondences: a distance (mm) on every frame or `off` (the tracker config's
    /// `ray_gate`, either tracker); `None`: the config's.
    pub ray_gate: Option<String>,
    /// The online calibration's estimator (method `online`; default: the config's, IEKF).
    pub estimator: Option<Estimator>,
}

impl Default for TrackSettings {
    fn default() -> Self {
        Self {
            config: None,
            front_facing: true,
            rigid_first: true,
            disabled: Vec::new(),
            m2d: None,
            ray_gate: None,
            estimator: None,
        }
    }
}

impl TrackSettings {
    fn off(&self, term: &str) -> bool {
        self.disabled.contains(&term)
    }
}

/// Apply the switches of `TrackSettings` to a tracker config with `front_facing`, `lm` and
/// `enabled` fields (both trackers' configs): the shared terms plus the listed own ones.
macro_rules! apply_switches {
    ($cfg:ident, $s:ident, [$($term:ident),*]) => {{
        $cfg.front_facing &= $s.front_facing;
        if !$s.rigid_first {
            $cfg.lm.rigid_iterations = 0;
        }
        let e = &mut $cfg.enabled;
        $(e.$term &= !$s.off(stringify!($term));)*
        for (on, term) in [
            (&mut e.collision, "collision"),
            (&mut e.pose_prior, "pose_prior"),
            (&mut e.joint_limits, "joint_limits"),
            (&mut e.temporal, "temporal"),
        ] {
            *on &= !$s.off(term);
        }
    }};
}

/// Every available method, in the order of tables and plots.
pub const METHODS: &[&dyn Method] = &[&Cylinders, &SphereMesh, &Online];

/// The method called `name`; an unknown name is an error listing the available ones.
pub fn by_name(name: &str) -> Result<&'static dyn Method> {
    METHODS
        .iter()
        .copied()
        .find(|m| m.name() == name)
        .ok_or_else(|| anyhow::anyhow!("unknown method `{name}` (available: {})", names()))
}

/// The available method names, comma-separated.
pub fn names() -> String {
    METHODS
        .iter()
        .map(|m| m.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A comma-separated list of method names (`all` = every method), without repeats.
pub fn parse_list(list: &str) -> Result<Vec<&'static dyn Method>> {
    if list.trim() == "all" {
        return Ok(METHODS.to_vec());
    }
    let mut out: Vec<&'static dyn Method> = Vec::new();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let m = by_name(name)?;
        if out.iter().any(|o| o.name() == m.name()) {
            bail!("method `{name}` is listed twice");
        }
        out.push(m);
    }
    if out.is_empty() {
        bail!("no method given (available: {})", names());
    }
    Ok(out)
}

/// The model as seen from a camera: its pixels and their depth.
#[derive(Clone, Debug, Default)]
pub struct RenderedModel {
    /// Linear pixel indices `v·width + u` of the model, increasing.
    pub pixels: Vec<u32>,
    /// Per pixel the model's depth (mm, camera z).
    pub depth_mm: Vec<f64>,
}

/// Renders a model at arbitrary poses.
pub trait ModelRenderer {
    /// The model at `pose` seen from `camera`.
    fn render(&mut self, pose: &Pose, camera: &Camera) -> Result<&RenderedModel>;

    /// Render the next poses with a record's estimated shape (its `shape`: honline β by name),
    /// for the methods that estimate the shape while tracking; the others ignore it.
    fn set_shape(&mut self, _shape: &BTreeMap<String, f64>) -> Result<()> {
        Ok(())
    }
}

/// Ray-casts any sphere-mesh (§3.3.2) of one topology: the buffers of [`SphereMeshRenderer`],
/// with the template given per call (a shape that changes from frame to frame).
pub struct SphereMeshRaster {
    elements: Vec<Element>,
    posed: Option<PosedSphereMesh>,
    renderer: DepthRenderer,
    hits: Vec<PixelHit>,
    out: RenderedModel,
}

impl SphereMeshRaster {
    /// A raster of templates with the elements of `template`.
    pub fn new(template: &SphereMeshTemplate) -> Self {
        Self {
            elements: template.elements.iter().map(|e| e.element).collect(),
            posed: None,
            renderer: DepthRenderer::new(),
            hits: Vec::new(),
            out: RenderedModel::default(),
        }
    }

    /// `template` (with the elements given to [`SphereMeshRaster::new`]) at `pose` seen from
    /// `camera`.
    pub fn render(
        &mut self,
        template: &SphereMeshTemplate,
        pose: &Pose,
        camera: &Camera,
    ) -> Result<&RenderedModel> {
        if self
            .posed
            .as_ref()
            .is_some_and(|p| p.spheres.len() != template.spheres.len())
        {
            self.posed = None;
        }
        let posed = self
            .posed
            .get_or_insert_with(|| PosedSphereMesh::new(template, pose));
        posed.update(template, pose);
        self.renderer.render_hits(
            &hmodel_spheremesh::intrinsics(camera),
            &posed.spheres,
            &self.elements,
            |_| true,
            &mut self.hits,
        )?;
        self.out.pixels.clear();
        self.out.depth_mm.clear();
        for h in &self.hits {
            self.out.pixels.push(h.pixel);
            self.out.depth_mm.push(h.point.z);
        }
        Ok(&self.out)
    }
}

/// Ray-casts a sphere-mesh (§3.3.2).
pub struct SphereMeshRenderer<'m> {
    template: &'m SphereMeshTemplate,
    raster: SphereMeshRaster,
}

impl<'m> SphereMeshRenderer<'m> {
    /// A renderer of `template`.
    pub fn new(template: &'m SphereMeshTemplate) -> Self {
        Self {
            template,
            raster: SphereMeshRaster::new(template),
        }
    }
}

impl ModelRenderer for SphereMeshRenderer<'_> {
    fn render(&mut self, pose: &Pose, camera: &Camera) -> Result<&RenderedModel> {
        self.raster.render(self.template, pose, camera)
    }
}

/// Ray-casts a sphere-mesh whose shape is estimated per frame: the base template reshaped by
/// the honline β of the record ([`ModelRenderer::set_shape`]) or of the tracker
/// ([`ShapedRenderer::set_beta`]); the base template until a shape is given.
pub struct ShapedRenderer<'m> {
    base: &'m SphereMeshTemplate,
    basis: &'m ShapeBasis,
    shaped: Option<SphereMeshTemplate>,
    beta: Vec<f64>,
    raster: SphereMeshRaster,
}

impl<'m> ShapedRenderer<'m> {
    /// A renderer of `base` reshaped through `basis` (the honline basis of `base`).
    pub fn new(base: &'m SphereMeshTemplate, basis: &'m ShapeBasis) -> Self {
        Self {
            base,
            basis,
            shaped: None,
            beta: basis.template_values(),
            raster: SphereMeshRaster::new(base),
        }
    }

    /// Render the next poses with the full β `beta` (in basis order); an error for a β the
    /// basis refuses (wrong length, non-finite, negative radius).
    pub fn set_beta(&mut self, beta: &[f64]) -> Result<()> {
        if self.shaped.is_some() && beta == self.beta.as_slice() {
            return Ok(());
        }
        self.shaped = Some(self.basis.apply(self.base, beta)?);
        self.beta.clear();
        self.beta.extend_from_slice(beta);
        Ok(())
    }
}

impl ModelRenderer for ShapedRenderer<'_> {
    fn render(&mut self, pose: &Pose, camera: &Camera) -> Result<&RenderedModel> {
        let template = self.shaped.as_ref().unwrap_or(self.base);
        self.raster.render(template, pose, camera)
    }

    /// β by name: entries the record lacks keep the base template's values; a name outside
    /// the basis is an error (a track of another model).
    fn set_shape(&mut self, shape: &BTreeMap<String, f64>) -> Result<()> {
        let mut beta = self.basis.template_values();
        for (name, &v) in shape {
            let Some(i) = self.basis.names().position(|n| n == name) else {
                bail!("shape parameter `{name}` is not in the honline basis of the template");
            };
            beta[i] = v;
        }
        self.set_beta(&beta)
    }
}

/// Rasterizes a cylinder model (Ch. 2).
pub struct CylinderRenderer<'m> {
    model: &'m CylinderModel,
    raster: CylinderRaster,
    out: RenderedModel,
}

impl<'m> CylinderRenderer<'m> {
    /// A renderer of `model`.
    pub fn new(model: &'m CylinderModel) -> Self {
        Self {
            model,
            raster: CylinderRaster::new(),
            out: RenderedModel::default(),
        }
    }
}

impl ModelRenderer for CylinderRenderer<'_> {
    fn render(&mut self, pose: &Pose, camera: &Camera) -> Result<&RenderedModel> {
        let posed = PosedSkeleton::new(&self.model.skeleton, pose);
        self.raster
            .render(self.model, &posed, &hmodel_spheremesh::intrinsics(camera))?;
        self.out.pixels.clear();
        self.out.depth_mm.clear();
        for &k in self.raster.hits() {
            if let Some(hit) = self.raster.hit(k as usize) {
                self.out.pixels.push(k);
                self.out.depth_mm.push(hit.point.z);
            }
        }
        Ok(&self.out)
    }
}

/// The Ch. 2 method: articulated ICP on cylinders fitted to the subject (with a wrist segment).
pub struct Cylinders;

/// A cylinder model as a [`MethodModel`].
pub struct CylinderMethodModel(pub CylinderModel);

impl Method for Cylinders {
    fn name(&self) -> &'static str {
        "cylinders"
    }
    fn summary(&self) -> &'static str {
        "Ch. 2 articulated ICP, cylinders fitted to the subject"
    }
    fn terms(&self) -> &'static [&'static str] {
        &[
            "e3d",
            "e2d",
            "wrist",
            "collision",
            "pose_prior",
            "joint_limits",
            "temporal",
        ]
    }
    fn model(&self, template: &SphereMeshTemplate) -> Result<Box<dyn MethodModel>> {
        Ok(Box::new(CylinderMethodModel(
            CylinderModel::from_sphere_mesh_with_wrist(template)?,
        )))
    }
}

impl MethodModel for CylinderMethodModel {
    fn skeleton(&self) -> &Skeleton {
        &self.0.skeleton
    }

    fn tracker<'a>(
        &'a self,
        prior: Option<&'a PcaPrior>,
        s: &TrackSettings,
    ) -> Result<Box<dyn FrameTracker + 'a>> {
        let mut cfg: htrack_icp::TrackerConfig = read_config(s.config.as_deref())?;
        apply_switches!(cfg, s, [e3d, e2d, wrist]);
        apply_ray_gate(
            s.ray_gate.as_deref(),
            &mut cfg.ray_gate,
            &mut cfg.ray_gate_noise,
        )?;
        Ok(Box::new(CylinderTracker::new(&self.0, cfg, prior)?))
    }

    fn renderer(&self) -> Box<dyn ModelRenderer + '_> {
        Box::new(CylinderRenderer::new(&self.0))
    }
}

/// The Ch. 3 method: the sphere-mesh tracker on the subject's template.
pub struct SphereMesh;

/// A sphere-mesh template as a [`MethodModel`].
pub struct SphereMeshMethodModel(pub SphereMeshTemplate);

impl Method for SphereMesh {
    fn name(&self) -> &'static str {
        "spheremesh"
    }
    fn summary(&self) -> &'static str {
        "Ch. 3 sphere-mesh tracker on the subject's template"
    }
    fn terms(&self) -> &'static [&'static str] {
        &[
            "d2m",
            "m2d",
            "collision",
            "pose_prior",
            "joint_limits",
            "temporal",
        ]
    }
    fn model(&self, template: &SphereMeshTemplate) -> Result<Box<dyn MethodModel>> {
        Ok(Box::new(SphereMeshMethodModel(template.clone())))
    }
}

/// Applies `--ray-gate` to `cfg`: `off`, or a distance in mm used on every frame; without it
/// the config's. Either must be a positive distance (the tracker would silently ignore
/// another).
/// `gate` and `min_noise` are the tracker config's `ray_gate` and `ray_gate_noise`.
fn apply_ray_gate(arg: Option<&str>, gate: &mut Option<f64>, min_noise: &mut f64) -> Result<()> {
    match arg {
        Some("off") => *gate = None,
        Some(text) => {
            let g: f64 = text
                .parse()
                .map_err(|_| anyhow::anyhow!("--ray-gate `{text}`: use a distance in mm or off"))?;
            *gate = Some(g);
            *min_noise = 0.0;
        }
        None => {}
    }
    match *gate {
        Some(g) if !(g.is_finite() && g > 0.0) => {
            bail!(
                "--ray-gate (or the config's ray_gate) must be a positive distance in mm, got {g}"
            )
        }
        _ => Ok(()),
    }
}

/// The `--m2d` mode.
fn m2d_mode(name: &str) -> Result<M2dMode> {
    match name {
        "render" => Ok(M2dMode::Render),
        "centers" => Ok(M2dMode::Centers),
        other => bail!("unknown --m2d `{other}`: use render or centers"),
    }
}

impl MethodModel for SphereMeshMethodModel {
    fn skeleton(&self) -> &Skeleton {
        &self.0.skeleton
    }

    fn tracker<'a>(
        &'a self,
        prior: Option<&'a PcaPrior>,
        s: &TrackSettings,
    ) -> Result<Box<dyn FrameTracker + 'a>> {
        let mut cfg: hmodel_spheremesh::TrackerConfig = read_config(s.config.as_deref())?;
        if let Some(m) = &s.m2d {
            cfg.m2d_mode = m2d_mode(m)?;
        }
        apply_ray_gate(
            s.ray_gate.as_deref(),
            &mut cfg.ray_gate,
            &mut cfg.ray_gate_noise,
        )?;
        apply_switches!(cfg, s, [d2m, m2d]);
        Ok(Box::new(SphereMeshTracker::new(&self.0, cfg, prior)?))
    }

    fn renderer(&self) -> Box<dyn ModelRenderer + '_> {
        Box::new(SphereMeshRenderer::new(&self.0))
    }
}

/// The Ch. 4 method: the sphere-mesh tracker with joint online calibration of the shape
/// (`honline_calib`, IEKF by default), starting from the given template. Its records carry the
/// estimated β and its certainty, and its model is rendered with each frame's estimate.
pub struct Online;

/// A starting template and its honline β basis as a [`MethodModel`].
pub struct OnlineMethodModel {
    /// The template calibration starts from.
    pub template: SphereMeshTemplate,
    /// Its honline β basis.
    pub basis: ShapeBasis,
}

impl Method for Online {
    fn name(&self) -> &'static str {
        "online"
    }
    fn summary(&self) -> &'static str {
        "Ch. 4 sphere-mesh tracking with online shape calibration (IEKF) from the template"
    }
    fn terms(&self) -> &'static [&'static str] {
        SphereMesh.terms()
    }
    fn model(&self, template: &SphereMeshTemplate) -> Result<Box<dyn MethodModel>> {
        Ok(Box::new(OnlineMethodModel {
            basis: ShapeBasis::honline(template)?,
            template: template.clone(),
        }))
    }
}

impl MethodModel for OnlineMethodModel {
    fn skeleton(&self) -> &Skeleton {
        &self.template.skeleton
    }

    /// `--config` is an [`OnlineConfig`] (its `tracker` field the sphere-mesh tracker's).
    fn tracker<'a>(
        &'a self,
        prior: Option<&'a PcaPrior>,
        s: &TrackSettings,
    ) -> Result<Box<dyn FrameTracker + 'a>> {
        let mut cfg: OnlineConfig = read_config(s.config.as_deref())?;
        if let Some(e) = s.estimator {
            cfg.estimator = e;
        }
        let tc = &mut cfg.tracker;
        if let Some(m) = &s.m2d {
            tc.m2d_mode = m2d_mode(m)?;
        }
        apply_ray_gate(
            s.ray_gate.as_deref(),
            &mut tc.ray_gate,
            &mut tc.ray_gate_noise,
        )?;
        apply_switches!(tc, s, [d2m, m2d]);
        Ok(Box::new(OnlineTracker::new(
            &self.template,
            &self.basis,
            cfg,
            prior,
        )?))
    }

    fn renderer(&self) -> Box<dyn ModelRenderer + '_> {
        Box::new(ShapedRenderer::new(&self.template, &self.basis))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn methods_are_found_by_name_and_lists_are_checked() {
        assert_eq!(
            by_name("spheremesh").map(|m| m.name()).ok(),
            Some("spheremesh")
        );
        let e = by_name("bogus")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("bogus") && e.contains("online"), "{e}");
        assert_eq!(parse_list("all").map(|l| l.len()).ok(), Some(METHODS.len()));
        assert!(parse_list("cylinders,cylinders").is_err());
        assert!(parse_list(" , ").is_err());
    }

    #[test]
    fn every_model_renders_the_rest_pose_in_front_of_the_camera() {
        let template = hand_model::spheremesh::default_right_hand();
        let camera = Camera::sr300_qvga();
        for m in METHODS {
            let model = m.model(&template).expect("model");
            let mut pose = Pose::zeros(model.skeleton());
            pose.set(model.skeleton(), "global_tz", 400.0).expect("tz");
            let mut r = model.renderer();
            let out = r.render(&pose, &camera).expect("render");
            assert!(out.pixels.len() > 500, "{}: {}", m.name(), out.pixels.len());
            assert_eq!(out.depth_mm.len(), out.pixels.len());
            assert!(out.pixels.windows(2).all(|w| w[0] < w[1]), "{}", m.name());
            assert!(
                out.depth_mm.iter().all(|d| (300.0..500.0).contains(d)),
                "{}",
                m.name()
            );
        }
    }

    #[test]
    fn the_online_renderer_follows_the_record_shape() {
        let template = hand_model::spheremesh::default_right_hand();
        let camera = Camera::sr300_qvga();
        let model = Online.model(&template).expect("model");
        let mut pose = Pose::zeros(model.skeleton());
        pose.set(model.skeleton(), "global_tz", 400.0).expect("tz");
        let mut r = model.renderer();
        let base = r.render(&pose, &camera).expect("render").pixels.len();
        let mut shape = BTreeMap::new();
        for f in ["index", "middle", "ring", "pinky"] {
            for p in ["bottom", "middle", "top"] {
                shape.insert(format!("{f}_{p}_length"), 40.0);
            }
        }
        r.set_shape(&shape).expect("shape");
        let longer = r.render(&pose, &camera).expect("render").pixels.len();
        assert!(longer > base + 100, "{base} → {longer}");
        shape.insert("no_such_parameter".into(), 1.0);
        assert!(r.set_shape(&shape).is_err());
        shape.clear();
        shape.insert("index_top_radius".into(), f64::NAN);
        assert!(r.set_shape(&shape).is_err());
    }
}
