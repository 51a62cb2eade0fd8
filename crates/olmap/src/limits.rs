//! What a single request may cost: worker threads, and memory estimated before anything
//! large is allocated.
//!
//! olmap estimates the memory of its large allocations (search lattices, simulated
//! datasets, images, grids) from the request before allocating them, and refuses a request
//! whose estimate exceeds [`MAX_ESTIMATE_BYTES`] with [`Error::TooLarge`] naming the
//! estimate and the limit, instead of letting the allocator abort the process. Thread
//! counts above the machine's parallelism are capped ([`thread_count`]): more threads than
//! cores never speeds up olmap's CPU-bound work, and 100,000 of them exhaust the process.

use crate::error::{Error, Result};

/// The largest memory estimate, in bytes, one request may need (4 GiB): a larger one is
/// refused with [`Error::TooLarge`] before anything is allocated.
pub const MAX_ESTIMATE_BYTES: u64 = 4 << 30;

/// The most worker threads olmap starts: the machine's available parallelism (1 when it
/// cannot be told).
pub fn max_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// A worker-thread count after the cap of [`thread_count`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ThreadCount {
    /// The count asked for (0: one per core).
    pub requested: usize,
    /// The count to use (0: one per core).
    pub threads: usize,
    /// The cap that applied ([`max_threads`]).
    pub limit: usize,
}

impl ThreadCount {
    /// Whether the request was above the cap.
    pub fn capped(&self) -> bool {
        self.threads != self.requested
    }

    /// A sentence for the user when the request was capped, `None` otherwise.
    pub fn note(&self) -> Option<String> {
        self.capped().then(|| {
            format!(
                "{} threads asked for, but this machine runs {} at once: using {}",
                self.requested, self.limit, self.threads
            )
        })
    }
}

/// The thread count to use for a request of `requested` threads (0: one per core): at most
/// [`max_threads`].
///
/// ```
/// use olmap::limits::{max_threads, thread_count};
/// let t = thread_count(100_000);
/// assert_eq!(t.threads, max_threads());
/// assert!(t.capped() && t.note().is_some());
/// assert_eq!(thread_count(0).threads, 0);
/// assert!(!thread_count(1).capped());
/// ```
pub fn thread_count(requested: usize) -> ThreadCount {
    let limit = max_threads();
    ThreadCount {
        requested,
        threads: requested.min(limit),
        limit,
    }
}

/// A byte count for people: `512 B`, `1.5 KiB`, `5.7 GiB`, ...
///
/// ```
/// assert_eq!(olmap::limits::human_bytes(5.7 * (1u64 << 30) as f64), "5.7 GiB");
/// assert_eq!(olmap::limits::human_bytes(100.0), "100 B");
/// ```
pub fn human_bytes(bytes: f64) -> String {
    const UNITS: [&str; 7] = ["KiB", "MiB", "GiB", "TiB", "PiB", "EiB", "ZiB"];
    if !(bytes.is_finite()) {
        return "an unbounded amount".into();
    }
    if bytes < 1024.0 {
        return format!("{bytes:.0} B");
    }
    let mut v = bytes / 1024.0;
    let mut unit = UNITS[0];
    for u in &UNITS[1..] {
        if v < 1024.0 {
            break;
        }
        v /= 1024.0;
        unit = u;
    }
    format!("{v:.1} {unit}")
}

/// Refuses a request whose memory estimate `bytes` exceeds [`MAX_ESTIMATE_BYTES`]:
/// [`Error::TooLarge`] saying `what` needs about that much, and the limit. `bytes` is a
/// float so that an estimate can be computed without overflowing (a non-finite estimate is
/// refused too).
///
/// ```
/// use olmap::limits::check_memory;
/// assert!(check_memory(|| "a small grid".into(), 1e6).is_ok());
/// let e = check_memory(|| "a 1e6 x 1e6 grid".into(), 1e12).unwrap_err().to_string();
/// assert!(e.contains("931.3 GiB") && e.contains("4.0 GiB"), "{e}");
/// ```
pub fn check_memory(what: impl FnOnce() -> String, bytes: f64) -> Result<()> {
    if bytes.is_finite() && bytes <= MAX_ESTIMATE_BYTES as f64 {
        return Ok(());
    }
    Err(Error::TooLarge {
        what: format!("{} would need about {}", what(), human_bytes(bytes)),
        limit: format!("{} per request", human_bytes(MAX_ESTIMATE_BYTES as f64)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_at_and_over_the_limit() {
        let limit = MAX_ESTIMATE_BYTES as f64;
        assert!(check_memory(|| "x".into(), limit).is_ok());
        for bytes in [limit * 1.01, f64::INFINITY, f64::NAN] {
            let e = check_memory(|| "the thing".into(), bytes).unwrap_err();
            assert!(matches!(e, Error::TooLarge { .. }), "{e}");
            assert!(e.to_string().contains("the thing"), "{e}");
        }
    }

    #[test]
    fn human_units() {
        assert_eq!(human_bytes(1023.0), "1023 B");
        assert_eq!(human_bytes(1024.0), "1.0 KiB");
        assert_eq!(human_bytes(3.0 * 1024.0 * 1024.0), "3.0 MiB");
        assert_eq!(human_bytes(f64::INFINITY), "an unbounded amount");
    }
}
