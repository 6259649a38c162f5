//! `hands bench`: the speed of the trackers (issue 5 "Speed") and of tracking with online
//! calibration (issue 8 "Speed"), measured by the command on the machine it runs on. Absolute times differ between machines, so every time is also given as a
//! ratio against a baseline measured in the same run: the median preprocessing time (wristband
//! segmentation, point sampling, distance transform) of the same frames. Neither tracker
//! changes that work, it is pure single-threaded CPU code of a fixed size, and it is the stage
//! that precedes tracking in the real pipeline, so "× preprocessing" compares across machines
//! better than microseconds do. The online calibrator (Ch. 4) is also given against the plain
//! sphere-mesh tracker (Ch. 3) of the same run: what calibrating while tracking costs.
//!
//! Three measurements: (1) one thread, per-stage medians on a synthetic sequence held in memory
//! (rendering and preprocessing are done once, before any clock runs on the trackers);
//! (2) two sequences tracked on two threads vs one after the other; (3) the sphere-mesh frame
//! time against the number of sensor points, on frames rendered at VGA so that 20000 points
//! exist.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use clap::Args;
use eval::markers::median;
use eval::synthetic::{SyntheticSequence, SyntheticSpec};
use hand_model::cylinder::CylinderModel;
use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::{ShapeBasis, SphereMeshTemplate};
use hmodel_spheremesh::synthetic::rendered_frame;
use indicatif::ProgressBar;
use sensor_io::io::write_atomic;
use sensor_io::preprocess::{PreprocessConfig, PreprocessedFrame, Segmentation, WristbandParams};
use sensor_io::record::HandRecord;
use sensor_io::Camera;
use serde::Serialize;

use crate::progress::frames_bar;
use crate::trackers::{CylinderTracker, FrameTracker, OnlineTracker, SphereMeshTracker};

/// Measure the trackers' speed on a synthetic sequence.
///
/// Example: `hands bench --model all --frames 240 --json bench.json`
#[derive(Args)]
pub struct BenchArgs {
    /// Which tracker: `spheremesh` (Ch. 3), `cylinders` (Ch. 2), `online` (Ch. 4: sphere-mesh
    /// tracking with joint cumulative calibration; the plain sphere-mesh tracker is then
    /// measured too, as its baseline) or `all`.
    #[arg(long, default_value = "all")]
    pub model: String,
    /// Frames of the synthetic sequence (60 Hz); the point-count scaling uses up to 20 of them.
    #[arg(long, default_value_t = 240)]
    pub frames: usize,
    /// Motion of the library (see `hands synth --list`).
    #[arg(long, default_value = "teaser")]
    pub motion: String,
    /// Sensor noise model: `none`, `quantized`, `tof`, `structured`.
    #[arg(long, default_value = "tof")]
    pub noise: String,
    /// Seed of the first sequence (the two-thread run adds a second one with seed + 1).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Sensor points per frame (the figure: ~2500).
    #[arg(long, default_value_t = 2500)]
    pub points: usize,
    /// Also write every number as JSON here (atomically).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The goal for one sphere-mesh frame (µs, median, one core).
const GOAL_US: f64 = 1500.0;

/// Issue 8's goal for one frame of tracking with joint cumulative calibration: ≥ 200 frames/s
/// on one core (µs, median).
const ONLINE_GOAL_US: f64 = 1e6 / 200.0;

/// The point counts of the scaling run (the range, 500 to 20000).
const SCALING_POINTS: [usize; 6] = [500, 1000, 2500, 5000, 10000, 20000];

/// The scaling row the others are divided by: the nominal frame.
const SCALING_REFERENCE: usize = 2500;

/// At most this many poses of the sequence are re-rendered per point count: enough for a
/// stable median, few enough that the 20000-point frames stay quick.
const SCALING_POSES: usize = 20;

/// How far from the truth a scaling frame starts: a few mm and degrees, what a 60 Hz frame
/// moves, so that the solver does the work of a tracked frame and not of a converged one.
const WARM_START_OFFSET: [(&str, f64); 5] = [
    ("global_tx", 3.0),
    ("global_ty", -2.0),
    ("global_rz", 0.03),
    ("index_mcp_flex", 0.08),
    ("middle_pip_flex", -0.08),
];

/// The thesis's per-stage figures (i7 + GTX 980, GPU rendering), quoted by the issue. They are
/// printed beside the measurements for reference only: nothing here measures them.
const THESIS_QUOTED: &str =
    "correspondences 250 µs/iter, front-facing 100 µs, silhouette 150 µs, rendering 500 µs/iter";

/// A tracker the benchmark can run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
enum Model {
    SphereMesh,
    Cylinders,
    Online,
}

impl Model {
    /// The goal for the model's median frame (µs).
    fn goal_us(self) -> f64 {
        match self {
            Self::SphereMesh | Self::Cylinders => GOAL_US,
            Self::Online => ONLINE_GOAL_US,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Self::SphereMesh => "spheremesh",
            Self::Cylinders => "cylinders",
            Self::Online => "online",
        }
    }

