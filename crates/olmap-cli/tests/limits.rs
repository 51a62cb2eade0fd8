//! Arguments and limits from the command line (issue 22): a closed pipe is not a crash, no
//! numeric option panics, hangs or aborts the process whatever its value, and what was
//! refused says why. The library's side is in `crates/olmap/tests/it/limits.rs`.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

use olmap::geometry::{Pose, PoseList};
use olmap::io::{self, WriteOptions};
use olmap::occupancy::{self, OccupancyList};

fn olmap_bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_olmap"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// Small inputs for every command: two scans of a furnished room (every 0.25 m), a map of
/// the first, a folder of both, a pose list, and a simulated dataset of two robots with
/// 2D scans and raw mirror logs.
struct Inputs {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

impl Inputs {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().to_path_buf();
        let scene = olmap::fixtures::furnished_room(0.25);
        let at = |x, y, yaw| Pose::from_xyz_ypr(x, y, 1.5, yaw, 0.0, 0.0);
        let a = olmap::fixtures::scan_of(&scene, &at(6.0, 4.5, 0.0), 8.0);
        let b = olmap::fixtures::scan_of(&scene, &at(6.5, 4.3, 0.1), 8.0);
        let w = WriteOptions::default();
        io::write_cloud(root.join("a.pcd"), &a, &w).unwrap();
        io::write_cloud(root.join("b.pcd"), &b, &w).unwrap();
        std::fs::create_dir(root.join("scans")).unwrap();
        io::write_cloud(root.join("scans/scan000.pcd"), &a, &w).unwrap();
        io::write_cloud(root.join("scans/scan001.pcd"), &b, &w).unwrap();
        occupancy::write_map(
            root.join("m.olm"),
            &OccupancyList::from_cloud(&a, 0.1).unwrap(),
        )
        .unwrap();
        let mut poses = PoseList::default();
        poses.push("scan000", at(6.0, 4.5, 0.0));
        poses.push("scan001", at(6.5, 4.3, 0.1));
        poses.write_path(root.join("poses.txt")).unwrap();
        let config = olmap::sim::SimConfig {
            world: olmap::sim::WorldKind::BoxRoom,
            robots: 2,
            stops: 2,
            scanner2d: Some(olmap::sim::PlanarScanner::sick_180_half_degree()),
            raw_logs: true,
            ..Default::default()
        };
        let data = olmap::sim::simulate(&config, |_, _| {}).unwrap();
        olmap::sim::write_dataset(root.join("sim"), &data).unwrap();
        Inputs { _dir: dir, root }
    }

    /// `{a}`, `{b}`, `{m}`, `{scans}`, `{poses}`, `{sim}`, `{s2a}`, `{s2b}`, `{raw}`,
    /// `{truth}` and `{out}` (a fresh path) replaced in `template`, split at spaces.
    fn args(&self, template: &str, out: &Path) -> Vec<String> {
        let p = |rel: &str| self.root.join(rel).display().to_string();
        let subs = [
            ("{a}", p("a.pcd")),
            ("{b}", p("b.pcd")),
            ("{m}", p("m.olm")),
            ("{scans}", p("scans")),
            ("{poses}", p("poses.txt")),
            ("{sim}", p("sim")),
            ("{s2a}", p("sim/robot0/scans2d/scan000.csv")),
            ("{s2b}", p("sim/robot1/scans2d/scan000.csv")),
            ("{raw}", p("sim/robot0/raw/scan000.mirror")),
            ("{truth}", p("sim/robot0/truth.txt")),
            ("{out}", out.display().to_string()),
        ];
        let mut s = template.to_string();
        for (k, v) in &subs {
            s = s.replace(k, v);
        }
        s.split_whitespace().map(String::from).collect()
    }
}

