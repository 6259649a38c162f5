//! Per-term energy traces and timing summaries of a tracked sequence, read from the tracker
//! records of DESIGN.md "Tracker output" (`energies` {term: value}, `timing_us` {stage: µs}).

use std::collections::BTreeMap;

use sensor_io::record::HandRecord;

use crate::markers::{mean, median};

/// Per term, its energy in every frame (NaN where a frame does not report that term), in
/// record order: the per-term curves of the ablation figures.
pub fn energy_traces(records: &[HandRecord]) -> BTreeMap<String, Vec<f64>> {
    traces(records, |r| &r.energies)
}

/// Per stage, its wall time (µs) in every frame (NaN where a frame does not report it).
pub fn timing_traces(records: &[HandRecord]) -> BTreeMap<String, Vec<f64>> {
    traces(records, |r| &r.timing_us)
}

fn traces(
    records: &[HandRecord],
    field: impl Fn(&HandRecord) -> &BTreeMap<String, f64>,
) -> BTreeMap<String, Vec<f64>> {
    let mut out: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in records {
        for name in field(r).keys() {
            if !out.contains_key(name) {
                out.insert(name.clone(), vec![f64::NAN; records.len()]);
            }
        }
    }
    for (k, r) in records.iter().enumerate() {
        for (name, &value) in field(r) {
            if let Some(trace) = out.get_mut(name) {
                trace[k] = value;
            }
        }
    }
    out
}

/// Statistics of one series over the frames that report a finite value.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SeriesSummary {
    /// Frames with a finite value.
    pub frames: usize,
    /// Mean.
    pub mean: f64,
    /// Median (the upper median for even counts).
    pub median: f64,
    /// 95th percentile (nearest rank).
    pub p95: f64,
    /// Maximum.
    pub max: f64,
}

impl SeriesSummary {
    /// Summarize the finite values of `values`; `None` when there is none.
    pub fn new(values: &[f64]) -> Option<Self> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let rank = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
        Some(Self {
            frames: v.len(),
            mean: mean(&v),
            median: median(&v),
            p95: v[rank - 1],
            max: v[v.len() - 1],
        })
    }
}

/// Per stage, the summary of its wall time (µs) over the frames that report it.
pub fn timing_summary(records: &[HandRecord]) -> BTreeMap<String, SeriesSummary> {
    summarize(timing_traces(records))
}

/// Per term, the summary of its energy over the frames that report it.
pub fn energy_summary(records: &[HandRecord]) -> BTreeMap<String, SeriesSummary> {
    summarize(energy_traces(records))
}

fn summarize(traces: BTreeMap<String, Vec<f64>>) -> BTreeMap<String, SeriesSummary> {
    traces
        .into_iter()
        .filter_map(|(k, v)| SeriesSummary::new(&v).map(|s| (k, s)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(k: u64, energies: &[(&str, f64)], timing: &[(&str, f64)]) -> HandRecord {
        let mut r = HandRecord::for_frame(k, k as f64 / 60.0);
        r.add_energies(energies.iter().copied());
        r.timing_us = timing.iter().map(|&(s, t)| (s.to_string(), t)).collect();
        r
    }

    #[test]
    fn traces_align_frames_and_mark_missing_terms() {
        let recs = [
            record(0, &[("d2m", 1.0), ("m2d", 2.0)], &[("solve", 100.0)]),
            record(1, &[("d2m", 3.0)], &[("solve", 300.0), ("render", 50.0)]),
        ];
        let e = energy_traces(&recs);
        assert_eq!(e["d2m"], vec![1.0, 3.0]);
        assert_eq!(e["m2d"][0], 2.0);
        assert!(e["m2d"][1].is_nan());
        let t = timing_summary(&recs);
        assert_eq!(t["solve"].frames, 2);
        assert_eq!((t["solve"].mean, t["solve"].max), (200.0, 300.0));
        assert_eq!(t["render"].frames, 1);
        assert_eq!(energy_summary(&recs)["m2d"].median, 2.0);
        assert!(energy_traces(&[]).is_empty());
    }

    #[test]
    fn series_summary_percentiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        let s = SeriesSummary::new(&v).unwrap();
        assert_eq!((s.frames, s.p95, s.max, s.mean), (100, 95.0, 100.0, 50.5));
        assert_eq!(SeriesSummary::new(&[f64::NAN]), None);
        assert_eq!(SeriesSummary::new(&[4.0]).unwrap().p95, 4.0);
    }
}
