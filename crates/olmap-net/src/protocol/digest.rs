//! What a node holds ([`Digest`]) and what it asks for ([`FetchRequest`]).

use std::collections::BTreeMap;

use super::{put_name, seal, Kind, Reader};
use crate::error::BadMessage;

/// Most records one fetch asks for.
pub const MAX_FETCH: usize = 256;
/// Most robots a digest may list.
const MAX_ROBOTS: usize = 4096;
/// Most ranges per robot a digest lists (a store with more gaps lists the first ones; the
/// rest are found on later rounds).
const MAX_RANGES: usize = 1024;

/// The records a node holds of one robot: every seq below `contiguous`, plus `ranges`
/// (half-open `[start, end)`, ascending, disjoint, above `contiguous`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RobotHoldings {
    /// Every seq `< contiguous` is held.
    pub contiguous: u32,
    /// Further held seqs, as half-open ranges.
    pub ranges: Vec<(u32, u32)>,
}

impl RobotHoldings {
    /// The holdings of a set of seqs given in ascending order (`u32::MAX`, reserved, is
    /// left out).
    pub fn from_sorted(seqs: impl IntoIterator<Item = u32>) -> RobotHoldings {
        let mut h = RobotHoldings::default();
        for s in seqs.into_iter().filter(|&s| s < u32::MAX) {
            if h.ranges.is_empty() && s == h.contiguous {
                h.contiguous += 1;
            } else if let Some(last) = h.ranges.last_mut().filter(|r| r.1 == s) {
                last.1 += 1;
            } else if h.ranges.len() < MAX_RANGES {
                h.ranges.push((s, s + 1));
            }
        }
        h
    }

    /// Whether `seq` is held.
    pub fn holds(&self, seq: u32) -> bool {
        seq < self.contiguous || self.ranges.iter().any(|&(a, b)| (a..b).contains(&seq))
    }

    /// Every held seq (bounded by `cap` items).
    pub fn seqs(&self, cap: usize) -> impl Iterator<Item = u32> + '_ {
        (0..self.contiguous)
            .chain(self.ranges.iter().flat_map(|&(a, b)| a..b))
            .take(cap)
    }

    /// Number of records held.
    pub fn count(&self) -> u64 {
        self.contiguous as u64
            + self
                .ranges
                .iter()
                .map(|&(a, b)| (b - a) as u64)
                .sum::<u64>()
    }
}

/// What a node holds, per robot: published periodically so that any node missing records
/// can fetch them (anti-entropy).
/// ```text
/// node_len u16, node name
/// robots   u32 count, then per robot:
///   robot u32, contiguous u32, ranges u32 count, then start u32, end u32 per range
/// ```
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Digest {
    /// The publishing node.
    pub node: String,
    /// Holdings per robot id.
    pub robots: BTreeMap<u32, RobotHoldings>,
}

impl Digest {
    /// The sealed payload.
    pub fn encode(&self) -> Vec<u8> {
        let mut body = Vec::new();
        put_name(&mut body, &self.node);
        let robots: Vec<_> = self.robots.iter().take(MAX_ROBOTS).collect();
        body.extend_from_slice(&(robots.len() as u32).to_le_bytes());
        for (robot, h) in robots {
            body.extend_from_slice(&robot.to_le_bytes());
            body.extend_from_slice(&h.contiguous.to_le_bytes());
            let ranges = &h.ranges[..h.ranges.len().min(MAX_RANGES)];
            body.extend_from_slice(&(ranges.len() as u32).to_le_bytes());
            for &(a, b) in ranges {
                body.extend_from_slice(&a.to_le_bytes());
                body.extend_from_slice(&b.to_le_bytes());
            }
        }
        seal(Kind::Digest, &body)
    }