/// Runs the program, killing it if it runs longer than `hang`: a hang detector for the
/// sweep (every case takes well under a second to a few seconds), not a speed check.
fn run_with_watchdog(args: &[String], hang: Duration) -> (Output, bool) {
    let mut child = olmap_bin()
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the olmap binary runs");
    // Drain both pipes on threads so that a chatty child never blocks on a full pipe.
    let mut so = child.stdout.take().unwrap();
    let mut se = child.stderr.take().unwrap();
    let ro = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut so, &mut v).ok();
        v
    });
    let re = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut se, &mut v).ok();
        v
    });
    let start = Instant::now();
    let mut hung = false;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > hang {
            hung = true;
            child.kill().ok();
            break child.wait().unwrap();
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = Output {
        status,
        stdout: ro.join().unwrap(),
        stderr: re.join().unwrap(),
    };
    (out, hung)
}

#[cfg(unix)]
fn killed_by(status: &ExitStatus) -> Option<i32> {
    std::os::unix::process::ExitStatusExt::signal(status)
}

#[cfg(not(unix))]
fn killed_by(_: &ExitStatus) -> Option<i32> {
    None
}

const NUM: &[&str] = &["0", "-1", "nan", "inf", "1e20", "1e-20"];
const INT: &[&str] = &["0", "-1", "4294967296", "18446744073709551615", "1e20"];

