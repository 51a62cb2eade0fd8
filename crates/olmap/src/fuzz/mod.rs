//! A mutation fuzzer for every reader, on the stable toolchain (feature `test-support`).
//!
//! The corpus ([`corpus`]) is the real sample files of the shared data (long text files
//! cut to their first lines) and files olmap writes itself in every format and encoding.
//! Each case picks a sample (by weight), applies 1 to 8 mutations ([`mutate`]: bit flips,
//! byte inserts and deletes, truncation, digit changes, header numbers replaced by huge or
//! non-numeric values, binary words replaced by edge values, chunk duplication, line
//! deletion and doubling, splices with another file) and feeds the result to the sample's
//! reader ([`Target`]) inside [`std::panic::catch_unwind`]. Case `i` of seed `s` depends
//! on nothing else, so any case can be replayed alone ([`replay`]).
//!
//! A panic inside a third-party decoder that olmap guards ([`crate::guard`]: the LASzip
//! decoder, the MCAP reader) is already a refusal when it reaches the fuzzer, so new
//! panics of those decoders are not reported; every panic of olmap's own code is.
//!
//! What a run looks for, besides panics: cases slower than [`FuzzConfig::slow_seconds`]
//! (time bombs), and error messages that say something twice (`line 3: X: line 3: X`).
//! Memory is not measured per case: every case runs in the calling process, so the
//! process's peak resident memory after a long run bounds what any case took (the
//! `fuzz` example prints it).
//!
//! `cargo test` runs a short pass (`tests/it/fuzz.rs`); long runs use the example:
//! ```text
//! cargo run --release -p olmap --example fuzz -- --seconds 600 --seed 1
//! ```

mod corpus;
mod mutate;
mod targets;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

pub use corpus::{corpus, Sample};
pub use mutate::{apply, mutate, Mutation};
pub use targets::Target;

use crate::sim::SimRng;

/// What to run.
#[derive(Debug, Clone)]
pub struct FuzzConfig {
    /// The seed: the same seed and case number give the same input.
    pub seed: u64,
    /// Stop after this many cases (`None`: no limit).
    pub cases: Option<u64>,
    /// Stop after this long (`None`: no limit). At least one limit must be set.
    pub seconds: Option<f64>,
    /// A case slower than this, twice in a row (the second time in CPU time where the
    /// system tells it), is reported as a finding (a time bomb), seconds.
    pub slow_seconds: f64,
    /// Also read every sample unmutated first (they must all read without error).
    pub check_samples: bool,
    /// The first case number (to resume a run or look at a range of it).
    pub first_case: u64,
    /// Announce every case before running it ([`FuzzEvent::Case`]): to find the case
    /// that aborts the process (an allocation failure cannot be caught).
    pub trace: bool,
}

impl Default for FuzzConfig {
    fn default() -> Self {
        FuzzConfig {
            seed: 1,
            cases: Some(1000),
            seconds: None,
            slow_seconds: 1.0,
            check_samples: true,
            first_case: 0,
            trace: false,
        }
    }
}

/// Cases and outcomes of one reader.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetStats {
    /// The reader's name ([`Target::name`]).
    pub target: String,
    /// Cases run.
    pub cases: u64,
    /// Cases the reader accepted.
    pub accepted: u64,
    /// Cases it refused with an error.
    pub refused: u64,
    /// Cases that panicked.
    pub panics: u64,
    /// The slowest case, seconds.
    pub slowest_seconds: f64,
}

/// What a finding is.
#[derive(Debug, Clone, PartialEq)]
pub enum FindingKind {
    /// The reader panicked, with the panic's message.
    Panic(String),
    /// The case took longer than [`FuzzConfig::slow_seconds`].
    Slow(f64),
    /// The reader's error message repeats a clause (the message, the clause).
    RepeatedMessage(String, String),
    /// An unmutated sample did not read (the error).
    BadSample(String),
}

/// A case worth looking at, with the input that caused it.
#[derive(Debug, Clone)]
pub struct Finding {
    /// What happened.
    pub kind: FindingKind,
    /// The reader.
    pub target: Target,
    /// The sample mutated.
    pub sample: String,
    /// The case number (replay it with [`replay`] and the same seed); `None` for an
    /// unmutated sample.
    pub case: Option<u64>,
    /// The input.
    pub bytes: Vec<u8>,
}

/// What happened during a run.
#[derive(Debug)]
pub enum FuzzEvent<'a> {
    /// A finding, as it happens (the caller may save the input).
    Finding(&'a Finding),
    /// Case `case` is about to run on `sample` (only with [`FuzzConfig::trace`]).
    Case {
        /// The case number.
        case: u64,
        /// The sample it mutates.
        sample: &'a Sample,
    },
    /// Progress: cases run so far and the time taken (every 10,000 cases).
    Progress {
        /// Cases run.
        cases: u64,
        /// Seconds since the start.
        seconds: f64,
    },
}

