//! The per-frame control flow shared by the trackers (thesis §2.4 Fig. 2.3, §3.3): warm start
//! from the previous frame, loss detection over a window of failed frames and re-initialization
//! from several hypotheses ([`super::loss`]), each solved a few times over
//! ([`PLACEMENT_SOLVES`]), with and without the rigid-only first iterations
//! ([`TrackingProblem::set_rigid_first`]), and looked at again a few frames later
//! ([`RECHECK_FRAMES`]), then each digit set to other flexions ([`super::digit_variants`]),
//! which also runs, confirmed over a few frames ([`CONFIRM_FRAMES`]), on a frame that fits much
//! worse than the recent ones ([`ScoreTrigger`]). The trackers provide the solve itself through
//! [`TrackingProblem`]; this loop only decides which poses to solve from and which to keep.

use super::loss::{FrameStats, LossParams};
use crate::kinematics::Pose;

/// What a tracker provides to [`FrameLoop`]: its solve over the current frame's data.
pub trait TrackingProblem {
    /// Run the tracker's LM solve from `pose` in place; false when it failed or left a
    /// non-finite pose.
    fn solve(&mut self, pose: &mut Pose) -> bool;
    /// Enter (`true`) or leave (`false`) the state of [`Self::solve_aside`]: the temporal
    /// history set aside, and the solves' report kept apart from the frame's.
    fn set_aside(&mut self, aside: bool);
    /// [`Self::solve`] without the temporal history, leaving no trace on the sequence: the
    /// history and what the tracker reports of its last solve stay as they were (the second
    /// look at a placement, whose starts must not be pulled toward the tracked pose and which
    /// must not move it when it stays).
    fn solve_aside(&mut self, pose: &mut Pose) -> bool {
        self.set_aside(true);
        let solved = self.solve(pose);
        self.set_aside(false);
        solved
    }
    /// Recompute the correspondences at `pose` (for scoring a solved hypothesis); false on
    /// failure.
    fn refresh(&mut self, pose: &Pose) -> bool;
    /// The loss statistics at the last linearization point (or refresh).
    fn frame_stats(&self, params: &LossParams) -> FrameStats;
    /// Initial poses placed on the current frame's data.
    fn hypotheses(&self) -> Vec<Hypothesis>;
    /// Whether a solved hypothesis with these statistics (from [`Self::frame_stats`] at its
    /// refreshed pose) is a poor placement, which lets the backups be tried: by default
    /// [`FrameStats::is_poor_placement`].
    fn is_poor_placement(&self, stats: &FrameStats) -> bool {
        stats.is_poor_placement()
    }
    /// Forget the temporal history (after a re-initialization or a frame without a hand).
    fn clear_history(&mut self);
    /// Turn the solves' rigid-only first iterations (thesis §2.4, Fig. 2.17) off (`false`) or
    /// back on (`true`) until the next call; whether the solves have any, so that turning them
    /// off changes something. [`FrameLoop`] solves its placements both ways; none by default.
    fn set_rigid_first(&mut self, _on: bool) -> bool {
        false
    }
    /// `pose` with digit `digit` (DESIGN.md order) set to other flexions, for the digit search
    /// at the second look at a placement and on a frame that fits much worse than the recent
    /// ones ([`super::digit_variants`]); none by default.
    fn digit_variants(&self, _pose: &Pose, _digit: usize) -> Vec<Pose> {
        Vec::new()
    }
}

/// A re-initialization start.
#[derive(Clone, Debug, PartialEq)]
pub struct Hypothesis {
    /// The initial pose.
    pub pose: Pose,
    /// Solved only when no other start (the current pose included) fits acceptably
    /// ([`FrameStats::is_poor_placement`]): a less likely placement that could otherwise
    /// win on a pose that none of the starts matches.
    pub backup: bool,
}

/// How one frame went in [`FrameLoop::step`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameOutcome {
    /// DESIGN.md flags: `no_hand`, `reinitialized`, `solver_failed`, `lost`.
    pub flags: Vec<&'static str>,
    /// Loss statistics at the returned pose (`None` for a frame without a hand).
    pub stats: Option<FrameStats>,
}

/// The warm-start / loss / re-initialization state of one sequence.
#[derive(Clone, Debug)]
pub struct FrameLoop {
    /// The current pose θ (never non-finite).
    pub pose: Pose,
    /// The pose of a fresh start (e.g. the PCA mean pose), used when every hypothesis fails.
    pub fallback: Pose,
    /// The settings as given, and as in force for the measured depth noise.
    base: LossParams,
    loss: LossParams,
    initialized: bool,
    failed_run: usize,
    /// The pose of the last frame not flagged `lost` (valid when `has_fitted`), what a frame
    /// without a hand reports.
    fitted: Pose,
    has_fitted: bool,
    /// Frames until the placement of the last re-initialization is looked at again.
    recheck_in: Option<usize>,
    /// The recent frames' scores, which trigger the digit search.
    scores: ScoreTrigger,
    /// The triggered digit search's candidate pose and the frames it has fitted better
    /// ([`FrameLoop::confirm_digits`]).
    candidate: Option<(Pose, usize)>,
}

/// Frames whose scores ([`FrameStats::score`]) the digit search's trigger compares a frame
/// with; it waits until half of them are in.
const SCORE_WINDOW: usize = 60;

/// A frame whose score exceeds this multiple of the recent frames' median triggers the digit
/// search ([`FrameLoop::step`]). Two fingers exchanged in the middle of a sequence leave the
/// model sticking out of the silhouette where the wrong one lies: on the library's ToF
/// `axis_interaction` (sphere-mesh tracker) the share outside rose from ≈ 0.04 to 0.06–0.15 and
/// the points' mean distance from ≈ 1.5 to 1.8–3.5 mm, for 300 frames at 15 mm mean keypoint
/// error. Measured in session 33, the search's pose adopted at once (the library's 16 motions
/// of the default hand, but `leave_reenter`, from frame 0; mean keypoint error summed, without
/// → with the trigger; confirmed over [`CONFIRM_FRAMES`] since), sphere-mesh: ToF 22.43 →
/// 21.07 mm (`axis_interaction` 4.28 → 2.07, `crossing` 5.36 → 6.21, the 14 others within
/// 0.05 mm, the median frame unchanged), noise-free 11.42 → 7.20 mm (`axis_interaction` 3.80 →
/// 0.53, `crossing` 2.33 → 1.35, `random` 0.69 → 0.75); Ch. 2 cylinders, ToF: 36.04 → 34.64 mm
/// (`crossing` 5.53 → 4.55, `axis_interaction` 2.71 → 2.10, `abduction` 2.08 → 2.27). The 74
/// cold starts of [`super::digit_variants`] (90 frames each) did not change. Tried and not
/// kept: letting a variant win with a mean distance up to 10 % larger (ToF moves it by a few
/// per cent), ToF library 21.07 → 20.49 mm, but ToF cold starts 157.67 → 199.01 mm
/// (`rotation_fast` from frame 105 3.67 → 25.42, `random` from 165 4.07 → 15.70). Confirmed
/// (session 34), the Ch. 2 cylinders' ToF library went 34.64 → 32.93 mm (`crossing` 4.55 →
/// 3.02, `abduction` 2.27 → 2.08), the sphere-mesh tracker's structured-light library 16.57 →
/// 12.38 mm against session 33's (`crossing` 6.54 → 2.55, `random` 1.09 → 0.87).
const SCORE_RATIO: f64 = 1.3;