/// Every numeric option of every command, at the extremes.
const SWEEP: &[(&str, &[&str])] = &[
    ("convert {a} {out}.xyz --min-range={v}", NUM),
    ("convert {a} {out}.xyz --max-range={v}", NUM),
    ("convert {a} {out}.xyz --z-min={v}", NUM),
    ("convert {a} {out}.xyz --z-max={v}", NUM),
    ("convert {a} {out}.xyz --voxel={v}", NUM),
    ("convert {a} {out}.xyz --box={v},{v},{v},1,1,1", NUM),
    ("convert {a} {out}.xyz --transform={v},0,0,{v},{v},0", NUM),
    ("voxelize {a} -o {out}.olm --resolution={v}", NUM),
    ("voxelize {a} -o {out}.olm --ray-trace --max-range={v}", NUM),
    ("voxelize {a} -o {out}.olm --hit={v}", INT),
    ("voxelize {a} -o {out}.olm --ray-trace --miss={v}", INT),
    ("voxelize {a} -o {out}.olm --max-count={v}", INT),
    ("voxelize {a} -o {out}.olm --bucket-radius={v}", NUM),
    ("voxelize {a} -o {out}.olm --pose={v},0,{v},{v},0,0", NUM),
    (
        "voxelize {a} -o {out}.olm --ray-trace --pose={v},0,0,0,0,0",
        NUM,
    ),
    ("voxelize {a} -o {out}.olm --threads={v}", INT),
    ("export {m} -o {out}.ply --min-count={v}", INT),
    ("align {b} {a} --resolution={v}", NUM),
    ("align {b} {a} --levels={v}", INT),
    ("align {b} {a} --dof 6dof --max-tilt={v}", NUM),
    ("align {b} {a} --max-range={v}", NUM),
    (
        "align {b} {a} --guess={v},{v},0,{v},0,0 --window 0.5,0.2,15",
        NUM,
    ),
    (
        "align {b} {a} --guess 0,0,0,0,0,0 --window={v},{v},{v}",
        NUM,
    ),
    ("align {b} {a} --guess 0,0,0,0,0,0 --window={v},0.2,10", NUM),
    (
        "align {b} {a} --search exact --guess={v},0,0,0,0,0 --window 0.5,0.2,15",
        NUM,
    ),
    (
        "align {b} {a} --search exact --guess 0,0,0,0,0,0 --window={v},0.2,10",
        NUM,
    ),
    ("align {b} {a} --search exact --resolution={v}", NUM),
    ("align {b} {a} --search exact --max-range={v}", NUM),
    (
        "align {b} {a} --search exact --guess 0,0,0,0,0,0 --window 0.5,0.2,10 --exact-max-work={v}",
        NUM,
    ),
    ("align {b} {a} --threads={v}", INT),
    ("localize {b} {m} --max-range={v}", NUM),
    ("localize {b} {m} --resolution={v}", NUM),
    ("localize {b} {m} --levels={v}", INT),
    (
        "localize {b} {m} --guess={v},0,0,0,0,0 --window 0.5,0.2,15",
        NUM,
    ),
    (
        "localize {b} {m} --guess 0,0,0,0,0,0 --window={v},0.2,10",
        NUM,
    ),
    ("map {scans} -o {out}.olm --resolution={v}", NUM),
    ("map {scans} -o {out}.olm --max-range={v}", NUM),
    ("map {scans} -o {out}.olm --bucket-radius={v}", NUM),
    ("map {scans} -o {out}.olm --min-count={v}", INT),
    ("map {scans} -o {out}.olm --register-band={v},2", NUM),
    ("map {scans} -o {out}.olm --dof 6dof --max-tilt={v}", NUM),
    ("mutual --a={v} --alpha 10 --b 2 --beta 20", NUM),
    ("mutual --a 2 --alpha={v} --b 2 --beta 20", NUM),
    ("mutual --a 2 --alpha 10 --b={v} --beta 20", NUM),
    ("mutual --a 2 --alpha 10 --b 2 --beta={v}", NUM),
    ("mutual --a 2 --alpha 10 --b 2 --beta 20 --offset={v}", NUM),
    (
        "mutual --a 2 --alpha 10 --b 2 --beta 20 --max-mismatch={v}",
        NUM,
    ),
    (
        "mutual --a 2 --alpha 10 --b 2 --beta 20 --range-error={v}",
        NUM,
    ),
    (
        "mutual --a 2 --alpha 10 --b 2 --beta 20 --beacon-width={v}",
        NUM,
    ),
    ("mutual --scans {s2a} {s2b} --radius={v}", NUM),
    ("mutual --scans {s2a} {s2b} --max-rms={v}", NUM),
    ("mutual --scans {s2a} {s2b} --offset={v}", NUM),
    (
        "simulate --world box-room --robots={v} --scans-per-robot 1 -o {out}",
        INT,
    ),
    (
        "simulate --world box-room --robots 1 --scans-per-robot={v} -o {out}",
        INT,
    ),
    (
        "simulate --world box-room --robots 1 --scans-per-robot 1 --seed={v} -o {out}",
        INT,
    ),
    (
        "simulate --world box-room --robots 1 --scans-per-robot 1 --range-noise={v} -o {out}",
        NUM,
    ),
    ("demo --out {out} --robots={v} --scans-per-robot 2", INT),
    ("demo --out {out} --robots 1 --scans-per-robot={v}", INT),
    (
        "grid2d {s2a} {s2b} --poses {truth} -o {out}.pgm --resolution={v}",
        NUM,
    ),
    (
        "grid2d {s2a} {s2b} --poses {truth} -o {out}.pgm --bucket-radius={v}",
        NUM,
    ),
    (
        "grid2d {s2a} {s2b} --poses {truth} -o {out}.pgm --max-range={v}",
        NUM,
    ),
    (
        "grid2d {s2a} {s2b} --poses {truth} -o {out}.pgm --hit={v}",
        NUM,
    ),
    (
        "grid2d {s2a} {s2b} --poses {truth} -o {out}.pgm --pass={v}",
        NUM,
    ),
    ("beacons {s2a} --radius={v}", NUM),
    ("beacons {s2a} --method rwht --radius={v}", NUM),
    ("beacons {s2a} --method reflective --radius={v}", NUM),
    ("beacons {s2a} --max-rms={v}", NUM),
    ("beacons {s2a} --method reflective --max-rms={v}", NUM),
    (
        "beacons {s2a} --method reflective --intensity-threshold={v}",
        NUM,
    ),
    ("scanner convert {raw} -o {out}.pcd --max-range={v}", NUM),
    ("scanner convert {raw} -o {out}.pcd --min-range={v}", NUM),
    ("scanner repeatability {a} {b} --threshold={v}", NUM),
    ("scanner repeatability {a} {b} --bin={v}", NUM),
    ("render {m} -o {out}.png --pixel={v}", NUM),
    ("render {m} -o {out}.png --grid={v}", NUM),
    ("render {m} -o {out}.png --band={v},2", NUM),
    ("render {m} -o {out}.png --min-count={v}", INT),
    (
        "render {m} -o {out}.png --view depth --from={v},{v},1,{v}",
        NUM,
    ),
    (
        "render {m} -o {out}.png --view depth --from 0,0,0,0 --fov={v}",
        NUM,
    ),
    (
        "render {m} -o {out}.png --view depth --from 0,0,0,0 --camera panoramic --fov={v}",
        NUM,
    ),
    (
        "render {m} -o {out}.png --view depth --from 0,0,0,0 --max-range={v}",
        NUM,
    ),
    (
        "render {m} -o {out}.png --view depth --from 0,0,0,0 --size={v}x100",
        INT,
    ),
    (
        "render {m} -o {out}.png --view overlap --scan {b} --from={v},{v},1,{v}",
        NUM,
    ),
    (
        "render {m} -o {out}.png --view overlap --scan {b} --from 0,0,0,0 --half-width={v}",
        NUM,
    ),
    (
        "render {m} -o {out}.png --view overlap --scan {b} --from 0,0,0,0 --headings={v}",
        INT,
    ),
    ("navgrid {m} --poses {poses} -o {out}.pgm --band={v},2", NUM),
    (
        "navgrid {m} --poses {poses} -o {out}.pgm --resolution={v}",
        NUM,
    ),
    (
        "navgrid {m} --poses {poses} -o {out}.pgm --max-range={v}",
        NUM,
    ),
    (
        "navgrid {m} --poses {poses} -o {out}.pgm --min-count={v}",
        INT,
    ),
    ("query {m} --at={v},{v},{v}", NUM),
    ("query {m} --ray=1,1,1,{v},{v},{v}", NUM),
    ("query {m} --ray={v},{v},{v},1,0,0", NUM),
    ("query {m} --ray=0,0,0,1,0,0 --max-range={v}", NUM),
    ("query {m} --radius=0,0,0,{v}", NUM),
    ("query {m} --radius={v},{v},{v},1", NUM),
    ("query {m} --segment=0,0,0,{v},{v},{v}", NUM),
    ("query {m} --at 1,1,1 --min-count={v}", INT),
];

