//! `olmap query`: point, ray, radius and segment queries of a map.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;
use clap::{ArgGroup, Args};
use nalgebra::{Point3, Vector3};
use serde_json::json;

use super::render::read;
use crate::args::parse_numbers;

/// Arguments of `olmap query`.
#[derive(Args)]
#[command(group(ArgGroup::new("what").required(true).args(["at", "ray", "radius", "segment"])))]
pub struct QueryArgs {
    /// The map (.olm or OctoMap .bt).
    pub map: PathBuf,
    /// Is the voxel holding this point occupied? X,Y,Z (m).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub at: Option<String>,
    /// The first occupied voxel along a ray from X,Y,Z in direction DX,DY,DZ, and its
    /// distance.
    #[arg(long, value_name = "X,Y,Z,DX,DY,DZ", allow_hyphen_values = true)]
    pub ray: Option<String>,
    /// The occupied voxels whose centres lie within R metres of X,Y,Z.
    #[arg(long, value_name = "X,Y,Z,R", allow_hyphen_values = true)]
    pub radius: Option<String>,
    /// Is the segment between two points free of occupied voxels?
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
    let r = map.resolution();
    let key_json = |k: olmap::geometry::VoxelKey| {
        let c = map.center(k);
        json!({"key": [k.x, k.y, k.z], "center": [c.x, c.y, c.z], "count": map.count(k)})
    };
    let (value, text) = if let Some(s) = &a.at {
        let [x, y, z] = parse_numbers::<3>(s, "--at")?;
        let p = Point3::new(x, y, z);
        let count = map.count_at(&p);
        let occupied = count >= a.min_count.max(1);
        (
            json!({"query": "at", "point": [x, y, z], "occupied": occupied, "count": count}),
            format!(
                "({x}, {y}, {z}): {} (count {count})",
                if occupied {
                    "occupied"
                } else {
                    "free or unknown"
                }
            ),
        )
    } else if let Some(s) = &a.ray {
        let [x, y, z, dx, dy, dz] = parse_numbers::<6>(s, "--ray")?;
        let hit = map.cast_ray(
            &Point3::new(x, y, z),
            &Vector3::new(dx, dy, dz),
            a.max_range,
            a.min_count,
        )?;
        match hit {
            Some(h) => (
                json!({"query": "ray", "hit": true, "distance_m": h.distance,
                       "point": [h.point.x, h.point.y, h.point.z], "voxel": key_json(h.key)}),
                format!(
                    "hit at {:.3} m: voxel {:?} centred at {:?} (count {}), accurate to one voxel ({r} m)",
                    h.distance, [h.key.x, h.key.y, h.key.z], map.center(h.key).coords.as_slice(), h.count
                ),
            ),
            None => (
                json!({"query": "ray", "hit": false, "max_range_m": a.max_range}),
                format!("no occupied voxel within {} m", a.max_range),
            ),
        }
    } else if let Some(s) = &a.radius {
        let [x, y, z, rad] = parse_numbers::<4>(s, "--radius")?;
        let near: Vec<_> = map
            .occupied_within(&Point3::new(x, y, z), rad)?
            .into_iter()
            .filter(|(_, c)| *c >= a.min_count.max(1))
            .collect();
        let mut text = format!(
            "{} occupied voxels within {rad} m of ({x}, {y}, {z})",
            near.len()
        );
        for (k, c) in near.iter().take(20) {
            let p = map.center(*k);
            text.push_str(&format!(
                "\n  ({:.3}, {:.3}, {:.3}) count {c}",
                p.x, p.y, p.z
            ));
        }
        if near.len() > 20 {
            text.push_str("\n  ...");
        }
        (
            json!({"query": "radius", "center": [x, y, z], "radius_m": rad, "count": near.len(),
                   "voxels": near.iter().map(|(k, _)| key_json(*k)).collect::<Vec<_>>()}),
            text,
        )
    } else if let Some(s) = &a.segment {
        let [x1, y1, z1, x2, y2, z2] = parse_numbers::<6>(s, "--segment")?;
        let free = map.segment_is_free(
            &Point3::new(x1, y1, z1),
            &Point3::new(x2, y2, z2),
            a.min_count,
        )?;
        (
            json!({"query": "segment", "from": [x1, y1, z1], "to": [x2, y2, z2], "free": free}),
            format!("segment {}", if free { "free" } else { "blocked" }),
        )
    } else {
        bail!("give one of --at, --ray, --radius, --segment");
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!("{text}");
    }
    Ok(ExitCode::SUCCESS)
}
