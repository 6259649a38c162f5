//! "No allocation per iteration in the hot loop" (issue 5), checked with a counting global
//! allocator: after warm-up frames, tracking the same frame with 8 LM iterations allocates
//! exactly as often as with 2 — every allocation of a frame (its output record, the solver
//! report's term list) is per frame, none per iteration (correspondences, m2d rendering, term
//! assembly, solve).
//!
//! The only `unsafe` of the workspace: a global allocator cannot be written without it, and it
//! lives in this test binary alone.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use hand_model::kinematics::Pose;
use hand_model::solver::PcaPrior;
use hand_model::spheremesh::default_right_hand;
use hmodel_spheremesh::synthetic::rendered_frame;
use hmodel_spheremesh::{M2dMode, Tracker, TrackerConfig};
use sensor_io::Camera;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let rec = tracker.track(&frame, 2, 0.0);
    let n = ALLOCATIONS.load(Ordering::Relaxed) - before;
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
