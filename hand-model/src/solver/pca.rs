//! Pose-space PCA data (thesis §2.3.2 "Pose Space Prior", Fig. 2.10) and the loader of the
//! original binary files (ANCHOR-FACTS §4).
//!
//! # File format (htrack `Eigen::read_binary`)
//! Little-endian. A matrix is `int64 rows, int64 cols`, then `rows·cols` `float32` in
//! column-major order; a vector is `int64 length`, then `length` `float32`. A prior directory
//! holds `mu` (the 20-vector mean), `thumb/P`, `thumb/Sigma`, `fingers/P`, `fingers/Sigma`
//! (and unused `Limits`, htrack's joint 20×20 `P`/`Sigma`). `P` has orthonormal principal
//! directions as columns; `Sigma` is `diag(variances)` of the latent coordinates.
//!
//! # What the 20 entries index
//! `y = θ[9..29) − μ` of the originals' pose vector: thumb `[abd, flex1, flex2, flex3]`, then
//! index, middle, ring, pinky, each `[abd, flex1, flex2, flex3]`; `thumb/` acts on `y[0..4)`,
//! `fingers/` on `y[4..20)`.
//!
//! # Conventions
//! A [`PcaPrior`] is stored in **this crate's** conventions, with DOF names, so it maps onto
//! any skeleton that has those DOFs (the cylinder model and the sphere-mesh templates both do).
//! - **htrack** (`htrack-pose-space-pca`): negative flexion toward the palm and positive
//!   abduction toward the little finger — the opposite of ours on every articulation DOF. The
//!   loader maps entry `i` to [`crate::cylinder::HTRACK_THETA_LAYOUT`]`[6 + i]` (our name,
//!   sign −1): `μ ← −μ`, rows of `P` negated (`P ← S·P`, `S = −I`, still orthonormal), variances
//!   unchanged. So `thumb_cmc_abd, thumb_cmc_flex, thumb_mcp_flex, thumb_ip_flex,
//!   index_mcp_abd, index_mcp_flex, index_pip_flex, index_dip_flex, middle_…, ring_…, pinky_…`
//!   ← `−htrack[9..29)`. (The abduction sign follows the htrack importer of
//!   [`crate::cylinder`]; the flexion sign is the documented negative-flexion convention.)
//! - **hmodel/honline** (`hmodel-pose-space`): positive flexion, same signs as ours; names from
//!   [`crate::spheremesh::HONLINE_THETA_DOFS`]`[9..29)`, sign +1.
//!
//! The priors were learned on the originals' skeletons, whose rest frames differ from ours; a
//! prior transfers as "the same joint angles are likely", not as identical geometry.
//!
//! # The project's own prior
//! [`PcaPrior::fit`] learns a prior from pose samples (mean, eigen-decomposition of the sample
//! covariance, components sorted by decreasing variance). The project's prior,
//! [`PcaPrior::project_default`], is fitted by the project's own code on its pose corpus (the
//! authored key poses and motions of `datasets::motion`, plus the recorded RealSense poses
//! retargeted to our skeleton, see `datasets::animbank`) with htrack's grouping (thumb 4 DOFs,
//! fingers 16 DOFs, [`htrack_groups`]); all components are kept so users can truncate (htrack
//! uses 3 + 3, [`HTRACK_LATENT_DIMS`]). It is the committed file `hand-model/data/pose-prior.json`,
//! regenerated from the repository root by
//!
//! ```text
//! cargo run --release -p tools -- prior build \
//!     --animbank ../shared/reference/pose-corpus-realsense/animbank.pose \
//!     --out hand-model/data/pose-prior.json
//! ```
//!
//! (the test `committed_prior_is_reproducible` of `datasets` checks that this reproduces the
//! committed file within 1e-9 when the corpus is present).
//!
//! # JSON file format ([`PCA_PRIOR_FORMAT`], version [`PCA_PRIOR_VERSION`])
//! ```json
//! { "format": "hands-pca-prior", "version": 1,
//!   "description": "free text: corpus, sample count, command",
//!   "groups": [ { "name": "thumb",
//!                 "dofs": ["thumb_cmc_abd", "thumb_cmc_flex", "thumb_mcp_flex", "thumb_ip_flex"],
//!                 "mean": [4 values, rad],
//!                 "variances": [m values, rad², decreasing],
//!                 "components": [m principal directions, each 4 values, unit length] },
//!               { "name": "fingers", "dofs": [16 names], ... } ] }
//! ```
//! Our conventions (positive flexion toward the palm); unknown fields are refused; the loader
//! checks shapes, finiteness, positive variances and unique DOF names ([`PcaPrior::validate`]).

use std::path::Path;

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::cylinder::HTRACK_THETA_LAYOUT;
use crate::error::{ModelError, Result};
use crate::kinematics::names::DIGIT_DOFS;
use crate::spheremesh::HONLINE_THETA_DOFS;

