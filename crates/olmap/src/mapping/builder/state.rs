//! The mappers' shared state: the map so far (search target, refinement points, footprint
//! box), the placed poses, and what odometry predicts for an unplaced scan.

use std::borrow::Cow;
use std::sync::atomic::AtomicUsize;
use std::sync::{Mutex, OnceLock};

use super::odometry_error::OdometryResiduals;
use super::{levels_from_extent, MapParams, ScanInput};
use crate::align::icp::IcpTarget;
use crate::align::SearchTarget;
use crate::cloud::{PointCloud, VoxelMerge};
use crate::error::Result;
use crate::geometry::{Aabb, Pose};
use crate::mapping::links::{ScanLink, TeamLinks};
use crate::occupancy::OccupancyList;

/// The map as the mappers grow it, and each scan's pose once placed.
///
/// The batch mappers borrow their scans, parameters and links; the incremental mapper owns
/// them and grows them a scan at a time ([`State::push_scan`]).
pub(super) struct State<'a> {
    pub(super) scans: Cow<'a, [ScanInput]>,
    /// The registration clouds cut to [`MapParams::register_band`] when set (`None`: the
    /// scan's own cloud; see [`State::cloud`]).
    clouds: Vec<Option<PointCloud>>,
    pub(super) params: Cow<'a, MapParams>,
    pub(super) team: Cow<'a, TeamLinks>,
    /// Each scan's capture order within its frame (the batch mappers: the input index;
    /// the incremental mapper: what the caller gives, e.g. the robot's seq, since scans
    /// may arrive out of order). Odometry predicts from the placed scan nearest in it.
    capture: Vec<u64>,
    /// Whether `capture` is the input index (no sort needed to walk it).
    capture_is_index: bool,
    pub(super) target: SearchTarget,
    /// The placed scans' points merged at [`MapParams::refine_map_voxel`], grown a scan
    /// at a time.
    refine_merge: VoxelMerge,
    /// The points the refinement aligns to (`refine_merge`'s voxel centroids), made when a
    /// registration first needs them after the map changed ([`State::refine_points`]).
    refine_map: OnceLock<PointCloud>,
    /// `refine_map` prepared for ICP, made when a registration first needs it after the
    /// map changed.
    pub(super) refine_prepared: OnceLock<IcpTarget>,
    /// The last `refine_prepared` since the map changed, to be brought up to the map when
    /// a registration next needs it ([`IcpTarget::updated`]: the tiles the new scans
    /// touched indexed again, not the whole map).
    pub(super) refine_stale: Mutex<Option<IcpTarget>>,
    pub(super) poses: Vec<Option<Pose>>,
    /// Registrations run (counted by registrations that may run in parallel).
    pub(super) registrations: AtomicUsize,
    /// Union of the placed scans' footprints.
    pub(super) map_box: Option<Aabb>,
    /// How far each frame's odometry predictions were off lately (placed against
    /// predicted): the first odometry window worth searching ([`super::odometry_error`]);
    /// `None` (the batch mappers): every window is searched from the first.
    residuals: Option<OdometryResiduals>,
}

/// The box of `cloud` moved to `pose` (`None` for an empty cloud).
pub(super) fn footprint(cloud: &PointCloud, pose: &Pose) -> Option<Aabb> {
    cloud.transformed(pose).bounding_box()
}

/// `cloud` cut to the registration band of `params`, or `None` when there is none.
fn band_cut(cloud: &PointCloud, params: &MapParams) -> Option<PointCloud> {
    params.register_band.map(|(lo, hi)| cloud.z_band(lo, hi))
}

/// Whether two boxes touch or overlap.
pub(super) fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|i| a.min[i] <= b.max[i] && b.min[i] <= a.max[i])
}