    /// The models to measure for `--model spec`. The online calibrator's baseline is the plain
    /// sphere-mesh tracker, so `online` measures that one first.
    fn parse_list(spec: &str) -> Result<Vec<Self>> {
        Ok(match spec {
            "spheremesh" => vec![Self::SphereMesh],
            "cylinders" => vec![Self::Cylinders],
            "online" => vec![Self::SphereMesh, Self::Online],
            "all" => vec![Self::SphereMesh, Self::Cylinders, Self::Online],
            other => bail!("unknown --model `{other}`: use spheremesh, cylinders, online or all"),
        })
    }
}

/// What the trackers are built from: the rendered subject's template, the cylinders fitted to
/// it (so that every tracker sees the same hand; the online calibrator starts from it too), its
/// honline β basis and the project's pose prior. Shared by reference between the threads, each
/// of which builds its own tracker.
struct Models {
    template: SphereMeshTemplate,
    cylinders: CylinderModel,
    basis: ShapeBasis,
    prior: PcaPrior,
}

impl Models {
    /// A fresh tracker of `model` with its default (thesis) settings: 1 rigid + 7 iterations
    /// (the online calibrator: honline's 1 rigid + 6), front-facing correspondences, m2d by
    /// rendering; the online calibrator with the joint cumulative estimator (IEKF) over the
    /// observable β.
    fn tracker(&self, model: Model) -> Result<Box<dyn FrameTracker + '_>> {
        Ok(match model {
            Model::SphereMesh => Box::new(SphereMeshTracker::new(
                &self.template,
                hmodel_spheremesh::TrackerConfig::default(),
                Some(&self.prior),
            )?),
            Model::Cylinders => Box::new(CylinderTracker::new(
                &self.cylinders,
                htrack_icp::TrackerConfig::default(),
                Some(&self.prior),
            )?),
            Model::Online => Box::new(OnlineTracker::new(
                &self.template,
                &self.basis,
                honline_calib::OnlineConfig::default(),
                Some(&self.prior),
            )?),
        })
    }
}

/// A synthetic sequence rendered and preprocessed once, held in memory.
struct Recorded {
    frames: Vec<PreprocessedFrame>,
    truth: Vec<HandRecord>,
    preprocess_us: Vec<f64>,
    template: SphereMeshTemplate,
}

/// Render and preprocess `spec` (a progress bar named `what`).
fn record(spec: SyntheticSpec, what: &str) -> Result<Recorded> {
    let n = spec.frames;
    let mut seq = SyntheticSequence::new(spec)?;
    let bar = frames_bar(Some(n), what);
    let mut frames = Vec::with_capacity(n);
    let run = seq.run(
        |f, truth| {
            frames.push(f.clone());
            truth.clone()
        },
        |_| bar.inc(1),
    )?;
    bar.finish_and_clear();
    Ok(Recorded {
        frames,
        truth: run.truth,
        preprocess_us: run.preprocess_us,
        template: seq.template().clone(),
    })
}

/// The per-frame timings of one tracked sequence.
#[derive(Default)]
struct Samples {
    correspondences: Vec<f64>,
    /// The sphere-mesh trackers' parts of `correspondences` (NaN for the cylinders).
    closest: Vec<f64>,
    along_ray: Vec<f64>,
    m2d: Vec<f64>,
    solve: Vec<f64>,
    /// The online calibrator's own stages (NaN for the trackers without them).
    reshape: Vec<f64>,
    laplace: Vec<f64>,
    filter: Vec<f64>,
    track: Vec<f64>,
    iterations: Vec<f64>,
    points: Vec<f64>,
    /// Frames tracked (the stages leave out those flagged `settling`).
    frames: usize,
    /// Wall-clock seconds of the whole loop.
    wall_s: f64,
}

