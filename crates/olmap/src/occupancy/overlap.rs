//! Overlap of a scan with a map: the score of a pose (thesis Algorithm 5, (5.7)).

use nalgebra::Point3;

use super::list::OccupancyList;
use super::packed::{entry_key, pack_key, unpack_key};
use crate::error::{Error, Result};
use crate::geometry::{Pose, VoxelKey};

impl OccupancyList {
    fn check_same_resolution(&self, other: &OccupancyList) -> Result<()> {
        if self.resolution() == other.resolution() {
            Ok(())
        } else {
            Err(Error::InvalidArgument(format!(
                "overlap needs equal resolutions, got map {} m and scan {} m",
                self.resolution(),
                other.resolution()
            )))
        }
    }

    /// `|L ∩ M|` (thesis (5.7)): how many voxels of `scan`, moved by `t_map_scan` (voxel
    /// centres transformed and re-voxelised), are stored in this map. Both lists must share
    /// the resolution. No allocation: this is the alignment inner loop.
    ///
    /// ```
    /// use olmap::cloud::PointCloud;
    /// use olmap::geometry::Pose;
    /// use olmap::occupancy::OccupancyList;
    /// use nalgebra::Point3;
    /// let map = OccupancyList::from_cloud(&PointCloud::from_points(vec![
    ///     Point3::new(1.05, 0.05, 0.05), Point3::new(1.15, 0.05, 0.05)]), 0.1).unwrap();
    /// let scan = OccupancyList::from_cloud(&PointCloud::from_points(vec![
    ///     Point3::new(0.05, 0.05, 0.05), Point3::new(0.15, 0.05, 0.05)]), 0.1).unwrap();
    /// let shift = Pose::from_xyz_ypr(1.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    /// assert_eq!(map.overlap(&scan, &shift).unwrap(), 2);
    /// assert_eq!(map.overlap(&scan, &Pose::identity()).unwrap(), 0);
    /// ```
    pub fn overlap(&self, scan: &OccupancyList, t_map_scan: &Pose) -> Result<u64> {
        self.check_same_resolution(scan)?;
        Ok(self.overlap_impl(scan, t_map_scan, |_| 1))
    }

    /// Like [`OccupancyList::overlap`], but each overlapping voxel scores the map's count
    /// there (strongly confirmed structure weighs more).
    pub fn weighted_overlap(&self, scan: &OccupancyList, t_map_scan: &Pose) -> Result<u64> {
        self.check_same_resolution(scan)?;
        Ok(self.overlap_impl(scan, t_map_scan, |c| c as u64))
    }

    #[inline]
    fn overlap_impl(
        &self,
        scan: &OccupancyList,
        t_map_scan: &Pose,
        score: impl Fn(u16) -> u64,
    ) -> u64 {
        let r = self.resolution();
        let iso = t_map_scan.isometry();
        let mut total = 0;
        for e in scan.table.entries() {
            let c = iso.transform_point(&unpack_key(entry_key(e)).center(r));
            let Some(k) = VoxelKey::from_point(&c, r).and_then(pack_key) else {
                continue;
            };
            let n = self.table.get(k);
            if n > 0 {
                total += score(n);
            }
        }
        total
    }

    /// How many of `keys`, shifted by an integer voxel `offset`, are stored: the overlap of
    /// an already rotated scan at a translation that is a whole number of voxels (the
    /// thesis groups poses by rotation so that translations are key offsets, §5.3.3).
    pub fn overlap_keys(&self, keys: &[VoxelKey], offset: [i32; 3]) -> u64 {
        keys.iter()
            .filter(|k| {
                let s = VoxelKey::new(
                    k.x.wrapping_add(offset[0]),
                    k.y.wrapping_add(offset[1]),
                    k.z.wrapping_add(offset[2]),
                );
                pack_key(s).is_some_and(|p| self.table.contains(p))
            })
            .count() as u64
    }

    /// The keys of this list's voxel centres moved by a pose, re-voxelised at this
    /// resolution (duplicates kept): the input of [`OccupancyList::overlap_keys`].
    pub fn transformed_keys(&self, pose: &Pose) -> Vec<VoxelKey> {
        let r = self.resolution();
        self.table
            .entries()
            .filter_map(|e| {
                let c: Point3<f64> = pose.transform_point(&unpack_key(entry_key(e)).center(r));
                VoxelKey::from_point(&c, r)
            })
            .collect()
    }
}
