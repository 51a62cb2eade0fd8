//! Hypotheses along a direction the refinement cannot observe: a corridor's length.
//!
//! In a corridor, ICP holds a scan across the corridor and in angle but barely along it:
//! the smallest eigenvalue of its normal equations belongs to a translation along the
//! corridor. The global search ranks poses by overlap, and along a corridor every shift
//! overlaps about as well (walls, floor and ceiling coincide anywhere), so its best few
//! candidates can all lie metres from the truth. On the trust suite's `ring-corridor` kind
//! (seed 4, 17 pairs) the search proposed the truth once; in 12 of the 16 wrong pairs the
//! truth fits better than every hypothesis verified (no contradiction at all, against
//! 300-1,600 contradicted voxels for the winner), and 2 of them were trusted 3.9 and 5.5 m
//! off.
//!
//! So when the verified winner's weakest direction is a horizontal translation clearly
//! weaker than the next ([`WEAK_AXIS_RATIO`], [`WEAK_AXIS_MIN_HORIZONTAL`]) and the winner
//! agrees with the scans as a trusted answer must, the scan is slid along that direction,
//! one finest cell at a time over its own length (at most [`WEAK_AXIS_MAX_SLIDE`] each
//! way), as placed by the winner and turned end for end about its centroid (a corridor
//! looks alike both ways; turning mirrors the centroid's offset from the corridor's centre
//! line, so the turned copy is first moved back across the corridor, up to
//! [`LATERAL_CELLS`] cells, to where its walls are best supported). Every position is
//! counted by `consistency::QuickFit` (the source side of the agreement, on the finest
//! level, at a fraction of its cost); the [`WEAK_AXIS_BY_FIT`] positions with the best
//! quick fit and the [`WEAK_AXIS_BY_AGREEMENT`] cleanest one (fewest contradicted voxels
//! per supported one, among those supported at least [`SLIDE_MIN_SUPPORT`] as well as the
//! winner) of the scan as placed and of it turned (in a corridor the turned copy laid over
//! the other scan near its sensor can contradict nothing and outshine the truth farther
//! along as placed: simulated office seed 4, robot 3, scan003 onto scan000), each at least
//! [`WEAK_AXIS_SEPARATION`] from the others and from every hypothesis already verified,
//! become hypotheses of their own, refined and counted like the search's ([`super`]).
//! Either the truth then wins, or a look-alike that fits about as well becomes the
//! distinct runner-up, or the truth — farther along, overlapping less, contradicting
//! nothing — becomes the cleaner rival ([`super::Verification::cleaner_rival`]) and the
//! verdict doubts the match: all better than a trusted pose metres off.
//!
//! Cost: only global searches whose winner is weakly held pay it (no real pair of the
//! shared data does); on the corridor kinds of the trust suite it about doubles a
//! registration (0.5 to 1 s on this 2-core machine).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::{CONTRADICTION_WEIGHT, DISTINCT_ROTATION};
use crate::align::consistency::QuickFit;
use crate::align::icp::Degeneracy;
use crate::align::lattice::Candidate;
use crate::align::target::SearchTarget;
use crate::geometry::Pose;

/// The winner's weakest eigenvalue must be below this fraction of the next for its
/// direction to count as unobservable (on the corridor ring's pairs the ratio is
/// 0.13-0.28; a room with walls on every side holds two horizontal translations about
/// equally).
pub const WEAK_AXIS_RATIO: f64 = 0.3;

/// The weakest eigenvector's horizontal translation part must be at least this long (of
/// 1) for the direction to be a slide along the floor (a weak tilt or turn is not one).
pub const WEAK_AXIS_MIN_HORIZONTAL: f64 = 0.7;

/// Positions along the weak direction with the best quick fit that become hypotheses.
pub const WEAK_AXIS_BY_FIT: usize = 2;

/// Positions along the weak direction with the fewest contradicted voxels per supported
/// one (supported at least [`SLIDE_MIN_SUPPORT`] as well as the winner) that become
/// hypotheses besides, of the scan as placed and of it turned end for end each: the truth
/// seen from farther along a corridor overlaps less than a look-alike but contradicts
/// nothing, and only such a hypothesis lets the verdict's cleaner-rival test see it.
pub const WEAK_AXIS_BY_AGREEMENT: usize = 1;

