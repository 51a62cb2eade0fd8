//! [`run_team_pipeline`]: the whole `olmap team` / `olmap demo` pipeline — map the merged
//! store as a team, optionally every robot alone, compare with the ground truth, write the
//! joint map, poses, store, solo maps and the reports — for every front end to call.

use std::path::{Path, PathBuf};

use super::report::{SoloRun, TeamReport};
use super::{map_solo, map_team, ScanStore, TeamMap, TeamParams};
use crate::error::{Error, Result};
use crate::file::write_atomic;
use crate::geometry::PoseList;
use crate::mapping::evaluate;
use crate::occupancy::{self, OccupancyList};
use crate::progress::{Progress, Stage};

/// What a team run is asked to do.
#[derive(Debug, Clone, Copy)]
pub struct TeamJob<'a> {
    /// Every robot's records.
    pub store: &'a ScanStore,
    /// The ground truth `T_world_scan`, named as [`super::scan_name`] names the scans.
    pub truth: Option<&'a PoseList>,
    /// The team mapper's parameters.
    pub params: &'a TeamParams,
    /// The output folder (created if missing).
    pub out: &'a Path,
    /// Also map every robot alone and compare.
    pub solo: bool,
}

/// What [`run_team_pipeline`] built, reported and wrote.
#[derive(Debug, Clone)]
pub struct TeamRun {
    /// The report (also in `OUT/report.json`).
    pub report: TeamReport,
    /// The joint map.
    pub team: TeamMap,
    /// Every robot alone (empty unless asked).
    pub solo: Vec<SoloRun>,
    /// The HTML report written beside `report.json` (with the `render` feature).
    pub html: Option<PathBuf>,
}

/// Writes the joint map as `.olm` (checked to read back equal), `.bt` and `.ply` (voxel
/// centres with counts as intensity, coloured by height with the `render` feature).
fn write_maps(out: &Path, stem: &str, map: &OccupancyList) -> Result<()> {
    let olm = out.join(format!("{stem}.olm"));
    occupancy::write_map(&olm, map)?;
    if occupancy::read_map(&olm)?.map != *map {
        return Err(Error::Write {
            path: olm,
            format: "olmap .olm",
            reason: "the map read back differs".into(),
        });
    }
    occupancy::write_map(out.join(format!("{stem}.bt")), map)?;
    #[cfg(feature = "render")]
    let cloud = crate::render::height_coloured_cloud(map, None);
    #[cfg(not(feature = "render"))]
    let cloud = map.to_cloud();
    crate::io::write_cloud(
        out.join(format!("{stem}.ply")),
        &cloud,
        &crate::io::WriteOptions::default(),
    )
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))
}

/// Maps every robot alone ([`Stage::SoloMaps`]) and writes `OUT/solo/ROBOT.olm` and
/// `ROBOT_poses.txt`.
fn solo_runs(job: &TeamJob<'_>, progress: Progress<'_>) -> Result<Vec<SoloRun>> {
    let total = job.store.len();
    let runs = map_solo(job.store, job.params, |done, _| {
        progress(Stage::SoloMaps, done, total)
    })?;
    let dir = job.out.join("solo");
    create_dir(&dir)?;
    let mut out = Vec::new();
    for (robot, map) in runs {
        let name = job.store.robot_name(robot);
        occupancy::write_map(dir.join(format!("{name}.olm")), &map.build.map)?;
        let poses = map.poses();
        poses.write_path(dir.join(format!("{name}_poses.txt")))?;
        let evaluation = job.truth.map(|t| evaluate(&poses, t)).transpose()?;
        out.push(SoloRun {
            robot,
            map,
            evaluation,
        });
    }
    Ok(out)
}

/// Runs a [`TeamJob`]: the team map ([`Stage::TeamMap`]) written as `OUT/team.olm`,
/// `.ply`, `.bt` with `team_poses.txt` and the merged `team.store`; with `solo`, every
/// robot alone under `OUT/solo/`; then `report.json` and (with the `render` feature)
/// `report.html`. Every file is written atomically.
pub fn run_team_pipeline(job: &TeamJob<'_>, progress: Progress<'_>) -> Result<TeamRun> {
    create_dir(job.out)?;
    let total = job.store.len();
    let team = map_team(job.store, job.params, |done, _| {
        progress(Stage::TeamMap, done, total)
    })?;
    write_maps(job.out, "team", &team.build.map)?;
    let team_poses = team.poses();
    team_poses.write_path(job.out.join("team_poses.txt"))?;
    job.store.write(job.out.join("team.store"))?;
    let team_eval = job.truth.map(|t| evaluate(&team_poses, t)).transpose()?;
    let solo = if job.solo {
        solo_runs(job, progress)?
    } else {
        Vec::new()
    };
    let report = TeamReport::new(job.store, &team, team_eval.as_ref(), &solo, job.solo);
    let path = job.out.join("report.json");
    write_atomic(&path, "JSON", |w| {
        serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)
    })?;
    #[cfg(feature = "render")]
    let html = Some(super::html::write_team_html(
        job.store, &team, &solo, &report, &path,
    )?);
    #[cfg(not(feature = "render"))]
    let html = None;
    Ok(TeamRun {
        report,
        team,
        solo,
        html,
    })
}
