//! The [`OccupancyList`] type: a sparse voxel map of integer occupancy counts.

use nalgebra::Point3;

use super::packed::{entry_count, entry_key, pack_key, unpack_key, MAX_COUNT};
use super::table::VoxelTable;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{Aabb, Pose, VoxelKey};

/// A sparse 3D occupancy map (thesis §5.3.1): voxel key -> occupancy count.
///
/// The count is proportional to the log odds of occupancy (thesis (3.28)): a return in a
/// voxel adds, a ray through it subtracts, and a voxel is stored only while its count is
/// positive. Counts saturate at [`MAX_COUNT`] (1023), which is also the default clamping
/// bound of [`super::SensorModel`]. Keys are `floor(coord / resolution)`; representable keys
/// span ±131,072 voxels per axis (see [`super::KEY_MIN`], [`super::KEY_MAX`]).
///
/// ```
/// use olmap::cloud::PointCloud;
/// use olmap::occupancy::OccupancyList;
/// use nalgebra::Point3;
/// let cloud = PointCloud::from_points(vec![
///     Point3::new(1.01, 0.0, 0.0),
///     Point3::new(1.02, 0.0, 0.0), // same 0.1 m voxel
///     Point3::new(-0.05, 0.0, 0.0),
/// ]);
/// let map = OccupancyList::from_cloud(&cloud, 0.1).unwrap();
/// assert_eq!(map.len(), 2);
/// assert_eq!(map.count_at(&Point3::new(1.05, 0.05, 0.05)), 2);
/// assert!(map.is_occupied(&Point3::new(-0.01, 0.0, 0.0)));
/// ```
#[derive(Clone)]
pub struct OccupancyList {
    resolution: f64,
    pub(crate) table: VoxelTable,
}

impl std::fmt::Debug for OccupancyList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OccupancyList")
            .field("resolution", &self.resolution)
            .field("voxels", &self.len())
            .finish()
    }
}

impl PartialEq for OccupancyList {
    /// Same resolution and the same (key, count) pairs.
    fn eq(&self, other: &Self) -> bool {
        self.resolution == other.resolution
            && self.len() == other.len()
            && self
                .table
                .entries()
                .all(|e| other.table.get(entry_key(e)) == entry_count(e))
    }
}

/// Summary of an occupancy list.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyStats {
    /// Voxel edge, metres.
    pub resolution: f64,
    /// Stored (occupied) voxels.
    pub voxels: usize,
    /// Box of the voxel cubes (not centres), `None` when empty.
    pub bbox: Option<Aabb>,
    /// Sum of all counts.
    pub total_count: u64,
    /// Largest count.
    pub max_count: u16,
    /// Bytes of memory held by the map.
    pub memory_bytes: usize,
}

impl OccupancyStats {
    /// Memory per stored voxel, bytes (`NaN` when empty).
    pub fn bytes_per_voxel(&self) -> f64 {
        self.memory_bytes as f64 / self.voxels as f64
    }
}

pub(crate) fn check_resolution(resolution: f64) -> Result<()> {
    if resolution.is_finite() && resolution > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "voxel resolution must be a positive number of metres, got {resolution}"
        )))
    }
}

impl OccupancyList {
    /// An empty list with voxels of `resolution` metres.
    pub fn new(resolution: f64) -> Result<Self> {
        check_resolution(resolution)?;
        Ok(OccupancyList {
            resolution,
            table: VoxelTable::default(),
        })
    }

    /// An empty list with room for `n` voxels.
    pub fn with_capacity(resolution: f64, n: usize) -> Result<Self> {
        check_resolution(resolution)?;
        Ok(OccupancyList {
            resolution,
            table: VoxelTable::with_capacity(n),
        })
    }

    /// Endpoints only: every point adds 1 to the count of its voxel (no ray tracing). A
    /// point whose key is outside the representable range is an error naming it
    /// ([`OccupancyList::check_keys`]), never a silent drop.
    pub fn from_cloud(cloud: &PointCloud, resolution: f64) -> Result<Self> {
        let mut list = Self::with_capacity(resolution, cloud.len() / 4)?;
        list.check_keys(cloud, &Pose::identity(), "the cloud")?;
        list.add_points(cloud, &Pose::identity(), 1);
        Ok(list)
    }

