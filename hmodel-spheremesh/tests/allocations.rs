//! "No allocation per iteration in the hot loop" (issue 5), checked with a counting global
//! allocator: after warm-up frames, tracking the same frame with 8 LM iterations allocates
//! exactly as often as with 2 — every allocation of a frame (its output record, the solver
//! report's term list) is per frame, none per iteration (correspondences, m2d rendering, term
//! assembly, solve).
//!
//! The counting allocator (per thread) is shared with `hand-model`'s allocation tests.
#![allow(unsafe_code)] // the counting allocator of the included file

#[path = "../../hand-model/tests/support/counting_alloc.rs"]
mod counting_alloc;

use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::default_right_hand;
use hmodel_spheremesh::synthetic::rendered_frame;
use hmodel_spheremesh::{M2dMode, Tracker, TrackerConfig};
use sensor_io::Camera;

/// Allocations of tracking one warm-started frame with `iterations` LM iterations (after two
/// warm-up frames that size every buffer).
fn allocations(iterations: usize, mode: M2dMode) -> usize {
    let t = default_right_hand();
    let truth = Pose::from_named(
        &t.skeleton,
        [
            ("global_tz", 400.0),
            ("global_ty", 40.0),
            ("index_mcp_flex", 0.4),
            ("middle_pip_flex", 0.6),
        ],
    )
    .unwrap();
    let mut start = truth.clone();
    start.values[t.skeleton.dof_index("global_tx").unwrap()] += 4.0;
    start.values[t.skeleton.dof_index("index_mcp_flex").unwrap()] += 0.1;
    let frame = rendered_frame(&t, &truth, &Camera::sr300_qvga(), 2500).unwrap();
    let prior = PcaPrior::project_default();
    let mut config = TrackerConfig {
        m2d_mode: mode,
        ..TrackerConfig::default()
    };
    config.lm.iterations = iterations;
    let mut tracker = Tracker::new(&t, config, Some(&prior)).unwrap();
    for i in 0..2 {
        tracker.set_pose(&start).unwrap();
        tracker.track(&frame, i, 0.0);
    }
    tracker.set_pose(&start).unwrap();
    let (n, rec) = counting_alloc::count(|| tracker.track(&frame, 2, 0.0));
    assert!(rec.flags.is_empty(), "{:?}", rec.flags);
    n
}

#[test]
fn no_allocation_per_iteration() {
    for mode in [M2dMode::Render, M2dMode::Centers] {
        let (two, eight) = (allocations(2, mode), allocations(8, mode));
        println!("{mode:?}: {two} allocations per frame with 2 iterations, {eight} with 8");
        assert_eq!(two, eight, "{mode:?}: allocations grow with the iterations");
    }
}
