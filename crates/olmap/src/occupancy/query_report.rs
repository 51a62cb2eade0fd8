//! [`QueryReport`]: the typed answers of `olmap query --json` (point, ray, radius and
//! segment queries of a map), and the functions that ask them.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::{OccupancyList, VoxelRay, VoxelState};
use crate::geometry::VoxelKey;
use crate::io::octomap_bt::BtIndex;
use crate::Result;

/// One voxel of a map: key, centre and count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VoxelReport {
    /// The key `[x, y, z]`.
    pub key: [i32; 3],
    /// The centre, metres.
    pub center: [f64; 3],
    /// The stored count.
    pub count: u16,
}

impl VoxelReport {
    /// The voxel `k` of `map`.
    pub fn new(map: &OccupancyList, k: VoxelKey) -> Self {
        let c = map.center(k);
        VoxelReport {
            key: [k.x, k.y, k.z],
            center: [c.x, c.y, c.z],
            count: map.count(k),
        }
    }
}

/// Whether the voxel of a point is occupied.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AtReport {
    /// `"at"`.
    pub query: String,
    /// The point asked, metres.
    pub point: [f64; 3],
    /// Whether its voxel's count reaches the threshold.
    pub occupied: bool,
    /// Its voxel's count.
    pub count: u16,
    /// Unknown, free or occupied, for a map that knows free space (a `.bt` tree with free
    /// nodes, see [`QueryReport::with_known_space`]): the tree's own classification,
    /// whatever `min_count` (a tree read as a map holds counts of 1); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<VoxelState>,
}

/// The first occupied voxel along a ray.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RayHitReport {
    /// `"ray"`.
    pub query: String,
    /// `true`.
    pub hit: bool,
    /// Distance along the ray to the voxel, metres.
    pub distance_m: f64,
    /// Where the ray enters the voxel, metres.
    pub point: [f64; 3],
    /// The voxel.
    pub voxel: VoxelReport,
}

/// A ray that met no occupied voxel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RayMissReport {
    /// `"ray"`.
    pub query: String,
    /// `false`.
    pub hit: bool,
    /// How far the ray reached, metres.
    pub max_range_m: f64,
}

/// The occupied voxels near a point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RadiusReport {
    /// `"radius"`.
    pub query: String,
    /// The centre asked, metres.
    pub center: [f64; 3],
    /// The radius, metres.
    pub radius_m: f64,
    /// Voxels found.
    pub count: usize,
    /// The voxels whose centres lie within the radius.
    pub voxels: Vec<VoxelReport>,
}

/// Whether a segment is free of occupied voxels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentReport {
    /// `"segment"`.
    pub query: String,
    /// One end, metres.
    pub from: [f64; 3],
    /// The other end, metres.
    pub to: [f64; 3],
    /// Whether no occupied voxel lies on it.
    pub free: bool,
    /// For a map that knows free space: whether every voxel on the segment is known to
    /// be free (no occupied and no unknown voxel: what a planner may drive through);
    /// absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub known_free: Option<bool>,
}

/// The answer of one `olmap query`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum QueryReport {
    /// A point query.
    At(AtReport),
    /// A ray that hit.
    RayHit(RayHitReport),
    /// A ray that missed.
    RayMiss(RayMissReport),
    /// A radius query.
    Radius(RadiusReport),
    /// A segment query.
    Segment(SegmentReport),
}

impl QueryReport {
    /// Is the voxel of `p` occupied (count at least `min_count`, and at least 1)?
    pub fn at(map: &OccupancyList, p: [f64; 3], min_count: u16) -> Self {
        let count = map.count_at(&Point3::new(p[0], p[1], p[2]));
        QueryReport::At(AtReport {
            query: "at".into(),
            point: p,
            occupied: count >= min_count.max(1),
            count,
            state: None,
        })
    }

    /// The first voxel of count at least `min_count` along the ray from `origin` in
    /// `direction`, up to `max_range` metres.
    pub fn ray(
        map: &OccupancyList,
        origin: [f64; 3],
        direction: [f64; 3],
        max_range: f64,
        min_count: u16,
    ) -> Result<Self> {
        let [x, y, z] = origin;
        let [dx, dy, dz] = direction;
        let hit = map.cast_ray(
            &Point3::new(x, y, z),
            &Vector3::new(dx, dy, dz),
            max_range,
            min_count,
        )?;
        Ok(match hit {
            Some(h) => QueryReport::RayHit(RayHitReport {
                query: "ray".into(),
                hit: true,
                distance_m: h.distance,
                point: [h.point.x, h.point.y, h.point.z],
                voxel: VoxelReport::new(map, h.key),
            }),
            None => QueryReport::RayMiss(RayMissReport {
                query: "ray".into(),
                hit: false,
                max_range_m: max_range,
            }),
        })
    }

    /// The voxels of count at least `min_count` (and at least 1) whose centres lie within
    /// `radius` metres of `center`.
    pub fn radius(
        map: &OccupancyList,
        center: [f64; 3],
        radius: f64,
        min_count: u16,
    ) -> Result<Self> {
        let [x, y, z] = center;
        let near: Vec<_> = map
            .occupied_within(&Point3::new(x, y, z), radius)?
            .into_iter()
            .filter(|(_, c)| *c >= min_count.max(1))
            .collect();
        Ok(QueryReport::Radius(RadiusReport {
            query: "radius".into(),
            center,
            radius_m: radius,
            count: near.len(),
            voxels: near
                .iter()
                .map(|(k, _)| VoxelReport::new(map, *k))
                .collect(),
        }))
    }

    /// Is the segment `from`-`to` free of voxels of count at least `min_count`?
    pub fn segment(
        map: &OccupancyList,
        from: [f64; 3],
        to: [f64; 3],
        min_count: u16,
    ) -> Result<Self> {
        let free = map.segment_is_free(
            &Point3::new(from[0], from[1], from[2]),
            &Point3::new(to[0], to[1], to[2]),
            min_count,
        )?;
        Ok(QueryReport::Segment(SegmentReport {
            query: "segment".into(),
            from,
            to,
            free,
            known_free: None,
        }))
    }

    /// Adds what a tree with free space knows: the state of a point query's voxel, and
    /// whether a segment is known free along its whole length (walked voxel by voxel
    /// through `resolution`-metre voxels; the walk stops at the first voxel that is not
    /// known free, and a tree spans at most 65,536 voxels per axis). Other answers are
    /// unchanged.
    pub fn with_known_space(mut self, index: &BtIndex, resolution: f64) -> Self {
        let state = |k: &VoxelKey| match index.state(k) {
            None => VoxelState::Unknown,
            Some(true) => VoxelState::Occupied,
            Some(false) => VoxelState::Free,
        };
        match &mut self {
            QueryReport::At(q) => {
                let p = Point3::new(q.point[0], q.point[1], q.point[2]);
                q.state = Some(
                    VoxelKey::from_point(&p, resolution).map_or(VoxelState::Unknown, |k| state(&k)),
                );
            }
            QueryReport::Segment(q) => {
                let a = Point3::from(q.from);
                let b = Point3::from(q.to);
                let ray = VoxelRay::new(&a, &b, resolution);
                let finite = ray.remaining() > 0;
                q.known_free =
                    Some(finite && ray.into_iter().all(|k| state(&k) == VoxelState::Free));
            }
            _ => {}
        }
        self
    }
}
