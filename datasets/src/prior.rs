//! The pose corpus and the project's own PCA pose prior (thesis §2.3.2 "Pose Space Prior",
//! Eq. 2.5–2.6; Fig. 2.10).
//!
//! The corpus holds 20-vectors of digit angles ([`DIGIT_DOFS`] order, rad, our conventions):
//! - **authored**: the 14 key poses of [`KeyPose::ALL`] and every motion of the
//!   [`MotionLibrary`] at seed 0 sampled at [`CORPUS_FPS`] (the motions blend the key poses
//!   with jitter, stagger and oscillations, so they fill the space between them);
//! - **recorded** (when available): the 2336 poses of the RealSense `animbank.pose`,
//!   retargeted by [`Retargeter`] and clamped to the default template's joint limits.
//!
//! [`build_project_prior`] fits [`PcaPrior::fit`] with htrack's grouping ([`htrack_groups`]),
//! all components kept. The committed `hand-model/data/pose-prior.json`
//! ([`PcaPrior::project_default`]) is its output; regenerate it from the repository root with
//!
//! ```text
//! cargo run --release -p tools -- prior build \
//!     --animbank ../shared/reference/pose-corpus-realsense/animbank.pose \
//!     --out hand-model/data/pose-prior.json
//! ```

use std::path::Path;

use hand_model::kinematics::names::DIGIT_DOFS;
use hand_model::solver::{htrack_groups, PcaPrior, HTRACK_LATENT_DIMS};

use crate::animbank::{read_animbank, AnimbankPose, Retargeter};
use crate::error::Result;
use crate::motion::{KeyPose, MotionLibrary};

/// Sampling rate of the library motions in the corpus (Hz).
pub const CORPUS_FPS: f64 = 10.0;

/// Seed of the library motions in the corpus.
pub const CORPUS_SEED: u64 = 0;

/// Index of the first digit DOF in an [`crate::motion::Articulation`] (after the two wrist DOFs).
const FIRST_DIGIT: usize = 2;

/// A pose corpus: digit-angle samples and where they came from.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseCorpus {
    /// The samples ([`DIGIT_DOFS`] order, rad).
    pub samples: Vec<Vec<f64>>,
    /// How many come from the key poses and the motion library (the first ones).
    pub authored: usize,
    /// How many are retargeted recorded poses (the last ones).
    pub recorded: usize,
}

/// The 20 digit angles of a key pose.
pub fn key_pose_digits(k: KeyPose) -> Vec<f64> {
    k.articulation().0[FIRST_DIGIT..].to_vec()
}

/// The authored samples: the key poses, then every library motion (seed [`CORPUS_SEED`])
/// sampled at [`CORPUS_FPS`].
pub fn authored_samples() -> Result<Vec<Vec<f64>>> {
    let mut out: Vec<Vec<f64>> = KeyPose::ALL.into_iter().map(key_pose_digits).collect();
    for name in MotionLibrary::names() {
        let m = MotionLibrary::by_name(name, CORPUS_SEED)?;
        for i in 0..m.num_frames(CORPUS_FPS) {
            let a = m.articulation_at(i as f64 / CORPUS_FPS);
            out.push(a.0[FIRST_DIGIT..].to_vec());
        }
    }
    Ok(out)
}

/// The corpus: [`authored_samples`], then `recorded` poses retargeted to the default template
/// and clamped to its limits.
pub fn pose_corpus(recorded: &[AnimbankPose]) -> Result<PoseCorpus> {
    let mut samples = authored_samples()?;
    let authored = samples.len();
    let r = Retargeter::default_template();
    samples.extend(recorded.iter().map(|p| r.retarget_clamped(p).to_vec()));
    Ok(PoseCorpus {
        samples,
        authored,
        recorded: recorded.len(),
    })
}

/// Fit the project prior to a corpus (htrack grouping, all components kept).
pub fn fit_prior(corpus: &PoseCorpus) -> Result<PcaPrior> {
    Ok(PcaPrior::fit(
        &htrack_groups(),
        &DIGIT_DOFS,
        &corpus.samples,
    )?)
}

/// The project prior with its file description: the corpus of [`pose_corpus`] with the
/// animbank file at `animbank` when given (an unreadable file is an error).
pub fn build_project_prior(animbank: Option<&Path>) -> Result<(PcaPrior, String)> {
    let recorded = match animbank {
        Some(p) => read_animbank(p)?,
        None => vec![],
    };
    let corpus = pose_corpus(&recorded)?;
    let prior = fit_prior(&corpus)?;
    let explained: Vec<String> = prior
        .groups
        .iter()
        .map(|g| {
            format!(
                "{} {:.1} %",
                g.name,
                100.0 * g.explained_variance(HTRACK_LATENT_DIMS)
            )
        })
        .collect();
    let description = format!(
        "Project pose prior (thesis §2.3.2), fitted by `hands prior build`: {} samples = {} \
         authored ({} key poses + {} library motions at {} Hz, seed {}) + {} RealSense \
         animbank poses retargeted to the default template and clamped to its limits. \
         Variance explained by {} components: {}.",
        corpus.samples.len(),
        corpus.authored,
        KeyPose::ALL.len(),
        MotionLibrary::names().len(),
        CORPUS_FPS,
        CORPUS_SEED,
        corpus.recorded,
        HTRACK_LATENT_DIMS,
        explained.join(", ")
    );
    Ok((prior, description))
}