/// Frames after a triggered digit search before the next may be: a search solves ≈ 10 frames'
/// worth, and a failure it did not mend would otherwise pay that on every frame.
const DIGIT_COOLDOWN: usize = 30;

/// Frames in a row whose scores stay out of the trigger's window while each would trigger the
/// search ([`ScoreTrigger::push`]): a pose lost gradually fills the window with its own scores
/// within a cooldown, after which nothing triggers the search again. Held out, a lasting bad
/// fit keeps triggering once a cooldown — three searches — before the window takes it as the
/// new normal (a lasting change of view that the search cannot mend). Measured in session 39
/// (ToF, mean keypoint error summed, better / worse by more than 0.05 mm): online calibration
/// (with its 2 mm collision tolerance, `honline_calib::OnlineConfig::collision_tolerance`) on
/// `axis_interaction` by a random subject — crossed fingers lost over frames 465–485 stayed
/// 21–33 mm off to the end without the hold; held, the search mended them at frame 505 (8.34
/// → 2.10 mm) — and on the library's 16 motions 19.07 → 18.48 mm (1 / 1: `axis_interaction`
/// 2.10 → 1.23, `crossing` 3.07 → 3.35); the Ch. 3 tracker's library 19.99 → 17.31 mm (2 / 0:
/// `crossing` 5.13 → 3.33, `axis_interaction` 2.08 → 1.21); the Ch. 2 cylinders' library
/// unchanged (33.36 mm); cold starts of 90 frames, whose window seldom fills, unchanged.
const HOLD_FRAMES: usize = 90;

/// The trigger of the digit search during tracking: the last 60 frames' scores
/// ([`FrameStats::score`]) and the cooldown. A frame whose score exceeds 1.3 times their median
/// (once 30 are in) triggers it, at most once in 30 frames; such frames join the window only
/// after 90 in a row, so that a pose lost gradually keeps triggering it. [`FrameLoop::step`]
/// holds one; a tracker with a frame loop of its own (online calibration) holds its own and
/// runs the search through [`FrameLoop::search_digits`].
#[derive(Clone, Debug)]
pub struct ScoreTrigger {
    scores: [f64; SCORE_WINDOW],
    len: usize,
    next: usize,
    cooldown: usize,
    /// High scores held out of the window in a row ([`HOLD_FRAMES`]).
    held: usize,
}

impl Default for ScoreTrigger {
    fn default() -> Self {
        Self::new()
    }
}

impl ScoreTrigger {
    /// An empty window.
    pub fn new() -> Self {
        Self {
            scores: [0.0; SCORE_WINDOW],
            len: 0,
            next: 0,
            cooldown: 0,
            held: 0,
        }
    }

    /// Forget the scores (after a new placement: the frames before it fitted another pose).
    pub fn clear(&mut self) {
        (self.len, self.next, self.held) = (0, 0, 0);
    }

    /// Add the score of a frame that was not lost (non-finite scores are ignored), unless it
    /// would trigger the search and fewer than 90 such scores have been held out in a row.
    pub fn push(&mut self, score: f64) {
        if !score.is_finite() {
            return;
        }
        if !self.is_high(score) {
            self.held = 0;
        } else if self.held < HOLD_FRAMES {
            self.held += 1;
            return;
        }
        self.scores[self.next] = score;
        self.next = (self.next + 1) % SCORE_WINDOW;
        self.len = (self.len + 1).min(SCORE_WINDOW);
    }

    /// Whether `score` triggers the digit search (which starts the cooldown); call it once a
    /// frame, before [`Self::push`]ing the frame's score.
    pub fn triggers(&mut self, score: f64) -> bool {
        if self.cooldown > 0 {
            self.cooldown -= 1;
            return false;
        }
        let due = self.is_high(score);
        if due {
            self.cooldown = DIGIT_COOLDOWN;
        }
        due
    }

    /// Whether `score` exceeds [`SCORE_RATIO`] times the window's median (false before half of
    /// the window is in).
    fn is_high(&self, score: f64) -> bool {
        if self.len < SCORE_WINDOW / 2 {
            return false;
        }
        let mut recent = self.scores;
        let recent = &mut recent[..self.len];
        let (_, median, _) = recent.select_nth_unstable_by(self.len / 2, f64::total_cmp);
        score > SCORE_RATIO * *median
    }
}

/// Frames in a row that a pose found by the digit search during tracking must fit better
/// than the tracked pose before it replaces it ([`FrameLoop::challenge`]): the frame that
/// triggered the search and the next two. Crossed index and middle fingers seen in depth can
/// fit a frame better exchanged while the tracker is still recovering from a failure: on the
/// library's ToF `crossing` (online calibration, which had no search of its own before) the
/// search at once took 4.07 → 7.62 mm mean keypoint error (the exchange held ≈ 100 frames);
/// confirmed, 4.07, while `axis_interaction` still went 4.56 → 2.50 (2.48 at once). The Ch. 3
/// tracker, ToF library from frame 0, mean keypoint error summed over its 16 motions, at once
/// → confirmed (and the bar solved once more, [`FrameLoop::step`]): 21.07 → 20.01 mm
/// (`crossing` 6.21 → 5.13, the others within 0.05); noise-free 7.20 → 7.40 (`crossing` 1.35
/// → 1.58, `random` 0.75 → 0.69).
pub const CONFIRM_FRAMES: usize = 3;