impl Samples {
    /// Frames tracked per wall-clock second.
    fn frames_per_s(&self) -> f64 {
        self.frames as f64 / self.wall_s
    }
}

/// Track `seq` from its first frame (one tracker, the calling thread), stopping early on
/// Ctrl-C.
fn track_all(tracker: &mut dyn FrameTracker, seq: &Recorded, bar: &ProgressBar) -> Samples {
    let mut s = Samples::default();
    let start = Instant::now();
    for (frame, truth) in seq.frames.iter().zip(&seq.truth) {
        if crate::interrupt::requested() {
            break;
        }
        let rec = tracker.track(frame, truth.frame, truth.timestamp);
        s.frames += 1;
        bar.inc(1);
        // The online calibrator's first frames after a placement are its seed's, a Ch. 3
        // tracker's (`honline_calib::watch`): they count in the wall time, not in the stages.
        if rec.flags.iter().any(|f| f == "settling") {
            continue;
        }
        let stage = |k: &str| rec.timing_us.get(k).copied().unwrap_or(f64::NAN);
        s.correspondences.push(stage("correspondences"));
        s.closest.push(stage("closest_points"));
        s.along_ray.push(stage("along_ray"));
        s.m2d.push(stage("m2d"));
        s.solve.push(stage("solve"));
        s.reshape.push(stage("reshape"));
        s.laplace.push(stage("laplace"));
        s.filter.push(stage("filter"));
        s.track.push(stage("track"));
        s.iterations
            .push(rec.iterations.map_or(f64::NAN, f64::from));
        s.points.push(frame.points.len() as f64);
    }
    s.wall_s = start.elapsed().as_secs_f64();
    s
}

/// Medians of the stages (µs).
#[derive(Serialize, Clone, Copy)]
struct Stages {
    correspondences_us: f64,
    /// Sphere-mesh trackers only (absent for the cylinders): the parts of `correspondences`
    /// (`hmodel_spheremesh::UpdateTiming`).
    #[serde(skip_serializing_if = "Option::is_none")]
    closest_points_us: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    along_ray_us: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    m2d_us: Option<f64>,
    solve_us: f64,
    /// Online calibration only (absent for the plain trackers): the template and collision
    /// term rebuilt on a moved β.
    #[serde(skip_serializing_if = "Option::is_none")]
    reshape_us: Option<f64>,
    /// Online calibration only: the Laplace information of the frame (Eq. 4.5).
    #[serde(skip_serializing_if = "Option::is_none")]
    laplace_us: Option<f64>,
    /// Online calibration only: the estimator's update and the certainties.
    #[serde(skip_serializing_if = "Option::is_none")]
    filter_us: Option<f64>,
    /// What the frame spends outside the stages above (taking the frame's points, keypoints,
    /// temporal history): track minus the other stages, per frame.
    other_us: f64,
    track_us: f64,
}

/// Per-frame medians of `per_frame` divided by the frame's iteration count (`per_iteration`
/// true) or as they are.
fn stage_medians(s: &Samples, per_iteration: bool) -> Stages {
    let m = |v: &[f64]| {
        let x: Vec<f64> = v
            .iter()
            .zip(&s.iterations)
            .filter(|(_, &it)| !per_iteration || it > 0.0)
            .map(|(&t, &it)| if per_iteration { t / it } else { t })
            .collect();
        median(&x)
    };
    // A stage the tracker does not report is NaN in every frame: absent, and no time of it.
    let calibration = [&s.reshape, &s.laplace, &s.filter];
    let other: Vec<f64> = (0..s.track.len())
        .map(|i| {
            let known = |v: &Vec<f64>| v.get(i).copied().filter(|x| !x.is_nan()).unwrap_or(0.0);
            known(&s.track)
                - known(&s.correspondences)
                - known(&s.solve)
                - calibration.iter().map(|v| known(v)).sum::<f64>()
        })
        .collect();
    let reported = |v: &[f64]| v.iter().any(|x| !x.is_nan()).then(|| m(v));
    Stages {
        correspondences_us: m(&s.correspondences),
        closest_points_us: reported(&s.closest),
        along_ray_us: reported(&s.along_ray),
        m2d_us: reported(&s.m2d),
        solve_us: m(&s.solve),
        reshape_us: reported(&s.reshape),
        laplace_us: reported(&s.laplace),
        filter_us: reported(&s.filter),
        other_us: m(&other),
        track_us: m(&s.track),
    }
}

