//! Seeded fault injection on a node's traffic: message drop, duplication, reordering and
//! scheduled partitions. Zenoh has no such knobs, and the protocol must converge through
//! all of them (anti-entropy), so tests and demos inject them here.

use std::time::{Duration, Instant};

/// What to inject. Faults apply to everything the node sends (records, fetch replies,
/// digests, statuses); a partition also drops everything it receives and fails its
/// fetches.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FaultPlan {
    /// Probability that a message is lost (0-1).
    pub drop: f64,
    /// Probability that a message is sent twice (0-1).
    pub duplicate: f64,
    /// Reordering window: messages are held back and released in random order among up to
    /// this many (0 = in order). Held messages are released within [`HOLD_LIMIT`].
    pub reorder: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Partitions: from `start` to `end` after the node starts, it neither sends nor
    /// receives.
    pub partitions: Vec<(Duration, Duration)>,
}

/// Longest a reordered message is held back.
pub const HOLD_LIMIT: Duration = Duration::from_millis(300);

impl FaultPlan {
    /// Whether the plan injects anything.
    pub fn is_active(&self) -> bool {
        self.drop > 0.0 || self.duplicate > 0.0 || self.reorder > 0 || !self.partitions.is_empty()
    }

    /// Checks probabilities (0 to 1) and partitions (start before end).
    pub fn check(&self) -> Result<(), String> {
        for (what, p) in [("drop", self.drop), ("duplicate", self.duplicate)] {
            if !(0.0..=1.0).contains(&p) {
                return Err(format!("fault {what} probability {p} is not within 0 to 1"));
            }
        }
        if self.reorder > 1024 {
            return Err(format!("reorder window {} is over 1024", self.reorder));
        }
        if let Some((a, b)) = self.partitions.iter().find(|(a, b)| a >= b) {
            return Err(format!(
                "partition from {a:?} to {b:?} does not end after it starts"
            ));
        }
        Ok(())
    }
}

/// A message waiting to go out: its key, payload and whether it may block.
#[derive(Debug, Clone)]
pub struct Outgoing {
    /// The key expression.
    pub key: String,
    /// The sealed payload.
    pub payload: Vec<u8>,
    /// Sent with blocking congestion control (records) rather than drop (digests).
    pub block: bool,
}

/// A fault plan at work: its random stream, clock and reorder buffer.
#[derive(Debug)]
pub struct Faults {
    plan: FaultPlan,
    state: u64,
    start: Instant,
    held: Vec<(Instant, Outgoing)>,
    /// Messages dropped so far (by chance or by a partition).
    pub dropped: u64,
    /// Messages sent twice so far.
    pub duplicated: u64,
}

impl Faults {
    /// Starts the plan's clock now.
    pub fn new(plan: FaultPlan) -> Faults {
        let state = plan.seed ^ 0x9E37_79B9_7F4A_7C15;
        Faults {
            plan,
            state,
            start: Instant::now(),
            held: Vec::new(),
            dropped: 0,
            duplicated: 0,
        }
    }

    /// A uniform number in [0, 1) (splitmix64).
    fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Whether the node is cut off now.
    pub fn partitioned(&self) -> bool {
        let t = self.start.elapsed();
        self.plan.partitions.iter().any(|&(a, b)| t >= a && t < b)
    }

    /// Whether a received message is lost to a partition (counted).
    pub fn drop_incoming(&mut self) -> bool {
        let cut = self.partitioned();
        if cut {
            self.dropped += 1;
        }
        cut
    }

    /// Passes one message through the plan: what is to be sent now (nothing, it, it
    /// twice, or older held messages instead).
    pub fn outgoing(&mut self, msg: Outgoing) -> Vec<Outgoing> {
        if self.partitioned() || self.uniform() < self.plan.drop {
            self.dropped += 1;
            return self.release_due();
        }
        let copies = if self.uniform() < self.plan.duplicate {
            self.duplicated += 1;
            2
        } else {
            1
        };
        let now = Instant::now();
        for _ in 0..copies {
            self.held.push((now, msg.clone()));
        }
        let mut out = Vec::new();
        while self.held.len() > self.plan.reorder {
            let i = (self.uniform() * self.held.len() as f64) as usize;
            out.push(self.held.swap_remove(i.min(self.held.len() - 1)).1);
        }
        out.extend(self.release_due());
        out
    }

    /// How many copies of a message that cannot be held back (a reply, which must leave
    /// before its query closes) to send: 0 (dropped), 1, or 2 (duplicated).
    pub fn copies(&mut self) -> usize {
        if self.partitioned() || self.uniform() < self.plan.drop {
            self.dropped += 1;
            return 0;
        }
        if self.uniform() < self.plan.duplicate {
            self.duplicated += 1;
            return 2;
        }
        1
    }

    /// Held messages whose time is up (call periodically).
    pub fn release_due(&mut self) -> Vec<Outgoing> {
        let now = Instant::now();
        let (due, keep): (Vec<_>, Vec<_>) = std::mem::take(&mut self.held)
            .into_iter()
            .partition(|(t, _)| now.duration_since(*t) >= HOLD_LIMIT);
        self.held = keep;
        due.into_iter().map(|(_, m)| m).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(i: usize) -> Outgoing {
        Outgoing {
            key: format!("k/{i}"),
            payload: vec![i as u8],
            block: true,
        }
    }

    #[test]
    fn drop_rate_follows_the_plan_and_the_seed_repeats() {
        let run = |seed| {
            let mut f = Faults::new(FaultPlan {
                drop: 0.3,
                duplicate: 0.1,
                seed,
                ..FaultPlan::default()
            });
            let sent: Vec<String> = (0..2000)
                .flat_map(|i| f.outgoing(msg(i)))
                .map(|m| m.key)
                .collect();
            (sent, f.dropped, f.duplicated)
        };
        let (a, dropped, dup) = run(7);
        // 2000 draws: 3-sigma bands around 600 drops and 140 duplicates.
        assert!((540..=660).contains(&dropped), "{dropped}");
        assert!((105..=175).contains(&dup), "{dup}");
        assert_eq!(a.len() as u64, 2000 - dropped + dup);
        assert_eq!(run(7).0, a);
        assert_ne!(run(8).0, a);
    }

    #[test]
    fn reordering_keeps_every_message_and_changes_the_order() {
        let mut f = Faults::new(FaultPlan {
            reorder: 8,
            seed: 3,
            ..FaultPlan::default()
        });
        let mut out: Vec<String> = (0..100)
            .flat_map(|i| f.outgoing(msg(i)))
            .map(|m| m.key)
            .collect();
        std::thread::sleep(HOLD_LIMIT);
        out.extend(f.release_due().into_iter().map(|m| m.key));
        assert_eq!(out.len(), 100);
        let inorder: Vec<String> = (0..100).map(|i| format!("k/{i}")).collect();
        assert_ne!(out, inorder);
        let mut sorted = out.clone();
        sorted.sort();
        let mut expect = inorder.clone();
        expect.sort();
        assert_eq!(sorted, expect);
    }
}