/// A re-initialization places the hand on what it sees of it, which is often the first fingers
/// of a hand entering the view, or part of a hand after a fast motion: this many frames later
/// the placement hypotheses are solved again ([`TrackingProblem::solve_aside`]) and one that
/// fits the frame better than the tracked pose replaces it.
///
/// Synthetic `leave_reenter` (30 Hz, seed 8, the hand leaves the view and comes back), mean
/// keypoint error over the frames with the hand wholly in view: the Ch. 2 cylinders 12.32 →
/// 4.30 mm noise-free and 6.53 → 5.26 mm under ToF (they had placed the hand entering the view
/// with every finger shifted by one, a fit their loss test cannot tell from a good one); the
/// Ch. 3 tracker 51.88 → 3.39 and 4.65 → 3.05 mm. On the 34 library sequences (but
/// `leave_reenter`) and 74 ToF cold starts no look replaced a pose, with either tracker.
pub const RECHECK_FRAMES: usize = 10;

/// LM solves in a row for each (non-backup) placement hypothesis ([`Hypothesis`]). A start is
/// the mean pose dropped on the point cloud, far from the hand, and one solve (the trackers'
/// 1 rigid + 7 iterations of a tracked frame) stops before a hand turned edge-on has come
/// round: the Ch. 2 cylinders placed a ToF hand turned 65° (`rotation_slow` from frame 165)
/// with the fingers pitched 40 mm toward the camera and tracked it 27 mm off; started at the
/// true pose they held it within 2 mm. Whether the backups are needed is judged after the
/// first solve as well as after the last: the further solves also bring a palm-on start out
/// of its poor placement into a pose that is no longer poor but wrong, where the edge-on
/// backup fits (`calibration` from frame 250: 3.03 → 23.03 mm judged after the last solve
/// alone). The backups get one solve: solved longer, the wrong one of a fist's two edge-on
/// rolls won (`rotating_fist` from frame 105: 3.49 → 18.77 mm), and as equals of the palm-on
/// starts the edge-on ones won on fists.
///
/// Measured on 74 cold starts (16 library motions from frames 45–250 and 10 random subjects,
/// 90 frames each), mean keypoint error summed, 1 → 3 solves:
/// - ToF: cylinders 403.03 → 295.35 mm (67 better, 3 worse by more than 0.05 mm; cuts above
///   10 mm 8 → 6), sphere-mesh 152.57 → 137.39 (50 better, none worse), online calibration
///   169.18 → 154.96 (56 better, none worse);
/// - noise-free: cylinders 398.74 → 302.46 mm (61 better, 5 worse; above 10 mm 10 → 7),
///   sphere-mesh 112.69 → 100.48 (31 better, 3 worse), online calibration 113.68 → 102.11
///   (35 better, 6 worse);
/// - the library's 16 ToF motions from frame 0: online calibration 23.30 → 23.15 mm,
///   sphere-mesh 20.02 → 19.98, cylinders 32.93 → 33.39 (`crossing` 3.02 → 3.82, re-placed
///   after losing the crossed fingers);
/// - 2 solves: cylinders ToF cold starts 339.71 mm; 4: cylinders 285.70, but sphere-mesh
///   140.35 (a random subject from frame 163 4.46 → 13.15 mm), at a third more cost.
pub const PLACEMENT_SOLVES: usize = 3;

impl FrameLoop {
    /// A loop that starts uninitialized at `fallback` (the first frame re-initializes).
    pub fn new(fallback: Pose, loss: LossParams) -> Self {
        Self {
            pose: fallback.clone(),
            fitted: fallback.clone(),
            fallback,
            base: loss.clone(),
            loss,
            initialized: false,
            failed_run: 0,
            has_fitted: false,
            recheck_in: None,
            scores: ScoreTrigger::new(),
            candidate: None,
        }
    }

    /// The loss settings in force (for the depth noise last set).
    pub fn loss(&self) -> &LossParams {
        &self.loss
    }

    /// Judge the next frames for a sensor of depth noise `sigma` (σ̂, mm; see
    /// [`LossParams::for_noise`]).
    pub fn set_noise(&mut self, sigma: Option<f64>) {
        self.loss = self.base.for_noise(sigma);
    }

    /// Continue from `pose` at the next frame instead of re-initializing.
    pub fn set_pose(&mut self, pose: Pose) {
        self.pose = pose;
        self.candidate = None;
        self.initialized = true;
        self.failed_run = 0;
    }

    /// Whether the next frame warm-starts (true) or re-initializes.
    pub fn is_initialized(&self) -> bool {
        self.initialized
    }

    /// Track one frame whose data the problem already holds; `num_points` is the number of
    /// sensor points (fewer than [`LossParams::min_points`]: `no_hand`, the pose becomes the
    /// last one that fitted its frame — not `lost` — and the next frame re-initializes; a
    /// re-initialization that failed on a patch of background taken for the hand would
    /// otherwise be held through every frame until the hand is back). A failed solve keeps the
    /// previous pose (`solver_failed`); [`LossParams::window`] failed frames in a row
    /// re-initialize. [`RECHECK_FRAMES`] frames after a re-initialization its hypotheses are
    /// tried again beside the tracked pose, then the digit variants of the pose kept
    /// ([`TrackingProblem::digit_variants`], solved aside; one that fits the frame better by
    /// score and by mean distance replaces it, digit by digit; flag `reinitialized` when either
    /// changed it). The variants must beat the tracked pose also when it is solved once more
    /// aside: a pose still converging otherwise lost to a variant by the variant's extra solve
    /// (74 cold starts of 90 frames, mean keypoint error summed, Ch. 3 tracker: ToF 157.67 →
    /// 152.60 mm, `rotation_fast` from frame 165 8.76 → 3.81; noise-free 113.07 → 112.69).
    /// The same digit search runs on a tracked frame whose score ([`FrameStats::score`])
    /// exceeds 1.3 times the median of the last 60 frames' (once 30 are in), at most once in
    /// 30 frames; its better pose replaces the tracked one only after it has fitted
    /// [`CONFIRM_FRAMES`] frames in a row better ([`Self::challenge`]).
    pub fn step(&mut self, problem: &mut impl TrackingProblem, num_points: usize) -> FrameOutcome {
        let mut out = FrameOutcome::default();
        if num_points < self.loss.min_points.max(1) {
            out.flags.push("no_hand");
            if self.has_fitted {
                self.pose.values.clone_from(&self.fitted.values);
            }
            self.initialized = false;
            self.failed_run = 0;
            self.recheck_in = None;
            self.candidate = None;
            problem.clear_history();
            return out;
        }
        if !self.initialized {
            self.reinitialize(problem);
            out.flags.push("reinitialized");
        } else {
            let mut trial = self.pose.clone();
            if problem.solve(&mut trial) {
                self.pose = trial;
            } else {
                out.flags.push("solver_failed");
            }
        }
        let mut stats = problem.frame_stats(&self.loss);
        if stats.failed {
            self.failed_run += 1;
            if self.failed_run >= self.loss.window {
                self.reinitialize(problem);
                if !out.flags.contains(&"reinitialized") {
                    out.flags.push("reinitialized");
                }
                self.failed_run = 0;
                stats = problem.frame_stats(&self.loss);
            }
        } else {
            self.failed_run = 0;
        }
        if self.recheck_due(&out.flags) {
            let placed = self.recheck(problem);
            let digits = self.refine_digits(problem);
            if digits.is_some() {
                problem.clear_history();
            }
            if let Some(better) = digits.or(placed) {
                // A new placement, as after the window's re-initialization.
                out.flags.push("reinitialized");
                self.failed_run = 0;
                stats = better;
            }
        }
        if out.flags.contains(&"reinitialized") {
            self.scores.clear();
            self.candidate = None;
        } else if let Some(better) = self.confirm_digits(problem, &stats) {
            out.flags.push("reinitialized");
            self.failed_run = 0;
            stats = better;
        }
        if stats.failed {
            out.flags.push("lost");
        } else {
            self.scores.push(stats.score());
            self.fitted.values.clone_from(&self.pose.values);
            self.has_fitted = true;
        }
        out.stats = Some(stats);
        self.initialized = true;
        out
    }

