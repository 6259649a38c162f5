//! Hand shapes of synthetic subjects: honline β vectors over the default template.
//!
//! A [`Subject`] is a name and a β vector of [`ShapeBasis::honline`] over
//! `hand_model::spheremesh::default_right_hand` (75 entries: phalanx lengths, finger bases, palm
//! centers, radii; see ANCHOR-FACTS §2.5). Shapes are built from the 3-dof latent anisotropic
//! scale of thesis Eq. 4.14 (`β = β̄ ∘ I·β̃`, β̃ = (height, width, thickness)) plus documented
//! per-parameter tweaks.
//!
//! # Named subjects
//! | name | latent (h, w, t) | tweak | hand length (mm) |
//! |---|---|---|---|
//! | `default` | (1, 1, 1) | — (the template) | 166.6 |
//! | `small` | (0.92, 0.90, 0.92) | — | 154.1 |
//! | `large` | (1.12, 1.10, 1.10) | — | 185.3 |
//! | `long_fingers` | (1, 1, 1) | phalanx lengths × 1.12 | 177.4 |
//! | `short_fingers` | (1, 1, 1) | phalanx lengths × 0.90 | 157.7 |
//! | `wide_palm` | (1, 1.12, 1) | palm radii × 1.05 | 166.7 |
//! | `narrow` | (1, 0.90, 0.95) | — | 166.3 |
//! | `thick` | (1, 1, 1.15) | — (all radii and base depths × 1.15) | 167.6 |
//! | `slender` | (1.02, 0.95, 0.88) | — | 168.8 |
//!
//! "Phalanx lengths" are the `*_length` entries of the five digits (kinds `PhalangeLength` and
//! `TopPhalangeLength`, the thumb membrane excluded); "palm radii" the `palm_*_radius` entries.
//! The hand length is the distance from the wrist keypoint to the middle fingertip keypoint at
//! rest (the test `every_named_subject_applies_and_is_adult_sized` prints it). The small
//! subject is 0.92 rather than 0.85 of the template because the template is already a
//! small-average hand (166.6 mm): 0.85 would leave the adult range.
//!
//! # Random subjects
//! [`Subject::random`] draws, from a `ChaCha8Rng` seeded by the seed: the latent scale
//! uniformly in [`LATENT_RANGES`] (height 0.85–1.15, width 0.85–1.15, thickness 0.85–1.2), then
//! an independent factor `1 + U(−p, p)` per β entry (p = `max_perturbation`), clamped to the β
//! bounds of `ShapeKind::default_limits`. A draw is rejected and redrawn (same generator, so
//! still deterministic) when `ShapeBasis::apply` refuses it or when its hand length leaves
//! [`HAND_LENGTH_RANGE`]; in effect the height stays above ≈ 0.9.

use hand_model::kinematics::Pose;
use hand_model::spheremesh::{PosedSphereMesh, ShapeBasis, ShapeKind, SphereMeshTemplate};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::default_template;
use crate::error::{DatasetError, Result};

/// Ranges of the latent scale (height, width, thickness) of random subjects.
pub const LATENT_RANGES: [[f64; 2]; 3] = [[0.85, 1.15], [0.85, 1.15], [0.85, 1.2]];

/// The realistic adult range of the hand length (wrist keypoint to middle fingertip, mm).
pub const HAND_LENGTH_RANGE: [f64; 2] = [150.0, 215.0];

/// The default per-parameter perturbation of `--subject random` (±6 %).
pub const DEFAULT_PERTURBATION: f64 = 0.06;

/// The largest per-parameter perturbation [`Subject::random`] accepts.
pub const MAX_PERTURBATION: f64 = 0.25;

/// Mixed into the seed so that a subject and a motion drawn from the same seed are independent.
const SUBJECT_SALT: u64 = 0x9E37_79B9_7F4A_7C15;

/// Named subjects, in table order.
const NAMES: [&str; 9] = [
    "default",
    "small",
    "large",
    "long_fingers",
    "short_fingers",
    "wide_palm",
    "narrow",
    "thick",
    "slender",
];

/// A synthetic subject: a hand shape as an honline β vector over the default template.
#[derive(Clone, Debug, PartialEq)]
pub struct Subject {
    /// Name (`default`, `small`, … or `random-<seed>`).
    pub name: String,
    /// β, one value per entry of [`ShapeBasis::honline`] of the default template (mm).
    pub beta: Vec<f64>,
}

/// The honline basis of the default template.
fn basis() -> Result<ShapeBasis> {
    Ok(ShapeBasis::honline(default_template())?)
}

fn is_phalanx_length(name: &str, kind: ShapeKind) -> bool {
    matches!(
        kind,
        ShapeKind::PhalangeLength | ShapeKind::TopPhalangeLength
    ) && name != "thumb_membrane_length"
}

