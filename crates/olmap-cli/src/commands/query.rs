//! `olmap query`: point, ray, radius and segment queries of a map.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::{ArgGroup, Args};
use olmap::occupancy::{MapFormat, QueryReport};

use super::render::read;
use crate::args::parse_numbers;

/// Arguments of `olmap query`.
#[derive(Args)]
#[command(group(ArgGroup::new("what").required(true).args(["at", "ray", "radius", "segment"])))]
pub struct QueryArgs {
    /// The map (.olm or OctoMap .bt).
    pub map: PathBuf,
    /// Is the voxel holding this point occupied? X,Y,Z (m). On a .bt with free nodes
    /// (`voxelize --free-space`) also: unknown, free or occupied.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub at: Option<String>,
    /// The first occupied voxel along a ray from X,Y,Z in direction DX,DY,DZ, and its
    /// distance.
    #[arg(long, value_name = "X,Y,Z,DX,DY,DZ", allow_hyphen_values = true)]
    pub ray: Option<String>,
    /// The occupied voxels whose centres lie within R metres of X,Y,Z.
    #[arg(long, value_name = "X,Y,Z,R", allow_hyphen_values = true)]
    pub radius: Option<String>,
    /// Is the segment between two points free of occupied voxels? On a .bt with free
    /// nodes also: is every voxel on it known free?
    #[arg(long, value_name = "X1,Y1,Z1,X2,Y2,Z2", allow_hyphen_values = true)]
    pub segment: Option<String>,
    /// Rays reach at most this far, metres.
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
    /// Only voxels with at least this count count as occupied.
    #[arg(long, default_value_t = 1)]
    pub min_count: u16,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap query`.
pub fn run(a: &QueryArgs) -> anyhow::Result<ExitCode> {
    let map = read(&a.map)?;
    let report = if let Some(s) = &a.at {
        QueryReport::at(&map, parse_numbers::<3>(s, "--at")?, a.min_count)
    } else if let Some(s) = &a.ray {
        let [x, y, z, dx, dy, dz] = parse_numbers::<6>(s, "--ray")?;
        QueryReport::ray(&map, [x, y, z], [dx, dy, dz], a.max_range, a.min_count)?
    } else if let Some(s) = &a.radius {
        let [x, y, z, rad] = parse_numbers::<4>(s, "--radius")?;
        QueryReport::radius(&map, [x, y, z], rad, a.min_count)?
    } else if let Some(s) = &a.segment {
        let [x1, y1, z1, x2, y2, z2] = parse_numbers::<6>(s, "--segment")?;
        QueryReport::segment(&map, [x1, y1, z1], [x2, y2, z2], a.min_count)?
    } else {
        bail!("give one of --at, --ray, --radius, --segment");
    };
    // A .bt tree with free nodes (`olmap voxelize --free-space`, OctoMap's own maps) also
    // tells free from unknown.
    let is_bt = MapFormat::from_path(&a.map) == Some(MapFormat::OctomapBt);
    let asks_state = a.at.is_some() || a.segment.is_some();
    let report = if is_bt && asks_state {
        let index = olmap::io::octomap_bt::read_leaves_path(&a.map)?.index();
        if index.has_free() {
            report.with_known_space(&index, map.resolution())
        } else {
            report
        }
    } else {
        report
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("{}", text(&report, map.resolution()));
    }
    Ok(ExitCode::SUCCESS)
}

/// The text answer of a query of a map of resolution `r`.
fn text(report: &QueryReport, r: f64) -> String {
    match report {
        QueryReport::At(q) => {
            let [x, y, z] = q.point;
            format!(
                "({x}, {y}, {z}): {} (count {})",
                match q.state {
                    Some(s) => format!("{s:?}").to_lowercase(),
                    None if q.occupied => "occupied".into(),
                    None => "free or unknown".into(),
                },
                q.count
            )
        }
        QueryReport::RayHit(h) => format!(
            "hit at {:.3} m: voxel {:?} centred at {:?} (count {}), accurate to one voxel ({r} m)",
            h.distance_m, h.voxel.key, h.voxel.center, h.voxel.count
        ),
        QueryReport::RayMiss(m) => format!("no occupied voxel within {} m", m.max_range_m),
        QueryReport::Radius(q) => {
            let [x, y, z] = q.center;
            let mut text = format!(
                "{} occupied voxels within {} m of ({x}, {y}, {z})",
                q.count, q.radius_m
            );
            for v in q.voxels.iter().take(20) {
                let p = v.center;
                text.push_str(&format!(
                    "\n  ({:.3}, {:.3}, {:.3}) count {}",
                    p[0], p[1], p[2], v.count
                ));
            }
            if q.voxels.len() > 20 {
                text.push_str("\n  ...");
            }
            text
        }
        QueryReport::Segment(q) => {
            let mut text = format!(
                "segment {}",
                if q.free {
                    "free of occupied voxels"
                } else {
                    "blocked"
                }
            );
            if let Some(k) = q.known_free {
                text.push_str(if k {
                    "; every voxel on it is known free"
                } else {
                    "; not every voxel on it is known free (unknown or occupied ones)"
                });
            }
            text
        }
    }
}
