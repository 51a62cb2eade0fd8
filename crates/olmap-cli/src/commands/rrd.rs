//! Rerun recordings (`.rrd`): a map's voxels, scan positions and robot paths for the Rerun
//! viewer (`rerun out.rrd`). Built only with the `rerun` cargo feature (the `rerun` crate
//! brings about 490 crates); without it, asking for `.rrd` output is a clear error.

use std::path::Path;

use olmap::geometry::PoseList;
use olmap::occupancy::OccupancyList;

/// Whether `path` asks for a Rerun recording.
pub fn is_rrd(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("rrd"))
}

/// The robot a scan name belongs to: the part before the first `/` (`robot0/scan003`), or
/// `scans` for names without one.
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
fn robot_of(name: &str) -> &str {
    name.split_once('/').map_or("scans", |(r, _)| r)
}

/// Writes `map` (voxel centres coloured by height, as points of half a voxel's radius) and,
/// when given, the scan positions of `poses` (labelled) and one path per robot to a Rerun
/// recording at `path`, z up.
#[cfg(feature = "rerun")]
pub fn write_rrd(path: &Path, map: &OccupancyList, poses: Option<&PoseList>) -> anyhow::Result<()> {
    use anyhow::Context;
    let rec = rerun::RecordingStreamBuilder::new("olmap")
        .save(path)
        .with_context(|| format!("{}: cannot start a Rerun recording", path.display()))?;
    rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
    let cloud = olmap::render::height_coloured_cloud(map, None);
    let points: Vec<[f32; 3]> = cloud.points().iter().map(|p| [p.x, p.y, p.z]).collect();
    let colours: Vec<rerun::Color> = cloud
        .colors()
        .unwrap_or_default()
        .iter()
        .map(|c| rerun::Color::from_rgb(c[0], c[1], c[2]))
        .collect();
    rec.log(
        "world/map",
        &rerun::Points3D::new(points)
            .with_colors(colours)
            .with_radii([0.5 * map.resolution() as f32]),
    )?;
    if let Some(poses) = poses {
        let position = |p: &olmap::geometry::NamedPose| {
            let t = p.pose.translation();
            [t.x as f32, t.y as f32, t.z as f32]
        };
        rec.log(
            "world/scans",
            &rerun::Points3D::new(poses.poses.iter().map(position))
                .with_labels(poses.poses.iter().map(|p| p.name.clone()))
                .with_radii([0.1f32]),
        )?;
        let mut robots: Vec<&str> = poses.poses.iter().map(|p| robot_of(&p.name)).collect();
        robots.sort_unstable();
        robots.dedup();
        for robot in robots {
            let strip: Vec<[f32; 3]> = poses
                .poses
                .iter()
                .filter(|p| robot_of(&p.name) == robot)
                .map(position)
                .collect();
            rec.log(
                format!("world/paths/{robot}"),
                &rerun::LineStrips3D::new([strip]),
            )?;
        }
    }
    rec.flush_blocking()
        .with_context(|| format!("{}: cannot write the Rerun recording", path.display()))?;
    Ok(())
}

/// Without the `rerun` feature: an error saying how to get it.
#[cfg(not(feature = "rerun"))]
pub fn write_rrd(
    path: &Path,
    _map: &OccupancyList,
    _poses: Option<&PoseList>,
) -> anyhow::Result<()> {
    anyhow::bail!(
        "{}: this olmap was built without Rerun support; rebuild with `cargo build --release \
         --features rerun` (adds the rerun crate), or export a PLY coloured by height",
        path.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rrd_outputs_and_robot_names() {
        assert!(is_rrd(Path::new("out/map.rrd")));
        assert!(is_rrd(Path::new("MAP.RRD")));
        assert!(!is_rrd(Path::new("map.ply")));
        assert_eq!(robot_of("robot2/scan004"), "robot2");
        assert_eq!(robot_of("scan004"), "scans");
    }
}
