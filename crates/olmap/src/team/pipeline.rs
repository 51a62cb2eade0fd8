//! [`run_team_pipeline`]: the whole `olmap team` / `olmap demo` pipeline — map the merged
//! store as a team, optionally every robot alone, compare with the ground truth, write the
//! joint map, poses, store, solo maps and the reports — for every front end to call.

use std::path::{Path, PathBuf};

use super::report::{SoloRun, TeamReport};
use super::{map_solo, map_team, ScanStore, TeamMap, TeamParams};
use crate::error::{Error, Result};
use crate::file::{html_path_beside, write_atomic, OutputSet};
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
fn write_maps(olm: &Path, bt: &Path, ply: &Path, map: &OccupancyList) -> Result<()> {
    occupancy::write_map(olm, map)?;
    if occupancy::read_map(olm)?.map != *map {
        return Err(Error::Write {
            path: olm.to_path_buf(),
            format: "olmap .olm",
            reason: "the map read back differs".into(),
        });
    }
    occupancy::write_map(bt, map)?;
    #[cfg(feature = "render")]
    let cloud = crate::render::height_coloured_cloud(map, None);
    #[cfg(not(feature = "render"))]
    let cloud = map.to_cloud();
    crate::io::write_cloud(ply, &cloud, &crate::io::WriteOptions::default())
}

/// The files a team run writes into its output folder, with their formats.
const TEAM_FILES: [(&str, &str); 6] = [
    ("team.olm", "olmap .olm"),
    ("team.bt", "OctoMap .bt"),
    ("team.ply", "PLY"),
    ("team_poses.txt", "pose list"),
    ("team.store", "olmap scan store"),
    ("report.json", "JSON"),
];

/// Declares the outputs of a team run into `out` (created if missing) in `set`, each
/// checked now: the files of [`run_team_pipeline`], `solo/` (replaced whole, or removed
/// when `solo` is off: an older run's solo maps would not match the new report), and
/// `report.html` (removed without the `render` feature, for the same reason).
pub(crate) fn declare_team_outputs(set: &mut OutputSet, out: &Path, solo: bool) -> Result<()> {
    set.folder(out)?;
    for (name, format) in TEAM_FILES {
        set.file(&out.join(name), format)?;
    }
    let html = html_path_beside(&out.join("report.json"));
    if cfg!(feature = "render") {
        set.file(&html, "HTML report")?;
    } else {
        set.remove(&html)?;
    }
    let solo_dir = out.join("solo");
    if solo {
        set.dir(&solo_dir, "solo maps folder")?;
    } else {
        set.remove(&solo_dir)?;
    }
    Ok(())
}

/// Maps every robot alone ([`Stage::SoloMaps`]) and compares each with `truth`.
fn solo_runs(
    store: &ScanStore,
    params: &TeamParams,
    truth: Option<&PoseList>,
    progress: Progress<'_>,
) -> Result<Vec<SoloRun>> {
    let total = store.len();
    let runs = map_solo(store, params, |done, _| {
        progress(Stage::SoloMaps, done, total)
    })?;
    let mut out = Vec::new();
    for (robot, map) in runs {
        let evaluation = truth.map(|t| evaluate(&map.poses(), t)).transpose()?;
        out.push(SoloRun {
            robot,
            map,
            evaluation,
        });
    }
    Ok(out)
}

/// Writes `ROBOT.olm` and `ROBOT_poses.txt` of every solo run into `dir`.
fn write_solo(store: &ScanStore, runs: &[SoloRun], dir: &Path) -> Result<()> {
    for run in runs {
        let name = store.robot_name(run.robot);
        occupancy::write_map(dir.join(format!("{name}.olm")), &run.map.build.map)?;
        run.map
            .poses()
            .write_path(dir.join(format!("{name}_poses.txt")))?;
    }
    Ok(())
}