/// The result of a run.
#[derive(Debug, Clone)]
pub struct FuzzReport {
    /// The seed.
    pub seed: u64,
    /// The first case number.
    pub first_case: u64,
    /// Cases run (mutated inputs).
    pub cases: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Per reader, in the order of first appearance in the corpus.
    pub targets: Vec<TargetStats>,
    /// Every finding.
    pub findings: Vec<Finding>,
}

impl FuzzReport {
    /// Panics caught.
    pub fn panics(&self) -> u64 {
        self.targets.iter().map(|t| t.panics).sum()
    }
}

/// The corpus index picked for case `case` and its mutated bytes: a function of the seed,
/// the case number and the corpus only.
pub fn case_input(samples: &[Sample], seed: u64, case: u64) -> (usize, Vec<u8>) {
    let mut rng = SimRng::for_item(seed, 0x00F0_2217, case);
    let total: f64 = samples.iter().map(|s| s.weight).sum();
    let mut x = rng.uniform() * total;
    let mut pick = samples.len() - 1;
    for (i, s) in samples.iter().enumerate() {
        if x < s.weight {
            pick = i;
            break;
        }
        x -= s.weight;
    }
    // Splices take tails of files of the same reader, or (less often) of any file.
    let same: Vec<&[u8]> = samples
        .iter()
        .filter(|s| s.target == samples[pick].target || rng.chance(0.1))
        .map(|s| s.bytes.as_slice())
        .collect();
    (pick, mutate(&samples[pick].bytes, &same, &mut rng))
}

/// Runs one case again: the sample it mutated, its bytes and what the reader said
/// (`Err` holding the panic message if it panicked).
pub fn replay(
    samples: &[Sample],
    seed: u64,
    case: u64,
) -> (usize, Vec<u8>, Result<Result<usize, String>, String>) {
    let (pick, bytes) = case_input(samples, seed, case);
    let outcome = run_one(samples[pick].target, &bytes);
    (pick, bytes, outcome)
}