    /// Solve from the current pose (when initialized) and every hypothesis, keep the best by
    /// [`FrameStats::score`]; the problem is left refreshed at the chosen pose. The current
    /// pose is always a candidate, so this never makes the fit worse by that measure. The
    /// backup hypotheses are solved only when the best of the others is a poor placement
    /// ([`FrameStats::is_poor_placement`]), and replace it only with one that is not.
    fn reinitialize(&mut self, problem: &mut impl TrackingProblem) {
        problem.clear_history();
        self.recheck_in = Some(RECHECK_FRAMES);
        let current = self.initialized.then(|| Hypothesis {
            pose: self.pose.clone(),
            backup: false,
        });
        let starts: Vec<_> = current.into_iter().chain(problem.hypotheses()).collect();
        let best = self.place(problem, starts, |p, pose| p.solve(pose));
        self.pose = best.map_or_else(|| self.fallback.clone(), |(_, p, _)| p);
        // Leave the problem at the chosen pose for the frame statistics.
        let _ = problem.refresh(&self.pose);
    }

    /// Counts down to the second look at the last placement; true on the frame it is due
    /// (not one that re-initialized already).
    fn recheck_due(&mut self, flags: &[&str]) -> bool {
        let Some(n) = self.recheck_in.as_mut() else {
            return false;
        };
        if flags.contains(&"reinitialized") {
            return false;
        }
        *n = n.saturating_sub(1);
        let due = *n == 0;
        if due {
            self.recheck_in = None;
        }
        due
    }

    /// The second look at a placement: the hypotheses solved aside
    /// ([`TrackingProblem::solve_aside`]) against the tracked pose, both judged at their
    /// refreshed correspondences. The best hypothesis replaces the pose (the history is then
    /// cleared, as on a re-initialization, and its frame statistics are returned) only when it
    /// is not a poor placement and beats the tracked pose both by [`FrameStats::score`] and by
    /// the mean distance of the points; otherwise nothing of the sequence changes.
    ///
    /// The mean distance too: on fists (ToF cold-start cuts of the `fist` motion, random
    /// subject 3) an edge-on placement won by the score alone, with less of the model outside
    /// the silhouette (0.08 against 0.13) but farther from the points (5.5 against 4.6 mm),
    /// and lost the hand that the tracked pose held (mean keypoint error 7.3 → 15.8 mm).
    fn recheck(&mut self, problem: &mut impl TrackingProblem) -> Option<FrameStats> {
        if !problem.refresh(&self.pose) {
            return None;
        }
        let tracked = problem.frame_stats(&self.loss);
        let starts = problem.hypotheses();
        let (score, pose, poor) = self.place(problem, starts, |p, pose| p.solve_aside(pose))?;
        if poor || score >= tracked.score() || !problem.refresh(&pose) {
            return None;
        }
        let stats = problem.frame_stats(&self.loss);
        if stats.mean_distance >= tracked.mean_distance {
            return None;
        }
        self.pose = pose;
        problem.clear_history();
        Some(stats)
    }

    /// The digit search (at the second look, or triggered by a jump of the score): each digit
    /// in turn set to each of its flexion variants ([`TrackingProblem::digit_variants`]) of the
    /// current pose and solved aside; a variant that is not a poor placement and beats the
    /// current pose both by [`FrameStats::score`] and by the points' mean distance (the pose as
    /// tracked and solved once more aside, see [`Self::lower_bar`]) replaces it, and the next
    /// digit starts from there. The problem is left at the chosen pose; the statistics are
    /// returned when the pose changed (the caller clears the history).
    fn refine_digits(&mut self, problem: &mut impl TrackingProblem) -> Option<FrameStats> {
        if !problem.refresh(&self.pose) {
            return None;
        }
        let tracked = problem.frame_stats(&self.loss);
        let mut bar = (tracked.score(), tracked.mean_distance);
        let beats = |s: &FrameStats, bar: (f64, f64)| s.score() < bar.0 && s.mean_distance < bar.1;
        let mut resolved = false;
        let mut best = None;
        for digit in 0..super::DIGITS {
            for mut pose in problem.digit_variants(&self.pose, digit) {
                if !problem.solve_aside(&mut pose) || !problem.refresh(&pose) {
                    continue;
                }
                let stats = problem.frame_stats(&self.loss);
                if problem.is_poor_placement(&stats) || !beats(&stats, bar) {
                    continue;
                }
                // Before the first win, the bar becomes the better (by each measure) of the
                // tracked pose and that pose solved aside as the variants are: a pose still
                // converging (a hand recovering from a failure) would otherwise lose to a
                // variant by the variant's extra solve alone.
                if !resolved {
                    resolved = true;
                    self.lower_bar(problem, &self.pose.clone(), &mut bar);
                    if !beats(&stats, bar) {
                        continue;
                    }
                }
                self.pose = pose;
                bar = (stats.score(), stats.mean_distance);
                best = Some(stats);
            }
        }
        if !problem.refresh(&self.pose) {
            return None;
        }
        best
    }

