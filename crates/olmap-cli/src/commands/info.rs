//! `olmap info`: describe point-cloud files.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use olmap::io::{self, CloudFormat, ReadOptions};

use olmap::occupancy::{self, MapFormat};
use serde_json::Value;

use crate::report::{cloud_json, cloud_text, map_json, map_text};

/// Arguments of `olmap info`.
#[derive(Args)]
pub struct InfoArgs {
    /// Point-cloud files (.pcd .ply .xyz .txt .dat .asc .pts .3d .csv .bin .graph, optionally
    /// .bz2) and map files (.olm, OctoMap .bt). Every file is described even when an earlier one fails.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Read every file as this format (pcd, ply, xyz, 3d, csv, kitti, graph) instead of
    /// guessing it from the file name.
    #[arg(long, value_parser = parse_format)]
    pub format: Option<CloudFormat>,
    /// 3DTK .3d files: keep only returns between 20 cm and 3270 cm (drops near-sensor echoes
    /// and the max-range sentinel).
    #[arg(long = "3dtk-valid")]
    pub threedtk_valid: bool,
    /// Print one JSON array (one object per file) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Parses a format name for clap.
pub fn parse_format(s: &str) -> Result<CloudFormat, String> {
    CloudFormat::from_name(s)
        .ok_or_else(|| format!("unknown format '{s}'; known: pcd, ply, xyz, 3d, csv, kitti, graph"))
}

/// JSON and text descriptions of a map file.
fn describe_map(path: &Path, shown: &str) -> olmap::Result<(Value, String)> {
    let loaded = occupancy::read_map(path)?;
    let stats = loaded.map.stats();
    let name = loaded.format.name();
    let mut v = map_json(shown, name, &stats);
    let mut text = map_text(shown, name, &stats);
    if let Some(bt) = &loaded.bt {
        v["octree"] = serde_json::json!({
            "nodes": bt.nodes,
            "occupied_leaves": bt.occupied_leaves,
            "free_leaves": bt.free_leaves,
            "occupied_leaves_by_depth": bt.occupied_leaves_by_depth,
        });
        text.push_str(&format!(
            "  {:<14}{} nodes, {} occupied and {} free leaves\n",
            "octree", bt.nodes, bt.occupied_leaves, bt.free_leaves
        ));
    }
    Ok((v, text))
}

/// JSON and text descriptions of a point-cloud file.
fn describe_cloud(
    path: &Path,
    shown: &str,
    options: &ReadOptions,
) -> olmap::Result<(Value, String)> {
    let loaded = io::read_cloud_with(path, options)?;
    let stats = loaded.cloud.stats();
    let o = loaded.cloud.origin();
    let origin = [o.x, o.y, o.z];
    Ok((
        cloud_json(shown, &stats, &loaded.report, origin),
        cloud_text(shown, &stats, &loaded.report, origin),
    ))
}

/// Runs the command.
pub fn run(args: &InfoArgs) -> anyhow::Result<ExitCode> {
    let options = ReadOptions {
        format: args.format,
        uos_valid_only: args.threedtk_valid,
    };
    let mut json = Vec::new();
    let mut failed = false;
    for path in &args.files {
        let shown = path.display().to_string();
        let described = if MapFormat::from_path(path).is_some() {
            describe_map(path, &shown)
        } else {
            describe_cloud(path, &shown, &options)
        };
        match described {
            Ok((v, _)) if args.json => json.push(v),
            Ok((_, text)) => print!("{text}"),
            Err(e) => {
                failed = true;
                if args.json {
                    json.push(serde_json::json!({ "path": shown, "error": e.to_string() }));
                } else {
                    eprintln!("error: {e}");
                }
            }
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&json)?);
    }
    Ok(if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}