    /// Checks that every point of `cloud` placed by `t_map_cloud` has a voxel key in the
    /// representable range ([`super::KEY_MIN`] to [`super::KEY_MAX`] per axis, ±13 km at
    /// 0.1 m, ±1.3 m at 10 µm): the first that does not (or is not finite) is
    /// [`Error::TooLarge`] naming `what`, the point's index, its coordinates in the map
    /// frame, its key and the range ([`crate::geometry::key_range_error`]).
    ///
    /// ```
    /// use olmap::cloud::PointCloud;
    /// use olmap::geometry::Pose;
    /// use olmap::occupancy::OccupancyList;
    /// use nalgebra::Point3;
    /// let cloud = PointCloud::from_points(vec![Point3::new(1.0, 0.0, 0.0), Point3::new(3.0, 0.0, 0.0)]);
    /// let map = OccupancyList::new(1e-5).unwrap(); // keys within ±1.31 m
    /// let e = map.check_keys(&cloud, &Pose::identity(), "scan.pcd").unwrap_err().to_string();
    /// assert!(e.contains("scan.pcd: point 1 at (3, 0, 0) m"), "{e}");
    /// ```
    pub fn check_keys(&self, cloud: &PointCloud, t_map_cloud: &Pose, what: &str) -> Result<()> {
        for (i, p) in cloud.points().iter().enumerate() {
            // The arithmetic of `add_points`: a cloud that passes loses no point there.
            let q = t_map_cloud.transform_point(&p.cast::<f64>());
            if self.pack(&q).is_none() {
                return Err(crate::geometry::key_range_error(
                    what,
                    i,
                    &q,
                    self.resolution,
                    super::packed::KEY_MAX as i64,
                ));
            }
        }
        Ok(())
    }

    /// Adds `increment` to the voxel of every point of `cloud` mapped by `t_map_cloud`
    /// (endpoints only). Returns how many points were skipped (non-finite or out of range).
    pub fn add_points(&mut self, cloud: &PointCloud, t_map_cloud: &Pose, increment: u16) -> usize {
        let mut skipped = 0;
        for p in cloud.points() {
            let q = t_map_cloud.transform_point(&p.cast::<f64>());
            match self.pack(&q) {
                Some(k) => self.add_packed(k, increment),
                None => skipped += 1,
            }
        }
        skipped
    }

    /// The voxels `cloud`'s points fall in once moved by `t_map_cloud`, each with a count
    /// of 1 (how many points fell in it is not kept): the occupancy the agreement counts
    /// read, where only whether a voxel holds a point matters. The voxel keys are computed
    /// side by side and sorted, then stored once each in a table made large enough, instead
    /// of a hash update per point in a table that grows (a map's side of a count is
    /// hundreds of thousands of points). Points whose key does not fit are left out, as
    /// [`OccupancyList::add_points`] skips them.
    pub(crate) fn occupied_by(
        cloud: &PointCloud,
        t_map_cloud: &Pose,
        resolution: f64,
    ) -> Result<Self> {
        use rayon::prelude::*;
        check_resolution(resolution)?;
        let mut keys: Vec<u64> = cloud
            .points()
            .par_iter()
            .with_min_len(4096)
            .filter_map(|p| {
                pack_key(VoxelKey::from_point(
                    &t_map_cloud.transform_point(&p.cast::<f64>()),
                    resolution,
                )?)
            })
            .collect();
        keys.par_sort_unstable();
        keys.dedup();
        let mut list = OccupancyList::with_capacity(resolution, keys.len())?;
        for k in keys {
            list.add_packed(k, 1);
        }
        Ok(list)
    }

    #[inline]
    pub(crate) fn pack(&self, p: &Point3<f64>) -> Option<u64> {
        pack_key(VoxelKey::from_point(p, self.resolution)?)
    }

    #[inline]
    pub(crate) fn add_packed(&mut self, key: u64, increment: u16) {
        self.table.update(key, |c| {
            (c as u32 + increment as u32).min(MAX_COUNT as u32) as u16
        });
    }

    #[inline]
    pub(crate) fn sub_packed(&mut self, key: u64, decrement: u16) {
        self.table.update(key, |c| c.saturating_sub(decrement));
    }

    /// Lowers every count above `max_count` (at least 1) to it.
    pub fn clamp_counts(&mut self, max_count: u16) {
        let max = max_count.max(1);
        let over: Vec<u64> = self
            .table
            .entries()
            .filter(|&e| entry_count(e) > max)
            .map(entry_key)
            .collect();
        for k in over {
            self.table.update(k, |_| max);
        }
    }

