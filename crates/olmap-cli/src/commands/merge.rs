//! `olmap merge`: maps of one resolution merged into one (counts add).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::occupancy::{self, MapFormat};

/// Arguments of `olmap merge`.
#[derive(Args)]
pub struct MergeArgs {
    /// Maps to merge (.olm or .bt, same resolution); counts add.
    #[arg(required = true, num_args = 2..)]
    pub maps: Vec<PathBuf>,
    /// Output map (.olm, or OctoMap .bt: occupancy only).
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Runs `olmap merge`.
pub fn run(a: &MergeArgs) -> anyhow::Result<ExitCode> {
    MapFormat::of_output(&a.output)?;
    olmap::file::check_output(&a.output, "map")?;
    let mut it = a.maps.iter();
    let first = it.next().expect("clap requires two maps");
    let mut map = occupancy::read_map(first)?.map;
    for p in it {
        let other = occupancy::read_map(p)?.map;
        map.merge(&other)
            .map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
    }
    occupancy::write_map(&a.output, &map)?;
    println!(
        "{} maps -> {} voxels -> {}",
        a.maps.len(),
        map.len(),
        a.output.display()
    );
    Ok(ExitCode::SUCCESS)
}
