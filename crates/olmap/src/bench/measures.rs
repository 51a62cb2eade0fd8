//! The measures of the benchmark set, each timed `repeat` times (median reported).

use std::path::Path;
use std::time::Instant;

use super::{
    ErrorBench, InsertionBench, LocalisationBench, MappingBench, OverlapBench, SearchBench,
    ThreadsBench,
};
use crate::align::{self, RegisterParams, SearchMode, SearchParams};
use crate::cloud::PointCloud;
use crate::geometry::{Pose, PoseError, PoseList};
use crate::io::{self, ReadOptions};
use crate::mapping::{build_map, MapParams, ScanInput};
use crate::occupancy::{OccupancyList, SensorModel};
use crate::{Error, Result};

/// One alignment problem: source, target, the true `T_target_source`, the search.
pub(super) struct Pair {
    name: String,
    source: PointCloud,
    target: PointCloud,
    truth: Pose,
    search: SearchParams,
}

fn mode_name(m: SearchMode) -> &'static str {
    match m {
        SearchMode::MultiResolution => "multires",
        SearchMode::Exact => "exact",
    }
}

/// The search modes.
const MODES: [SearchMode; 2] = [SearchMode::MultiResolution, SearchMode::Exact];

/// 3DTK scan001 onto scan000 (data README §1.7) when `data` holds them, else two
/// simulated office scans.
pub(super) fn alignment_pair(data: Option<&Path>) -> Result<Pair> {
    if let Some(d) = data.filter(|d| d.join("3dtk_dat/scan000.3d").is_file()) {
        let valid = ReadOptions {
            uos_valid_only: true,
            ..Default::default()
        };
        let read = |i: usize| -> Result<PointCloud> {
            let p = d.join(format!("3dtk_dat/scan00{i}.3d"));
            Ok(io::read_cloud_with(&p, &valid)?.cloud)
        };
        let refs = PoseList::read_path(d.join("3dtk_dat/reference_poses_rh_m.txt"))?;
        return Ok(Pair {
            name: "3dtk_001-000".into(),
            source: read(1)?,
            target: read(0)?,
            truth: refs.poses[0].pose.inverse() * refs.poses[1].pose,
            search: SearchParams::default(),
        });
    }
    let world = crate::sim::office(3);
    let scanner = crate::sim::MirrorScanner::enhanced();
    let sensor = crate::sim::RobotModel::default().sensor_pose();
    let t_target = Pose::from_xyz_ypr(4.0, 7.5, 0.0, 0.3, 0.0, 0.0) * sensor;
    let t_source = Pose::from_xyz_ypr(5.3, 7.3, 0.0, 1.1, 0.0, 0.0) * sensor;
    Ok(Pair {
        name: "sim_office".into(),
        source: scanner.scan(&world, &[], &t_source, 3, 1),
        target: scanner.scan(&world, &[], &t_target, 3, 0),
        truth: t_target.inverse() * t_source,
        search: SearchParams {
            max_range: 8.0,
            ..Default::default()
        },
    })
}

/// The median of some timings.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Runs `f` `repeat` times (at least once): its last result, and the median of the
/// seconds it reports.
fn repeated<T>(repeat: usize, mut f: impl FnMut() -> Result<(T, f64)>) -> Result<(T, f64)> {
    let mut times = Vec::with_capacity(repeat);
    let (mut v, s) = f()?;
    times.push(s);
    for _ in 1..repeat.max(1) {
        let (next, s) = f()?;
        times.push(s);
        v = next;
    }
    Ok((v, median(times)))
}

fn errors(e: &PoseError) -> ErrorBench {
    ErrorBench {
        translation_error_m: e.translation_m,
        rotation_error_deg: e.rotation_deg,
    }
}