/// What [`run_team_in_memory`] computed: [`TeamRun`] without files.
#[derive(Debug, Clone)]
pub struct TeamResult {
    /// The report, as [`run_team_pipeline`] writes it to `report.json`.
    pub report: TeamReport,
    /// The joint map.
    pub team: TeamMap,
    /// Every robot alone (empty unless asked).
    pub solo: Vec<SoloRun>,
}

/// [`run_team_pipeline`] in memory: the team map ([`Stage::TeamMap`]), with `solo` every
/// robot alone ([`Stage::SoloMaps`]), their errors against `truth` and the report, with no
/// file written (for callers that keep the results, such as the Python package).
pub fn run_team_in_memory(
    store: &ScanStore,
    truth: Option<&PoseList>,
    params: &TeamParams,
    solo: bool,
    progress: Progress<'_>,
) -> Result<TeamResult> {
    let total = store.len();
    let team = map_team(store, params, |done, _| {
        progress(Stage::TeamMap, done, total)
    })?;
    let team_eval = truth.map(|t| evaluate(&team.poses(), t)).transpose()?;
    let solo_runs = if solo {
        solo_runs(store, params, truth, progress)?
    } else {
        Vec::new()
    };
    let report = TeamReport::new(store, &team, team_eval.as_ref(), &solo_runs, solo);
    Ok(TeamResult {
        report,
        team,
        solo: solo_runs,
    })
}

/// Runs a [`TeamJob`]: the team map ([`Stage::TeamMap`]) written as `OUT/team.olm`,
/// `.ply`, `.bt` with `team_poses.txt` and the merged `team.store`; with `solo`, every
/// robot alone under `OUT/solo/`; then `report.json` and (with the `render` feature)
/// `report.html`. Every output path is checked before mapping, and the outputs are written
/// as one [`OutputSet`]: after an error or a kill the folder holds the older run's complete
/// set (or nothing), never a mixture; an older `solo/` is removed by a run without it.
pub fn run_team_pipeline(job: &TeamJob<'_>, progress: Progress<'_>) -> Result<TeamRun> {
    let mut set = OutputSet::new();
    declare_team_outputs(&mut set, job.out, job.solo)?;
    let run = team_run_into(&mut set, job, progress)?;
    set.commit()?;
    Ok(run)
}

/// [`run_team_pipeline`] writing into a set declared by [`declare_team_outputs`], not
/// committed: for pipelines with more outputs (the demo's dataset).
pub(crate) fn team_run_into(
    set: &mut OutputSet,
    job: &TeamJob<'_>,
    progress: Progress<'_>,
) -> Result<TeamRun> {
    let total = job.store.len();
    let team = map_team(job.store, job.params, |done, _| {
        progress(Stage::TeamMap, done, total)
    })?;
    let staged = |set: &mut OutputSet, name: &str| set.path(&job.out.join(name));
    write_maps(
        &staged(set, "team.olm")?,
        &staged(set, "team.bt")?,
        &staged(set, "team.ply")?,
        &team.build.map,
    )?;
    let team_poses = team.poses();
    team_poses.write_path(staged(set, "team_poses.txt")?)?;
    job.store.write(staged(set, "team.store")?)?;
    let team_eval = job.truth.map(|t| evaluate(&team_poses, t)).transpose()?;
    let solo = if job.solo {
        let dir = staged(set, "solo")?;
        let runs = solo_runs(job.store, job.params, job.truth, progress)?;
        write_solo(job.store, &runs, &dir)?;
        runs
    } else {
        Vec::new()
    };
    let report = TeamReport::new(job.store, &team, team_eval.as_ref(), &solo, job.solo);
    write_atomic(&staged(set, "report.json")?, "JSON", |w| {
        serde_json::to_writer_pretty(&mut *w, &report).map_err(std::io::Error::other)
    })?;
    #[cfg(feature = "render")]
    let html = {
        let html = html_path_beside(&job.out.join("report.json"));
        super::html::write_team_html(job.store, &team, &solo, &report, &set.path(&html)?)?;
        Some(html)
    };
    #[cfg(not(feature = "render"))]
    let html = None;
    Ok(TeamRun {
        report,
        team,
        solo,
        html,
    })
}
