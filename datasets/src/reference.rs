//! Where the tests find the public reference data (`../shared/reference` beside the repository,
//! never copied into it; `shared/reference/README.md`).

use std::path::PathBuf;

/// The reference folder: `$HANDS_REFERENCE` when set, else `shared/reference` beside the
/// repository (resolved from this crate's source folder at build time).
pub fn reference_root() -> PathBuf {
    match std::env::var_os("HANDS_REFERENCE") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shared/reference"
        )),
    }
}

/// `rel` inside the reference folder when it exists; otherwise prints that the caller skipped
/// (tests must say so) and returns `None`.
pub fn reference_path(rel: &str) -> Option<PathBuf> {
    let p = reference_root().join(rel);
    if p.exists() {
        Some(p)
    } else {
        println!("skipped: {} absent", p.display());
        None
    }
}