    /// Lower `bar` (score, mean distance) to those of `pose` solved aside, by each measure
    /// where it does better.
    fn lower_bar(&self, problem: &mut impl TrackingProblem, pose: &Pose, bar: &mut (f64, f64)) {
        let mut again = pose.clone();
        if problem.solve_aside(&mut again) && problem.refresh(&again) {
            let s = problem.frame_stats(&self.loss);
            *bar = (bar.0.min(s.score()), bar.1.min(s.mean_distance));
        }
    }

    /// The digit search during tracking, confirmed: a frame that triggers it
    /// ([`ScoreTrigger`]) makes the search's better pose a candidate, which replaces the
    /// tracked pose (its statistics returned, the history cleared) only once it has also
    /// fitted the next [`CONFIRM_FRAMES`] − 1 frames better ([`Self::challenge`]); one frame
    /// where it does not drops it. The problem is left at the pose kept.
    fn confirm_digits(
        &mut self,
        problem: &mut impl TrackingProblem,
        stats: &FrameStats,
    ) -> Option<FrameStats> {
        let tracked = self.pose.clone();
        // Both ways leave the problem at the candidate.
        let (candidate, at_candidate, wins) = match self.candidate.take() {
            Some((c, wins)) => {
                let (pose, s) = self.challenge(problem, &tracked, c)?;
                (pose, s, wins + 1)
            }
            None => {
                if !self.scores.triggers(stats.score()) {
                    return None;
                }
                let s = self.refine_digits(problem)?;
                (std::mem::replace(&mut self.pose, tracked), s, 1)
            }
        };
        if wins < CONFIRM_FRAMES {
            self.candidate = Some((candidate, wins));
            let _ = problem.refresh(&self.pose);
            return None;
        }
        self.pose = candidate;
        problem.clear_history();
        Some(at_candidate)
    }

    /// Whether `candidate` (a pose the digit search found on an earlier frame), solved aside
    /// on the frame the problem holds, still fits it better than `tracked` by the search's
    /// rule: not a poor placement, and better by score and by mean distance than `tracked` as
    /// it is and solved aside. Returns the solved candidate and its statistics, the problem
    /// left there, when it does; `None` leaves the problem at `tracked`. The loop's pose and
    /// the history do not change.
    pub fn challenge(
        &self,
        problem: &mut impl TrackingProblem,
        tracked: &Pose,
        mut candidate: Pose,
    ) -> Option<(Pose, FrameStats)> {
        if !problem.refresh(tracked) {
            return None;
        }
        let s = problem.frame_stats(&self.loss);
        let mut bar = (s.score(), s.mean_distance);
        self.lower_bar(problem, tracked, &mut bar);
        let won = problem.solve_aside(&mut candidate) && problem.refresh(&candidate) && {
            let s = problem.frame_stats(&self.loss);
            !problem.is_poor_placement(&s) && s.score() < bar.0 && s.mean_distance < bar.1
        };
        if !won {
            let _ = problem.refresh(tracked);
            return None;
        }
        let stats = problem.frame_stats(&self.loss);
        Some((candidate, stats))
    }

    /// The digit search of [`Self::step`] on its own, from `pose` on the frame the problem
    /// holds: the pose of a tracker that drives its own loop (online calibration) and wants
    /// its fingers looked at with a problem built for that. Returns the better pose and its
    /// statistics when a variant replaced one of its digits, and `None` (nothing better) when
    /// none did; the loop then continues from the pose returned, if any (history cleared).
    pub fn search_digits(
        &mut self,
        problem: &mut impl TrackingProblem,
        pose: Pose,
    ) -> Option<(Pose, FrameStats)> {
        self.set_pose(pose);
        let stats = self.refine_digits(problem)?;
        problem.clear_history();
        Some((self.pose.clone(), stats))
    }

    /// The best of `starts` solved by `solve` ([`Self::best_start`]) with the solves'
    /// rigid-only first iterations and, where the problem has any, without them: a better of
    /// the two placements that is not poor, or the better of two poor ones.
    ///
    /// Both ways, because neither wins everywhere (session 38). A rigid first iteration aligns
    /// the placed mean pose with the data as a whole, which holds a hand seen edge-on or
    /// turning, but on a fist it tilted the open palm to fit the curled fingers, and the joints
    /// could not undo that (the cylinders on a ToF fist seen from the back, `axis_speed` from
    /// frame 105: 29.90 mm mean keypoint error with it, 2.15 without). Without it alone, the
    /// cylinders' 74 ToF cold starts went 295.35 → 317.08 mm summed (`rotation_slow` from
    /// frame 105 11.38 → 48.35). Both ways (74 cold starts of 90 frames, mean keypoint error
    /// summed; better / worse by more than 0.05 mm):
    /// - ToF: cylinders 295.35 → 262.69 mm (10 / 3; cuts above 10 mm 6 → 3), sphere-mesh
    ///   137.39 → 134.02 (7 / 0), online calibration 145.66 → 141.28 (8 / 1);
    /// - noise-free: cylinders 302.46 → 251.09 (11 / 5; above 10 mm 7 → 5), sphere-mesh
    ///   100.48 → 95.99 (7 / 0), online calibration 102.11 → 96.04 (11 / 0);
    /// - the library's 16 ToF motions from frame 0 unchanged (cylinders 33.39 → 33.36,
    ///   sphere-mesh 19.98 → 19.99; by random subjects, cylinders 98.12 → 98.11);
    /// - the 16 structured-light motions: sphere-mesh unchanged (12.37), online calibration
    ///   13.81 → 18.40, all of it `crossing` (1.73 → 6.34): its first placement took the pose
    ///   found without the rigid iteration (0.2 → 0.4 mm at frame 0), and 490 frames later the
    ///   digit search that had recovered the crossed fingers did not fire — a fragile motion
    ///   (`honline_calib::OnlineConfig::collision_tolerance`'s docs), not a systematic loss.
    ///
    /// A placement costs twice the solves; tracked frames cost the same.
    fn place<P: TrackingProblem>(
        &self,
        problem: &mut P,
        starts: Vec<Hypothesis>,
        solve: impl Fn(&mut P, &mut Pose) -> bool,
    ) -> Option<(f64, Pose, bool)> {
        let with = self.best_start(problem, starts.clone(), &solve);
        if !problem.set_rigid_first(false) {
            problem.set_rigid_first(true);
            return with;
        }
        let without = self.best_start(problem, starts, &solve);
        problem.set_rigid_first(true);
        match (with, without) {
            (Some(a), Some(b)) => Some(if (b.2, b.0) < (a.2, a.0) { b } else { a }),
            (a, b) => a.or(b),
        }
    }

