//! The ray-trace sensor model (thesis Algorithm 2, done exactly): 3D DDA voxel traversal
//! (Amanatides & Woo 1987) and scan insertion.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::list::OccupancyList;
use super::packed::{pack_key, MAX_COUNT};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};

/// The voxels a segment passes through, in order from the voxel of `start` to the voxel of
/// `end` (both included), 6-connected: consecutive voxels share a face.
///
/// Amanatides & Woo's traversal: per axis, the ray parameter of the next voxel boundary
/// (`t_max`) and the parameter step between boundaries (`t_delta`); each step crosses the
/// nearest boundary. The number of steps is fixed in advance to the sum of the per-axis key
/// differences, so the walk always ends exactly in the end voxel, whatever the rounding.
///
/// ```
/// use olmap::occupancy::VoxelRay;
/// use olmap::geometry::VoxelKey;
/// use nalgebra::Point3;
/// let keys: Vec<VoxelKey> =
///     VoxelRay::new(&Point3::new(0.05, 0.05, 0.05), &Point3::new(0.35, 0.05, 0.05), 0.1).collect();
/// assert_eq!(keys.len(), 4);
/// assert_eq!(keys[3], VoxelKey::new(3, 0, 0));
/// ```
#[derive(Debug, Clone)]
pub struct VoxelRay {
    key: [i64; 3],
    step: [i64; 3],
    t_max: [f64; 3],
    t_delta: [f64; 3],
    remaining: [u64; 3],
    started: bool,
    /// Segment parameter (0 at `start`, 1 at `end`) where the last returned voxel was entered.
    t_entry: f64,
}

impl VoxelRay {
    /// The traversal from `start` to `end` (metres) through voxels of `resolution` metres.
    /// Non-finite input gives an empty traversal.
    pub fn new(start: &Point3<f64>, end: &Point3<f64>, resolution: f64) -> Self {
        let mut ray = VoxelRay {
            key: [0; 3],
            step: [0; 3],
            t_max: [f64::INFINITY; 3],
            t_delta: [f64::INFINITY; 3],
            remaining: [0; 3],
            started: true,
            t_entry: 0.0,
        };
        let s = start.coords / resolution;
        let e = end.coords / resolution;
        if !(s
            .iter()
            .chain(e.iter())
            .all(|v| v.is_finite() && v.abs() < 1e15))
        {
            return ray;
        }
        let d: Vector3<f64> = e - s;
        for i in 0..3 {
            let k0 = s[i].floor() as i64;
            let k1 = e[i].floor() as i64;
            ray.key[i] = k0;
            ray.remaining[i] = k0.abs_diff(k1);
            if k1 > k0 {
                ray.step[i] = 1;
                ray.t_delta[i] = 1.0 / d[i];
                ray.t_max[i] = ((k0 + 1) as f64 - s[i]) / d[i];
            } else if k1 < k0 {
                ray.step[i] = -1;
                ray.t_delta[i] = -1.0 / d[i];
                ray.t_max[i] = (k0 as f64 - s[i]) / d[i];
            }
        }
        ray.started = false;
        ray
    }

    fn current(&self) -> VoxelKey {
        VoxelKey::new(self.key[0] as i32, self.key[1] as i32, self.key[2] as i32)
    }

    /// Where along the segment the voxel last returned by the iterator was entered, as a
    /// fraction of the segment (0 for the first voxel, the one holding `start`): the
    /// distance from `start` to that voxel's boundary is `entry() * |end - start|`.
    pub fn entry(&self) -> f64 {
        self.t_entry
    }

    /// Voxels left to visit, including the current one if not yet returned.
    pub fn remaining(&self) -> u64 {
        self.remaining.iter().sum::<u64>() + u64::from(!self.started)
    }

    /// Whether every voxel still to come (the current one included) lies outside the key
    /// box `[lo, hi]`: on some axis the keys the walk can still reach miss the box. A
    /// query stops there instead of walking on through empty space (a ray of 1e12 m).
    pub(crate) fn past_box(&self, lo: [i64; 3], hi: [i64; 3]) -> bool {
        (0..3).any(|i| {
            let (k, r) = (self.key[i], self.remaining[i] as i64);
            let (a, b) = match self.step[i] {
                1 => (k, k.saturating_add(r)),
                -1 => (k.saturating_sub(r), k),
                _ => (k, k),
            };
            b < lo[i] || a > hi[i]
        })
    }
}

