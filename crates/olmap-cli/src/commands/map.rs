//! `olmap export` and `olmap merge`: map files in and out.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::Args;
use olmap::io::{self, WriteOptions};
use olmap::occupancy::{self, MapFormat};

/// Arguments of `olmap export`.
#[derive(Args)]
pub struct ExportArgs {
    /// Input map (.olm or OctoMap .bt).
    pub map: PathBuf,
    /// Output: a map file (.olm, .bt), or a point cloud of voxel centres with counts as intensity
    /// (.ply .pcd .xyz .csv ...).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Keep only voxels with at least this count.
    #[arg(long, default_value_t = 1)]
    pub min_count: u16,
    /// Point-cloud output: colour the voxel centres by height (blue low, red high) for 3D
    /// viewers (PLY, PCD keep the colours).
    #[arg(long)]
    pub colour_by_height: bool,
}

/// Runs `olmap export`.
pub fn export(a: &ExportArgs) -> anyhow::Result<ExitCode> {
    let map = occupancy::read_map(&a.map)?.map.threshold(a.min_count);
    if MapFormat::from_path(&a.output).is_some() {
        occupancy::write_map(&a.output, &map)?;
    } else {
        let cloud = if a.colour_by_height {
            olmap::render::height_coloured_cloud(&map, None)
        } else {
            map.to_cloud()
        };
        io::write_cloud(&a.output, &cloud, &WriteOptions::default())?;
    }
    println!("{} voxels -> {}", map.len(), a.output.display());
    Ok(ExitCode::SUCCESS)
}

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
pub fn merge(a: &MergeArgs) -> anyhow::Result<ExitCode> {
    if MapFormat::from_path(&a.output).is_none() {
        bail!(
            "{}: the output must be a map file (.olm or .bt)",
            a.output.display()
        );
    }
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