    /// The best of `starts` solved by `solve` as (score, pose, poor placement): each start
    /// solved [`PLACEMENT_SOLVES`] times in a row; the backups once, only when the best of the
    /// others is a poor placement after its first solve or after its last, and then only one
    /// that is not.
    fn best_start<P: TrackingProblem>(
        &self,
        problem: &mut P,
        starts: impl IntoIterator<Item = Hypothesis>,
        solve: &impl Fn(&mut P, &mut Pose) -> bool,
    ) -> Option<(f64, Pose, bool)> {
        let (backups, firsts): (Vec<_>, Vec<_>) = starts.into_iter().partition(|h| h.backup);
        let mut best: Option<(f64, Pose, bool)> = None;
        // The best first start after one solve: (score, poor placement).
        let mut first_look: Option<(f64, bool)> = None;
        for h in firsts {
            let mut pose = h.pose;
            if !solve(problem, &mut pose) || !problem.refresh(&pose) {
                continue;
            }
            let (s, poor) = self.judge(problem);
            if first_look.is_none_or(|b| s < b.0) {
                first_look = Some((s, poor));
            }
            let solved = (1..PLACEMENT_SOLVES).all(|_| solve(problem, &mut pose));
            if !solved || !problem.refresh(&pose) {
                continue;
            }
            let (s, poor) = self.judge(problem);
            if best.as_ref().is_none_or(|b| s < b.0) {
                best = Some((s, pose, poor));
            }
        }
        if first_look.is_some_and(|(_, poor)| !poor) && best.as_ref().is_some_and(|b| !b.2) {
            return best;
        }
        for h in backups {
            let mut pose = h.pose;
            if !solve(problem, &mut pose) || !problem.refresh(&pose) {
                continue;
            }
            let (s, poor) = self.judge(problem);
            if !poor && best.as_ref().is_none_or(|b| s < b.0) {
                best = Some((s, pose, poor));
            }
        }
        best
    }