impl Iterator for VoxelRay {
    type Item = VoxelKey;

    #[inline]
    fn next(&mut self) -> Option<VoxelKey> {
        if !self.started {
            self.started = true;
            return Some(self.current());
        }
        // The axis with the nearest boundary among those that still have steps to take.
        let mut axis = usize::MAX;
        let mut best = f64::INFINITY;
        for i in 0..3 {
            if self.remaining[i] > 0 && (axis == usize::MAX || self.t_max[i] < best) {
                axis = i;
                best = self.t_max[i];
            }
        }
        if axis == usize::MAX {
            return None;
        }
        self.key[axis] += self.step[axis];
        self.t_entry = best;
        self.t_max[axis] += self.t_delta[axis];
        self.remaining[axis] -= 1;
        Some(self.current())
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.remaining() as usize;
        (n, Some(n))
    }
}

/// Parameters of the ray-trace sensor model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorModel {
    /// Added to the endpoint voxel of a ray, once per scan. Default 1 (thesis Algorithm 2).
    pub hit: u16,
    /// Subtracted from every voxel a ray passes through before its endpoint, once per scan;
    /// a voxel whose count drops to 0 is removed. Default 1.
    pub miss: u16,
    /// Counts never exceed this (clamping, as OctoMap's upper bound). Default and maximum
    /// [`MAX_COUNT`] = 1023.
    pub max_count: u16,
    /// Rays longer than this (metres) are cut here: free space up to `max_range`, no hit.
    /// Default 30 m.
    pub max_range: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel {
            hit: 1,
            miss: 1,
            max_count: MAX_COUNT,
            max_range: 30.0,
        }
    }
}

impl SensorModel {
    /// Checks the model: `max_range > 0` (infinite allowed: no cut), `1 <= max_count <=`
    /// [`MAX_COUNT`]; [`Error::InvalidArgument`] names what is wrong.
    pub fn validate(&self) -> Result<()> {
        if self.max_range.is_nan()
            || self.max_range <= 0.0
            || self.max_count == 0
            || self.max_count > MAX_COUNT
        {
            return Err(Error::InvalidArgument(format!(
                "sensor model needs max_range > 0 and 1 <= max_count <= {MAX_COUNT}, got {self:?}"
            )));
        }
        Ok(())
    }
}

/// What one scan insertion did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InsertStats {
    /// Rays cast (points of the scan).
    pub rays: u64,
    /// Rays cut at the maximum range (no endpoint hit).
    pub truncated: u64,
    /// Points skipped: non-finite, or with a voxel outside the representable range.
    pub skipped: u64,
    /// Voxel steps walked by all rays together.
    pub voxels_traversed: u64,
    /// Distinct voxels that received a hit.
    pub hit_voxels: u64,
    /// Distinct stored voxels that received a miss (not also hit by this scan).
    pub missed_voxels: u64,
    /// Voxels removed because their count reached 0.
    pub removed_voxels: u64,
}

#[derive(Default)]
struct Partial {
    hits: Vec<u64>,
    misses: Vec<u64>,
    stats: InsertStats,
}

impl Partial {
    fn merge(mut self, mut other: Partial) -> Partial {
        self.hits.append(&mut other.hits);
        self.misses.append(&mut other.misses);
        let (a, b) = (&mut self.stats, other.stats);
        a.rays += b.rays;
        a.truncated += b.truncated;
        a.skipped += b.skipped;
        a.voxels_traversed += b.voxels_traversed;
        self
    }
}

/// Keys already looked up along recent rays (direct mapped): neighbouring rays cross the
/// same voxels near the sensor, and each needs one map lookup per scan only.
struct RecentKeys([u64; 4096]);

impl RecentKeys {
    #[inline]
    fn seen(&mut self, k: u64) -> bool {
        let slot = ((k.wrapping_mul(0x9E37_79B9_7F4A_7C15)) >> 52) as usize;
        if self.0[slot] == k {
            true
        } else {
            self.0[slot] = k;
            false
        }
    }
}

