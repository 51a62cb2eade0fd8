//! Typed reports of map files and map building for the command line: [`MapInfo`] (a map
//! file, `olmap info`), [`FileInfo`] with [`describe_file`] (any file `olmap info`
//! describes), and [`VoxelizeReport`] (`olmap voxelize --json`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{read_map, MapFormat, OccupancyStats};
use crate::cloud::BoxReport;
use crate::io::{CloudInfo, ReadOptions};

/// Node and leaf counts of an OctoMap `.bt` tree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OctreeReport {
    /// All nodes of the tree.
    pub nodes: u64,
    /// Leaves marked occupied.
    pub occupied_leaves: u64,
    /// Leaves marked free.
    pub free_leaves: u64,
    /// Occupied leaves per depth (index 16 = single voxels).
    pub occupied_leaves_by_depth: [u64; 17],
}

/// The description of one map file; field order is the JSON schema of `olmap info --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapInfo {
    /// The file, as shown to the user.
    pub path: String,
    /// The map format's name.
    pub format: String,
    /// Voxel edge, metres.
    pub resolution: f64,
    /// Stored voxels.
    pub voxels: usize,
    /// Box of the voxel cubes, `None` when empty.
    pub bbox: Option<BoxReport>,
    /// Sum of all counts.
    pub total_count: u64,
    /// Largest count.
    pub max_count: u16,
    /// Bytes of memory held by the map.
    pub memory_bytes: usize,
    /// For `.bt` files: the tree's counts (the key is absent for other maps).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub octree: Option<OctreeReport>,
}

impl MapInfo {
    /// The description of a map shown as `path`, of format `format`, with statistics `s`
    /// (no octree part).
    pub fn new(path: &str, format: &str, s: &OccupancyStats) -> Self {
        MapInfo {
            path: path.to_string(),
            format: format.to_string(),
            resolution: s.resolution,
            voxels: s.voxels,
            bbox: s.bbox.as_ref().map(BoxReport::new),
            total_count: s.total_count,
            max_count: s.max_count,
            memory_bytes: s.memory_bytes,
            octree: None,
        }
    }

    /// Reads the map file `path` and describes it (`shown`: the path as the user gave it).
    pub fn read(path: &Path, shown: &str) -> crate::Result<Self> {
        let loaded = read_map(path)?;
        let mut info = MapInfo::new(shown, loaded.format.name(), &loaded.map.stats());
        info.octree = loaded.bt.as_ref().map(|bt| OctreeReport {
            nodes: bt.nodes,
            occupied_leaves: bt.occupied_leaves,
            free_leaves: bt.free_leaves,
            occupied_leaves_by_depth: bt.occupied_leaves_by_depth,
        });
        Ok(info)
    }

    /// Memory per stored voxel, bytes (`NaN` when empty), as
    /// [`OccupancyStats::bytes_per_voxel`].
    pub fn bytes_per_voxel(&self) -> f64 {
        self.memory_bytes as f64 / self.voxels as f64
    }
}

/// A file `olmap info` could not describe.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileError {
    /// The file, as shown to the user.
    pub path: String,
    /// Why it failed.
    pub error: String,
}

/// One entry of `olmap info --json`: a cloud, a map, or an error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum FileInfo {
    /// A point-cloud file.
    Cloud(CloudInfo),
    /// A map file.
    Map(MapInfo),
    /// A file that could not be read.
    Error(FileError),
}

/// Describes `path` (shown as `shown`): as a map when its extension is a map format's,
/// else as a cloud read with `options`. A failure becomes [`FileInfo::Error`].
pub fn describe_file(path: &Path, shown: &str, options: &ReadOptions) -> FileInfo {
    let described = if MapFormat::from_path(path).is_some() {
        MapInfo::read(path, shown).map(FileInfo::Map)
    } else {
        CloudInfo::read(path, shown, options).map(FileInfo::Cloud)
    };
    described.unwrap_or_else(|e| {
        FileInfo::Error(FileError {
            path: shown.to_string(),
            error: e.to_string(),
        })
    })
}

/// The summary of `olmap voxelize --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VoxelizeReport {
    /// The map file written.
    pub output: String,
    /// Clouds given.
    pub clouds: usize,
    /// Clouds left out by the position buckets.
    pub clouds_skipped_by_buckets: usize,
    /// Points of the integrated clouds.
    pub points: usize,
    /// Voxel edge, metres.
    pub resolution: f64,
    /// Whether the clouds were ray traced.
    pub ray_trace: bool,
    /// Voxels in the map.
    pub voxels: usize,
    /// Points skipped (non-finite or outside the key range).
    pub skipped_points: u64,
    /// Rays cut at the maximum range.
    pub truncated_rays: u64,
    /// Voxels the rays passed through.
    pub voxels_traversed: u64,
    /// Memory per stored voxel, bytes.
    pub bytes_per_voxel: f64,
    /// Wall time, seconds.
    pub seconds: f64,
}