/// The `format` tag of a JSON prior file.
pub const PCA_PRIOR_FORMAT: &str = "hands-pca-prior";
/// The version of the JSON prior format this crate writes and reads.
pub const PCA_PRIOR_VERSION: u32 = 1;
/// Smallest variance [`PcaPrior::fit`] stores (rad²): directions the corpus never moves along
/// (rank-deficient samples) get this floor so the prior stays invertible.
pub const PCA_VARIANCE_FLOOR: f64 = 1e-8;

/// The committed project prior (see the module docs for the command that regenerates it).
const PROJECT_PRIOR_JSON: &str = include_str!("../../data/pose-prior.json");

/// htrack's grouping in our DOF names: `thumb` = the 4 thumb DOFs, `fingers` = the 16 finger
/// DOFs ([`DIGIT_DOFS`] order).
pub fn htrack_groups() -> [(&'static str, &'static [&'static str]); 2] {
    [("thumb", &DIGIT_DOFS[..4]), ("fingers", &DIGIT_DOFS[4..])]
}

/// Latent dimensions htrack uses per group (`latent_size` 3 for thumb and fingers).
pub const HTRACK_LATENT_DIMS: usize = 3;
/// Latent dimensions hmodel/honline use per group (their files hold exactly 2).
pub const HMODEL_LATENT_DIMS: usize = 2;

/// One PCA group (thumb or fingers) over named DOFs, in this crate's sign conventions.
#[derive(Clone, Debug, PartialEq)]
pub struct PcaGroup {
    /// `"thumb"` or `"fingers"` for the original files.
    pub name: String,
    /// The k DOF names the group acts on, in the order of `mean` and of the rows of `basis`.
    pub dofs: Vec<String>,
    /// μ (k).
    pub mean: Vec<f64>,
    /// `Π_P` (k × m): principal directions as columns (orthonormal in the original data).
    pub basis: DMatrix<f64>,
    /// Variances of the m latent coordinates (the eigenvalues; Eq. 2.6's `Σ` is
    /// `diag(1/√variance)`).
    pub variances: Vec<f64>,
}

impl PcaGroup {
    /// Number of DOFs k.
    pub fn num_dofs(&self) -> usize {
        self.dofs.len()
    }

    /// Number of latent dimensions m.
    pub fn num_latent(&self) -> usize {
        self.variances.len()
    }

    /// Keep at most `m` latent dimensions (the leading columns).
    pub fn truncate(&mut self, m: usize) {
        let m = m.min(self.num_latent());
        self.basis = self.basis.columns(0, m).into_owned();
        self.variances.truncate(m);
    }

    /// Fraction of the total variance carried by the first `m` components (1 when `m` ≥ the
    /// number kept; meaningful as "variance explained" when all k components are kept).
    pub fn explained_variance(&self, m: usize) -> f64 {
        let total: f64 = self.variances.iter().sum();
        self.variances.iter().take(m).sum::<f64>() / total
    }

    /// `max |PᵀP − I|`: how far the basis is from orthonormal.
    pub fn orthonormality_error(&self) -> f64 {
        let m = self.num_latent();
        let g = self.basis.transpose() * &self.basis - DMatrix::<f64>::identity(m, m);
        g.amax()
    }
}

/// A pose-space PCA prior: independent groups over named articulation DOFs.
#[derive(Clone, Debug, PartialEq)]
pub struct PcaPrior {
    /// The groups (thumb, fingers for the original files).
    pub groups: Vec<PcaGroup>,
}

impl PcaPrior {
    /// Load an htrack prior directory (`mu`, `thumb/{P,Sigma}`, `fingers/{P,Sigma}`), converting
    /// htrack's negative-flexion convention to ours (module docs).
    pub fn load_htrack_dir(dir: &Path) -> Result<Self> {
        let map: Vec<(&str, f64)> = HTRACK_THETA_LAYOUT[6..]
            .iter()
            .map(|&(_, name, sign)| (name, sign))
            .collect();
        Self::load_dir(dir, &map)
    }

    /// Load an hmodel/honline prior directory (positive flexion: no sign change).
    pub fn load_hmodel_dir(dir: &Path) -> Result<Self> {
        let map: Vec<(&str, f64)> = HONLINE_THETA_DOFS[9..29]
            .iter()
            .map(|name| (name.unwrap_or("unused"), 1.0))
            .collect();
        Self::load_dir(dir, &map)
    }

    /// Load `dir` with the 20 entries of `mu` named and signed by `map` (`ours = sign · file`).
    fn load_dir(dir: &Path, map: &[(&str, f64)]) -> Result<Self> {
        let mu = read_htrack_vector(&dir.join("mu"))?;
        if mu.len() != map.len() {
            return Err(ModelError::field(
                dir.join("mu"),
                "length",
                None,
                format!("{} entries, expected {}", mu.len(), map.len()),
            ));
        }
        let mut groups = Vec::with_capacity(2);
        for (name, range) in [("thumb", 0..4), ("fingers", 4..20)] {
            let p_path = dir.join(name).join("P");
            let s_path = dir.join(name).join("Sigma");
            let p = read_htrack_matrix(&p_path)?;
            let s = read_htrack_matrix(&s_path)?;
            let k = range.len();
            if p.nrows() != k || p.ncols() == 0 || p.ncols() > k {
                return Err(ModelError::field(
                    &p_path,
                    "shape",
                    None,
                    format!(
                        "{}×{}, expected {k}×m with 1 ≤ m ≤ {k}",
                        p.nrows(),
                        p.ncols()
                    ),
                ));
            }
            let m = p.ncols();
            if s.nrows() < m || s.ncols() < m {
                return Err(ModelError::field(
                    &s_path,
                    "shape",
                    None,
                    format!("{}×{}, expected at least {m}×{m}", s.nrows(), s.ncols()),
                ));
            }
            let variances: Vec<f64> = (0..m).map(|i| s[(i, i)]).collect();
            let signs: Vec<f64> = map[range.clone()].iter().map(|&(_, s)| s).collect();
            let mut basis = p;
            for (i, &sg) in signs.iter().enumerate() {
                basis.row_mut(i).scale_mut(sg);
            }
            groups.push(PcaGroup {
                name: name.into(),
                dofs: map[range.clone()]
                    .iter()
                    .map(|&(n, _)| n.to_string())
                    .collect(),
                mean: range.clone().zip(&signs).map(|(i, s)| s * mu[i]).collect(),
                basis,
                variances,
            });
        }
        let prior = Self { groups };
        prior.validate(dir)?;
        Ok(prior)
    }

    /// Fit a prior to pose samples: per group, the mean and the eigen-decomposition of the
    /// sample covariance (divisor n − 1), **all** k components kept, sorted by decreasing
    /// variance; each direction's largest-magnitude entry is made positive (a deterministic
    /// sign); variances below [`PCA_VARIANCE_FLOOR`] are raised to it.
    ///
    /// `groups` = (name, DOF names) pairs, e.g. [`htrack_groups`]; every sample holds one value
    /// per entry of `dof_names` (rad). Refused: fewer than 2 samples, a sample of the wrong
    /// length or with a non-finite value, a group DOF missing from `dof_names`, repeated DOFs.
    ///
    /// ```
    /// use hand_model::solver::{htrack_groups, PcaPrior};
    /// use hand_model::kinematics::names::DIGIT_DOFS;
    /// let samples: Vec<Vec<f64>> = (0..50)
    ///     .map(|i| (0..20).map(|d| ((i * 7 + d * 3) % 11) as f64 * 0.1).collect())
    ///     .collect();
    /// let prior = PcaPrior::fit(&htrack_groups(), &DIGIT_DOFS, &samples).unwrap();
    /// assert_eq!(prior.groups[1].num_latent(), 16);
    /// assert!(prior.groups[1].variances[0] >= prior.groups[1].variances[1]);
    /// ```
    pub fn fit(
        groups: &[(&str, &[&str])],
        dof_names: &[&str],
        samples: &[Vec<f64>],
    ) -> Result<Self> {
        let bad = |reason: String| ModelError::InvalidArgument {
            name: "samples",
            reason,
        };
        if samples.len() < 2 {
            return Err(bad(format!("{} samples, need at least 2", samples.len())));
        }
        for (i, s) in samples.iter().enumerate() {
            if s.len() != dof_names.len() {
                return Err(bad(format!(
                    "sample {i} has {} values for {} DOF names",
                    s.len(),
                    dof_names.len()
                )));
            }
            if let Some(j) = s.iter().position(|v| !v.is_finite()) {
                return Err(bad(format!("sample {i}, value {j} is not finite")));
            }
        }
        let n = samples.len() as f64;
        let mut out = Vec::with_capacity(groups.len());
        for &(name, dofs) in groups {
            let idx: Vec<usize> = dofs
                .iter()
                .map(|d| {
                    dof_names.iter().position(|n| n == d).ok_or_else(|| {
                        bad(format!(
                            "group `{name}`: DOF `{d}` is not among the sample names"
                        ))
                    })
                })
                .collect::<Result<_>>()?;
            let k = idx.len();
            let mut mean = vec![0.0; k];
            for s in samples {
                for (m, &i) in mean.iter_mut().zip(&idx) {
                    *m += s[i];
                }
            }
            mean.iter_mut().for_each(|m| *m /= n);
            let mut cov = DMatrix::<f64>::zeros(k, k);
            let mut y = vec![0.0; k];
            for s in samples {
                for (a, &i) in idx.iter().enumerate() {
                    y[a] = s[i] - mean[a];
                }
                for a in 0..k {
                    for b in a..k {
                        cov[(a, b)] += y[a] * y[b];
                    }
                }
            }
            for a in 0..k {
                for b in a..k {
                    let v = cov[(a, b)] / (n - 1.0);
                    cov[(a, b)] = v;
                    cov[(b, a)] = v;
                }
            }
            let eig = SymmetricEigen::new(cov);
            let mut order: Vec<usize> = (0..k).collect();
            order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
            let mut basis = DMatrix::<f64>::zeros(k, k);
            let mut variances = Vec::with_capacity(k);
            for (c, &e) in order.iter().enumerate() {
                let mut v = eig.eigenvectors.column(e).normalize();
                let big = v.iamax();
                if v[big] < 0.0 {
                    v.neg_mut();
                }
                basis.set_column(c, &v);
                variances.push(eig.eigenvalues[e].max(PCA_VARIANCE_FLOOR));
            }
            out.push(PcaGroup {
                name: name.to_string(),
                dofs: dofs.iter().map(|d| d.to_string()).collect(),
                mean,
                basis,
                variances,
            });
        }
        let prior = Self { groups: out };
        prior.validate(Path::new("<fit>"))?;
        Ok(prior)
    }

    /// The project's own prior, fitted by the project's code on its pose corpus (module docs),
    /// all components kept (truncate with [`PcaPrior::truncated`], e.g. to
    /// [`HTRACK_LATENT_DIMS`]). Embedded from `hand-model/data/pose-prior.json`.
    pub fn project_default() -> Self {
        static PRIOR: std::sync::OnceLock<PcaPrior> = std::sync::OnceLock::new();
        PRIOR
            .get_or_init(|| {
                Self::from_json(
                    PROJECT_PRIOR_JSON,
                    Path::new("hand-model/data/pose-prior.json"),
                )
                .expect("the embedded project prior is valid")
            })
            .clone()
    }

    /// Serialize to the JSON format of the module docs (`description`: free text).
    pub fn to_json(&self, description: &str) -> String {
        let file = PriorFile {
            format: PCA_PRIOR_FORMAT.into(),
            version: PCA_PRIOR_VERSION,
            description: description.into(),
            groups: self
                .groups
                .iter()
                .map(|g| GroupFile {
                    name: g.name.clone(),
                    dofs: g.dofs.clone(),
                    mean: g.mean.clone(),
                    variances: g.variances.clone(),
                    components: g
                        .basis
                        .column_iter()
                        .map(|c| c.iter().copied().collect())
                        .collect(),
                })
                .collect(),
        };
        let mut text = serde_json::to_string_pretty(&file).expect("a prior serializes");
        text.push('\n');
        text
    }

    /// Parse the JSON format of the module docs; `source` names the data in errors.
    pub fn from_json(text: &str, source: &Path) -> Result<Self> {
        let file: PriorFile = serde_json::from_str(text).map_err(|e| ModelError::Parse {
            file: source.to_path_buf(),
            reason: format!("not a {PCA_PRIOR_FORMAT} JSON file: {e}"),
        })?;
        if file.format != PCA_PRIOR_FORMAT {
            return Err(ModelError::field(
                source,
                "format",
                None,
                format!("`{}`, expected `{PCA_PRIOR_FORMAT}`", file.format),
            ));
        }
        if file.version != PCA_PRIOR_VERSION {
            return Err(ModelError::field(
                source,
                "version",
                None,
                format!(
                    "{}, this build reads version {PCA_PRIOR_VERSION}",
                    file.version
                ),
            ));
        }
        if file.groups.is_empty() {
            return Err(ModelError::field(source, "groups", None, "no groups"));
        }
        let mut groups = Vec::with_capacity(file.groups.len());
        for (gi, g) in file.groups.into_iter().enumerate() {
            let k = g.dofs.len();
            if let Some(c) = g.components.iter().position(|c| c.len() != k) {
                return Err(ModelError::field(
                    source,
                    "groups.components",
                    Some(gi),
                    format!(
                        "component {c} has {} entries for {k} DOFs",
                        g.components[c].len()
                    ),
                ));
            }
            let m = g.components.len();
            let basis = DMatrix::from_iterator(k, m, g.components.into_iter().flatten());
            groups.push(PcaGroup {
                name: g.name,
                dofs: g.dofs,
                mean: g.mean,
                basis,
                variances: g.variances,
            });
        }
        let prior = Self { groups };
        prior.validate(source)?;
        for (gi, g) in prior.groups.iter().enumerate() {
            if g.orthonormality_error() > 1e-6 {
                return Err(ModelError::field(
                    source,
                    "groups.components",
                    Some(gi),
                    format!(
                        "group `{}`: components are not orthonormal (max |PᵀP − I| = {:.2e})",
                        g.name,
                        g.orthonormality_error()
                    ),
                ));
            }
        }
        Ok(prior)
    }

    /// Write the JSON file atomically (a temporary file in the same folder, then a rename).
    pub fn save_json(&self, path: &Path, description: &str) -> Result<()> {
        crate::spheremesh::write_atomic(path, self.to_json(description).as_bytes())
    }

    /// Read a JSON prior file ([`PcaPrior::from_json`]).
    pub fn load_json(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Self::from_json(&text, path)
    }

    /// Keep at most `m` latent dimensions per group.
    pub fn truncated(&self, m: usize) -> Self {
        let mut out = self.clone();
        out.groups.iter_mut().for_each(|g| g.truncate(m));
        out
    }

    /// Check shapes and numbers: per group k = |dofs| = |mean| = rows of P, m = cols of P =
    /// |variances| with 1 ≤ m ≤ k, unique non-empty DOF names across groups, finite values,
    /// positive variances. `source` names the data for messages.
    pub fn validate(&self, source: &Path) -> Result<()> {
        let mut seen: Vec<&str> = vec![];
        for (gi, g) in self.groups.iter().enumerate() {
            let bad = |reason: String| Err(ModelError::field(source, "groups", Some(gi), reason));
            let (k, m) = (g.dofs.len(), g.variances.len());
            if k == 0 || g.mean.len() != k || g.basis.nrows() != k {
                return bad(format!(
                    "group `{}`: {} DOFs, {} means, {} basis rows",
                    g.name,
                    k,
                    g.mean.len(),
                    g.basis.nrows()
                ));
            }
            if m == 0 || m > k || g.basis.ncols() != m {
                return bad(format!(
                    "group `{}`: {} variances for a basis with {} columns over {k} DOFs",
                    g.name,
                    m,
                    g.basis.ncols()
                ));
            }
            if !(g.mean.iter().chain(g.basis.iter()).all(|v| v.is_finite())) {
                return bad(format!("group `{}`: non-finite mean or basis", g.name));
            }
            if !g.variances.iter().all(|v| v.is_finite() && *v > 0.0) {
                return bad(format!("group `{}`: variances must be positive", g.name));
            }
            for d in &g.dofs {
                if d.is_empty() || seen.contains(&d.as_str()) {
                    return bad(format!("group `{}`: empty or repeated DOF `{d}`", g.name));
                }
                seen.push(d);
            }
        }
        Ok(())
    }
}

/// On-disk form of a [`PcaPrior`] (module docs).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PriorFile {
    format: String,
    version: u32,
    #[serde(default)]
    description: String,
    groups: Vec<GroupFile>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GroupFile {
    name: String,
    dofs: Vec<String>,
    mean: Vec<f64>,
    variances: Vec<f64>,
    /// The m principal directions, each with one entry per DOF.
    components: Vec<Vec<f64>>,
}

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|source| ModelError::Io {
        file: path.to_path_buf(),
        source,
    })
}