impl Subject {
    /// The names of the fixed subjects.
    pub fn names() -> &'static [&'static str] {
        &NAMES
    }

    /// A fixed named subject (see the module table); unknown names are an error.
    pub fn named(name: &str) -> Result<Subject> {
        let basis = basis()?;
        let (latent, phalanx, palm_radius) = match name {
            "default" => ([1.0, 1.0, 1.0], 1.0, 1.0),
            "small" => ([0.92, 0.90, 0.92], 1.0, 1.0),
            "large" => ([1.12, 1.10, 1.10], 1.0, 1.0),
            "long_fingers" => ([1.0, 1.0, 1.0], 1.12, 1.0),
            "short_fingers" => ([1.0, 1.0, 1.0], 0.90, 1.0),
            "wide_palm" => ([1.0, 1.12, 1.0], 1.0, 1.05),
            "narrow" => ([1.0, 0.90, 0.95], 1.0, 1.0),
            "thick" => ([1.0, 1.0, 1.15], 1.0, 1.0),
            "slender" => ([1.02, 0.95, 0.88], 1.0, 1.0),
            _ => {
                return Err(DatasetError::UnknownSubject {
                    name: name.into(),
                    known: format!("{}, random", NAMES.join(", ")),
                })
            }
        };
        let mut beta = basis.from_latent(latent);
        for (b, p) in beta.iter_mut().zip(&basis.params) {
            if is_phalanx_length(&p.name, p.kind) {
                *b *= phalanx;
            }
            if p.name.starts_with("palm_") && p.kind == ShapeKind::Radius {
                *b *= palm_radius;
            }
        }
        Ok(Subject {
            name: name.into(),
            beta,
        })
    }

    /// A random subject drawn from `seed` (see the module docs). `max_perturbation` is the
    /// relative per-parameter perturbation, in `[0, MAX_PERTURBATION]`; anything else is refused.
    pub fn random(seed: u64, max_perturbation: f64) -> Result<Subject> {
        if !(max_perturbation.is_finite() && (0.0..=MAX_PERTURBATION).contains(&max_perturbation)) {
            return Err(DatasetError::arg(
                "max_perturbation",
                format!("must lie in [0, {MAX_PERTURBATION}], got {max_perturbation}"),
            ));
        }
        let basis = basis()?;
        let template = default_template();
        // Salted so that subject and motion drawn from the same seed are independent.
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ SUBJECT_SALT);
        let name = format!("random-{seed}");
        for _ in 0..256 {
            let mut latent = [1.0; 3];
            for (l, [lo, hi]) in latent.iter_mut().zip(LATENT_RANGES) {
                *l = rng.random_range(lo..=hi);
            }
            let mut beta = basis.from_latent(latent);
            for (b, p) in beta.iter_mut().zip(&basis.params) {
                let f = if max_perturbation > 0.0 {
                    1.0 + rng.random_range(-max_perturbation..=max_perturbation)
                } else {
                    1.0
                };
                *b *= f;
                if let Some([lo, hi]) = p.limits {
                    *b = b.clamp(lo, hi);
                }
            }
            let Ok(shaped) = basis.apply(template, &beta) else {
                continue;
            };
            let len = hand_length(&shaped);
            if (HAND_LENGTH_RANGE[0]..=HAND_LENGTH_RANGE[1]).contains(&len) {
                return Ok(Subject { name, beta });
            }
        }
        // Practically unreachable: fall back to the template itself.
        Ok(Subject {
            name,
            beta: basis.template_values(),
        })
    }

    /// The default template reshaped to this subject's β.
    pub fn template(&self) -> Result<SphereMeshTemplate> {
        let basis = basis()?;
        let mut t = basis.apply(default_template(), &self.beta)?;
        t.name = format!("{} ({})", default_template().name, self.name);
        Ok(t)
    }

    /// `(parameter name, value)` pairs: the `shape` object of DESIGN.md's ground-truth files.
    pub fn shape_named(&self) -> Result<Vec<(String, f64)>> {
        let basis = basis()?;
        if basis.len() != self.beta.len() {
            return Err(DatasetError::arg(
                "beta",
                format!("{} values for {} parameters", self.beta.len(), basis.len()),
            ));
        }
        Ok(basis
            .names()
            .map(String::from)
            .zip(self.beta.iter().copied())
            .collect())
    }

    /// The hand length of the reshaped template: wrist keypoint to middle fingertip at rest (mm).
    pub fn hand_length(&self) -> Result<f64> {
        Ok(hand_length(&self.template()?))
    }
}

/// Wrist keypoint to middle fingertip keypoint of a template at rest (mm).
pub fn hand_length(template: &SphereMeshTemplate) -> f64 {
    let posed = PosedSphereMesh::new(template, &Pose::zeros(&template.skeleton));
    let k = posed.keypoints(template);
    (k[12] - k[0]).norm()
}

/// `--subject <name|random>`: a named subject, or `random` drawn from `seed` with
/// [`DEFAULT_PERTURBATION`]. Unknown names are an error listing the known ones.
pub fn subject_by_name(name: &str, seed: u64) -> Result<Subject> {
    if name == "random" {
        Subject::random(seed, DEFAULT_PERTURBATION)
    } else {
        Subject::named(name)
    }
}