/// What a sweep case did wrong, if anything: a panic, an abort or signal, an exit status
/// other than 0 (done), 1 (refused with a message) or 2 (a bad command line), a refusal
/// without a message, or a hang.
fn problem(out: &Output, hung: bool) -> Option<String> {
    let stderr = String::from_utf8_lossy(&out.stderr);
    if hung {
        return Some("did not finish (hung)".into());
    }
    if stderr.contains("panicked") {
        return Some(format!("panicked: {stderr}"));
    }
    if let Some(sig) = killed_by(&out.status) {
        return Some(format!("killed by signal {sig}: {stderr}"));
    }
    match out.status.code() {
        Some(0) => None,
        Some(1 | 2) if stderr.contains("error") => None,
        other => Some(format!("exit status {other:?}: {stderr}")),
    }
}

#[test]
fn audit_numeric_options_never_panic_hang_or_abort() {
    // The audit of issue 22 found panics (align/map/localize --resolution 40, --max-range
    // 0, --resolution nan; --guess 1e20 with a window; beacons --method rwht --radius
    // 1e20; scanner repeatability --bin 1e-20), aborts on huge allocations (--window 1e5,
    // --max-tilt 1e9, simulate --scans-per-robot 1e9) and hangs (render --pixel 1e20 or
    // --grid 1e-20, render --view depth --max-range 1e9, query --max-range 1e12, align
    // --search exact on a uniform scene) from ordinary numbers on the command line.
    let inputs = Inputs::new();
    let cases: Vec<(String, &str)> = SWEEP
        .iter()
        .flat_map(|(t, vals)| vals.iter().map(move |v| (t.replace("{v}", v), *v)))
        .collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some((template, _)) = cases.get(i) else {
                    break;
                };
                let out = inputs.root.join(format!("out{i}"));
                let args = inputs.args(template, &out);
                let (output, hung) = run_with_watchdog(&args, Duration::from_secs(600));
                if let Some(p) = problem(&output, hung) {
                    failures
                        .lock()
                        .unwrap()
                        .push(format!("olmap {}: {p}", args.join(" ")));
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// The program with stdout on a pipe whose reading end is already closed: the first
/// write fails at once, as when `head -1` has read its line and left.
#[cfg(unix)]
fn with_closed_stdout(args: &[String]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    olmap_bin()
        .args(args)
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .expect("the olmap binary runs")
}

#[cfg(unix)]
#[test]
fn audit_closed_pipe_is_quiet() {
    // `olmap info --json FILE | head -1` panicked ("failed printing to stdout"): every
    // command that prints now ends quietly (exit 0, or killed by SIGPIPE as Unix tools
    // are: status 141 in a shell) with nothing on stderr.
    let inputs = Inputs::new();
    let commands = [
        "--help",
        "--version",
        "help align",
        "align --help",
        "info {a} {m}",
        "info --json {a}",
        "convert {a} {out}.xyz",
        "convert --json {a} {out}.ply",
        "voxelize {a} -o {out}.olm",
        "voxelize --json {a} -o {out}.olm",
        "export {m} -o {out}.xyz",
        "merge {m} {m} -o {out}.olm",
        "align {b} {a}",
        "align --json {b} {a}",
        "localize {b} {m}",
        "map {scans} -o {out}.olm",
        "map --json {scans} -o {out}.olm",
        "eval --poses {poses} --reference {poses}",
        "poses {poses}",
        "poses --json {truth}",
        "mutual --a 2 --alpha 10 --b 2 --beta 20",
        "mutual --json --a 2 --alpha 10 --b 2 --beta 20",
        "simulate --world box-room --robots 1 --scans-per-robot 1 -o {out}",
        "grid2d {s2a} {s2b} --poses {truth} -o {out}.pgm",
        "beacons {s2a}",
        "beacons --json {s2a}",
        "team {sim} -o {out}",
        "team --json {sim} -o {out}",
        "demo --out {out} --robots 2 --scans-per-robot 2",
        "scanner convert {raw} -o {out}.pcd",
        "scanner repeatability {a} {b}",
        "render {m} -o {out}.png",
        "render --json {m} -o {out}.png",
        "navgrid {m} --poses {poses} -o {out}.pgm",
        "query {m} --at 0,0,0",
        "query --json {m} --radius 0,0,0,2",
        "bench --quick --json",
    ];
    let mut failures = Vec::new();
    for (i, c) in commands.iter().enumerate() {
        let args = inputs.args(c, &inputs.root.join(format!("pipe{i}")));
        let out = with_closed_stdout(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let quiet = out.status.success() || killed_by(&out.status) == Some(libc_sigpipe());
        if !quiet || !stderr.is_empty() {
            failures.push(format!("olmap {c}: {:?}, stderr: {stderr}", out.status));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// SIGPIPE's number (13 on every Unix olmap builds on).
#[cfg(unix)]
fn libc_sigpipe() -> i32 {
    13
}

#[test]
fn audit_threads_capped() {
    // `--threads 100000` started that many threads: capped at the machine's cores, with a
    // warning, and the command does its work.
    let inputs = Inputs::new();
    let out = inputs.root.join("t.olm");
    let args = inputs.args("voxelize {a} -o {out} --threads 100000", &out);
    let r = olmap_bin().args(&args).output().unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning: --threads: 100000 threads asked for"),
        "{stderr}"
    );
    assert!(out.exists());
}

#[test]
fn audit_guess_missing_file_says_so() {
    // `--guess nofile.txt` said "invalid float literal".
    let inputs = Inputs::new();
    let args = inputs.args("align {b} {a} --guess nofile.txt", Path::new("-"));
    let r = olmap_bin().args(&args).output().unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1));
    assert!(
        stderr.contains("'nofile.txt' is neither a pose") && stderr.contains("no file"),
        "{stderr}"
    );
}

#[test]
fn audit_refusals_name_the_argument_and_the_limit() {
    // The cases the issue names, end to end: each refused with what was wrong and the
    // limit, and nothing written.
    let inputs = Inputs::new();
    let cases = [
        (
            "align {b} {a} --resolution 40",
            "resolution (40 m) must not exceed max_range (30 m)",
        ),
        (
            "align {b} {a} --guess 0,0,0,0,0,0 --window 1e5,1,10",
            "limit 4.0 GiB",
        ),
        ("align {b} {a} --resolution 1e-6", "the target: point"),
        (
            "align {b} {a} --search exact --exact-max-work 1000",
            "the exact search gave up",
        ),
        (
            "convert {a} {out}.xyz --voxel 1e-9",
            "voxel downsampling: point",
        ),
        (
            "convert {a} {out}.xyz --z-min 5 --z-max 1",
            "z_min (5 m) is above",
        ),
        (
            "convert {a} {out}.xyz --min-range 10 --max-range 1",
            "min_range (10 m) is above",
        ),
        (
            "convert {a} {out}.xyz --box 0,5,0,10,1,10",
            "the box is inverted",
        ),
        (
            "simulate --robots 1 --scans-per-robot 1000000000 -o {out}",
            "limit 4.0 GiB",
        ),
        (
            "render {m} -o {out}.png --view overlap --scan {b} --from 0,0,0,0 --headings 100000000",
            "3600 headings",
        ),
        (
            "voxelize {a} -o {out}.olm --resolution 1e-5",
            "outside the representable keys",
        ),
        (
            "map {scans} {scans} -o {out}.olm",
            "two scans are named scan000",
        ),
    ];
    for (i, (template, words)) in cases.iter().enumerate() {
        let out = inputs.root.join(format!("refused{i}"));
        let args = inputs.args(template, &out);
        let r = olmap_bin().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{template}: {stderr}");
        assert!(stderr.contains(words), "{template}: {stderr}");
        let written = std::fs::read_dir(&inputs.root).unwrap().flatten().any(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with(&format!("refused{i}"))
        });
        assert!(!written, "{template}: an output was written");
    }
    // A segment from 1e15 m away through the room's walls is blocked (the map is the first
    // scan, in its sensor frame: the walls are 6 m either side along x).
    let args = inputs.args(
        "query {m} --json --segment -1e15,0,0,1e15,0,0",
        Path::new("-"),
    );
    let r = olmap_bin().args(&args).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["free"], false, "{v}");
}

#[test]
fn audit_team_skips_a_bad_scan_with_a_warning() {
    // One bad scan or a missing truth.txt aborted `olmap team`.
    let inputs = Inputs::new();
    let sim = inputs.root.join("sim");
    std::fs::write(sim.join("robot1/scans/scan001.pcd"), b"garbage").unwrap();
    std::fs::remove_file(sim.join("robot1/truth.txt")).unwrap();
    let out = inputs.root.join("team");
    let r = olmap_bin()
        .args(["team", "--json"])
        .arg(&sim)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning: skipped") && stderr.contains("scan001.pcd"),
        "{stderr}"
    );
    assert!(stderr.contains("truth.txt"), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["scans"], 3, "three of four scans mapped");
    assert!(out.join("report.json").exists());
}