/// Ray-traced insertion of simulated office scans at 0.05 m.
pub(super) fn insertion(quick: bool, repeat: usize) -> Result<InsertionBench> {
    let world = crate::sim::office(5);
    let scanner = crate::sim::MirrorScanner::enhanced();
    let sensor = crate::sim::RobotModel::default().sensor_pose();
    let scans: Vec<(PointCloud, Pose)> = (0..if quick { 1 } else { 4 })
        .map(|i| {
            let pose = Pose::from_xyz_ypr(3.0 + 2.5 * i as f64, 7.5, 0.0, 0.5 * i as f64, 0.0, 0.0)
                * sensor;
            (scanner.scan(&world, &[], &pose, 5, i as u64), pose)
        })
        .collect();
    let model = SensorModel {
        max_range: 8.0,
        ..Default::default()
    };
    let points: usize = scans.iter().map(|(c, _)| c.len()).sum();
    let (map, s) = repeated(repeat, || {
        let mut map = OccupancyList::new(0.05)?;
        let t = Instant::now();
        for (cloud, pose) in &scans {
            map.insert_scan(cloud, pose, &model)?;
        }
        Ok((map, t.elapsed().as_secs_f64()))
    })?;
    Ok(InsertionBench {
        resolution: 0.05,
        points,
        seconds: s,
        points_per_second: points as f64 / s,
        map_voxels: map.len(),
    })
}

/// Registers the pair: the result, its error, and the seconds of the whole call (target
/// preparation and search).
fn register(p: &Pair, mode: SearchMode) -> Result<(align::Registration, PoseError, f64)> {
    let params = RegisterParams {
        search: SearchParams {
            search: mode,
            ..p.search.clone()
        },
        refine: None,
        trust: Default::default(),
    };
    let t = Instant::now();
    let r = align::register(&p.source, &p.target, &params)?;
    let total = t.elapsed().as_secs_f64();
    let e = PoseError::between(&r.pose, &p.truth);
    Ok((r, e, total))
}

/// The pair aligned by the multi-resolution search, and its overlap evaluation rates.
pub(super) fn alignment(p: &Pair, repeat: usize) -> Result<(SearchBench, OverlapBench)> {
    let mode = SearchMode::MultiResolution;
    let mut totals = Vec::new();
    let ((r, e), search) = repeated(repeat, || {
        let (r, e, total) = register(p, mode)?;
        totals.push(total);
        let s = r.search.seconds;
        Ok(((r, e), s))
    })?;
    let total = median(totals);
    let s = &r.search;
    // Overlap evaluations: poses scored, and voxel lookups (poses x scan voxels).
    let lookups: usize = s.levels.iter().map(|l| l.evaluated * l.scan_voxels).sum();
    let overlap = OverlapBench {
        poses_per_second: s.evaluated as f64 / search,
        voxel_lookups_per_second: lookups as f64 / search,
    };
    let row = SearchBench {
        name: p.name.clone(),
        mode: mode_name(mode).into(),
        seconds: search,
        total_seconds: total,
        evaluated: s.evaluated,
        score: s.score,
        overlap_fraction: Some(s.overlap_fraction),
        exact: s.exact,
        error: errors(&e),
    };
    Ok((row, overlap))
}

/// Both search modes (and the exhaustive search) on a problem small enough for the exact
/// one: a simulated room scan against another over the whole target, every heading, at
/// 0.3 m (larger problems: see README).
pub(super) fn modes(repeat: usize) -> Result<Vec<SearchBench>> {
    let pts = crate::fixtures::furnished_room(0.05);
    let t_target = Pose::from_xyz_ypr(6.0, 4.5, 1.2, 0.4, 0.0, 0.0);
    let motion = Pose::from_xyz_ypr(0.9, -0.4, 0.0, 2.0, 0.0, 0.0);
    let range = 4.0;
    let target = crate::fixtures::scan_of(&pts, &t_target, range);
    let source = crate::fixtures::scan_of(&pts, &(t_target * motion), range);
    let base = SearchParams {
        resolution: 0.3,
        levels: 3,
        dof: crate::align::Dof::XyYaw,
        max_scan_voxels: 300,
        max_range: range,
        ..Default::default()
    };
    let target = crate::align::SearchTarget::from_cloud(&target, base.resolution, base.levels)?;
    let row = |mode: &str, a: &align::Alignment, seconds: f64| SearchBench {
        name: "sim_room_0.3m".into(),
        mode: mode.into(),
        seconds,
        total_seconds: seconds,
        evaluated: a.evaluated,
        score: a.score,
        overlap_fraction: None,
        exact: a.exact,
        error: errors(&PoseError::between(&a.pose, &motion)),
    };
    let mut rows = Vec::new();
    for mode in MODES {
        let params = SearchParams {
            search: mode,
            ..base.clone()
        };
        let (a, seconds) = repeated(repeat, || {
            let a = align::global_search(&source, &target, &params)?;
            let s = a.seconds;
            Ok((a, s))
        })?;
        rows.push(row(mode_name(mode), &a, seconds));
    }
    let (a, seconds) = repeated(repeat, || {
        let a = align::exhaustive_search(&source, &target, &base)?;
        let s = a.seconds;
        Ok((a, s))
    })?;
    rows.push(row("exhaustive", &a, seconds));
    Ok(rows)
}