/// One model on one thread.
#[derive(Serialize)]
struct SingleThread {
    model: Model,
    frames: usize,
    points_median: f64,
    iterations_median: f64,
    per_frame: Stages,
    per_iteration: Stages,
    /// Frames over the wall-clock time of the loop.
    frames_per_s: f64,
    /// Median track time over the median preprocessing time of the same frames.
    ratio_to_baseline: f64,
    /// Median track time over the plain sphere-mesh tracker's on the same frames in the same
    /// run (for the online calibrator: what calibrating costs); absent when the sphere-mesh
    /// tracker was not measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    ratio_to_spheremesh: Option<f64>,
    /// The goal for the median frame (µs): 1.5 ms for the trackers (issue 5), 5 ms
    /// (200 frames/s) for tracking with online calibration (issue 8).
    goal_us: f64,
    /// Whether the median frame meets it.
    meets_goal: bool,
}

/// Two sequences on two threads vs one after the other.
#[derive(Serialize)]
struct TwoCores {
    model: Model,
    frames: usize,
    sequential_frames_per_s: f64,
    parallel_frames_per_s: f64,
    speedup: f64,
    /// Amdahl's bound for parallelizing the correspondence stage inside a frame on 2 cores,
    /// 1 / (1 − p/2) with p its measured share of the frame: not measured, the tracker has no
    /// intra-frame parallelism.
    intra_frame_bound: f64,
    /// Which way of using the second core wins, from the two numbers above.
    wins: String,
}

/// The sphere-mesh frame time at one point count.
#[derive(Serialize)]
struct ScalingRow {
    requested_points: usize,
    points_median: f64,
    frames: usize,
    track_ms_median: f64,
    ratio_to_2500: f64,
}

/// The scaling run: its camera and one row per point count.
#[derive(Serialize)]
struct Scaling {
    camera: Camera,
    rows: Vec<ScalingRow>,
}

/// Everything `--json` writes.
#[derive(Serialize)]
struct Report {
    motion: String,
    noise: String,
    seed: u64,
    frames: usize,
    points: usize,
    baseline: &'static str,
    baseline_us: f64,
    goal_us: f64,
    thesis_quoted: &'static str,
    single_thread: Vec<SingleThread>,
    two_cores: Vec<TwoCores>,
    intra_frame_parallelism: &'static str,
    /// Absent when the sphere-mesh tracker is not selected (or on Ctrl-C before it).
    scaling: Option<Scaling>,
    /// What `std::thread::available_parallelism` reports.
    cores: usize,
    interrupted: bool,
}

