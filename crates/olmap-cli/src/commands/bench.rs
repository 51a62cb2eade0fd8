//! `olmap bench`: the standard benchmark set on the shared data (when present) and the
//! simulator, as a table or JSON.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use olmap::align::{self, RegisterParams, SearchMode, SearchParams};
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError, PoseList};
use olmap::io::{self, ReadOptions};
use olmap::mapping::{build_map, MapParams, ScanInput};
use olmap::occupancy::{OccupancyList, SensorModel};
use serde_json::{json, Value};

use crate::args::progress;

/// Arguments of `olmap bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// The shared data folder (default: $OLMAP_DATA, else ../shared/data); its 3DTK pair
    /// is aligned when present, a simulated pair otherwise.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// A small, fast set (for tests and smoke runs): the simulated pair only, a smaller
    /// thesis map at 0.05 m, fewer scans. Its numbers are not comparable with a full run.
    #[arg(long)]
    pub quick: bool,
    /// Largest thread count of the scaling run (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Runs of every timed measure; the median is reported (default: 5, 1 with --quick).
    /// A 2-core machine varies by 10-30 % from run to run.
    #[arg(long)]
    pub repeat: Option<usize>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// One alignment problem: source, target, the true `T_target_source`, the search.
struct Pair {
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

fn data_dir(a: &BenchArgs) -> Option<PathBuf> {
    if a.quick {
        return None;
    }
    a.data
        .clone()
        .or_else(|| std::env::var_os("OLMAP_DATA").map(PathBuf::from))
        .or_else(|| Some(PathBuf::from("../shared/data")))
        .filter(|d| d.join("3dtk_dat/scan000.3d").is_file())
}

/// 3DTK scan001 onto scan000 (data README §1.7), or two simulated office scans.
fn alignment_pair(a: &BenchArgs) -> anyhow::Result<Pair> {
    if let Some(d) = data_dir(a) {
        let valid = ReadOptions {
            uos_valid_only: true,
            ..Default::default()
        };
        let read = |i: usize| -> anyhow::Result<PointCloud> {
            let p = d.join(format!("3dtk_dat/scan00{i}.3d"));
            Ok(io::read_cloud_with(&p, &valid)
                .with_context(|| format!("reading {}", p.display()))?
                .cloud)
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
    let world = olmap::sim::office(3);
    let scanner = olmap::sim::MirrorScanner::enhanced();
    let sensor = olmap::sim::RobotModel::default().sensor_pose();
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

/// Runs `f` `repeat` times: its last result, and the median of the seconds it reports.
fn repeated<T>(
    repeat: usize,
    mut f: impl FnMut() -> anyhow::Result<(T, f64)>,
) -> anyhow::Result<(T, f64)> {
    let mut times = Vec::with_capacity(repeat);
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let (v, s) = f()?;
        times.push(s);
        last = Some(v);
    }
    let last = last.ok_or_else(|| anyhow::anyhow!("no run"))?;
    Ok((last, median(times)))
}

fn errors(e: &PoseError) -> Value {
    json!({"translation_error_m": e.translation_m, "rotation_error_deg": e.rotation_deg})
}

/// Peak resident memory of this process (VmHWM), bytes; `None` off Linux.
fn peak_memory() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn insertion(quick: bool, repeat: usize) -> anyhow::Result<Value> {
    let world = olmap::sim::office(5);
    let scanner = olmap::sim::MirrorScanner::enhanced();
    let sensor = olmap::sim::RobotModel::default().sensor_pose();
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
    Ok(
        json!({"resolution": 0.05, "points": points, "seconds": s, "points_per_second": points as f64 / s,
              "map_voxels": map.len()}),
    )
}

/// Registers the pair: the result, its error, and the seconds of the whole call (target
/// preparation and search).
fn register(p: &Pair, mode: SearchMode) -> anyhow::Result<(align::Registration, PoseError, f64)> {
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

fn alignment(p: &Pair, repeat: usize) -> anyhow::Result<(Value, Value)> {
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
    let overlap = json!({"poses_per_second": s.evaluated as f64 / search,
                         "voxel_lookups_per_second": lookups as f64 / search});
    let mut row = json!({"name": p.name, "mode": mode_name(mode), "seconds": search,
                         "total_seconds": total, "evaluated": s.evaluated, "score": s.score,
                         "overlap_fraction": s.overlap_fraction, "exact": s.exact});
    merge(&mut row, errors(&e));
    Ok((row, overlap))
}

/// Both search modes (and the exhaustive search) on a problem small enough for the exact
/// one: a simulated room scan against another over the whole target, every heading, at
/// 0.3 m (larger problems: see README).
fn modes(repeat: usize) -> anyhow::Result<Vec<Value>> {
    let pts = olmap::fixtures::furnished_room(0.05);
    let t_target = Pose::from_xyz_ypr(6.0, 4.5, 1.2, 0.4, 0.0, 0.0);
    let motion = Pose::from_xyz_ypr(0.9, -0.4, 0.0, 2.0, 0.0, 0.0);
    let range = 4.0;
    let target = olmap::fixtures::scan_of(&pts, &t_target, range);
    let source = olmap::fixtures::scan_of(&pts, &(t_target * motion), range);
    let base = SearchParams {
        resolution: 0.3,
        levels: 3,
        dof: olmap::align::Dof::XyYaw,
        max_scan_voxels: 300,
        max_range: range,
        ..Default::default()
    };
    let target = olmap::align::SearchTarget::from_cloud(&target, base.resolution, base.levels)?;
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
        let mut row = json!({"name": "sim_room_0.3m", "mode": mode_name(mode), "seconds": seconds,
                             "total_seconds": seconds,
                             "evaluated": a.evaluated, "score": a.score, "exact": a.exact});
        merge(&mut row, errors(&PoseError::between(&a.pose, &motion)));
        rows.push(row);
    }
    let (a, seconds) = repeated(repeat, || {
        let a = align::exhaustive_search(&source, &target, &base)?;
        let s = a.seconds;
        Ok((a, s))
    })?;
    let mut row = json!({"name": "sim_room_0.3m", "mode": "exhaustive", "seconds": seconds,
                         "total_seconds": seconds,
                         "evaluated": a.evaluated, "score": a.score, "exact": a.exact});
    merge(&mut row, errors(&PoseError::between(&a.pose, &motion)));
    rows.push(row);
    Ok(rows)
}

fn merge(a: &mut Value, b: Value) {
    if let (Some(a), Value::Object(b)) = (a.as_object_mut(), b) {
        a.extend(b);
    }
}

fn localisation(quick: bool, repeat: usize) -> anyhow::Result<Vec<Value>> {
    let b = olmap::sim::thesis_localisation(7, 16)?;
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
    let mut row = json!({"name": if quick { "thesis_quick" } else { "thesis" }, "mode": mode_name(mode),
                         "seconds": search, "total_seconds": median(totals), "evaluated": r.search.evaluated, "score": r.search.score,
                         "resolution": map.resolution(), "map_voxels": map.len(),
                         "scan_voxels": r.search.scan_voxels, "area_m2": b.area_m2, "exact": r.search.exact});
    merge(&mut row, errors(&e));
    Ok(vec![row])
}

fn mapping(quick: bool, repeat: usize) -> anyhow::Result<Value> {
    let world = olmap::fixtures::hall(0.15);
    let n = if quick { 4 } else { 10 };
    let scans: Vec<ScanInput> = olmap::fixtures::hall_trajectory(n, 0.9)
        .iter()
        .enumerate()
        .map(|(i, t)| ScanInput {
            name: format!("stop{i:02}"),
            cloud: olmap::fixtures::scan_of(&world, t, 8.0),
            odometry: None,
        })
        .collect();
    let (m, s) = repeated(repeat, || {
        let t = Instant::now();
        let m = build_map(&scans, &MapParams::default(), |_, _| {})?;
        Ok((m, t.elapsed().as_secs_f64()))
    })?;
    Ok(
        json!({"scans": n, "seconds": s, "seconds_per_scan": s / n as f64, "map_voxels": m.map.len()}),
    )
}

fn scaling(p: &Pair, max_threads: usize, repeat: usize) -> anyhow::Result<Vec<Value>> {
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
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build()?;
        let (_, s) = repeated(repeat, || {
            let (r, _, _) = pool.install(|| register(p, SearchMode::MultiResolution))?;
            Ok(((), r.search.seconds))
        })?;
        let b = *base.get_or_insert(s);
        rows.push(json!({"threads": n, "seconds": s, "speedup": b / s}));
    }
    Ok(rows)
}

/// Runs `olmap bench`.
pub fn run(a: &BenchArgs) -> anyhow::Result<ExitCode> {
    let max_threads = if a.threads > 0 {
        a.threads
    } else {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    };
    let repeat = a.repeat.unwrap_or(if a.quick { 1 } else { 5 }).max(1);
    let bar = progress(6, "bench", a.json);
    let modes = modes(repeat)?;
    let insertion = insertion(a.quick, repeat)?;
    bar.inc(1);
    let pair = alignment_pair(a)?;
    let (alignment, overlap) = alignment(&pair, repeat)?;
    bar.inc(1);
    let localisation = localisation(a.quick, repeat)?;
    bar.inc(1);
    let mapping = mapping(a.quick, repeat)?;
    bar.inc(1);
    let threads = scaling(&pair, max_threads, repeat)?;
    bar.inc(1);
    bar.finish_and_clear();
    let ratio = |rows: &[Value]| {
        let t = |m: &str| {
            rows.iter()
                .find(|r| r["mode"] == m)
                .and_then(|r| r["seconds"].as_f64())
        };
        match (t("exact"), t("multires")) {
            (Some(e), Some(m)) if m > 0.0 => json!(e / m),
            _ => json!(null),
        }
    };
    let v = json!({
        "quick": a.quick,
        "repeat": repeat,
        "insertion": insertion,
        "overlap": overlap,
        "alignment": [alignment],
        "localisation": localisation,
        "modes": modes,
        "exact_over_multires_time": ratio(&modes),
        "mapping": mapping,
        "threads": threads,
        "peak_memory_bytes": peak_memory(),
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    print_table(&v);
    Ok(ExitCode::SUCCESS)
}

fn print_table(v: &Value) {
    let f = |x: &Value| x.as_f64().unwrap_or(f64::NAN);
    println!("(timings: the median of {} runs)", v["repeat"]);
    let i = &v["insertion"];
    println!(
        "insertion (ray traced, {} m)   {:>12.0} points/s ({} points in {:.3} s)",
        i["resolution"],
        f(&i["points_per_second"]),
        i["points"],
        f(&i["seconds"])
    );
    let o = &v["overlap"];
    println!(
        "overlap evaluations            {:>12.0} poses/s, {:.0} voxel lookups/s",
        f(&o["poses_per_second"]),
        f(&o["voxel_lookups_per_second"])
    );
    println!(
        "{:<14} {:<10} {:>9} {:>9} {:>7} {:>8} {:>8} {:>10}",
        "problem", "mode", "search s", "total s", "score", "err m", "err deg", "evaluated"
    );
    for r in v["alignment"]
        .as_array()
        .into_iter()
        .chain(v["localisation"].as_array())
        .chain(v["modes"].as_array())
        .flatten()
    {
        println!(
            "{:<14} {:<10} {:>9.4} {:>9.4} {:>7} {:>8.3} {:>8.2} {:>10}",
            r["name"].as_str().unwrap_or(""),
            r["mode"].as_str().unwrap_or(""),
            f(&r["seconds"]),
            f(&r["total_seconds"]),
            r["score"].to_string(),
            f(&r["translation_error_m"]),
            f(&r["rotation_error_deg"]),
            r["evaluated"].to_string()
        );
    }
    println!(
        "exact / multires time          {:.2}x (sim_room_0.3m)",
        f(&v["exact_over_multires_time"])
    );
    let m = &v["mapping"];
    println!(
        "map building (batch)           {:.3} s per scan ({} scans)",
        f(&m["seconds_per_scan"]),
        m["scans"]
    );
    for t in v["threads"].as_array().into_iter().flatten() {
        println!(
            "alignment on {:>2} thread(s)      {:.3} s (x{:.2})",
            t["threads"],
            f(&t["seconds"]),
            f(&t["speedup"])
        );
    }
    if let Some(b) = v["peak_memory_bytes"].as_u64() {
        println!(
            "peak memory (VmHWM)            {:.1} MiB",
            b as f64 / 1048576.0
        );
    }
}