/// Reads `bytes` with `target`, catching a panic: `Ok(Ok(items))`, `Ok(Err(message))`
/// for an error, `Err(panic message)`.
fn run_one(target: Target, bytes: &[u8]) -> Result<Result<usize, String>, String> {
    match catch_unwind(AssertUnwindSafe(|| target.read(bytes))) {
        Ok(r) => Ok(r.map_err(printed_message)),
        Err(payload) => Err(payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(a panic without a message)".into())),
    }
}

/// Something an error message says twice: a clause (the message split at `": "`, a part
/// of 6 characters or more that comes again: `line 3: X: line 3: X` gives `line 3`), or a
/// place (`line N` or `byte N` twice, as in `line 2: ... at line 2 column 5`).
pub fn repeated_clause(message: &str) -> Option<String> {
    let parts: Vec<&str> = message.split(": ").map(str::trim).collect();
    let clause = parts
        .iter()
        .enumerate()
        .find_map(|(i, p)| (p.len() >= 6 && parts[i + 1..].contains(p)).then(|| p.to_string()));
    clause.or_else(|| {
        let mut places: Vec<String> = Vec::new();
        for word in ["line ", "byte "] {
            for (at, _) in message.match_indices(word) {
                let digits: String = message[at + word.len()..]
                    .chars()
                    .take_while(char::is_ascii_digit)
                    .collect();
                if !digits.is_empty() {
                    places.push(format!("{word}{digits}"));
                }
            }
        }
        places.sort();
        places
            .windows(2)
            .find(|w| w[0] == w[1])
            .map(|w| w[0].clone())
    })
}

/// CPU seconds this thread has used (Linux: `/proc/thread-self/stat`, in 10 ms ticks);
/// `None` elsewhere.
fn thread_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    // After the command name in parentheses: state, then fields 4.. ; utime and stime
    // are fields 14 and 15 (1-based), in clock ticks of 1/100 s.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11);
    let utime: f64 = fields.next()?.parse().ok()?;
    let stime: f64 = fields.next()?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// The one-line message the CLI prints for a reader's error: wrapped with a path as the
/// path-level readers do, then the chain of causes said once
/// ([`crate::error::chain_message`]).
fn printed_message(e: crate::error::ParseError) -> String {
    let e = crate::Error::read("input", "fuzzed", e);
    let mut chain: Vec<&(dyn std::error::Error + 'static)> = vec![&e];
    while let Some(next) = chain.last().and_then(|c| c.source()) {
        chain.push(next);
    }
    crate::error::chain_message(chain)
}

/// Runs the fuzzer over `samples` and reports; `on_event` hears of every finding as it
/// happens, and of the progress.
pub fn run(
    config: &FuzzConfig,
    samples: &[Sample],
    mut on_event: impl FnMut(FuzzEvent<'_>),
) -> FuzzReport {
    let start = Instant::now();
    let mut targets: Vec<(Target, TargetStats)> = Vec::new();
    for s in samples {
        if !targets.iter().any(|(t, _)| *t == s.target) {
            targets.push((
                s.target,
                TargetStats {
                    target: s.target.name(),
                    cases: 0,
                    accepted: 0,
                    refused: 0,
                    panics: 0,
                    slowest_seconds: 0.0,
                },
            ));
        }
    }
    let mut findings = Vec::new();
    let mut record = |f: Finding, on_event: &mut dyn FnMut(FuzzEvent<'_>)| {
        on_event(FuzzEvent::Finding(&f));
        findings.push(f);
    };
    if config.check_samples {
        for s in samples {
            if let Err(e) = run_one(s.target, &s.bytes).and_then(|r| r) {
                record(
                    Finding {
                        kind: FindingKind::BadSample(e),
                        target: s.target,
                        sample: s.name.clone(),
                        case: None,
                        bytes: s.bytes.clone(),
                    },
                    &mut on_event,
                );
            }
        }
    }
    let limit = config.seconds.map(Duration::from_secs_f64);
    let mut case = config.first_case;
    if !samples.is_empty() {
        loop {
            if config.cases.is_some_and(|n| case - config.first_case >= n)
                || limit.is_some_and(|l| start.elapsed() >= l)
                || (config.cases.is_none() && limit.is_none())
            {
                break;
            }
            let (pick, bytes) = case_input(samples, config.seed, case);
            let sample = &samples[pick];
            if config.trace {
                on_event(FuzzEvent::Case { case, sample });
            }
            let t0 = Instant::now();
            let outcome = run_one(sample.target, &bytes);
            let mut took = t0.elapsed().as_secs_f64();
            if took > config.slow_seconds {
                // A busy machine stalls a case now and then: a time bomb is slow again,
                // and in the CPU time of this thread where the system tells it.
                let cpu0 = thread_cpu_seconds();
                let t1 = Instant::now();
                let _ = run_one(sample.target, &bytes);
                let again = match (cpu0, thread_cpu_seconds()) {
                    (Some(a), Some(b)) => b - a,
                    _ => t1.elapsed().as_secs_f64(),
                };
                took = took.min(again);
            }
            let stats = &mut targets
                .iter_mut()
                .find(|(t, _)| *t == sample.target)
                .expect("every target has its stats")
                .1;
            stats.cases += 1;
            stats.slowest_seconds = stats.slowest_seconds.max(took);
            let finding = |kind| Finding {
                kind,
                target: sample.target,
                sample: sample.name.clone(),
                case: Some(case),
                bytes: bytes.clone(),
            };
            match outcome {
                Ok(Ok(_)) => stats.accepted += 1,
                Ok(Err(message)) => {
                    stats.refused += 1;
                    if let Some(clause) = repeated_clause(&message) {
                        record(
                            finding(FindingKind::RepeatedMessage(message, clause)),
                            &mut on_event,
                        );
                    }
                }
                Err(message) => {
                    stats.panics += 1;
                    record(finding(FindingKind::Panic(message)), &mut on_event);
                }
            }
            if took > config.slow_seconds {
                record(finding(FindingKind::Slow(took)), &mut on_event);
            }
            case += 1;
            if (case - config.first_case).is_multiple_of(10_000) {
                on_event(FuzzEvent::Progress {
                    cases: case - config.first_case,
                    seconds: start.elapsed().as_secs_f64(),
                });
            }
        }
    }
    FuzzReport {
        seed: config.seed,
        first_case: config.first_case,
        cases: case - config.first_case,
        seconds: start.elapsed().as_secs_f64(),
        targets: targets.into_iter().map(|(_, s)| s).collect(),
        findings,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_cpu_time_is_read_on_linux() {
        let t0 = thread_cpu_seconds();
        assert_eq!(t0.is_some(), cfg!(target_os = "linux"));
        let mut x = 0u64;
        for i in 0..1_000_000u64 {
            x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(i));
        }
        if let (Some(a), Some(b)) = (t0, thread_cpu_seconds()) {
            assert!(a >= 0.0 && b >= a, "{a} {b}");
        }
    }

    #[test]
    fn repeated_clauses_are_found() {
        assert_eq!(
            repeated_clause("a.pcd: not a valid PCD file: line 3: bad x: line 3: bad x"),
            Some("line 3".into())
        );
        assert_eq!(repeated_clause("line 3: expected x: found y"), None);
        // Short parts (`x`, `3`) repeat innocently.
        assert_eq!(repeated_clause("x: 3: x: 3"), None);
        assert_eq!(
            repeated_clause("line 2: invalid JSON: expected value at line 2 column 5"),
            Some("line 2".into())
        );
        assert_eq!(
            repeated_clause("the file ends at byte 40 inside the point at byte 40"),
            Some("byte 40".into())
        );
        assert_eq!(
            repeated_clause("line 2: given twice (first on line 1)"),
            None
        );
    }
}