/// The least support, as a share of the winner's, of a position ranked among the cleanest
/// ([`WEAK_AXIS_BY_AGREEMENT`]). Below the verdict's [`super::CLEANER_MIN_SUPPORT`] (0.5),
/// because the quick count sees only the scan's side on the finest level, where the share
/// of a position overlapping less is smaller than in the verdict's counts of both sides:
/// the truth along a corridor of the simulated office (seed 11, robot 3, scan003 onto
/// scan000, 4.69 m along and turned) had 0.46 of the winner's support in the quick count
/// and 0.60 in the verdict's. Proposing a position is not trusting it: the verdict still
/// asks 0.5 of the refined hypothesis.
pub const SLIDE_MIN_SUPPORT: f64 = 0.4;

/// The farthest slide tried each way (metres); below it, the scan's own length along the
/// direction (beyond that nothing of it overlaps where it was).
pub const WEAK_AXIS_MAX_SLIDE: f64 = 15.0;

/// Positions kept as hypotheses lie at least this far (metres) from each other and from
/// every hypothesis already verified (or are turned more than the verification's
/// [`DISTINCT_ROTATION`] from it): nearer ones would refine into the same basin.
pub const WEAK_AXIS_SEPARATION: f64 = 0.5;

/// The turned copy is put back across the corridor within this many finest cells either
/// way before it slides.
pub const LATERAL_CELLS: i32 = 10;

/// At most this many surface voxels are moved per position (a regular subset of the
/// source's, in a fixed order): the ranking needs the shape, not every voxel.
pub(super) const MAX_QUICK_VOXELS: usize = 4000;

/// The unit horizontal direction (target frame) along which a refinement's normal
/// equations hold the pose weakly, or `None` when none does ([`WEAK_AXIS_RATIO`],
/// [`WEAK_AXIS_MIN_HORIZONTAL`]).
pub fn weak_horizontal_axis(d: &Degeneracy) -> Option<Vector3<f64>> {
    let (weakest, next) = (d.eigenvalues[0], d.eigenvalues[1]);
    // (NaN eigenvalues, from no data, are not weak.)
    let weak = weakest < WEAK_AXIS_RATIO * next;
    if !weak {
        return None;
    }
    let v = &d.eigenvectors[0];
    let h = (v[3] * v[3] + v[4] * v[4]).sqrt();
    (h >= WEAK_AXIS_MIN_HORIZONTAL).then(|| Vector3::new(v[3] / h, v[4] / h, 0.0))
}