fn header(bytes: &[u8], at: usize, source: &Path) -> Result<usize> {
    let raw: [u8; 8] = bytes
        .get(at..at + 8)
        .and_then(|s| s.try_into().ok())
        .ok_or_else(|| ModelError::Parse {
            file: source.to_path_buf(),
            reason: "truncated size header".into(),
        })?;
    let v = i64::from_le_bytes(raw);
    if !(0..=1 << 24).contains(&v) {
        return Err(ModelError::Parse {
            file: source.to_path_buf(),
            reason: format!("implausible size {v}"),
        });
    }
    Ok(v as usize)
}

fn floats(bytes: &[u8], count: usize, source: &Path) -> Result<Vec<f64>> {
    if bytes.len() != count * 4 {
        return Err(ModelError::Parse {
            file: source.to_path_buf(),
            reason: format!("{} payload bytes, expected {}", bytes.len(), count * 4),
        });
    }
    let vals: Vec<f64> = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
        .collect();
    if let Some(i) = vals.iter().position(|v| !v.is_finite()) {
        return Err(ModelError::Parse {
            file: source.to_path_buf(),
            reason: format!("value {i} is not finite"),
        });
    }
    Ok(vals)
}

/// Parse an htrack binary matrix (`int64 rows, int64 cols`, float32 column-major).
pub fn parse_htrack_matrix(bytes: &[u8], source: &Path) -> Result<DMatrix<f64>> {
    let rows = header(bytes, 0, source)?;
    let cols = header(bytes, 8, source)?;
    let count = rows.checked_mul(cols).ok_or_else(|| ModelError::Parse {
        file: source.to_path_buf(),
        reason: "size overflow".into(),
    })?;
    let vals = floats(&bytes[16..], count, source)?;
    Ok(DMatrix::from_vec(rows, cols, vals))
}