/// Run `hands bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    let models = Model::parse_list(&args.model)?;
    ensure!(
        (1..=100_000).contains(&args.frames),
        "--frames must be in 1..=100000, got {}",
        args.frames
    );
    // The online calibrator's first frames are its seed's (`honline_calib::watch`), left out
    // of its stages.
    let settle = honline_calib::watch::SETTLE_FRAMES;
    ensure!(
        !models.contains(&Model::Online) || args.frames > settle,
        "--frames must be above {settle} for the online calibrator, whose first {settle} frames \
         follow the Ch. 3 tracker that placed the hand; got {}",
        args.frames
    );
    ensure!(
        (1..=100_000).contains(&args.points),
        "--points must be in 1..=100000, got {}",
        args.points
    );
    if let Some(dir) = args.json.as_ref().and_then(|p| p.parent()) {
        ensure!(
            dir.as_os_str().is_empty() || dir.is_dir(),
            "--json: the folder {} does not exist",
            dir.display()
        );
    }
    let spec = SyntheticSpec {
        motion: args.motion.clone(),
        frames: args.frames,
        noise: args.noise.clone(),
        seed: args.seed,
        preprocess: PreprocessConfig {
            segmentation: Segmentation::Wristband(WristbandParams::default()),
            num_points: args.points,
            ..PreprocessConfig::default()
        },
        ..SyntheticSpec::default()
    };
    let first = record(spec.clone(), "bench: render + preprocess")
        .with_context(|| format!("synthesizing `{}`", args.motion))?;
    let built = Models {
        cylinders: CylinderModel::from_sphere_mesh_with_wrist(&first.template)?,
        template: first.template.clone(),
        basis: ShapeBasis::honline(&first.template)?,
        prior: PcaPrior::project_default(),
    };
    let baseline_us = median(&first.preprocess_us);
    let mut report = Report {
        motion: args.motion.clone(),
        noise: args.noise.clone(),
        seed: args.seed,
        frames: args.frames,
        points: args.points,
        baseline: "median preprocessing time of the same frames (wristband segmentation, sampling, distance transform)",
        baseline_us,
        goal_us: GOAL_US,
        thesis_quoted: THESIS_QUOTED,
        single_thread: Vec::new(),
        two_cores: Vec::new(),
        intra_frame_parallelism: "not implemented in the trackers: only its Amdahl bound is given",
        scaling: None,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        interrupted: false,
    };

    let mut singles = Vec::new();
    for &m in &models {
        let bar = frames_bar(Some(args.frames), &format!("bench: {} 1 thread", m.name()));
        let s = track_all(built.tracker(m)?.as_mut(), &first, &bar);
        bar.finish_and_clear();
        // A model that Ctrl-C stopped before its first frame has nothing to show.
        if s.frames == 0 {
            break;
        }
        report.single_thread.push(single_thread(m, &s, baseline_us));
        singles.push(s);
    }
    let plain = report
        .single_thread
        .iter()
        .find(|c| c.model == Model::SphereMesh)
        .map(|c| c.per_frame.track_us);
    for c in &mut report.single_thread {
        c.ratio_to_spheremesh = plain.map(|p| c.per_frame.track_us / p);
    }
    if !report.single_thread.is_empty() {
        println!("{}", single_thread_table(&report));
    }

    if !crate::interrupt::requested() {
        let second = record(
            SyntheticSpec {
                seed: args.seed.wrapping_add(1),
                ..spec
            },
            "bench: second sequence",
        )?;
        for (&m, single) in models.iter().zip(&singles) {
            let c = two_cores(&built, m, [&first, &second], single)?;
            // Cut short by Ctrl-C, the two runs did unequal work: no speed-up to report.
            if crate::interrupt::requested() {
                break;
            }
            report.two_cores.push(c);
        }
        if !report.two_cores.is_empty() {
            println!("{}", two_cores_table(&report));
        }
    }

    if models.contains(&Model::SphereMesh) && !crate::interrupt::requested() {
        let s = scaling(&built, &first)?;
        println!("{}", scaling_table(&s));
        report.scaling = Some(s);
    }

    report.interrupted = crate::interrupt::requested();
    if report.interrupted {
        eprintln!("interrupted: the tables above hold what was measured");
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        write_atomic(path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("numbers → {}", path.display());
    }
    Ok(())
}

fn single_thread(model: Model, s: &Samples, baseline_us: f64) -> SingleThread {
    let per_frame = stage_medians(s, false);
    SingleThread {
        model,
        frames: s.frames,
        points_median: median(&s.points),
        iterations_median: median(&s.iterations),
        per_frame,
        per_iteration: stage_medians(s, true),
        frames_per_s: s.frames_per_s(),
        ratio_to_baseline: per_frame.track_us / baseline_us,
        ratio_to_spheremesh: None,
        goal_us: model.goal_us(),
        meets_goal: per_frame.track_us <= model.goal_us(),
    }
}

/// A stage's label, its value (`None`: the model has no such stage) and the thesis's figure
/// per iteration and per frame.
type StageRow = (&'static str, fn(&Stages) -> Option<f64>, [&'static str; 2]);

/// A unit of the per-stage table (`iter`, `frame`) and where a model's medians in it are.
type Unit = (&'static str, fn(&SingleThread) -> &Stages);

/// The stages of a [`Stages`], in table order, with the thesis's figure for each (per
/// iteration, per frame) where it quotes one.
const STAGE_ROWS: [StageRow; 10] = [
    (
        "correspondences",
        |s| Some(s.correspondences_us),
        ["250 (+ rendering 500)", "front-facing 100, silhouette 150"],
    ),
    (
        "· closest points (front-facing)",
        |s| s.closest_points_us,
        ["250", "—"],
    ),
    ("· along-ray registration", |s| s.along_ray_us, ["—", "—"]),
    ("· m2d (rendering)", |s| s.m2d_us, ["500", "—"]),
    ("solve", |s| Some(s.solve_us), ["—", "—"]),
    (
        "reshape (β → template, collision)",
        |s| s.reshape_us,
        ["—", "—"],
    ),
    ("Laplace information", |s| s.laplace_us, ["—", "—"]),
    (
        "filter (estimate, certainties)",
        |s| s.filter_us,
        ["—", "—"],
    ),
    ("other", |s| Some(s.other_us), ["—", "—"]),
    ("total", |s| Some(s.track_us), ["—", "—"]),
];

/// A median (µs) as a table cell, "—" for a stage the model does not have.
fn cell(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_string(), |v| format!("{v:.0}"))
}

