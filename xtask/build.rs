//! No build step: the build-dependencies only align the host packages' features with the
//! tests' (`Cargo.toml`).
fn main() {}