/// Parse an htrack binary vector (`int64 length`, float32 values).
pub fn parse_htrack_vector(bytes: &[u8], source: &Path) -> Result<DVector<f64>> {
    let len = header(bytes, 0, source)?;
    let vals = floats(&bytes[8..], len, source)?;
    Ok(DVector::from_vec(vals))
}

/// Read an htrack binary matrix file.
pub fn read_htrack_matrix(path: &Path) -> Result<DMatrix<f64>> {
    parse_htrack_matrix(&read_bytes(path)?, path)
}

/// Read an htrack binary vector file.
pub fn read_htrack_vector(path: &Path) -> Result<DVector<f64>> {
    parse_htrack_vector(&read_bytes(path)?, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HTRACK: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/reference/htrack-pose-space-pca"
    );
    const HMODEL: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/reference/hmodel-pose-space"
    );

    fn present(dir: &str) -> bool {
        if Path::new(dir).is_dir() {
            true
        } else {
            eprintln!("skipped: {dir} absent");
            false
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 2e-6
    }

    #[test]
    fn parses_and_refuses_malformed_bytes() {
        let src = Path::new("<memory>");
        let mut b = vec![];
        b.extend_from_slice(&2i64.to_le_bytes());
        b.extend_from_slice(&1i64.to_le_bytes());
        b.extend_from_slice(&1.5f32.to_le_bytes());
        b.extend_from_slice(&(-2.0f32).to_le_bytes());
        let m = parse_htrack_matrix(&b, src).unwrap();
        assert_eq!((m.nrows(), m.ncols()), (2, 1));
        assert_eq!(m[(1, 0)], -2.0);
        assert!(parse_htrack_matrix(&b[..b.len() - 1], src).is_err());
        assert!(parse_htrack_matrix(&b[..10], src).is_err());
        let mut neg = b.clone();
        neg[..8].copy_from_slice(&(-1i64).to_le_bytes());
        assert!(parse_htrack_matrix(&neg, src).is_err());
        let mut nan = b.clone();
        nan[16..20].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(parse_htrack_matrix(&nan, src).is_err());
        let v = parse_htrack_vector(&b[8..], src);
        assert!(v.is_err(), "1 then 2 floats is not a vector of length 1");
    }

    #[test]
    fn htrack_files_load_with_anchor_values() {
        if !present(HTRACK) {
            return;
        }
        let dir = Path::new(HTRACK);
        // Raw files: sizes of ANCHOR-FACTS §4.
        let mu = read_htrack_vector(&dir.join("mu")).unwrap();
        assert_eq!(mu.len(), 20);
        for (i, v) in [
            (0, 0.085593),
            (1, -0.445539),
            (5, -0.247644),
            (19, -0.289409),
        ] {
            assert!(close(mu[i], v), "mu[{i}] = {}", mu[i]);
        }
        let p20 = read_htrack_matrix(&dir.join("P")).unwrap();
        assert_eq!((p20.nrows(), p20.ncols()), (20, 20));
        let s20 = read_htrack_matrix(&dir.join("Sigma")).unwrap();
        assert!((s20[(0, 0)] - 2.266).abs() < 1e-3);
        let tp = read_htrack_matrix(&dir.join("thumb/P")).unwrap();
        assert_eq!((tp.nrows(), tp.ncols()), (4, 4));
        for (r, row) in [
            (0, [-0.150154, -0.420226, -0.894908]),
            (3, [0.771612, 0.392173, -0.312886]),
        ] {
            for c in 0..3 {
                assert!(close(tp[(r, c)], row[c]), "thumb P[{r},{c}]");
            }
        }
        let fp = read_htrack_matrix(&dir.join("fingers/P")).unwrap();
        assert_eq!((fp.nrows(), fp.ncols()), (16, 16));
        assert!(close(fp[(1, 1)], -0.314745));
        assert!(close(fp[(15, 2)], -0.267405));
        let lim = read_htrack_matrix(&dir.join("Limits")).unwrap();
        assert_eq!((lim.nrows(), lim.ncols()), (2, 2));

        // Converted prior: our names and signs.
        let prior = PcaPrior::load_htrack_dir(dir).unwrap();
        let [thumb, fingers] = &prior.groups[..] else {
            panic!("two groups")
        };
        assert_eq!(thumb.dofs[0], "thumb_cmc_abd");
        assert_eq!(thumb.dofs[3], "thumb_ip_flex");
        assert_eq!(fingers.dofs[0], "index_mcp_abd");
        assert_eq!(fingers.dofs[1], "index_mcp_flex");
        assert_eq!(fingers.dofs[15], "pinky_dip_flex");
        assert_eq!((thumb.num_dofs(), thumb.num_latent()), (4, 4));
        assert_eq!((fingers.num_dofs(), fingers.num_latent()), (16, 16));
        assert!(close(thumb.mean[1], 0.445539), "flexion sign flipped");
        assert!(close(fingers.mean[2], 0.376956));
        assert!(close(thumb.basis[(0, 0)], 0.150154));
        // (ANCHOR-FACTS lists the 4th as 0.009127; the file holds 0.0090923.)
        let tv = [0.235249, 0.081992, 0.019017, 0.009092];
        for (v, e) in thumb.variances.iter().zip(tv) {
            assert!(close(*v, e));
        }
        assert!((fingers.variances[0] - 2.190982).abs() < 1e-5);
        assert!(thumb.orthonormality_error() < 1e-5);
        assert!(fingers.orthonormality_error() < 1e-5);
        let t3 = prior.truncated(HTRACK_LATENT_DIMS);
        assert_eq!(t3.groups[1].basis.ncols(), 3);
        assert_eq!(t3.groups[1].variances.len(), 3);
    }

    #[test]
    fn hmodel_files_load_with_anchor_values() {
        if !present(HMODEL) {
            return;
        }
        let prior = PcaPrior::load_hmodel_dir(Path::new(HMODEL)).unwrap();
        let (thumb, fingers) = (&prior.groups[0], &prior.groups[1]);
        assert_eq!(
            (thumb.num_dofs(), thumb.num_latent()),
            (4, HMODEL_LATENT_DIMS)
        );
        assert_eq!((fingers.num_dofs(), fingers.num_latent()), (16, 2));
        assert!(close(thumb.mean[0], 0.585766));
        assert!(close(fingers.mean[2], 1.478608));
        assert!(close(thumb.basis[(2, 0)], -0.781745));
        assert!(close(fingers.basis[(3, 1)], 0.575425));
        assert!(close(thumb.variances[1], 0.202641));
        assert!(close(fingers.variances[0], 2.105993));
        assert_eq!(fingers.dofs[4], "middle_mcp_abd");
    }

    /// Deterministic pseudo-random numbers in [−1, 1) (no dev-dependency needed here).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    #[test]
    fn fit_recovers_a_known_covariance() {
        // Samples μ + Σ_j s_j a_j d_j with orthonormal directions d_j and scales s_j.
        let names = ["a", "b", "c", "d"];
        let d = [
            [0.5, 0.5, 0.5, 0.5],
            [0.5, -0.5, 0.5, -0.5],
            [0.5, 0.5, -0.5, -0.5],
            [0.5, -0.5, -0.5, 0.5],
        ];
        let scales = [2.0, 1.0, 0.3, 0.05];
        let mu = [0.1, -0.2, 0.3, 0.4];
        let mut st = 7u64;
        let samples: Vec<Vec<f64>> = (0..20000)
            .map(|_| {
                let mut x = mu.to_vec();
                for (dj, s) in d.iter().zip(scales) {
                    let a = lcg(&mut st) * s;
                    x.iter_mut().zip(dj).for_each(|(x, dv)| *x += a * dv);
                }
                x
            })
            .collect();
        let groups: [(&str, &[&str]); 1] = [("all", &names)];
        let prior = PcaPrior::fit(&groups, &names, &samples).unwrap();
        let g = &prior.groups[0];
        assert_eq!((g.num_dofs(), g.num_latent()), (4, 4));
        for (m, e) in g.mean.iter().zip(mu) {
            assert!((m - e).abs() < 0.03, "{m} vs {e}");
        }
        // Uniform on [−s, s]: variance s²/3.
        for (v, s) in g.variances.iter().zip(scales) {
            let e = s * s / 3.0;
            assert!((v - e).abs() < 0.05 * e, "{v} vs {e}");
        }
        assert!(g.variances.windows(2).all(|w| w[0] >= w[1]));
        assert!(g.orthonormality_error() < 1e-12);
        for (j, dj) in d.iter().enumerate().take(2) {
            let c: f64 = (0..4).map(|i| g.basis[(i, j)] * dj[i]).sum();
            assert!(c.abs() > 0.99, "component {j}: |cos| = {c}");
            // Deterministic sign: the largest entry is positive.
            let col = g.basis.column(j);
            assert!(col[col.iamax()] > 0.0);
        }
        assert!(g.explained_variance(2) > 0.95 && g.explained_variance(4) == 1.0);
        // A group follows its own DOF order.
        let split: [(&str, &[&str]); 2] = [("ba", &["b", "a"]), ("dc", &["d", "c"])];
        let two = PcaPrior::fit(&split, &names, &samples).unwrap();
        assert_eq!(two.groups[0].dofs, ["b", "a"]);
        assert!((two.groups[0].mean[0] - mu[1]).abs() < 0.03);
        let overlap: [(&str, &[&str]); 2] = [("ab", &["a", "b"]), ("bc", &["b", "c"])];
        assert!(PcaPrior::fit(&overlap, &names, &samples).is_err());
        // Refusals.
        assert!(PcaPrior::fit(&groups, &names, &samples[..1]).is_err());
        assert!(PcaPrior::fit(&groups, &names[..3], &samples).is_err());
        let missing: [(&str, &[&str]); 1] = [("x", &["zz"])];
        assert!(PcaPrior::fit(&missing, &names, &samples).is_err());
        let mut nan = samples[..10].to_vec();
        nan[3][1] = f64::NAN;
        assert!(PcaPrior::fit(&groups, &names, &nan).is_err());
        // Rank-deficient samples: the floor keeps the variances positive.
        let flat: Vec<Vec<f64>> = (0..10).map(|i| vec![i as f64, 0.0, 0.0, 0.0]).collect();
        let p = PcaPrior::fit(&groups, &names, &flat).unwrap();
        assert_eq!(p.groups[0].variances[3], PCA_VARIANCE_FLOOR);
    }

    #[test]
    fn json_round_trips_and_refuses_bad_files() {
        let prior = PcaPrior::project_default();
        let text = prior.to_json("test");
        let back = PcaPrior::from_json(&text, Path::new("<memory>")).unwrap();
        assert_eq!(back, prior, "float_roundtrip JSON is exact");
        let dir = std::env::temp_dir().join(format!("hands-pca-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("prior.json");
        prior.save_json(&path, "saved").unwrap();
        assert_eq!(PcaPrior::load_json(&path).unwrap(), prior);
        let leftovers = std::fs::read_dir(&dir).unwrap().count();
        assert_eq!(leftovers, 1, "no temporary file left");
        let e = PcaPrior::load_json(&dir.join("missing.json")).unwrap_err();
        assert!(e.to_string().contains("missing.json"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();

        let src = Path::new("bad.json");
        let bad = |t: &str, needle: &str| {
            let e = PcaPrior::from_json(t, src).unwrap_err().to_string();
            assert!(
                e.contains("bad.json") && e.contains(needle),
                "{needle}: {e}"
            );
        };
        bad("", "not a hands-pca-prior");
        bad("[1, 2", "not a hands-pca-prior");
        bad(&text.replace("hands-pca-prior", "other"), "format");
        bad(&text.replace("\"version\": 1", "\"version\": 9"), "version");
        bad(
            &text.replace("\"groups\"", "\"extra\": 1, \"groups\""),
            "unknown field",
        );
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let edit = |f: &dyn Fn(&mut serde_json::Value)| {
            let mut v = v.clone();
            f(&mut v);
            v.to_string()
        };
        bad(&edit(&|v| v["groups"] = serde_json::json!([])), "no groups");
        bad(
            &edit(&|v| v["groups"][0]["components"][1] = serde_json::json!([1.0])),
            "component 1",
        );
        bad(
            &edit(&|v| v["groups"][0]["variances"][0] = serde_json::json!(-1.0)),
            "positive",
        );
        bad(
            &edit(&|v| v["groups"][1]["mean"] = serde_json::json!([0.0])),
            "means",
        );
        bad(
            &edit(&|v| v["groups"][1]["dofs"][0] = serde_json::json!("thumb_cmc_abd")),
            "repeated",
        );
        bad(
            &edit(&|v| v["groups"][0]["components"][0][0] = serde_json::json!(3.0)),
            "orthonormal",
        );
    }

    #[test]
    fn project_prior_is_embedded_with_htrack_grouping() {
        let prior = PcaPrior::project_default();
        let [thumb, fingers] = &prior.groups[..] else {
            panic!("two groups")
        };
        let groups = htrack_groups();
        assert_eq!(thumb.dofs, groups[0].1);
        assert_eq!(fingers.dofs, groups[1].1);
        assert_eq!((thumb.num_latent(), fingers.num_latent()), (4, 16));
        assert!(thumb.orthonormality_error() < 1e-9 && fingers.orthonormality_error() < 1e-9);
        // Positive flexion convention: the mean finger flexions are positive.
        for i in [1, 2, 5, 6, 9, 10, 13, 14] {
            assert!(fingers.mean[i] > 0.0, "{}", fingers.dofs[i]);
        }
        for g in [thumb, fingers] {
            eprintln!(
                "{}: variances {:.4?}, 3 components explain {:.1} %",
                g.name,
                g.variances,
                100.0 * g.explained_variance(HTRACK_LATENT_DIMS)
            );
            assert!(g.explained_variance(HTRACK_LATENT_DIMS) > 0.8);
        }
    }
}
