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

/// The 3DTK indoor scans' folder (`DATA/3dtk_dat`), or `None` as [`dir`].
pub fn threedtk_dir() -> Option<PathBuf> {
    dir().map(|d| d.join("3dtk_dat"))
}

/// The reference poses `T_map_scan` of the 3DTK scans (`reference_poses_rh_m.txt`:
/// right-handed metres, named `scan000` ...), or `None` as [`dir`].
///
/// # Panics
/// When the file is there but does not read (the shared data is broken).
pub fn threedtk_reference() -> Option<crate::geometry::PoseList> {
    let path = threedtk_dir()?.join("reference_poses_rh_m.txt");
    Some(
        crate::geometry::PoseList::read_path(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
}

/// 3DTK scan `index` (`scanNNN.3d`) as a right-handed cloud in metres, with only the
/// valid returns (20-3270 cm) when `valid_only`; `None` as [`dir`].
///
/// # Panics
/// When the file is there but does not read.
pub fn threedtk_scan(index: usize, valid_only: bool) -> Option<crate::cloud::PointCloud> {
    let path = threedtk_dir()?.join(format!("scan{index:03}.3d"));
    let options = crate::io::ReadOptions {
        uos_valid_only: valid_only,
        ..Default::default()
    };
    Some(
        crate::io::read_cloud_with(&path, &options)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .cloud,
    )
}
