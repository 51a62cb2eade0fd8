//! Locating the shared real-sensor test data (for tests, benchmarks and examples).
//!
//! The data lives outside the repository (it is third-party and not ours to commit). Its
//! folder is `$OLMAP_DATA`, or `../shared/data` beside the repository root. When it is
//! missing, [`dir`] returns `None` so that data tests can skip, unless
//! `OLMAP_REQUIRE_DATA=1`, where a missing folder is a hard failure (CI sets it).

use std::path::{Path, PathBuf};

/// The data folder, or `None` (after printing why to stderr) when it is absent and not
/// required.
///
/// # Panics
/// When `OLMAP_REQUIRE_DATA=1` and the folder is missing: a test run that must use the real
/// data fails loudly instead of passing by skipping.
pub fn dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("OLMAP_DATA") {
        Some(d) => PathBuf::from(d),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"),
    };
    if dir.join("README.md").is_file() {
        return Some(dir);
    }
    if std::env::var("OLMAP_REQUIRE_DATA").is_ok_and(|v| v == "1") {
        panic!(
            "OLMAP_REQUIRE_DATA=1 but the test data is not at {} (set OLMAP_DATA)",
            dir.display()
        );
    }
    eprintln!(
        "skipping a real-data test: no test data at {} (set OLMAP_DATA)",
        dir.display()
    );
    None
}