    /// Decodes an opened body: counts checked against the bytes present, ranges ascending,
    /// disjoint and above the contiguous prefix.
    pub fn decode(body: &[u8]) -> Result<Digest, BadMessage> {
        let bad = BadMessage::Body;
        let mut r = Reader::new(body);
        let node = r.name("node name").map_err(bad)?;
        let n = r.count(12, MAX_ROBOTS, "robots").map_err(bad)?;
        let mut robots = BTreeMap::new();
        for _ in 0..n {
            let robot = r.u32("robot").map_err(bad)?;
            let contiguous = r.u32("contiguous").map_err(bad)?;
            let k = r.count(8, MAX_RANGES, "ranges").map_err(bad)?;
            let mut ranges = Vec::with_capacity(k);
            let mut floor = contiguous;
            for _ in 0..k {
                let a = r.u32("range start").map_err(bad)?;
                let b = r.u32("range end").map_err(bad)?;
                if a <= floor || b <= a {
                    return Err(BadMessage::Body(format!(
                        "robot {robot}: range {a}..{b} is not ascending above {floor}"
                    )));
                }
                floor = b;
                ranges.push((a, b));
            }
            if robots
                .insert(robot, RobotHoldings { contiguous, ranges })
                .is_some()
            {
                return Err(BadMessage::Body(format!("robot {robot} listed twice")));
            }
        }
        r.finish("digest").map_err(bad)?;
        Ok(Digest { node, robots })
    }
}

/// A request for some records of one robot, sent as the payload of a `get` on
/// `olmap/TEAM/rec/ROBOT/*`; whoever holds them replies with each as a record payload on
/// its own key.
/// ```text
/// robot u32, count u32 (<= MAX_FETCH), seq u32 per record
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FetchRequest {
    /// The robot whose records are wanted.
    pub robot: u32,
    /// The wanted seqs.
    pub seqs: Vec<u32>,
}

impl FetchRequest {
    /// The sealed payload (at most [`MAX_FETCH`] seqs are sent).
    pub fn encode(&self) -> Vec<u8> {
        let seqs = &self.seqs[..self.seqs.len().min(MAX_FETCH)];
        let mut body = Vec::with_capacity(8 + 4 * seqs.len());
        body.extend_from_slice(&self.robot.to_le_bytes());
        body.extend_from_slice(&(seqs.len() as u32).to_le_bytes());
        for s in seqs {
            body.extend_from_slice(&s.to_le_bytes());
        }
        seal(Kind::Fetch, &body)
    }

    /// Decodes an opened body.
    pub fn decode(body: &[u8]) -> Result<FetchRequest, BadMessage> {
        let bad = BadMessage::Body;
        let mut r = Reader::new(body);
        let robot = r.u32("robot").map_err(bad)?;
        let n = r.count(4, MAX_FETCH, "seqs").map_err(bad)?;
        let seqs = (0..n)
            .map(|_| r.u32("seq"))
            .collect::<Result<Vec<_>, _>>()
            .map_err(bad)?;
        r.finish("fetch request").map_err(bad)?;
        Ok(FetchRequest { robot, seqs })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::open;

    #[test]
    fn holdings_summarise_gaps_and_digests_round_trip() {
        let h = RobotHoldings::from_sorted([0, 1, 2, 5, 6, 9]);
        assert_eq!(h.contiguous, 3);
        assert_eq!(h.ranges, vec![(5, 7), (9, 10)]);
        assert_eq!(h.count(), 6);
        assert!(h.holds(6) && !h.holds(3) && !h.holds(7) && h.holds(9));
        assert_eq!(h.seqs(100).collect::<Vec<_>>(), vec![0, 1, 2, 5, 6, 9]);
        let d = Digest {
            node: "mapper".into(),
            robots: [(0, h), (7, RobotHoldings::from_sorted([0]))].into(),
        };
        let body = d.encode();
        assert_eq!(
            Digest::decode(open(&body, Kind::Digest, 1 << 20).unwrap()).unwrap(),
            d
        );
        let f = FetchRequest {
            robot: 2,
            seqs: vec![3, 4, 8],
        };
        let body = f.encode();
        assert_eq!(
            FetchRequest::decode(open(&body, Kind::Fetch, 1 << 20).unwrap()).unwrap(),
            f
        );
    }

    #[test]
    fn a_digest_claiming_more_than_it_carries_is_refused() {
        let mut body = Vec::new();
        put_name(&mut body, "n");
        body.extend_from_slice(&4000u32.to_le_bytes());
        assert!(Digest::decode(&body).is_err());
        let mut body = Vec::new();
        body.extend_from_slice(&1u32.to_le_bytes());
        body.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(FetchRequest::decode(&body).is_err());
    }
}