/// The per-stage table: one column per model, the thesis's figures beside them.
fn single_thread_table(r: &Report) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "## One thread: {} frames of `{}` ({} noise, seed {}), {} points requested\n\
         baseline: preprocessing {:.0} µs/frame (median over the same frames, measured in this run)\n",
        r.frames, r.motion, r.noise, r.seed, r.points, r.baseline_us
    );
    let cols = &r.single_thread;
    let mut columns = vec!["median"];
    columns.extend(cols.iter().map(|c| c.model.name()));
    columns.push("thesis (quoted, i7 + GTX 980, not measured)");
    table_header(&mut t, &columns);
    let mut row = |label: &str, cell: &dyn Fn(&SingleThread) -> String, thesis: &str| {
        let cells: Vec<String> = cols.iter().map(cell).collect();
        let _ = writeln!(t, "| {label} | {} | {thesis} |", cells.join(" | "));
    };
    row("points", &|c| format!("{:.0}", c.points_median), "~2500");
    row(
        "iterations",
        &|c| format!("{:.0}", c.iterations_median),
        "1 rigid + 7",
    );
    let units: [Unit; 2] = [("iter", |c| &c.per_iteration), ("frame", |c| &c.per_frame)];
    for (u, (unit, stages)) in units.into_iter().enumerate() {
        for (stage, value, thesis) in STAGE_ROWS {
            row(
                &format!("{stage} µs/{unit}"),
                &|c| cell(value(stages(c))),
                thesis[u],
            );
        }
    }
    row(
        "frames/s (frames / wall time)",
        &|c| format!("{:.0}", c.frames_per_s),
        "—",
    );
    row(
        "× baseline (total / preprocessing)",
        &|c| format!("{:.2}", c.ratio_to_baseline),
        "—",
    );
    row(
        "× spheremesh (total / plain sphere-mesh tracker)",
        &|c| {
            c.ratio_to_spheremesh
                .map_or("—".into(), |r| format!("{r:.2}"))
        },
        "—",
    );
    row(
        "goal (µs/frame)",
        &|c| {
            let verdict = if c.meets_goal { "met" } else { "not met" };
            format!("{verdict} (≤ {:.0})", c.goal_us)
        },
        "—",
    );
    let _ = writeln!(
        t,
        "\ncorrespondences = the whole refresh before each solve (re-pose, closest points, \
         front-facing test, silhouette candidates, m2d rendering / the E2D raster), with the \
         sphere-mesh trackers' parts of it (·): closest points with their front-facing \
         substitutes, the along-ray registration (on frames whose measured depth noise is \
         ≥ 1.5 mm), the m2d pushes; the \
         reshape, Laplace and filter rows are what online calibration adds (\"—\": the model \
         has no such stage); other = total minus the stages above; goals: 1500 µs (issue 5), \
         online 5000 µs = 200 frames/s (issue 8)"
    );
    let _ = write!(
        t,
        "\nthesis figures (quoted from the issue, not measured here): {THESIS_QUOTED}"
    );
    t
}

