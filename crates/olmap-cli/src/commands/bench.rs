//! `olmap bench`: the standard benchmark set on the shared data (when present) and the
//! simulator, as a table or JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::bench::{BenchOptions, BenchReport, ErrorBench, Outcome, TrustOptions};

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
    /// Largest thread count of the scaling run (default and most: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Runs of every timed measure; the median is reported (default: 5, 1 with --quick).
    /// A 2-core machine varies by 10-30 % from run to run.
    #[arg(long)]
    pub repeat: Option<usize>,
    /// Run the trust suite instead: simulated pairs built to tempt a registration into a
    /// confident wrong answer (unrelated places, identical rooms, rows of desks, corridors,
    /// symmetric halls, floors, two walls, low overlap, pieces, outliers, partial views),
    /// each verdict judged against the truth (right within 0.3 m and 3°).
    #[arg(long)]
    pub trust: bool,
    /// Trust suite: pairs per kind of scene (14 kinds; default 17, 238 pairs).
    #[arg(long, default_value_t = 17, requires = "trust")]
    pub pairs_per_scene: usize,
    /// Trust suite and network figures: the seed of the simulated pairs or team (default 1;
    /// only with --trust or --net).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Run the network figures instead (needs the `net` feature): bytes on the wire per
    /// scan (occupancy list at 0.1 m against the raw cloud), publish→placement latency
    /// with the demo's 4 robots publishing 10 stops at 1 stop/s each to a mapper over
    /// loopback, and memory per placed scan. With --quick: 3 robots, 3 stops.
    #[arg(long, conflicts_with = "trust")]
    pub net: bool,
    /// Network figures: the robots publish out of step (robot i of n at i/n of a second
    /// after robot 0), as robots without a shared clock do, instead of all four records of
    /// each stop in the same instant (the default, the worst case for the queue).
    #[arg(long, requires = "net")]
    pub staggered: bool,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// The data folder: `--data`, else $OLMAP_DATA, else ../shared/data (used when it holds
/// the 3DTK pair; never with `--quick`).
fn data_dir(a: &BenchArgs) -> Option<PathBuf> {
    if a.quick {
        return None;
    }
    a.data
        .clone()
        .or_else(|| std::env::var_os("OLMAP_DATA").map(PathBuf::from))
        .or_else(|| Some(PathBuf::from("../shared/data")))
}

