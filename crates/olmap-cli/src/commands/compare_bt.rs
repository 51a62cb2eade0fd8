//! `olmap compare-bt`: two OctoMap `.bt` trees compared voxel by voxel.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::io::octomap_bt;

/// Arguments of `olmap compare-bt`.
///
/// Both trees are read without expanding them (memory in proportion to the files) and
/// swept together in Morton order: every voxel of the trees' resolution that both know
/// (free or occupied) is counted as agreeing or not. Trees of different resolutions are
/// refused. Typical use: an olmap `voxelize --free-space` map against OctoMap's own tree of
/// the same scans (`graph2tree`).
#[derive(Args)]
pub struct CompareBtArgs {
    /// The first tree (.bt).
    pub first: PathBuf,
    /// The second tree (.bt).
    pub second: PathBuf,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command.
pub fn run(a: &CompareBtArgs) -> anyhow::Result<ExitCode> {
    let first = octomap_bt::read_leaves_path(&a.first)?;
    let second = octomap_bt::read_leaves_path(&a.second)?;
    let c = first.compare(&second)?;
    if a.json {
        let mut v = serde_json::to_value(c)?;
        v["agreement"] = serde_json::json!(c.agreement());
        v["first"] = serde_json::json!(a.first.display().to_string());
        v["second"] = serde_json::json!(a.second.display().to_string());
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        let pct = |n: u64| 100.0 * n as f64 / c.both_known.max(1) as f64;
        println!(
            "{} m voxels: {} known in {}, {} in {}, {} in both",
            c.resolution,
            c.known_here,
            a.first.display(),
            c.known_there,
            a.second.display(),
            c.both_known
        );
        println!(
            "  agreement {:.3} %: occupied in both {} ({:.3} %), free in both {} ({:.3} %)",
            100.0 * c.agreement(),
            c.occupied_both,
            pct(c.occupied_both),
            c.free_both,
            pct(c.free_both)
        );
        println!(
            "  occupied in the first, free in the second {} ({:.3} %); free in the first, \
             occupied in the second {} ({:.3} %)",
            c.occupied_here_free_there,
            pct(c.occupied_here_free_there),
            c.free_here_occupied_there,
            pct(c.free_here_occupied_there)
        );
    }
    Ok(ExitCode::SUCCESS)
}