/// Starts along `axis` from the winner's pose `from` (module documentation; `quick` holds
/// at most [`MAX_QUICK_VOXELS`] of the source's surface voxels): up to
/// [`WEAK_AXIS_BY_FIT`] + [`WEAK_AXIS_BY_AGREEMENT`] positions, none near a pose of `taken` (the
/// hypotheses already verified). Their search score and overlap are zero: the search never
/// proposed them.
pub(super) fn slide_starts(
    quick: &QuickFit,
    target: &SearchTarget,
    from: &Pose,
    axis: &Vector3<f64>,
    taken: &[Pose],
) -> Vec<Candidate> {
    let res = target.resolution();
    if quick.centres().is_empty() {
        return Vec::new();
    }
    // The scan's centroid and length along the axis, as the winner places it.
    let placed: Vec<Point3<f64>> = quick
        .centres()
        .iter()
        .map(|c| from.transform_point(c))
        .collect();
    let n = placed.len() as f64;
    let centroid = placed.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n;
    let (lo, hi) = placed
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            let t = p.coords.dot(axis);
            (lo.min(t), hi.max(t))
        });
    let reach = (hi - lo).min(WEAK_AXIS_MAX_SLIDE);
    let steps = (reach / res).ceil() as i64;
    let side = Vector3::new(-axis.y, axis.x, 0.0);
    let turn = Pose::from_translation(centroid)
        * Pose::from_xyz_ypr(0.0, 0.0, 0.0, std::f64::consts::PI, 0.0, 0.0)
        * Pose::from_translation(-centroid);
    let turned = turn * *from;
    // Turning about the centroid mirrors its offset from the corridor's centre line: the
    // turned copy is first put back on the walls across the corridor (the most supported
    // of [`LATERAL_CELLS`] cells either way, where it is), then slid with a cell to spare.
    let across = |j: i32| Pose::from_translation(side * (f64::from(j) * res)) * turned;
    let lateral = (-LATERAL_CELLS..=LATERAL_CELLS)
        .map(|j| (j, quick.at(target, &across(j)).0))
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.abs().cmp(&a.0.abs())))
        .map_or(0, |(j, _)| j);
    let turned = across(lateral);
    // Every position, and whether it is of the turned copy.
    let mut poses: Vec<Pose> = Vec::new();
    let mut is_turned: Vec<bool> = Vec::new();
    for k in -steps..=steps {
        let along = axis * (k as f64 * res);
        if k != 0 {
            poses.push(Pose::from_translation(along) * *from);
            is_turned.push(false);
        }
        for j in -1..=1 {
            let shift = along + side * (f64::from(j) * res);
            poses.push(Pose::from_translation(shift) * turned);
            is_turned.push(true);
        }
    }
    let counts: Vec<(u64, u64)> = poses.par_iter().map(|p| quick.at(target, p)).collect();
    let values: Vec<f64> = counts
        .iter()
        .map(|&(s, c)| s as f64 - CONTRADICTION_WEIGHT * c as f64)
        .collect();
    let mut order: Vec<usize> = (0..poses.len()).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]).then(a.cmp(&b)));
    let near = |a: &Pose, b: &Pose| {
        (a.translation() - b.translation()).norm() < WEAK_AXIS_SEPARATION
            && a.rotation().angle_to(&b.rotation()) <= DISTINCT_ROTATION
    };
    // The cleanest positions of each copy (as placed, turned): the fewest contradicted
    // voxels per supported one, among those supported at least `SLIDE_MIN_SUPPORT` as well
    // as the winner (a little below the verdict's cleaner-rival test). Per copy, because
    // where the turned copy lies on the other scan near its sensor and contradicts nothing,
    // it would always be the cleanest and hide the truth farther along unturned (or the
    // other way round).
    let (won_supported, _) = quick.at(target, from);
    let floor = SLIDE_MIN_SUPPORT * won_supported as f64;
    let rate = |i: usize| counts[i].1 as f64 / counts[i].0.max(1) as f64;
    let cleanest = |turned: bool| {
        let mut clean: Vec<usize> = (0..poses.len())
            .filter(|&i| is_turned[i] == turned && counts[i].0 as f64 >= floor && counts[i].0 > 0)
            .collect();
        // (Among equally clean positions, the one overlapping most.)
        clean.sort_by(|&a, &b| {
            rate(a)
                .total_cmp(&rate(b))
                .then(counts[b].0.cmp(&counts[a].0))
                .then(a.cmp(&b))
        });
        clean
    };
    let (clean_placed, clean_turned) = (cleanest(false), cleanest(true));
    let mut kept: Vec<Pose> = taken.to_vec();
    let mut out = Vec::new();
    for (ranked, quota) in [
        (&order, WEAK_AXIS_BY_FIT),
        (&clean_placed, WEAK_AXIS_BY_AGREEMENT),
        (&clean_turned, WEAK_AXIS_BY_AGREEMENT),
    ] {
        let mut taken_here = 0;
        for &i in ranked.iter() {
            if taken_here == quota {
                break;
            }
            let p = poses[i];
            if kept.iter().any(|t| near(t, &p)) {
                continue;
            }
            kept.push(p);
            taken_here += 1;
            out.push(Candidate {
                pose: p,
                overlap: 0,
                score: 0,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn degeneracy(values: [f64; 6], weakest: [f64; 6]) -> Degeneracy {
        let mut vectors = [[0.0; 6]; 6];
        vectors[0] = weakest;
        for (i, v) in vectors.iter_mut().enumerate().skip(1) {
            v[i] = 1.0;
        }
        Degeneracy {
            eigenvalues: values,
            eigenvectors: vectors,
            condition: values[5] / values[0],
            weak: Vec::new(),
            weak_fraction: 0.02,
        }
    }

    #[test]
    fn a_corridor_s_length_is_a_weak_horizontal_axis() {
        let s = 0.5f64.sqrt();
        let d = degeneracy([0.03, 0.2, 0.3, 0.4, 0.45, 0.5], [0.0, 0.0, 0.1, s, s, 0.0]);
        let a = weak_horizontal_axis(&d).expect("weak");
        assert!((a - Vector3::new(s, s, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn a_room_or_a_weak_turn_has_none() {
        // Two horizontal translations held about equally: a room.
        let d = degeneracy(
            [0.15, 0.2, 0.3, 0.4, 0.45, 0.5],
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        );
        assert!(weak_horizontal_axis(&d).is_none());
        // Weak, but mostly a turn about z.
        let d = degeneracy(
            [0.01, 0.2, 0.3, 0.4, 0.45, 0.5],
            [0.0, 0.0, 0.9, 0.3, 0.3, 0.0],
        );
        assert!(weak_horizontal_axis(&d).is_none());
    }
}
