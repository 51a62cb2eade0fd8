//! Nearest target points, remembered between iterations where that is provably exact.
//!
//! Each query asks the k-d tree for the [`CANDIDATES`] nearest target points of a mapped
//! source point `q` and keeps them, with `R`, the distance of the farthest of them. When the
//! point later moves to `q'` with `|q' - q| = δ`, every other target point is at least
//! `R - δ` from `q'`; so if the nearest of the kept points is closer than that, it is the
//! nearest of all, and no query is needed. Late in a refinement the updates move points by
//! millimetres and most points skip their query; the correspondences are exactly those of
//! a fresh query every time (up to which of two target points exactly equidistant from
//! `q'` is taken), so the result does not change.

use nalgebra::Point3;

use super::target::{IcpSource, Target};

/// Target points kept per source point.
pub(super) const CANDIDATES: usize = 4;

/// A safety margin on the movement test against rounding (metres).
const MARGIN: f64 = 1e-9;

/// One source point's last answer.
#[derive(Clone, Copy)]
pub(super) struct Remembered {
    /// Where the point was when the tree was asked.
    at: Point3<f64>,
    /// The nearest target points then, nearest first (`len` of them).
    items: [u32; CANDIDATES],
    len: u8,
    /// No target point but the kept ones is closer than this to `at`: the distance of the
    /// farthest kept one when `CANDIDATES` were kept, the query's gate when fewer lay
    /// within it (none: nothing within the gate), infinite when the tree holds no other
    /// point; negative: nothing remembered.
    reach: f64,
}

impl Remembered {
    const NONE: Remembered = Remembered {
        at: Point3::new(0.0, 0.0, 0.0),
        items: [0; CANDIDATES],
        len: 0,
        reach: -1.0,
    };
}

/// The remembered nearest target points of every point of one source (index for index).
pub(super) struct NearestCache {
    pub(super) entries: Vec<Remembered>,
}

impl NearestCache {
    /// Nothing remembered for `n` source points.
    pub(super) fn new(n: usize) -> Self {
        NearestCache {
            entries: vec![Remembered::NONE; n],
        }
    }
}

/// What one refinement remembers of its sources' nearest target points (the full source and
/// the thin one), to hand from one stage of the refinement to the next against the same
/// target: a hypothesis' finishing starts from what its first stage kept when that stage
/// ran on the full source (no thin source, the default), and a rerun from the start
/// reuses the thin source's.
pub(crate) struct NearestMemory {
    pub(super) fine: NearestCache,
    pub(super) thin: NearestCache,
    /// The target points the kept indices refer to (a memory must never be used with
    /// another target: see [`NearestMemory::fit`]).
    target_points: Option<usize>,
}

impl NearestMemory {
    /// Nothing remembered for `src`'s points.
    pub(crate) fn new(src: &IcpSource) -> Self {
        NearestMemory {
            fine: NearestCache::new(src.fine.points.len()),
            thin: NearestCache::new(src.coarse.as_ref().map_or(0, |t| t.points.len())),
            target_points: None,
        }
    }

    /// `self` as it can serve `src` against a target of `target_points` points: emptied
    /// when it was made for another source's size or used with a target of another size.
    /// (Callers hand a memory on only between refinements against one target; the size
    /// check is a guard, not the rule.)
    pub(super) fn fit(&mut self, src: &IcpSource, target_points: usize) {
        let thin = src.coarse.as_ref().map_or(0, |t| t.points.len());
        if self.fine.entries.len() != src.fine.points.len()
            || self.thin.entries.len() != thin
            || self.target_points.is_some_and(|n| n != target_points)
        {
            *self = NearestMemory::new(src);
        }
        self.target_points = Some(target_points);
    }
}

