//! Fuzzes every reader with mutated real and olmap-written files (see `olmap::fuzz`).
//!
//! ```text
//! cargo run --release -p olmap --example fuzz -- [--seconds S] [--cases N] [--seed K]
//!     [--data DIR] [--out DIR] [--slow SECONDS] [--replay CASE] [--from CASE] [--trace]
//! ```
//! Without `--seconds` or `--cases` it runs 100,000 cases. `--data` is the shared data
//! folder (default: `$OLMAP_DATA` or `../shared/data`; without it only olmap's own files
//! are used). Every finding's input is saved under `--out` (default
//! `target/fuzz-findings`) as `<seed>-<case>-<kind>.bin`; `--replay CASE` runs one case
//! of the seed again and prints what the reader said; `--from CASE` starts at that case;
//! `--trace` names every case on stderr before running it (to find a case that aborts the
//! process, such as a failed allocation). At the end: cases per reader, panics,
//! slow cases, repeated messages and the process's peak resident memory. The exit status
//! is 1 when anything was found.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Mutex;

use olmap::fuzz::{self, FindingKind, FuzzConfig, FuzzEvent};

/// The last panic's message with its location, kept by the panic hook (which prints
/// nothing: the report says what panicked).
static LAST_PANIC: Mutex<Option<String>> = Mutex::new(None);

struct Args {
    config: FuzzConfig,
    data: Option<PathBuf>,
    out: PathBuf,
    replay: Option<u64>,
}

fn parse_args() -> Result<Args, String> {
    let mut config = FuzzConfig {
        cases: None,
        ..Default::default()
    };
    let mut data = olmap::test_data::dir();
    let mut out = PathBuf::from("target/fuzz-findings");
    let mut replay = None;
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        let number = |v: String| {
            v.parse::<f64>()
                .map_err(|_| format!("{flag}: '{v}' is not a number"))
        };
        match flag.as_str() {
            "--seconds" => config.seconds = Some(number(value()?)?),
            "--cases" => config.cases = Some(number(value()?)? as u64),
            "--seed" => config.seed = number(value()?)? as u64,
            "--slow" => config.slow_seconds = number(value()?)?,
            "--data" => data = Some(PathBuf::from(value()?)),
            "--out" => out = PathBuf::from(value()?),
            "--replay" => replay = Some(number(value()?)? as u64),
            "--from" => config.first_case = number(value()?)? as u64,
            "--trace" => config.trace = true,
            "-h" | "--help" => {
                return Err(
                    "usage: fuzz [--seconds S] [--cases N] [--seed K] [--data DIR] \
                            [--out DIR] [--slow SECONDS] [--replay CASE] [--from CASE] [--trace]"
                        .into(),
                )
            }
            other => return Err(format!("unknown argument '{other}' (try --help)")),
        }
    }
    if config.cases.is_none() && config.seconds.is_none() {
        config.cases = Some(100_000);
    }
    Ok(Args {
        config,
        data,
        out,
        replay,
    })
}

/// Peak resident memory of this process (VmHWM), MiB; `None` off Linux.
fn peak_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    std::panic::set_hook(Box::new(|info| {
        *LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()) = Some(info.to_string());
    }));
    let samples = match fuzz::corpus(args.data.as_deref()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    println!(
        "corpus: {} samples ({} from {}), seed {}",
        samples.len(),
        samples
            .iter()
            .filter(|s| !s.name.starts_with("olmap "))
            .count(),
        args.data
            .as_deref()
            .map_or("no shared data".into(), |d| d.display().to_string()),
        args.config.seed
    );
    if let Some(case) = args.replay {
        let (pick, bytes, outcome) = fuzz::replay(&samples, args.config.seed, case);
        println!(
            "case {case}: {} ({} bytes, from {}): {outcome:?}",
            samples[pick].target.name(),
            bytes.len(),
            samples[pick].name
        );
        if outcome.is_err() {
            if let Some(p) = LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()).take() {
                println!("{p}");
            }
        }
        return ExitCode::SUCCESS;
    }
    if let Err(e) = std::fs::create_dir_all(&args.out) {
        eprintln!("error: {}: {e}", args.out.display());
        return ExitCode::FAILURE;
    }
    let seed = args.config.seed;
    let report = fuzz::run(&args.config, &samples, |event| match event {
        FuzzEvent::Case { case, sample } => {
            use std::io::Write as _;
            let mut err = std::io::stderr().lock();
            let _ = writeln!(err, "case {case}: {}", sample.name);
            let _ = err.flush();
        }
        FuzzEvent::Progress { cases, seconds } => {
            if cases.is_multiple_of(100_000) {
                println!(
                    "{cases} cases, {seconds:.0} s, peak {:.0} MiB",
                    peak_mib().unwrap_or(0.0)
                );
            }
        }
        FuzzEvent::Finding(f) => {
            let (kind, detail) = match &f.kind {
                FindingKind::Panic(m) => {
                    let at = LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()).take();
                    ("panic", at.unwrap_or_else(|| m.clone()))
                }
                FindingKind::Slow(s) => ("slow", format!("{s:.2} s")),
                FindingKind::RepeatedMessage(m, c) => ("repeated", format!("'{c}' in: {m}")),
                FindingKind::BadSample(e) => ("bad-sample", e.clone()),
            };
            let case = f.case.map_or("sample".into(), |c| c.to_string());
            let file = args.out.join(format!("{seed}-{case}-{kind}.bin"));
            let saved = std::fs::write(&file, &f.bytes).is_ok();
            println!(
                "FOUND {kind}: {} case {case} (from {}): {detail}{}",
                f.target.name(),
                f.sample,
                if saved {
                    format!(" [input: {}]", file.display())
                } else {
                    String::new()
                }
            );
        }
    });
    println!(
        "\n{} cases in {:.1} s ({:.0} cases/s), seed {seed}",
        report.cases,
        report.seconds,
        report.cases as f64 / report.seconds.max(1e-9)
    );
    println!(
        "{:<24} {:>10} {:>10} {:>10} {:>7} {:>12}",
        "reader", "cases", "accepted", "refused", "panics", "slowest (ms)"
    );
    for t in &report.targets {
        println!(
            "{:<24} {:>10} {:>10} {:>10} {:>7} {:>12.2}",
            t.target,
            t.cases,
            t.accepted,
            t.refused,
            t.panics,
            t.slowest_seconds * 1e3
        );
    }
    let count = |k: fn(&FindingKind) -> bool| report.findings.iter().filter(|f| k(&f.kind)).count();
    println!(
        "panics: {}, slow cases: {}, repeated messages: {}, unreadable samples: {}",
        report.panics(),
        count(|k| matches!(k, FindingKind::Slow(_))),
        count(|k| matches!(k, FindingKind::RepeatedMessage(..))),
        count(|k| matches!(k, FindingKind::BadSample(_))),
    );
    match peak_mib() {
        Some(m) => println!("peak resident memory: {m:.0} MiB"),
        None => println!("peak resident memory: not available"),
    }
    if report.findings.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