impl<'a> State<'a> {
    /// An empty map (nothing placed) for `scans`, its search pyramid sized by the frame
    /// scan `params.first` ([`levels_from_extent`]).
    pub(super) fn new(
        scans: Cow<'a, [ScanInput]>,
        params: Cow<'a, MapParams>,
        team: Cow<'a, TeamLinks>,
    ) -> Result<State<'a>> {
        let res = params.register.search.resolution;
        let levels = levels_from_extent(&scans[params.first], &params);
        let clouds = scans.iter().map(|s| band_cut(&s.cloud, &params)).collect();
        let refine_merge = VoxelMerge::new(params.refine_map_voxel)?;
        Ok(State {
            poses: vec![None; scans.len()],
            capture: (0..scans.len() as u64).collect(),
            capture_is_index: true,
            scans,
            clouds,
            params,
            team,
            target: SearchTarget::from_scans(&[], res, levels)?,
            refine_merge,
            refine_map: OnceLock::new(),
            refine_prepared: OnceLock::new(),
            refine_stale: Mutex::new(None),
            registrations: AtomicUsize::new(0),
            map_box: None,
            residuals: None,
        })
    }

    /// The points the refinement aligns to: the placed scans merged at
    /// [`MapParams::refine_map_voxel`].
    pub(super) fn refine_points(&self) -> &PointCloud {
        self.refine_map.get_or_init(|| self.refine_merge.cloud())
    }

    /// The cloud scan `s` registers with: its points cut to [`MapParams::register_band`]
    /// when set.
    pub(super) fn cloud(&self, s: usize) -> &PointCloud {
        self.clouds[s].as_ref().unwrap_or(&self.scans[s].cloud)
    }

    /// Appends a scan (not placed) in odometry frame `frame` with `links` to scans already
    /// held; each link's reverse goes to the scan at its other end. Returns its index.
    /// The links must point at held scans (checked by the caller).
    pub(super) fn push_scan(
        &mut self,
        scan: ScanInput,
        frame: usize,
        capture: u64,
        links: Vec<ScanLink>,
    ) -> usize {
        let s = self.scans.len();
        self.capture_is_index &= capture == s as u64;
        self.capture.push(capture);
        self.clouds.push(band_cut(&scan.cloud, &self.params));
        self.scans.to_mut().push(scan);
        self.poses.push(None);
        let team = self.team.to_mut();
        for l in &links {
            team.links[l.other()].push(l.reversed(s));
        }
        team.frame.push(frame);
        team.links.push(links);
        s
    }

    /// The odometry prediction of scan `s` from the placed scan of its frame fewest scans
    /// away in capture order (odometry drifts with every move, so the scan nearest in
    /// position may be many moves and tens of degrees of drift away), and the odometry
    /// path length between the two.
    pub(super) fn predict(&self, s: usize) -> Option<(Pose, f64)> {
        let odo_s = self.scans[s].odometry?;
        let p = self.predicts_from(s)?;
        let pose_p = self.poses[p].expect("placed");
        let odo_p = self.scans[p].odometry.expect("filtered");
        let motion = odo_p.inverse() * odo_s;
        Some((pose_p * motion, self.path_length(p, s)))
    }

    /// The expected error of scan `s`'s odometry prediction (σ per horizontal axis, σ of
    /// heading) from its frame's recent residuals ([`super::odometry_error`]).
    /// `None` unless [`State::learn_odometry_errors`] was called.
    pub(super) fn expected_odometry_error(&self, s: usize) -> Option<(f64, f64)> {
        let residuals = self.residuals.as_ref()?;
        residuals.expected(self.team.frame[s], self.predicted_moves(s)?)
    }

    /// The moves odometry predicts scan `s` over: from the placed scan it is predicted
    /// from ([`State::predicts_from`]).
    fn predicted_moves(&self, s: usize) -> Option<u64> {
        Some(self.moves_between(self.predicts_from(s)?, s))
    }

    /// The moves between scans `a` and `b` of one frame: its scans with odometry captured
    /// from the one to the other (both included), less one; at least 1. (Another robot's
    /// scans in between are not its moves.)
    fn moves_between(&self, a: usize, b: usize) -> u64 {
        let (ca, cb) = (self.capture[a], self.capture[b]);
        let (lo, hi) = (ca.min(cb), ca.max(cb));
        let frame = self.team.frame[a];
        let n = (0..self.scans.len())
            .filter(|&i| {
                self.team.frame[i] == frame
                    && self.scans[i].odometry.is_some()
                    && (lo..=hi).contains(&self.capture[i])
            })
            .count() as u64;
        n.saturating_sub(1).max(1)
    }

    /// From now on, keeps each placed scan's odometry residual and lets
    /// [`State::register`] skip the odometry windows too small for its frame's recent
    /// errors ([`super::odometry_error`]). The incremental mapper does (each scan's
    /// latency counts); the batch mappers do not (their results stay those of the growing
    /// windows from the first: in the demo's solo maps, starting at the wider window
    /// exposed rivals 0.5-1.4 m away that the ±0.5 m window had left out, and 5 of 40
    /// scans stayed unplaced).
    pub(super) fn learn_odometry_errors(&mut self) {
        self.residuals
            .get_or_insert_with(OdometryResiduals::default);
    }

    /// The placed scan [`State::predict`] predicts scan `s` from.
    pub(super) fn predicts_from(&self, s: usize) -> Option<usize> {
        self.scans[s].odometry?;
        self.poses
            .iter()
            .enumerate()
            .filter(|(i, p)| p.is_some() && self.team.frame[*i] == self.team.frame[s])
            .filter(|(i, _)| self.scans[*i].odometry.is_some())
            .map(|(i, _)| i)
            .min_by_key(|&i| (self.capture[i].abs_diff(self.capture[s]), i))
    }

    /// The odometry path length between scans `a` and `b` of one frame: the moves between
    /// the frame's scans with odometry, in capture order.
    pub(super) fn path_length(&self, a: usize, b: usize) -> f64 {
        let (lo, hi) = {
            let (ca, cb) = (self.capture[a], self.capture[b]);
            (ca.min(cb), ca.max(cb))
        };
        let frame = self.team.frame[a];
        let between: Vec<usize> = if self.capture_is_index {
            (lo as usize..=hi as usize).collect()
        } else {
            let mut by_capture: Vec<(u64, usize)> = (0..self.scans.len())
                .filter(|&i| (lo..=hi).contains(&self.capture[i]))
                .map(|i| (self.capture[i], i))
                .collect();
            by_capture.sort_unstable();
            by_capture.into_iter().map(|(_, i)| i).collect()
        };
        let mut last: Option<Pose> = None;
        let mut length = 0.0;
        for i in between.into_iter().filter(|&i| self.team.frame[i] == frame) {
            if let Some(odo) = self.scans[i].odometry {
                if let Some(prev) = last {
                    length += (odo.translation() - prev.translation()).norm();
                }
                last = Some(odo);
            }
        }
        length
    }

    /// How far a match may be from an odometry prediction made over `distance` metres.
    pub(super) fn odometry_tolerance(&self, distance: f64) -> f64 {
        self.params.odometry_tolerance.max(0.25 * distance)
    }

    /// The overlap fraction of scan `s` at `pose` with the map as it is now (finest level):
    /// a cheap update of a cached result's score after the map grew.
    pub(super) fn overlap_fraction_at(&self, list: &OccupancyList, pose: &Pose) -> Result<f64> {
        let n = list.len().max(1) as f64;
        Ok(self.target.pyramid().base().overlap(list, pose)? as f64 / n)
    }

    /// How near scan `s` probably is to the placed scans, smaller first: with odometry,
    /// `(false, metres)` from its predicted position to the nearest placed scan; without,
    /// `(true, index gap)` to the nearest placed scan in the input (usually capture order).
    pub(super) fn nearness(&self, s: usize) -> (bool, f64) {
        let placed = self
            .poses
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (i, p)));
        match self.predict(s) {
            Some((prior, _)) => (
                false,
                placed
                    .map(|(_, p)| (p.translation() - prior.translation()).norm())
                    .fold(f64::INFINITY, f64::min),
            ),
            None => (
                true,
                placed
                    .map(|(i, _)| i.abs_diff(s) as f64)
                    .fold(f64::INFINITY, f64::min),
            ),
        }
    }

    /// The odometry path length back to the placed scan scan `s` is predicted from, when it
    /// is so long that [`State::register`] would add a window as wide as the odometry
    /// tolerance after its three growing ones (a path of more than 8 m with the default
    /// 0.5 m first window and 25 % tolerance). A window that wide is a search of a whole
    /// stretch of building: in a corridor lined with look-alike stretches it finds one
    /// (a simulated corridor ring with the thesis' degraded odometry had a scan trusted
    /// 8.7 m off after a 22-scan gap, and every later scan followed it).
    pub(super) fn long_prediction(&self, s: usize) -> Option<f64> {
        let (_, distance) = self.predict(s)?;
        (self.odometry_tolerance(distance) > 4.0 * self.params.odometry_window.0)
            .then_some(distance)
    }

    /// Whether odometry puts scan `s` clearly outside the map so far (its predicted
    /// footprint, widened by every window and tolerance, misses the map's box): no search
    /// can succeed yet, so the batch mapper does not spend one.
    pub(super) fn far_from_map(&self, s: usize) -> bool {
        if self.unlinked(s) {
            return true;
        }
        let (Some((prior, distance)), Some(map)) = (self.predict(s), self.map_box) else {
            return false;
        };
        let Some(fp) = footprint(self.cloud(s), &prior) else {
            return false;
        };
        let margin = (4.0 * self.params.odometry_window.0).max(self.odometry_tolerance(distance));
        let widened = Aabb::new(
            fp.min - nalgebra::Vector3::repeat(margin),
            fp.max + nalgebra::Vector3::repeat(margin),
        );
        !overlaps(&widened, &map)
    }

    /// Empties the map and places the scans `placed` (index, pose) again, in that order:
    /// after their poses changed.
    pub(super) fn rebuild(&mut self, placed: &[(usize, Pose)]) -> Result<()> {
        let res = self.params.register.search.resolution;
        let levels = self.target.pyramid().levels();
        self.target = SearchTarget::from_scans(&[], res, levels)?;
        self.refine_merge = VoxelMerge::new(self.params.refine_map_voxel)?;
        self.refine_map = OnceLock::new();
        self.refine_prepared = OnceLock::new();
        *self
            .refine_stale
            .get_mut()
            .unwrap_or_else(|e| e.into_inner()) = None;
        self.map_box = None;
        if let Some(r) = &mut self.residuals {
            r.clear();
        }
        self.poses.iter_mut().for_each(|p| *p = None);
        for &(s, pose) in placed {
            self.place(s, pose)?;
        }
        Ok(())
    }

    /// Adds scan `s` at `pose` to the map: its footprint to the map box, its registration
    /// cloud to the search target, its whole cloud to the refinement points.
    pub(super) fn place(&mut self, s: usize, pose: Pose) -> Result<()> {
        // What odometry predicted, before the scan is placed (kept once it is).
        let prediction = self.residuals.as_ref().and_then(|_| {
            let (predicted, _) = self.predict(s)?;
            Some((predicted, self.predicted_moves(s)?))
        });
        // Field by field (not `self.cloud(s)`): the target is changed below.
        let cloud = self.clouds[s].as_ref().unwrap_or(&self.scans[s].cloud);
        if let Some(fp) = footprint(cloud, &pose) {
            self.map_box = Some(self.map_box.map_or(fp, |b| b.union(&fp)));
        }
        self.target.add_scan(cloud, &pose)?;
        // ICP refines against the whole scans (the floor fixes the height a band leaves free).
        self.refine_merge.add(&self.scans[s].cloud, &pose)?;
        self.refine_map = OnceLock::new();
        if let Some(prepared) = self.refine_prepared.take() {
            *self
                .refine_stale
                .get_mut()
                .unwrap_or_else(|e| e.into_inner()) = Some(prepared);
        }
        self.poses[s] = Some(pose);
        if let (Some(r), Some((predicted, moves))) = (&mut self.residuals, prediction) {
            r.record(self.team.frame[s], &predicted, &pose, moves);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot drives a 5 m square and comes back near its start: the last scan is 0.5 m
    /// from the first by odometry but four moves from it, one move from the fourth.
    #[test]
    fn odometry_predicts_from_the_fewest_moves_not_the_nearest_position() {
        let corners = [(0.0, 0.0), (5.0, 0.0), (5.0, 5.0), (0.0, 5.0), (0.3, 0.4)];
        let scans: Vec<ScanInput> = corners
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| ScanInput {
                name: format!("s{i}"),
                cloud: PointCloud::new(),
                odometry: Some(Pose::from_xyz_ypr(x, y, 0.0, 0.0, 0.0, 0.0)),
            })
            .collect();
        let params = MapParams::default();
        let team = TeamLinks::none(scans.len());
        let mut state = State {
            scans: Cow::Borrowed(&scans),
            clouds: vec![None; scans.len()],
            capture: (0..scans.len() as u64).collect(),
            capture_is_index: true,
            params: Cow::Borrowed(&params),
            team: Cow::Borrowed(&team),
            target: SearchTarget::from_scans(&[], 0.1, 1).unwrap(),
            refine_merge: VoxelMerge::new(0.05).unwrap(),
            refine_map: OnceLock::new(),
            refine_prepared: OnceLock::new(),
            refine_stale: Mutex::new(None),
            poses: vec![None; scans.len()],
            registrations: AtomicUsize::new(0),
            map_box: None,
            residuals: None,
        };
        state.poses[0] = Some(Pose::identity());
        state.poses[3] = Some(Pose::from_xyz_ypr(0.2, 5.1, 0.0, 0.0, 0.0, 0.0));
        assert_eq!(state.predicts_from(4), Some(3));
        let (predicted, path) = state.predict(4).unwrap();
        // From scan 3's placed pose by the one move in between (5.0 m, 4.6 m of it in y).
        assert!((predicted.translation() - nalgebra::Vector3::new(0.5, 0.5, 0.0)).norm() < 1e-9);
        assert!((path - (0.3f64.hypot(4.6))).abs() < 1e-9);
        // The path length counts every move between two scans, not their distance.
        assert!((state.path_length(0, 4) - (5.0 + 5.0 + 5.0 + 0.3f64.hypot(4.6))).abs() < 1e-9);
        // The moves between two scans are their robot's own: four here, two when every
        // other scan is another robot's (the odometry error of `odometry_error` grows with
        // them).
        assert_eq!(state.moves_between(0, 4), 4);
        assert_eq!(state.moves_between(3, 4), 1);
        state.team.to_mut().frame = vec![0, 1, 0, 1, 0];
        assert_eq!(state.moves_between(0, 4), 2);
        assert_eq!(state.moves_between(4, 2), 1);
    }
}