/// Track the two sequences one after the other, then on two threads (one tracker each), with
/// fresh trackers every time so that both runs do the same work.
fn two_cores(
    built: &Models,
    model: Model,
    seqs: [&Recorded; 2],
    single: &Samples,
) -> Result<TwoCores> {
    let n: usize = seqs.iter().map(|s| s.frames.len()).sum();
    let bar = frames_bar(
        Some(2 * n),
        &format!("bench: {} sequential then 2 threads", model.name()),
    );
    let start = Instant::now();
    let mut sequential_frames = 0;
    for seq in seqs {
        sequential_frames += track_all(built.tracker(model)?.as_mut(), seq, &bar).frames;
    }
    let sequential_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let parallel_frames = std::thread::scope(|scope| -> Result<usize> {
        let bar = &bar;
        let handles = seqs.map(|seq| {
            scope.spawn(move || -> Result<usize> {
                Ok(track_all(built.tracker(model)?.as_mut(), seq, bar).frames)
            })
        });
        let mut total = 0;
        for h in handles {
            total += h
                .join()
                .map_err(|_| anyhow::anyhow!("a tracking thread panicked"))??;
        }
        Ok(total)
    })?;
    let parallel_s = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let sequential = sequential_frames as f64 / sequential_s;
    let parallel = parallel_frames as f64 / parallel_s;
    let p = median(&single.correspondences) / median(&single.track);
    let speedup = parallel / sequential;
    let bound = 1.0 / (1.0 - p / 2.0);
    Ok(TwoCores {
        model,
        frames: n,
        sequential_frames_per_s: sequential,
        parallel_frames_per_s: parallel,
        speedup,
        intra_frame_bound: bound,
        wins: verdict(speedup, bound),
    })
}

/// Below this speed-up two threads gained nothing worth the name: the second core was busy
/// (a shared machine) or memory-bound.
const NO_GAIN: f64 = 1.1;

/// The verdict of frames in parallel (measured `speedup`) vs rayon inside a frame (only its
/// Amdahl `bound`, nothing measured).
fn verdict(speedup: f64, bound: f64) -> String {
    if speedup < NO_GAIN {
        format!("neither measured a gain: {speedup:.2}× on two threads (is the second core busy?)")
    } else if speedup >= bound {
        format!("frames in parallel: {speedup:.2}× measured ≥ {bound:.2}×, rayon's best case")
    } else {
        format!(
            "frames in parallel measured {speedup:.2}×; rayon could reach at most {bound:.2}× \
             (not implemented, not measured)"
        )
    }
}

fn two_cores_table(r: &Report) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "## Two cores: two sequences (seeds {} and {}), one after the other vs on two threads \
         ({} cores available)\n",
        r.seed,
        r.seed.wrapping_add(1),
        r.cores
    );
    table_header(
        &mut t,
        &[
            "model",
            "frames",
            "sequential frames/s",
            "2 threads frames/s",
            "speed-up (measured)",
            "rayon in a frame: Amdahl bound (not measured)",
            "wins",
        ],
    );
    for c in &r.two_cores {
        let _ = writeln!(
            t,
            "| {} | {} | {:.0} | {:.0} | {:.2}× | {:.2}× | {} |",
            c.model.name(),
            c.frames,
            c.sequential_frames_per_s,
            c.parallel_frames_per_s,
            c.speedup,
            c.intra_frame_bound,
            c.wins
        );
    }
    let _ = write!(
        t,
        "\nrayon inside a frame is not implemented in the trackers; its bound assumes the \
         correspondence stage (its measured share p of the frame) split perfectly over 2 cores \
         and the rest serial: 1 / (1 − p/2). The machine may be shared: a busy second core \
         lowers the measured speed-up."
    );
    t
}

/// `q` at `k` times its resolution (pixel centers preserved: the inverse of
/// `Camera::downsampled(k)`).
fn upsampled(q: &Camera, k: u32) -> Camera {
    let f = f64::from(k);
    Camera {
        width: q.width * k,
        height: q.height * k,
        fx: q.fx * f,
        fy: q.fy * f,
        cx: (q.cx + 0.5) * f - 0.5,
        cy: (q.cy + 0.5) * f - 0.5,
        name: format!("{}x{k}", q.name),
        ..q.clone()
    }
}

/// The camera of the scaling run: the SR300 at 2× (VGA), or 3× or 4× when at 2× the hand of
/// the median pose covers fewer pixels than the largest point count. One camera serves every count, so that only the number of points
/// changes between rows (the m2d rendering cost grows with the camera's pixels, not with the
/// points).
fn scaling_camera(template: &SphereMeshTemplate, poses: &[(Pose, Pose)]) -> Result<Camera> {
    let qvga = Camera::sr300_qvga();
    let largest = SCALING_POINTS.iter().copied().max().unwrap_or(0) as f64;
    let mut camera = upsampled(&qvga, 2);
    for k in 2..=4 {
        camera = upsampled(&qvga, k);
        let pixels = poses
            .iter()
            .map(|(exact, _)| {
                rendered_frame(template, exact, &camera, usize::MAX).map(|f| f.points.len() as f64)
            })
            .collect::<hand_model::Result<Vec<_>>>()
            .context("rendering the scaling poses")?;
        if median(&pixels) >= largest {
            break;
        }
    }
    Ok(camera)
}

