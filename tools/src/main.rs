//! The `hands` command-line interface.
fn main() {}