/// Runs `olmap bench --trust`.
fn run_trust(a: &BenchArgs) -> anyhow::Result<ExitCode> {
    if a.pairs_per_scene == 0 {
        anyhow::bail!("--pairs-per-scene must be at least 1");
    }
    let options = TrustOptions {
        seed: a.seed.unwrap_or(1),
        per_scene: a.pairs_per_scene,
        ..Default::default()
    };
    let kinds = olmap::sim::TrustScene::ALL.len() as u64;
    let bar = progress(kinds * a.pairs_per_scene as u64, "trust suite", a.json);
    let r = olmap::bench::run_trust(&options, |_, _| bar.inc(1))?;
    bar.finish_and_clear();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "{:<18} {:<10} {:>5} {:>8} {:>8} {:>8} {:>9} {:>6}",
        "scene", "answer", "pairs", "trusted", "alias", "WRONG", "untrusted", "right"
    );
    for s in &r.scenes {
        println!(
            "{:<18} {:<10} {:>5} {:>8} {:>8} {:>8} {:>9} {:>6}",
            s.scene,
            s.answer,
            s.pairs,
            s.trusted_right,
            s.trusted_alias,
            s.trusted_wrong,
            s.untrusted,
            s.right
        );
    }
    println!(
        "trusted and wrong: {} of {} pairs ({} trusted aliases); unique pairs trusted and right: {} of {}; {:.1} s",
        r.trusted_wrong,
        r.rows.len(),
        r.trusted_alias,
        r.unique_trusted_right,
        r.unique_pairs,
        r.seconds
    );
    for row in r.rows.iter().filter(|r| r.outcome == Outcome::TrustedWrong) {
        println!(
            "  WRONG {}: {:.2} m, {:.1}° off",
            row.name,
            row.error_m.unwrap_or(f64::NAN),
            row.error_deg.unwrap_or(f64::NAN)
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs `olmap bench`.
pub fn run(a: &BenchArgs) -> anyhow::Result<ExitCode> {
    if a.trust {
        return run_trust(a);
    }
    if a.net {
        return run_net(a);
    }
    if a.seed.is_some() {
        anyhow::bail!("--seed is for the trust suite (--trust) or the network figures (--net)");
    }
    let count = olmap::limits::thread_count(a.threads);
    if let Some(note) = count.note() {
        eprintln!("warning: --threads: {note}");
    }
    let max_threads = if count.threads > 0 {
        count.threads
    } else {
        count.limit
    };
    let options = BenchOptions {
        data: data_dir(a),
        quick: a.quick,
        max_threads,
        repeat: a.repeat.unwrap_or(if a.quick { 1 } else { 5 }).max(1),
    };
    let bar = progress(6, "bench", a.json);
    let v = olmap::bench::run(&options, |_, _| bar.inc(1))?;
    bar.finish_and_clear();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    print_table(&v);
    Ok(ExitCode::SUCCESS)
}

/// The text table of a report, as the JSON-value table printed it: a number that is not
/// finite (JSON `null`) shows as `NaN`, and the thread count is not padded (a JSON value
/// ignored the width).
fn print_table(v: &BenchReport) {
    let f = |x: f64| if x.is_finite() { x } else { f64::NAN };
    println!("(timings: the median of {} runs)", v.repeat);
    let i = &v.insertion;
    println!(
        "insertion (ray traced, {} m)   {:>12.0} points/s ({} points in {:.3} s)",
        i.resolution,
        f(i.points_per_second),
        i.points,
        f(i.seconds)
    );
    let o = &v.overlap;
    println!(
        "overlap evaluations            {:>12.0} poses/s, {:.0} voxel lookups/s",
        f(o.poses_per_second),
        f(o.voxel_lookups_per_second)
    );
    println!(
        "{:<14} {:<10} {:>9} {:>9} {:>7} {:>8} {:>8} {:>10}",
        "problem", "mode", "search s", "total s", "score", "err m", "err deg", "evaluated"
    );
    let row = |name: &str, mode: &str, s: f64, t: f64, score: i64, e: &ErrorBench, n: usize| {
        println!(
            "{:<14} {:<10} {:>9.4} {:>9.4} {:>7} {:>8.3} {:>8.2} {:>10}",
            name,
            mode,
            f(s),
            f(t),
            score.to_string(),
            f(e.translation_error_m),
            f(e.rotation_error_deg),
            n.to_string()
        );
    };
    for r in &v.alignment {
        row(
            &r.name,
            &r.mode,
            r.seconds,
            r.total_seconds,
            r.score,
            &r.error,
            r.evaluated,
        );
    }
    for r in &v.localisation {
        row(
            &r.name,
            &r.mode,
            r.seconds,
            r.total_seconds,
            r.score,
            &r.error,
            r.evaluated,
        );
    }
    for r in &v.modes {
        row(
            &r.name,
            &r.mode,
            r.seconds,
            r.total_seconds,
            r.score,
            &r.error,
            r.evaluated,
        );
    }
    println!(
        "exact / multires time          {:.2}x (sim_room_0.3m)",
        v.exact_over_multires_time.map_or(f64::NAN, f)
    );
    let m = &v.mapping;
    println!(
        "map building (batch)           {:.3} s per scan ({} scans)",
        f(m.seconds_per_scan),
        m.scans
    );
    for t in &v.threads {
        println!(
            "alignment on {} thread(s)      {:.3} s (x{:.2})",
            t.threads,
            f(t.seconds),
            f(t.speedup)
        );
    }
    if let Some(b) = v.peak_memory_bytes {
        println!(
            "peak memory (VmHWM)            {:.1} MiB",
            b as f64 / 1048576.0
        );
    }
}

/// `olmap bench --net`.
#[cfg(feature = "net")]
fn run_net(a: &BenchArgs) -> anyhow::Result<ExitCode> {
    let mut opts = olmap_net::bench::NetBenchOptions::default();
    if a.quick {
        // Three robots: in two robots' first stops of the demo's lab neither sees the
        // other, and the second robot would wait for a sighting.
        opts.robots = 3;
        opts.stops = 3;
    }
    opts.staggered = a.staggered;
    opts.seed = a.seed.unwrap_or(opts.seed);
    let json = a.json;
    let r = olmap_net::bench::run_net_bench(&opts, |stage| {
        if !json {
            eprintln!("bench --net: {stage}");
        }
    })?;
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(ExitCode::SUCCESS);
    }
    let kb = |b: f64| b / 1024.0;
    println!(
        "{} robots x {} stops at {} stop/s each ({}), occupancy lists at {} m, loopback, seed {}",
        r.robots,
        r.stops,
        r.rate,
        if r.staggered {
            "out of step"
        } else {
            "all in the same instant"
        },
        r.resolution,
        r.seed
    );
    println!(
        "  bytes per scan: occupancy list {:.1} KiB (max {:.1}), raw cloud {:.1} KiB: {:.1}x less ({:.0} -> {:.0} points)",
        kb(r.list_bytes_per_scan),
        kb(r.list_bytes_max as f64),
        kb(r.raw_bytes_per_scan),
        r.raw_bytes_per_scan / r.list_bytes_per_scan,
        r.points_raw,
        r.points_list
    );
    match r.latency_ms {
        Some([p50, p95, max]) => println!(
            "  publish->placement latency: p50 {p50:.0} ms, p95 {p95:.0} ms, max {max:.0} ms ({} live map updates)",
            r.map_runs
        ),
        None => println!("  no scan placed: no latency"),
    }
    if let Some([p50, p95, max]) = r.arrival_latency_ms {
        println!(
            "  of scans placed when their record arrived (not after waiting for the map to reach them): p50 {p50:.0} ms, p95 {p95:.0} ms, max {max:.0} ms"
        );
    }
    println!(
        "  placed {}/{} scans in {:.1} s",
        r.placed, r.published, r.wall_s
    );
    if let (Some(peak), Some(per)) = (r.peak_rss_mib, r.memory_per_placed_kib) {
        println!("  peak memory {peak:.0} MiB (robots and mapper in one process), {per:.0} KiB per placed scan");
    }
    Ok(ExitCode::SUCCESS)
}

/// `olmap bench --net` without the `net` feature.
#[cfg(not(feature = "net"))]
fn run_net(_: &BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("this olmap was built without the `net` feature: no network figures")
}