/// `truth`'s pose moved by [`WARM_START_OFFSET`].
fn warm_start(template: &SphereMeshTemplate, truth: &HandRecord) -> Result<(Pose, Pose)> {
    let sk = &template.skeleton;
    let exact = Pose::from_named(sk, truth.pose.iter().map(|(k, v)| (k.as_str(), *v)))
        .with_context(|| format!("the ground-truth pose of frame {}", truth.frame))?;
    let mut start = exact.clone();
    for (name, offset) in WARM_START_OFFSET {
        let i = sk
            .dof_index(name)
            .with_context(|| format!("the template has no DOF `{name}`"))?;
        start.values[i] += offset;
    }
    Ok((exact, start))
}

/// The sphere-mesh frame time per point count: up to [`SCALING_POSES`] true poses of `seq`,
/// each rendered noise-free at VGA and subsampled to the count, tracked once from its warm
/// start (one thread).
fn scaling(built: &Models, seq: &Recorded) -> Result<Scaling> {
    let step = seq.truth.len().div_ceil(SCALING_POSES).max(1);
    let poses = seq
        .truth
        .iter()
        .step_by(step)
        .map(|t| warm_start(&built.template, t))
        .collect::<Result<Vec<_>>>()?;
    let camera = scaling_camera(&built.template, &poses)?;
    let mut tracker = hmodel_spheremesh::Tracker::new(
        &built.template,
        hmodel_spheremesh::TrackerConfig::default(),
        Some(&built.prior),
    )?;
    let bar = frames_bar(
        Some(SCALING_POINTS.len() * poses.len()),
        "bench: point-count scaling",
    );
    let mut rows = Vec::new();
    'counts: for n in SCALING_POINTS {
        let (mut ms, mut points) = (Vec::new(), Vec::new());
        for (k, (exact, start)) in poses.iter().enumerate() {
            if crate::interrupt::requested() {
                break 'counts;
            }
            let frame = rendered_frame(&built.template, exact, &camera, n)
                .with_context(|| format!("rendering pose {k} at {n} points"))?;
            tracker.set_pose(start)?;
            let rec = tracker.track(&frame, k as u64, 0.0);
            ms.push(rec.timing_us.get("track").copied().unwrap_or(f64::NAN) / 1e3);
            points.push(frame.points.len() as f64);
            bar.inc(1);
        }
        rows.push(ScalingRow {
            requested_points: n,
            points_median: median(&points),
            frames: ms.len(),
            track_ms_median: median(&ms),
            ratio_to_2500: f64::NAN,
        });
    }
    bar.finish_and_clear();
    let reference = rows
        .iter()
        .find(|r| r.requested_points == SCALING_REFERENCE)
        .map_or(f64::NAN, |r| r.track_ms_median);
    for r in &mut rows {
        r.ratio_to_2500 = r.track_ms_median / reference;
    }
    Ok(Scaling { camera, rows })
}

fn scaling_table(s: &Scaling) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "## Point-count scaling (spheremesh, one thread, noise-free frames rendered at {}×{}, \
         warm start a few mm and degrees off the truth)\n",
        s.camera.width, s.camera.height
    );
    let _ = writeln!(
        t,
        "points are every k-th rendered pixel, k the smallest step that keeps at most the \
         requested count (`rendered_frame`), hence fewer than requested\n"
    );
    table_header(
        &mut t,
        &[
            "requested points",
            "points (median)",
            "frames",
            "median ms/frame",
            "× 2500 points",
        ],
    );
    for r in &s.rows {
        let _ = writeln!(
            t,
            "| {} | {:.0} | {} | {:.3} | {:.2} |",
            r.requested_points, r.points_median, r.frames, r.track_ms_median, r.ratio_to_2500
        );
    }
    t
}

/// Append the header and separator lines of a markdown table with `columns`.
fn table_header(t: &mut String, columns: &[&str]) {
    let _ = writeln!(t, "| {} |", columns.join(" | "));
    let _ = writeln!(t, "|{}", "---|".repeat(columns.len()));
}
