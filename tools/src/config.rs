//! `--config` files: JSON settings laid over the defaults at every depth.
//!
//! A file may hold any subset of the fields, nested ones included: `{"tracker": {"lm":
//! {"iterations": 5}}}` changes that one field of the online calibrator's tracker and keeps the
//! rest of *its* defaults. Deserializing the file directly would not: serde's `#[serde(default)]`
//! fills a nested struct that the file names from that struct's own `Default`, so the online
//! calibrator's schedule (`honline_calib::honline_schedule`: 7 iterations, β's step decoupled
//! from the pose prior) silently became the plain tracker's. Unknown fields are still refused
//! (`deny_unknown_fields`), at any depth.

use std::path::Path;

use anyhow::{Context, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;

/// Settings from `--config` laid over `T::default()` (see the module docs), or the defaults.
pub(crate) fn read_config<T: Serialize + DeserializeOwned + Default>(
    path: Option<&Path>,
) -> Result<T> {
    read_config_over(path, T::default())
}

/// Settings from `--config` laid over `base`, or `base` without a file.
pub(crate) fn read_config_over<T: Serialize + DeserializeOwned>(
    path: Option<&Path>,
    base: T,
) -> Result<T> {
    let Some(path) = path else {
        return Ok(base);
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_over(&text, base).with_context(|| format!("parsing {}", path.display()))
}

/// [`read_config_over`] on the file's text.
fn parse_over<T: Serialize + DeserializeOwned>(text: &str, base: T) -> Result<T> {
    let patch: Value = serde_json::from_str(text)?;
    let mut merged = serde_json::to_value(base).context("the defaults as JSON")?;
    lay_over(&mut merged, patch);
    Ok(serde_json::from_value(merged)?)
}

/// `patch` over `base`: objects field by field (recursively), anything else replaced.
fn lay_over(base: &mut Value, patch: Value) {
    match (base, patch) {
        (Value::Object(base), Value::Object(patch)) => {
            for (key, value) in patch {
                match base.get_mut(&key) {
                    Some(slot) => lay_over(slot, value),
                    None => {
                        base.insert(key, value);
                    }
                }
            }
        }
        (slot, value) => *slot = value,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hmodel_spheremesh::calibration::CalibrationConfig;
    use honline_calib::{OfflineConfig, OnlineConfig};

    /// Every settings type a `--config` file can set: its defaults survive the trip through
    /// JSON (an infinite or NaN default would turn into `null` and fail here).
    #[test]
    fn defaults_round_trip() {
        fn check<T: Serialize + DeserializeOwned + PartialEq + Clone + std::fmt::Debug>(base: T) {
            assert_eq!(parse_over("{}", base.clone()).unwrap(), base);
        }
        check(htrack_icp::TrackerConfig::default());
        check(hmodel_spheremesh::TrackerConfig::default());
        check(OnlineConfig::default());
        check(OfflineConfig::default());
        check(CalibrationConfig::default());
        check(CalibrationConfig::clouds());
    }

    /// A nested field set alone keeps its siblings' defaults of the outer type: the online
    /// calibrator's tracker schedule is not reset to the plain tracker's.
    #[test]
    fn a_nested_field_keeps_the_outer_defaults() {
        let text = r#"{"tracker": {"lm": {"step_tolerance": 0.001}}, "shape_prior": 4.0}"#;
        let got: OnlineConfig = parse_over(text, OnlineConfig::default()).unwrap();
        let mut want = OnlineConfig::default();
        want.tracker.lm.step_tolerance = 0.001;
        want.shape_prior = 4.0;
        assert_eq!(got, want);
        assert!(got.tracker.lm.decouple_aux, "the honline schedule is kept");
        // Two levels down, over another base.
        let text = r#"{"frame": {"tracker": {"lm": {"iterations": 5}}}}"#;
        let got: OfflineConfig = parse_over(text, OfflineConfig::default()).unwrap();
        assert_eq!(got.frame.tracker.lm.iterations, 5);
        assert!(got.frame.tracker.lm.decouple_aux);
        let got: CalibrationConfig =
            parse_over(r#"{"d2m": 2.0}"#, CalibrationConfig::clouds()).unwrap();
        assert_eq!(
            got,
            CalibrationConfig {
                d2m: 2.0,
                ..CalibrationConfig::clouds()
            }
        );
    }

    /// Unknown fields are refused at any depth; a value of the wrong type too.
    #[test]
    fn unknown_or_mistyped_fields_are_errors() {
        for text in [
            r#"{"shape_prir": 4.0}"#,
            r#"{"tracker": {"lm": {"iteratons": 5}}}"#,
            r#"{"tracker": {"lm": 5}}"#,
            r#"{"shape_prior": "high"}"#,
            "[1, 2]",
            "{",
        ] {
            assert!(parse_over(text, OnlineConfig::default()).is_err(), "{text}");
        }
    }
}