    /// Voxel edge, metres.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Number of stored voxels.
    pub fn len(&self) -> usize {
        self.table.len()
    }

    /// Whether no voxel is stored.
    pub fn is_empty(&self) -> bool {
        self.table.len() == 0
    }

    /// The key of the voxel holding a point.
    pub fn key_of(&self, p: &Point3<f64>) -> Option<VoxelKey> {
        VoxelKey::from_point(p, self.resolution)
    }

    /// The count of a voxel (0 when not stored or not representable).
    pub fn count(&self, key: VoxelKey) -> u16 {
        pack_key(key).map_or(0, |k| self.table.get(k))
    }

    /// The count of the voxel holding a point.
    pub fn count_at(&self, p: &Point3<f64>) -> u16 {
        self.pack(p).map_or(0, |k| self.table.get(k))
    }

    /// Whether the voxel holding a point is stored (count > 0).
    pub fn is_occupied(&self, p: &Point3<f64>) -> bool {
        self.count_at(p) > 0
    }

    /// Sets the count of a voxel (0 removes it; counts above [`MAX_COUNT`] saturate).
    pub fn set(&mut self, key: VoxelKey, count: u32) -> Result<()> {
        let k = pack_key(key).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "voxel key {key:?} is outside the representable range"
            ))
        })?;
        let c = count.min(MAX_COUNT as u32) as u16;
        self.table.update(k, |_| c);
        Ok(())
    }

    /// Every stored voxel and its count, in no particular order.
    pub fn iter(&self) -> impl Iterator<Item = (VoxelKey, u16)> + '_ {
        self.table
            .entries()
            .map(|e| (unpack_key(entry_key(e)), entry_count(e)))
    }

    /// Every stored voxel sorted by key (x, then y, then z): a deterministic order for files
    /// and tests.
    pub fn sorted(&self) -> Vec<(VoxelKey, u16)> {
        let mut v: Vec<u64> = self.table.entries().collect();
        v.sort_unstable();
        v.into_iter()
            .map(|e| (unpack_key(entry_key(e)), entry_count(e)))
            .collect()
    }

    /// The centre of a voxel, metres.
    pub fn center(&self, key: VoxelKey) -> Point3<f64> {
        key.center(self.resolution)
    }

    /// A new list of the voxels for which `keep` holds.
    pub fn filtered(&self, mut keep: impl FnMut(VoxelKey, u16) -> bool) -> OccupancyList {
        let mut out = OccupancyList {
            resolution: self.resolution,
            table: VoxelTable::default(),
        };
        for e in self.table.entries() {
            if keep(unpack_key(entry_key(e)), entry_count(e)) {
                out.table.update(entry_key(e), |_| entry_count(e));
            }
        }
        out
    }

    /// [`OccupancyList::filtered`] with `keep` asked for many voxels side by side (the same
    /// list: the kept voxels are stored in the same order).
    pub fn par_filtered(&self, keep: impl Fn(VoxelKey, u16) -> bool + Sync) -> OccupancyList {
        use rayon::prelude::*;
        let entries: Vec<_> = self.table.entries().collect();
        let kept: Vec<bool> = entries
            .par_iter()
            .with_min_len(1024)
            .map(|e| keep(unpack_key(entry_key(*e)), entry_count(*e)))
            .collect();
        let mut out = OccupancyList {
            resolution: self.resolution,
            table: VoxelTable::default(),
        };
        for (e, k) in entries.iter().zip(kept) {
            if k {
                out.table.update(entry_key(*e), |_| entry_count(*e));
            }
        }
        out
    }

    /// The voxels with a count of at least `min_count` (e.g. 2 to drop single mixed-pixel
    /// returns, thesis §4.4.1).
    pub fn threshold(&self, min_count: u16) -> OccupancyList {
        self.filtered(|_, c| c >= min_count)
    }

    /// The voxels whose centre lies inside a box.
    pub fn crop(&self, aabb: &Aabb) -> OccupancyList {
        let r = self.resolution;
        self.filtered(|k, _| aabb.contains(&k.center(r)))
    }

    /// The voxels whose centre height is in `[z_min, z_max]` (e.g. the thesis' sub-ceiling
    /// localisation band 2.3-2.9 m, §5.4).
    pub fn z_slice(&self, z_min: f64, z_max: f64) -> OccupancyList {
        let r = self.resolution;
        self.filtered(|k, _| {
            let z = k.center(r).z;
            z >= z_min && z <= z_max
        })
    }

    /// Adds another list's counts to this one (saturating). Both must have the same
    /// resolution. Merging is commutative and associative.
    pub fn merge(&mut self, other: &OccupancyList) -> Result<()> {
        if self.resolution != other.resolution {
            return Err(Error::InvalidArgument(format!(
                "cannot merge occupancy lists of different resolutions ({} m and {} m)",
                self.resolution, other.resolution
            )));
        }
        for e in other.table.entries() {
            self.add_packed(entry_key(e), entry_count(e));
        }
        Ok(())
    }

    /// The list moved by a pose `T_new_old`: every voxel centre is transformed and
    /// re-voxelised; counts of voxels that land together add (saturating). Voxels that leave
    /// the representable range are dropped.
    pub fn transformed(&self, pose: &Pose) -> OccupancyList {
        let mut out = OccupancyList {
            resolution: self.resolution,
            table: VoxelTable::with_capacity(self.len()),
        };
        for e in self.table.entries() {
            let c = pose.transform_point(&unpack_key(entry_key(e)).center(self.resolution));
            if let Some(k) = out.pack(&c) {
                out.add_packed(k, entry_count(e));
            }
        }
        out
    }

    /// Voxel centres as a point cloud, counts as intensity.
    pub fn to_cloud(&self) -> PointCloud {
        let sorted = self.sorted();
        let pts = sorted
            .iter()
            .map(|(k, _)| self.center(*k).cast::<f32>())
            .collect();
        let mut c = PointCloud::from_points(pts);
        c.set_intensity(Some(sorted.iter().map(|(_, n)| *n as f32).collect()))
            .expect("one count per voxel");
        c
    }

    /// Summary statistics.
    pub fn stats(&self) -> OccupancyStats {
        let mut lo = [i32::MAX; 3];
        let mut hi = [i32::MIN; 3];
        let (mut total, mut max) = (0u64, 0u16);
        for e in self.table.entries() {
            let k = unpack_key(entry_key(e));
            for (i, v) in [k.x, k.y, k.z].into_iter().enumerate() {
                lo[i] = lo[i].min(v);
                hi[i] = hi[i].max(v);
            }
            let c = entry_count(e);
            total += c as u64;
            max = max.max(c);
        }
        let r = self.resolution;
        let bbox = (!self.is_empty()).then(|| {
            Aabb::new(
                Point3::new(lo[0] as f64 * r, lo[1] as f64 * r, lo[2] as f64 * r),
                Point3::new(
                    (hi[0] + 1) as f64 * r,
                    (hi[1] + 1) as f64 * r,
                    (hi[2] + 1) as f64 * r,
                ),
            )
        });
        OccupancyStats {
            resolution: r,
            voxels: self.len(),
            bbox,
            total_count: total,
            max_count: max,
            memory_bytes: self.table.memory_bytes() + std::mem::size_of::<Self>(),
        }
    }

    /// Releases spare table capacity (keeps the load at most 0.8).
    pub fn shrink_to_fit(&mut self) {
        self.table.shrink_to_fit();
    }

    /// Map entropy, thesis (7.4), in nats:
    /// `H = (|M| - V/eps^3) p0 ln p0 + sum ln(e^-m + 1) / (e^-m + 1)`, where `m` is a voxel's
    /// log odds, `count * log_odds_per_count` ((7.3): `p = 1 / (e^-m + 1)`), `p0` the
    /// occupancy probability of unlisted voxels and `V` the mapped volume in m³ (`None`: the
    /// volume of the map's bounding box). As in the thesis, each voxel contributes
    /// `-p ln p`.
    pub fn entropy(&self, p0: f64, volume_m3: Option<f64>, log_odds_per_count: f64) -> Result<f64> {
        if !(p0 > 0.0 && p0 < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "p0 must be in (0, 1), got {p0}"
            )));
        }
        let volume = match volume_m3 {
            Some(v) if v.is_finite() && v >= 0.0 => v,
            Some(v) => {
                return Err(Error::InvalidArgument(format!(
                    "volume must be >= 0 m³, got {v}"
                )))
            }
            None => self.stats().bbox.map_or(0.0, |b| b.extent().product()),
        };
        let cells = volume / self.resolution.powi(3);
        let listed: f64 = self
            .table
            .entries()
            .map(|e| {
                let m = entry_count(e) as f64 * log_odds_per_count;
                let d = (-m).exp() + 1.0;
                d.ln() / d
            })
            .sum();
        Ok((self.len() as f64 - cells) * p0 * p0.ln() + listed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `occupied_by` holds exactly the voxels `add_points` fills (each once, count 1),
    /// whatever the pose, and leaves out the points whose key does not fit, as it does.
    #[test]
    fn occupied_by_holds_the_voxels_add_points_fills() {
        let mut rng = crate::sim::SimRng::new(9);
        let mut points: Vec<Point3<f32>> = (0..30_000)
            .map(|_| {
                Point3::new(
                    rng.range(-8.0, 8.0) as f32,
                    rng.range(-8.0, 8.0) as f32,
                    rng.range(0.0, 3.0) as f32,
                )
            })
            .collect();
        points.push(Point3::new(1e9, 0.0, 0.0));
        let cloud = PointCloud::from_points(points);
        let pose = Pose::from_xyz_ypr(1.3, -0.4, 0.2, 0.7, 0.05, -0.02);
        let mut expected = OccupancyList::new(0.1).unwrap();
        assert_eq!(expected.add_points(&cloud, &pose, 1), 1);
        let got = OccupancyList::occupied_by(&cloud, &pose, 0.1).unwrap();
        assert_eq!(got.len(), expected.len());
        for (k, c) in got.iter() {
            assert_eq!(c, 1);
            assert!(expected.count(k) > 0, "{k:?}");
        }
    }

    fn sample() -> OccupancyList {
        let mut l = OccupancyList::new(0.1).unwrap();
        l.set(VoxelKey::new(0, 0, 0), 1).unwrap();
        l.set(VoxelKey::new(10, 0, 25), 3).unwrap();
        l.set(VoxelKey::new(-5, 2, 28), 2).unwrap();
        l
    }

    #[test]
    fn filters() {
        let l = sample();
        assert_eq!(l.threshold(2).len(), 2);
        // Sub-ceiling band 2.3-2.9 m: centres at 2.55 and 2.85 m.
        assert_eq!(l.z_slice(2.3, 2.9).len(), 2);
        let b = Aabb::new(Point3::new(-1.0, -1.0, -1.0), Point3::new(0.5, 0.5, 0.5));
        assert_eq!(l.crop(&b).sorted(), vec![(VoxelKey::new(0, 0, 0), 1)]);
        let s = l.stats();
        assert_eq!((s.voxels, s.total_count, s.max_count), (3, 6, 3));
        let bb = s.bbox.unwrap();
        assert!((bb.min.x + 0.5).abs() < 1e-12 && (bb.max.z - 2.9).abs() < 1e-12);
    }

    #[test]
    fn transform_moves_voxel_centres() {
        let l = sample();
        let t = Pose::from_xyz_ypr(1.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        let m = l.transformed(&t);
        assert_eq!(m.len(), 3);
        // Centre (1.05, 0.05, 2.55) turns to (-0.05, 1.05, 2.55), then moves to (0.95, 1.05, 2.55).
        assert_eq!(m.count(VoxelKey::new(9, 10, 25)), 3);
        assert_eq!(l.transformed(&Pose::identity()), l);
    }

    #[test]
    fn entropy_follows_the_thesis_formula() {
        let l = sample();
        // Every listed voxel contributes -p ln p with p = 1 / (e^-m + 1).
        let listed: f64 = [1.0f64, 3.0, 2.0]
            .iter()
            .map(|m| {
                let p = 1.0 / ((-m).exp() + 1.0);
                -p * p.ln()
            })
            .sum();
        let p0: f64 = 0.5;
        let v = 1000.0 * 0.001; // 1000 cells of 0.1 m
        let h = l.entropy(p0, Some(v), 1.0).unwrap();
        let expected = -(1000.0 - 3.0) * p0 * p0.ln() + listed;
        assert!((h - expected).abs() < 1e-9, "{h} vs {expected}");
        assert!(l.entropy(0.0, None, 1.0).is_err());
        assert!(l.entropy(0.5, Some(-1.0), 1.0).is_err());
        // More confident voxels (higher counts) lower the entropy of the listed part.
        let mut sure = l.clone();
        sure.merge(&l).unwrap();
        assert!(sure.entropy(p0, Some(v), 1.0).unwrap() < h);
    }
}
