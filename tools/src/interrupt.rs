//! Ctrl-C for long jobs: the first interrupt asks the running loop to stop after the current
//! frame (it then writes what it has, atomically, and says so); a second one exits at once.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Install the handler (idempotent; a failure to install only loses the graceful stop).
pub fn install() {
    let _ = ctrlc::set_handler(|| {
        if REQUESTED.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\ninterrupted: finishing the current frame (Ctrl-C again to abort)");
    });
}

/// Whether an interrupt was requested.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}