/// Localisation of the thesis scan in its map (at half resolution when `quick`).
pub(super) fn localisation(quick: bool, repeat: usize) -> Result<Vec<LocalisationBench>> {
    let b = crate::sim::thesis_localisation(7, 16)?;
    let (map, params) = if quick {
        let coarse = b.map.downsample(2)?;
        let mut p = b.params.clone();
        p.max_scan_voxels = 2000;
        (coarse, p)
    } else {
        (b.map.clone(), b.params.clone())
    };
    // The exact search is left out: at 0.02 m its proof takes minutes (README).
    let mode = SearchMode::MultiResolution;
    let params = RegisterParams {
        search: SearchParams {
            search: mode,
            ..params
        },
        refine: None,
        trust: Default::default(),
    };
    let mut totals = Vec::new();
    let (r, search) = repeated(repeat, || {
        let t = Instant::now();
        let r = align::localize(&b.scan, &map, &params)?;
        totals.push(t.elapsed().as_secs_f64());
        let s = r.search.seconds;
        Ok((r, s))
    })?;
    let e = PoseError::between(&r.pose, &b.truth);
    Ok(vec![LocalisationBench {
        name: if quick { "thesis_quick" } else { "thesis" }.into(),
        mode: mode_name(mode).into(),
        seconds: search,
        total_seconds: median(totals),
        evaluated: r.search.evaluated,
        score: r.search.score,
        resolution: map.resolution(),
        map_voxels: map.len(),
        scan_voxels: r.search.scan_voxels,
        area_m2: b.area_m2,
        exact: r.search.exact,
        error: errors(&e),
    }])
}

/// Batch map building of a simulated hall.
pub(super) fn mapping(quick: bool, repeat: usize) -> Result<MappingBench> {
    let world = crate::fixtures::hall(0.15);
    let n = if quick { 4 } else { 10 };
    let scans: Vec<ScanInput> = crate::fixtures::hall_trajectory(n, 0.9)
        .iter()
        .enumerate()
        .map(|(i, t)| ScanInput {
            name: format!("stop{i:02}"),
            cloud: crate::fixtures::scan_of(&world, t, 8.0),
            odometry: None,
        })
        .collect();
    let (m, s) = repeated(repeat, || {
        let t = Instant::now();
        let m = build_map(&scans, &MapParams::default(), |_, _| {})?;
        Ok((m, t.elapsed().as_secs_f64()))
    })?;
    Ok(MappingBench {
        scans: n,
        seconds: s,
        seconds_per_scan: s / n as f64,
        map_voxels: m.map.len(),
    })
}

/// The pair's search on 1, 2, 4, ... threads and on `max_threads`.
pub(super) fn scaling(p: &Pair, max_threads: usize, repeat: usize) -> Result<Vec<ThreadsBench>> {
    // Never more threads than the machine runs at once (a pool of 100,000 exhausts it).
    let max_threads = crate::limits::thread_count(max_threads.max(1)).threads;
    let mut counts = vec![1];
    while counts.last().copied().unwrap_or(1) * 2 <= max_threads {
        counts.push(counts.last().copied().unwrap_or(1) * 2);
    }
    if counts.last() != Some(&max_threads) {
        counts.push(max_threads);
    }
    let mut rows = Vec::new();
    let mut base = None;
    for n in counts {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| {
                Error::InvalidArgument(format!("cannot build a pool of {n} threads: {e}"))
            })?;
        let (_, s) = repeated(repeat, || {
            let (r, _, _) = pool.install(|| register(p, SearchMode::MultiResolution))?;
            Ok(((), r.search.seconds))
        })?;
        let b = *base.get_or_insert(s);
        rows.push(ThreadsBench {
            threads: n,
            seconds: s,
            speedup: b / s,
        });
    }
    Ok(rows)
}