impl OccupancyList {
    /// Integrates one scan with the ray-trace sensor model.
    ///
    /// `cloud` is in the sensor frame (its origin is where rays start) and `t_map_sensor`
    /// places it in the map. For every point: the endpoint voxel gains `model.hit`; every
    /// voxel strictly before the endpoint voxel along the ray (the sensor's voxel included)
    /// loses `model.miss` if stored, and is removed when its count reaches 0. Rays longer
    /// than `model.max_range` are cut there and give free space only. Each voxel is updated
    /// at most once per scan for hits and once for misses, and a voxel hit by the scan is
    /// not also missed by it: a scan is one observation. Work is spread over the rayon
    /// thread pool; the result does not depend on the number of threads.
    ///
    /// ```
    /// use olmap::cloud::PointCloud;
    /// use olmap::geometry::Pose;
    /// use olmap::occupancy::{OccupancyList, SensorModel};
    /// use nalgebra::Point3;
    /// let mut map = OccupancyList::new(0.1).unwrap();
    /// // A wall 1 m ahead...
    /// map.insert_scan(&PointCloud::from_points(vec![Point3::new(1.05, 0.05, 0.05)]),
    ///                 &Pose::identity(), &SensorModel::default()).unwrap();
    /// assert_eq!(map.count_at(&Point3::new(1.05, 0.05, 0.05)), 1);
    /// // ...then seen through: the voxel is freed and removed.
    /// map.insert_scan(&PointCloud::from_points(vec![Point3::new(2.05, 0.05, 0.05)]),
    ///                 &Pose::identity(), &SensorModel::default()).unwrap();
    /// assert_eq!(map.count_at(&Point3::new(1.05, 0.05, 0.05)), 0);
    /// assert_eq!(map.len(), 1);
    /// ```
    pub fn insert_scan(
        &mut self,
        cloud: &PointCloud,
        t_map_sensor: &Pose,
        model: &SensorModel,
    ) -> Result<InsertStats> {
        Ok(self.insert_scan_tracked(cloud, t_map_sensor, model)?.0)
    }

