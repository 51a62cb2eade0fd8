//! Nearest target points, remembered between iterations where that is provably exact.
//!
//! Each query asks the k-d tree for the two nearest target points of a mapped source point
//! `q`, at distances `r1 ≤ r2`. When the point later moves to `q'` with `|q' - q| = δ`, the
//! first is at most `r1 + δ` away and every other at least `r2 - δ`, so while
//! `δ < (r2 - r1) / 2` the nearest point is still the first and no query is needed. Late in
//! a refinement the updates move points by millimetres and most points skip their query;
//! the correspondences are exactly those of a fresh query every time (a tie, `r1 = r2`,
//! always asks again), so the result does not change.

use kiddo::SquaredEuclidean;
use nalgebra::Point3;

use super::target::Target;

/// A safety margin on the movement test against rounding (metres).
const MARGIN: f64 = 1e-9;

/// One source point's last answer.
#[derive(Clone, Copy)]
pub(super) struct Remembered {
    /// Where the point was when the tree was asked.
    at: Point3<f64>,
    /// The nearest target point.
    item: u32,
    /// How far the point may move with `item` staying the nearest: `(r2 - r1) / 2`
    /// (negative: nothing remembered).
    slack: f64,
}

impl Remembered {
    const NONE: Remembered = Remembered {
        at: Point3::new(0.0, 0.0, 0.0),
        item: 0,
        slack: -1.0,
    };
}

/// The remembered nearest target point of every point of one source (index for index).
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

/// The nearest target point of `q` and its squared distance (`None` for an empty tree),
/// from `memo` when `q` has not moved far enough to change it, else from the tree (and
/// remembered).
#[inline]
pub(super) fn nearest(
    tgt: &Target,
    q: &Point3<f64>,
    memo: &mut Remembered,
) -> Option<(usize, f64)> {
    if memo.slack > 0.0 && (q - memo.at).norm() + MARGIN < memo.slack {
        let i = memo.item as usize;
        return Some((i, (q - tgt.points[i]).norm_squared()));
    }
    let two = tgt
        .tree
        .query(&[q.x, q.y, q.z])
        .nearest_n::<SquaredEuclidean<f64>>(std::num::NonZeroUsize::new(2).expect("2 > 0"))
        .execute();
    let first = two.first()?;
    if first.distance.is_nan() {
        *memo = Remembered::NONE;
        return None;
    }
    let i = first.item as usize;
    let r1 = first.distance.sqrt();
    let slack = match two.get(1) {
        Some(second) if !second.distance.is_nan() => 0.5 * (second.distance.sqrt() - r1),
        Some(_) => -1.0,
        None => f64::INFINITY,
    };
    *memo = Remembered {
        at: *q,
        item: first.item,
        slack,
    };
    Some((i, (q - tgt.points[i]).norm_squared()))
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

    /// Points walking in small random steps: every answer, remembered or asked, is the
    /// as near as the nearest target point a scan of all of them finds, and most late answers are
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
        let params = IcpParams {
            target_voxel: 0.0,
            ..Default::default()
        };
        let prepared = IcpTarget::new(&PointCloud::from_points(points), &params).unwrap();
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
                let (i, d2) = nearest(tgt, &q, &mut memo).unwrap();
                // (The two planes share a line of points: compare distances, not indices.)
                assert_eq!(d2, (q - tgt.points[brute(&q)]).norm_squared(), "at {q:?}");
                assert_eq!(d2, (q - tgt.points[i]).norm_squared());
                if memo.at == before && memo.slack > 0.0 {
                    remembered += 1;
                } else {
                    asked += 1;
                }
            }
        }
        assert!(remembered > 200, "{remembered} remembered, {asked} asked");
    }
}