    /// The score of the pose the problem was refreshed at, and whether it is a poor placement.
    fn judge(&self, problem: &impl TrackingProblem) -> (f64, bool) {
        let stats = problem.frame_stats(&self.loss);
        (stats.score(), problem.is_poor_placement(&stats))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1-DOF problem: the data is explained when θ is within 1 of `target`; the solve jumps
    /// to the target only from within `reach` of it, and from farther moves `step` toward it.
    struct Toy {
        target: f64,
        reach: f64,
        step: f64,
        at: f64,
        solves: usize,
        /// Of `solves`, those made aside.
        aside: usize,
        cleared: usize,
        /// Offsets from the target of the hypotheses, and whether each is a backup.
        starts: Vec<(f64, bool)>,
        /// The share of the model outside the silhouette at a pose, from its offset.
        outside: fn(f64) -> f64,
        /// Offsets from the target of digit 0's variants (the other digits have none).
        variants: Vec<f64>,
        /// With `Some`, the solves have rigid-only first iterations, and without them they
        /// reach this far instead of `reach`.
        free_reach: Option<f64>,
        /// Whether the rigid-only first iterations are on.
        rigid: bool,
    }

    impl Toy {
        fn new(target: f64, reach: f64, starts: Vec<(f64, bool)>) -> Self {
            Self {
                target,
                reach,
                step: 0.0,
                at: 0.0,
                solves: 0,
                aside: 0,
                cleared: 0,
                starts,
                outside: |_| 0.0,
                variants: Vec::new(),
                free_reach: None,
                rigid: true,
            }
        }
    }

    impl TrackingProblem for Toy {
        fn solve(&mut self, pose: &mut Pose) -> bool {
            self.solves += 1;
            let gap = self.target - pose.values[0];
            let reach = match (self.rigid, self.free_reach) {
                (false, Some(free)) => free,
                _ => self.reach,
            };
            if gap.abs() < reach {
                pose.values[0] = self.target;
            } else {
                pose.values[0] += self.step.copysign(gap);
            }
            self.at = pose.values[0];
            true
        }
        fn refresh(&mut self, pose: &Pose) -> bool {
            self.at = pose.values[0];
            true
        }
        fn frame_stats(&self, p: &LossParams) -> FrameStats {
            let d = (self.at - self.target).abs();
            FrameStats {
                outside: (self.outside)(self.at - self.target),
                ..FrameStats::from_distances(std::iter::repeat_n(Some(d), 100), p)
            }
        }
        fn hypotheses(&self) -> Vec<Hypothesis> {
            self.starts
                .iter()
                .map(|&(offset, backup)| Hypothesis {
                    pose: Pose {
                        values: vec![self.target + offset],
                    },
                    backup,
                })
                .collect()
        }
        fn set_aside(&mut self, aside: bool) {
            self.aside += usize::from(aside);
        }
        fn clear_history(&mut self) {
            self.cleared += 1;
        }
        fn set_rigid_first(&mut self, on: bool) -> bool {
            self.rigid = on;
            self.free_reach.is_some()
        }
        fn digit_variants(&self, _pose: &Pose, digit: usize) -> Vec<Pose> {
            let offsets = if digit == 0 { &self.variants[..] } else { &[] };
            offsets
                .iter()
                .map(|o| Pose {
                    values: vec![self.target + o],
                })
                .collect()
        }
    }

    #[test]
    fn loses_after_the_window_and_recovers_by_reinitializing() {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        let mut toy = Toy::new(0.0, 10.0, vec![(5.0, false)]);
        assert_eq!(fl.step(&mut toy, 10).flags, ["no_hand"]);
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert!(fl.step(&mut toy, 500).flags.is_empty());
        // The hand jumps out of the solve's reach: failed frames, then a re-initialization
        // from the hypothesis (within reach) after the window.
        toy.target = 100.0;
        toy.reach = 6.0;
        let window = fl.loss().window;
        for _ in 0..window - 1 {
            assert_eq!(fl.step(&mut toy, 500).flags, ["lost"]);
        }
        let last = fl.step(&mut toy, 500);
        assert_eq!(last.flags, ["reinitialized"]);
        assert_eq!(fl.pose.values[0], 100.0);
        assert!(toy.cleared >= 2);
    }

    /// Where the solves have rigid-only first iterations, placements are solved with and
    /// without them and the better wins, whichever way it was found; the solves are left
    /// with them on. Without such iterations each start is solved one way only.
    #[test]
    fn placements_are_solved_with_and_without_the_rigid_first_iterations() {
        for (reach, free_reach) in [(6.0, Some(10.0)), (10.0, Some(6.0)), (10.0, None)] {
            // From 8 off the target, only the solves that reach 10 place the hand.
            let mut toy = Toy::new(0.0, reach, vec![(8.0, false)]);
            toy.free_reach = free_reach;
            let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
            let ways = if free_reach.is_some() { 2 } else { 1 };
            assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
            assert_eq!(fl.pose.values[0], 0.0, "{reach} {free_reach:?}");
            assert!(toy.rigid);
            assert_eq!(toy.solves, ways * PLACEMENT_SOLVES);
        }
    }

    /// A backup start is solved only when the other starts leave a poor placement, and then
    /// wins when it fits better.
    #[test]
    fn backups_are_tried_only_after_a_poor_placement() {
        let mut toy = Toy::new(0.0, 6.0, vec![(5.0, false), (3.0, true)]);
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(
            toy.solves, PLACEMENT_SOLVES,
            "the first start placed the hand: no backup solved"
        );
        // Out of the first start's reach, within the backup's.
        toy.starts = vec![(8.0, false), (3.0, true)];
        toy.solves = 0;
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!((toy.solves, fl.pose.values[0]), (PLACEMENT_SOLVES + 1, 0.0));
        // Both out of reach: the backup fits a little better but poorly too, and is not taken.
        toy.starts = vec![(8.0, false), (7.0, true)];
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        fl.step(&mut toy, 500);
        assert_eq!(fl.pose.values[0], 8.0);
    }

    /// A start that one solve leaves short of the hand is solved [`PLACEMENT_SOLVES`] times;
    /// whether the backups are needed is judged after its first solve and after its last, so
    /// that a start the further solves bring out of its poor placement, not onto the hand,
    /// does not shut out a backup that fits, nor one they bring into a poor placement.
    #[test]
    fn a_placement_is_solved_until_it_arrives() {
        let mut toy = Toy::new(0.0, 0.5, vec![(2.2, false)]);
        toy.step = 1.0;
        let mut fl = FrameLoop::new(Pose { values: vec![9.0] }, LossParams::default());
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!((toy.solves, fl.pose.values[0]), (PLACEMENT_SOLVES, 0.0));
        // Poor after one solve (far outside), no longer poor but 1 off after three.
        toy.starts = vec![(4.0, false), (0.3, true)];
        toy.outside = |offset| if offset.abs() > 2.5 { 0.3 } else { 0.0 };
        toy.solves = 0;
        let mut fl = FrameLoop::new(Pose { values: vec![9.0] }, LossParams::default());
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!((toy.solves, fl.pose.values[0]), (PLACEMENT_SOLVES + 1, 0.0));
        // Not poor after one solve, poor after the last (0.8 off): the backup is solved too.
        toy.starts = vec![(3.8, false), (0.3, true)];
        toy.outside = |offset| {
            if (0.5..1.5).contains(&offset.abs()) {
                0.3
            } else {
                0.0
            }
        };
        toy.solves = 0;
        let mut fl = FrameLoop::new(Pose { values: vec![9.0] }, LossParams::default());
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!((toy.solves, fl.pose.values[0]), (PLACEMENT_SOLVES + 1, 0.0));
    }

    /// A frame without a hand reports the last pose that fitted, not the pose of a failed
    /// re-initialization before it (a patch of background taken for the hand).
    #[test]
    fn no_hand_reports_the_last_fitted_pose() {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        let mut toy = Toy::new(3.0, 10.0, vec![(1.0, false)]);
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(fl.step(&mut toy, 10).flags, ["no_hand"]);
        assert_eq!(fl.pose.values[0], 3.0);
        // Background far from any start: the re-initialization fails.
        toy.target = 300.0;
        toy.reach = 1.0;
        toy.starts = vec![(50.0, false)];
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized", "lost"]);
        assert_eq!(fl.pose.values[0], 350.0);
        assert_eq!(fl.step(&mut toy, 10).flags, ["no_hand"]);
        assert_eq!(
            fl.pose.values[0], 3.0,
            "the last fitted pose, not the failed one"
        );
    }

    /// A placement made on part of the hand (a poor start that still explains the data well
    /// enough not to be lost) is looked at again [`RECHECK_FRAMES`] frames later: a start that
    /// now fits better wins, one that does not leaves no trace.
    #[test]
    fn a_placement_is_looked_at_again() {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        let mut toy = Toy::new(0.0, 3.0, vec![(4.0, false)]);
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(fl.pose.values[0], 4.0, "out of the solve's reach, not lost");
        // Another start that fits worse than the tracked pose: nothing changes.
        toy.starts = vec![(5.0, false)];
        let cleared = toy.cleared;
        for _ in 0..RECHECK_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty());
            assert_eq!(fl.pose.values[0], 4.0);
        }
        assert_eq!(
            (toy.aside, toy.cleared),
            (PLACEMENT_SOLVES, cleared),
            "looked at once, aside"
        );
        // After the next placement, a start within reach wins on the tenth frame.
        fl.set_pose(Pose { values: vec![4.0] });
        fl.initialized = false;
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        toy.starts = vec![(1.0, false)];
        for _ in 1..RECHECK_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty());
        }
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(fl.pose.values[0], 0.0);
        assert_eq!(
            toy.cleared,
            cleared + 2,
            "the history is cleared when a start wins"
        );
        // Once only: the next frames track.
        toy.starts = vec![(-1.0, false)];
        let aside = toy.aside;
        for _ in 0..2 * RECHECK_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty());
        }
        assert_eq!(toy.aside, aside);
    }

    /// The second look replaces the tracked pose only with a start that is nearer the points
    /// too, not one that wins by the score's share of the model outside the silhouette alone.
    #[test]
    fn a_second_look_needs_nearer_points() {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        // The tracked pose (offset 2) sticks out of the silhouette; a start at offset 3 does
        // not: a better score, farther points.
        let mut toy = Toy::new(0.0, 0.5, vec![(2.0, false)]);
        toy.outside = |offset| if offset < 2.5 { 0.1 } else { 0.0 };
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        toy.starts = vec![(3.0, false)];
        for _ in 0..RECHECK_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty());
            assert_eq!(fl.pose.values[0], 2.0);
        }
        assert_eq!(toy.aside, PLACEMENT_SOLVES, "looked at, and kept");
    }

    /// At the second look, a digit variant of the tracked pose that the solve takes to a
    /// better fit replaces it (flag `reinitialized`, the history cleared); one that fits worse
    /// leaves no trace.
    #[test]
    fn a_digit_variant_that_fits_better_replaces_the_tracked_pose() {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        let mut toy = Toy::new(0.0, 3.0, vec![(4.0, false)]);
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(fl.pose.values[0], 4.0);
        // The placement's start stays out of reach; a variant within reach.
        toy.variants = vec![5.0, 2.0];
        let cleared = toy.cleared;
        for _ in 1..RECHECK_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty());
        }
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(fl.pose.values[0], 0.0);
        assert_eq!(
            toy.aside,
            PLACEMENT_SOLVES + 3,
            "the start, both variants and the tracked pose once more, aside"
        );
        assert_eq!(toy.cleared, cleared + 1);
        // A variant that fits worse: the tracked pose stays, the history too.
        fl.set_pose(Pose { values: vec![4.0] });
        fl.initialized = false;
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        toy.variants = vec![6.0];
        let cleared = toy.cleared;
        for _ in 0..RECHECK_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty());
            assert_eq!(fl.pose.values[0], 4.0);
        }
        assert_eq!(toy.cleared, cleared);
    }

    /// A loop that has tracked the toy at its target for a whole score window, the toy's
    /// digit variant 0.2 from the target, its solve reaching 0.5.
    fn tracked_a_window() -> (FrameLoop, Toy) {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        let mut toy = Toy::new(0.0, 0.5, vec![(0.2, false)]);
        toy.variants = vec![0.2];
        for _ in 0..SCORE_WINDOW {
            fl.step(&mut toy, 500);
        }
        (fl, toy)
    }

    /// A tracked frame that fits much worse than the recent ones triggers the digit search;
    /// its better pose replaces the tracked one once it has fitted [`CONFIRM_FRAMES`] frames
    /// better; the next jump within the cooldown does not search.
    #[test]
    fn a_jump_of_the_score_triggers_the_digit_search() {
        let (mut fl, mut toy) = tracked_a_window();
        assert_eq!(fl.pose.values[0], 0.0);
        // The data move beyond the solve's reach: the tracked pose fits 3 mm off.
        toy.target = 3.0;
        let aside = toy.aside;
        for n in 1..CONFIRM_FRAMES {
            assert!(fl.step(&mut toy, 500).flags.is_empty(), "frame {n}");
            assert_eq!(fl.pose.values[0], 0.0, "a candidate, not yet confirmed");
        }
        assert_eq!(fl.step(&mut toy, 500).flags, ["reinitialized"]);
        assert_eq!(fl.pose.values[0], 3.0, "the variant near the data won");
        // Each frame: the candidate (the variant) and the tracked pose, solved aside.
        assert_eq!(toy.aside, aside + 2 * CONFIRM_FRAMES);
        // Again, within the cooldown: no search, the pose stays off.
        toy.target = 6.0;
        assert!(fl.step(&mut toy, 500).flags.is_empty());
        assert_eq!(toy.aside, aside + 2 * CONFIRM_FRAMES);
        assert_eq!(fl.pose.values[0], 3.0);
    }

    /// A lasting bad fit (a pose lost gradually) keeps triggering the search once a cooldown
    /// while its scores are held out of the window, then becomes the window's normal.
    #[test]
    fn a_lasting_bad_fit_triggers_the_search_until_it_is_held_long_enough() {
        let mut trigger = ScoreTrigger::new();
        for _ in 0..SCORE_WINDOW {
            assert!(!trigger.triggers(1.0));
            trigger.push(1.0);
        }
        let fired: Vec<usize> = (0..300)
            .filter(|_| {
                let fired = trigger.triggers(2.0);
                trigger.push(2.0);
                fired
            })
            .collect();
        assert_eq!(fired, [0, 31, 62, 93]);
        // A good fit again is not high: it resets the hold and joins the window at once.
        assert!(!trigger.triggers(1.0));
        trigger.push(1.0);
        assert_eq!(trigger.held, 0);
    }

    /// A candidate of the triggered digit search that fits the next frame worse than the
    /// tracked pose is dropped: the data jumped for one frame and came back.
    #[test]
    fn a_candidate_that_loses_a_frame_is_dropped() {
        let (mut fl, mut toy) = tracked_a_window();
        toy.target = 3.0;
        assert!(fl.step(&mut toy, 500).flags.is_empty());
        assert!(fl.candidate.is_some());
        toy.target = 0.0;
        assert!(fl.step(&mut toy, 500).flags.is_empty());
        assert!(fl.candidate.is_none());
        assert_eq!(fl.pose.values[0], 0.0);
    }

    /// [`FrameLoop::search_digits`] on its own: a variant that fits better than the tracked
    /// pose replaces it only when it also beats that pose solved once more, so a pose still
    /// converging is not taken over by a variant's extra solve.
    #[test]
    fn a_variant_must_beat_the_tracked_pose_solved_again() {
        let mut fl = FrameLoop::new(Pose { values: vec![0.0] }, LossParams::default());
        let mut toy = Toy::new(0.0, 3.0, Vec::new());
        toy.variants = vec![0.2];
        // Within the solve's reach of the data: solved again, the tracked pose fits as well.
        assert_eq!(fl.search_digits(&mut toy, Pose { values: vec![1.5] }), None);
        assert_eq!(fl.pose.values[0], 1.5);
        assert_eq!(toy.aside, 2);
        // Out of it: the variant wins.
        toy.reach = 1.0;
        let (pose, stats) = fl
            .search_digits(&mut toy, Pose { values: vec![1.5] })
            .expect("the variant fits better");
        assert_eq!((pose.values[0], fl.pose.values[0]), (0.0, 0.0));
        assert_eq!(stats.mean_distance, 0.0);
        assert_eq!(toy.cleared, 1);
    }
}