    /// [`OccupancyList::insert_scan`], also returning the packed keys it may have changed
    /// (every voxel hit or missed).
    pub(crate) fn insert_scan_tracked(
        &mut self,
        cloud: &PointCloud,
        t_map_sensor: &Pose,
        model: &SensorModel,
    ) -> Result<(InsertStats, Vec<u64>)> {
        model.validate()?;
        let res = self.resolution();
        let origin = t_map_sensor.transform_point(&cloud.origin());
        if self.pack(&origin).is_none() {
            return Err(Error::InvalidArgument(format!(
                "the sensor origin {origin} is outside the map's representable range"
            )));
        }
        let iso = *t_map_sensor.isometry();
        let map: &OccupancyList = self;
        let chunk = 2048;
        let partial = cloud
            .points()
            .par_chunks(chunk)
            .map(|points| {
                let mut part = Partial::default();
                let mut recent = RecentKeys([u64::MAX; 4096]);
                for p in points {
                    part.stats.rays += 1;
                    let end = iso.transform_point(&p.cast::<f64>());
                    let d = end - origin;
                    let r = d.norm();
                    if !r.is_finite() {
                        part.stats.skipped += 1;
                        continue;
                    }
                    let (end, hit) = if r > model.max_range {
                        part.stats.truncated += 1;
                        (origin + d * (model.max_range / r), false)
                    } else {
                        (end, true)
                    };
                    let Some(end_key) = VoxelKey::from_point(&end, res).and_then(pack_key) else {
                        part.stats.skipped += 1;
                        continue;
                    };
                    let ray = VoxelRay::new(&origin, &end, res);
                    let steps = ray.remaining();
                    part.stats.voxels_traversed += steps;
                    // All voxels before the last one, and the last one too for a cut ray.
                    let free = if hit { steps.saturating_sub(1) } else { steps };
                    for key in ray.take(free as usize) {
                        let Some(k) = pack_key(key) else { continue };
                        if !recent.seen(k) && map.table.contains(k) {
                            part.misses.push(k);
                        }
                    }
                    if hit {
                        part.hits.push(end_key);
                    }
                }
                part
            })
            .reduce(Partial::default, Partial::merge);
        let Partial {
            mut hits,
            mut misses,
            mut stats,
        } = partial;
        hits.par_sort_unstable();
        hits.dedup();
        misses.par_sort_unstable();
        misses.dedup();
        // A voxel hit by this scan is not also freed by it.
        misses.retain(|k| hits.binary_search(k).is_err());
        stats.hit_voxels = hits.len() as u64;
        stats.missed_voxels = misses.len() as u64;
        let before = self.len();
        for &k in &misses {
            self.sub_packed(k, model.miss);
        }
        stats.removed_voxels = (before - self.len()) as u64;
        let cap = model.max_count as u32;
        for &k in &hits {
            self.table.update(k, |c| {
                (c as u32 + model.hit as u32).min(cap).max(c as u32) as u16
            });
        }
        misses.append(&mut hits);
        Ok((stats, misses))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_aligned_and_negative_rays() {
        let keys: Vec<_> = VoxelRay::new(
            &Point3::new(-0.05, 0.0, 0.0),
            &Point3::new(-0.35, 0.0, 0.0),
            0.1,
        )
        .collect();
        assert_eq!(
            keys,
            (0..4)
                .map(|i| VoxelKey::new(-1 - i, 0, 0))
                .collect::<Vec<_>>()
        );
        let same: Vec<_> = VoxelRay::new(
            &Point3::new(0.01, 0.01, 0.01),
            &Point3::new(0.02, 0.03, 0.04),
            0.1,
        )
        .collect();
        assert_eq!(same, vec![VoxelKey::new(0, 0, 0)]);
        assert_eq!(
            VoxelRay::new(&Point3::new(f64::NAN, 0.0, 0.0), &Point3::origin(), 0.1).count(),
            0
        );
    }

    #[test]
    fn diagonal_ray_is_face_connected_and_ends_at_the_end() {
        let a = Point3::new(0.013, -0.27, 0.4);
        let b = Point3::new(2.71, 1.38, -0.93);
        let keys: Vec<_> = VoxelRay::new(&a, &b, 0.1).collect();
        assert_eq!(keys[0], VoxelKey::from_point(&a, 0.1).unwrap());
        assert_eq!(
            *keys.last().unwrap(),
            VoxelKey::from_point(&b, 0.1).unwrap()
        );
        for w in keys.windows(2) {
            let d = (w[1].x - w[0].x).abs() + (w[1].y - w[0].y).abs() + (w[1].z - w[0].z).abs();
            assert_eq!(d, 1);
        }
    }

    #[test]
    fn scan_is_one_observation() {
        let mut map = OccupancyList::new(0.1).unwrap();
        // Ten returns in the same voxel: one hit, not ten.
        let pts = vec![Point3::new(1.05f32, 0.05, 0.05); 10];
        let s = map
            .insert_scan(
                &PointCloud::from_points(pts),
                &Pose::identity(),
                &SensorModel::default(),
            )
            .unwrap();
        assert_eq!(map.count_at(&Point3::new(1.05, 0.05, 0.05)), 1);
        assert_eq!(s.hit_voxels, 1);
        // A long ray is cut: nothing is hit beyond max range.
        let model = SensorModel {
            max_range: 0.5,
            ..Default::default()
        };
        let s = map
            .insert_scan(
                &PointCloud::from_points(vec![Point3::new(3.0, 0.05, 0.05)]),
                &Pose::identity(),
                &model,
            )
            .unwrap();
        assert_eq!((s.truncated, s.hit_voxels), (1, 0));
        assert_eq!(map.len(), 1);
        // Clamping: counts stop at max_count.
        let model = SensorModel {
            hit: 5,
            max_count: 7,
            ..Default::default()
        };
        for _ in 0..3 {
            map.insert_scan(
                &PointCloud::from_points(vec![Point3::new(1.05, 0.05, 0.05)]),
                &Pose::identity(),
                &model,
            )
            .unwrap();
        }
        assert_eq!(map.count_at(&Point3::new(1.05, 0.05, 0.05)), 7);
    }
}