/// The nearest target point of `q` within `gate` metres and its squared distance (`None`
/// when there is none), from `memo` when its kept points prove it (the nearest of them is
/// the nearest of all, or none of them and no other point is within the gate), else from
/// the tree (and remembered). The tree is asked only for points within the gate: a source
/// point far from the map (where the scan sees what the map has not) costs a small search,
/// not a walk to a distant nearest point, and is then remembered as having nothing near.
#[inline]
pub(super) fn nearest(
    tgt: &Target,
    q: &Point3<f64>,
    memo: &mut Remembered,
    gate: f64,
) -> Option<(usize, f64)> {
    let gate2 = gate * gate;
    if memo.reach >= 0.0 {
        let moved = (q - memo.at).norm();
        // Every target point not kept is at least this far from `q`.
        let floor = memo.reach - moved - MARGIN;
        let mut best: Option<(usize, f64)> = None;
        for &i in &memo.items[..memo.len as usize] {
            let d2 = (q - tgt.points[i as usize]).norm_squared();
            if best.is_none_or(|(_, b)| d2 < b) {
                best = Some((i as usize, d2));
            }
        }
        match best {
            Some((i, d2)) if d2.sqrt() < floor => return (d2 <= gate2).then_some((i, d2)),
            _ if floor > gate && best.is_none_or(|(_, d2)| d2 > gate2) => return None,
            _ => {}
        }
    }
    let found = tgt.nearest(
        q,
        std::num::NonZeroUsize::new(CANDIDATES).expect("CANDIDATES > 0"),
        Some(gate2),
    );
    if found.iter().any(|r| r.distance.is_nan()) || gate.is_nan() {
        *memo = Remembered::NONE;
        return None;
    }
    // Every target point is kept when the tree holds no more than were found; with fewer
    // than `CANDIDATES` found, every other point lies beyond the gate; otherwise the
    // farthest kept one bounds all the others. Only a finite bound is kept.
    let reach = if tgt.points.len() <= found.len() {
        f64::INFINITY
    } else if found.len() < CANDIDATES {
        gate
    } else {
        found.iter().map(|r| r.distance).fold(0.0, f64::max).sqrt()
    };
    if reach.is_finite() || tgt.points.len() <= found.len() {
        let mut items = [0; CANDIDATES];
        for (slot, r) in items.iter_mut().zip(&found) {
            *slot = r.item;
        }
        *memo = Remembered {
            at: *q,
            items,
            len: found.len() as u8,
            reach,
        };
    } else {
        *memo = Remembered::NONE;
    }
    let first = found.first()?;
    let i = first.item as usize;
    let d2 = (q - tgt.points[i]).norm_squared();
    (d2 <= gate2).then_some((i, d2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::icp::{IcpParams, IcpTarget};
    use crate::cloud::PointCloud;

    /// A point from a seeded xorshift generator, uniform in `[-s, s)³`.
    fn point(state: &mut u64, s: f64) -> Point3<f64> {
        let mut u = || {
            *state ^= *state << 13;
            *state ^= *state >> 7;
            *state ^= *state << 17;
            (*state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        Point3::new(u() * s, u() * s, u() * s)
    }

    /// `points` prepared as an ICP target, every one kept.
    fn every_point(points: Vec<nalgebra::Point3<f32>>) -> IcpTarget {
        let params = IcpParams {
            target_voxel: 0.0,
            ..Default::default()
        };
        IcpTarget::new(&PointCloud::from_points(points), &params).unwrap()
    }

    /// Points walking in small random steps: every answer, remembered or asked, is as near
    /// as the nearest target point a scan of all of them finds, and many answers are
    /// remembered.
    #[test]
    fn remembered_answers_are_the_nearest_points() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        // Two planes and some clutter, about 5 cm apart.
        let mut points = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (a, b) = (i as f32 * 0.05, j as f32 * 0.05);
                points.push(nalgebra::Point3::new(a, b, 0.0));
                points.push(nalgebra::Point3::new(a, 0.0, b));
            }
        }
        for _ in 0..300 {
            points.push(point(&mut state, 1.0).cast::<f32>());
        }
        let prepared = every_point(points);
        let tgt = prepared.inner.as_ref().unwrap();
        let brute = |q: &Point3<f64>| {
            (0..tgt.points.len())
                .min_by(|&a, &b| {
                    (q - tgt.points[a])
                        .norm_squared()
                        .total_cmp(&(q - tgt.points[b]).norm_squared())
                })
                .unwrap()
        };
        let (mut asked, mut remembered) = (0, 0);
        for _ in 0..200 {
            let mut q = point(&mut state, 1.0) + nalgebra::Vector3::new(1.0, 1.0, 0.5);
            let mut memo = Remembered::NONE;
            for step in [0.05, 0.02, 0.01, 0.003, 0.001, 0.0003, 0.0001, 0.0001] {
                q += point(&mut state, step).coords;
                let before = memo.at;
                let (i, d2) = nearest(tgt, &q, &mut memo, f64::INFINITY).unwrap();
                // (The two planes share a line of points: compare distances, not indices.)
                assert_eq!(d2, (q - tgt.points[brute(&q)]).norm_squared(), "at {q:?}");
                assert_eq!(d2, (q - tgt.points[i]).norm_squared());
                if memo.at == before {
                    remembered += 1;
                } else {
                    asked += 1;
                }
            }
        }
        assert!(remembered > 200, "{remembered} remembered, {asked} asked");
    }

    /// With a shrinking gate, as a refinement's correspondence distance shrinks: an answer
    /// is given exactly when the nearest target point lies within the gate, it is that
    /// point, and "nothing within the gate" is remembered too (points off the planes,
    /// far from any target point, stop asking).
    #[test]
    fn gated_answers_are_the_nearest_points_within_the_gate() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut points = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (a, b) = (i as f32 * 0.05, j as f32 * 0.05);
                points.push(nalgebra::Point3::new(a, b, 0.0));
            }
        }
        let prepared = every_point(points);
        let tgt = prepared.inner.as_ref().unwrap();
        let brute = |q: &Point3<f64>| {
            tgt.points
                .iter()
                .map(|p| (q - p).norm_squared())
                .fold(f64::INFINITY, f64::min)
        };
        let (mut none_remembered, mut found, mut missed) = (0, 0, 0);
        for _ in 0..300 {
            // Above and beside the plane, up to 1 m off it.
            let mut q = point(&mut state, 1.0) + nalgebra::Vector3::new(1.0, 1.0, 0.0);
            let mut memo = Remembered::NONE;
            let steps = [0.05, 0.02, 0.01, 0.003, 0.001, 0.0003, 0.0001, 0.0001];
            let gates = [2.0, 1.4, 0.5, 0.5, 0.3, 0.3, 0.1, 0.02];
            for (step, gate) in steps.into_iter().zip(gates) {
                q += point(&mut state, step).coords;
                let before = memo.at;
                let truth = brute(&q);
                match nearest(tgt, &q, &mut memo, gate) {
                    Some((i, d2)) => {
                        assert!(
                            truth <= gate * gate,
                            "{q:?}: {truth} beyond the gate {gate}"
                        );
                        assert_eq!(d2, truth, "at {q:?}");
                        assert_eq!(d2, (q - tgt.points[i]).norm_squared());
                        found += 1;
                    }
                    None => {
                        assert!(truth > gate * gate, "{q:?}: {truth} within the gate {gate}");
                        missed += 1;
                        if memo.at == before {
                            none_remembered += 1;
                        }
                    }
                }
            }
        }
        assert!(
            found > 300 && missed > 300,
            "{found} found, {missed} missed"
        );
        assert!(none_remembered > 100, "{none_remembered} misses remembered");
    }
}
