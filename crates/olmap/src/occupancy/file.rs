//! Map files: reading and writing occupancy lists by file name.

use std::io::BufRead;
use std::path::Path;

use super::free::FreeSpace;
use super::list::OccupancyList;
use crate::error::{Error, ParseError, Result};
use crate::io::octomap_bt::{self, BtStats};

/// The map file formats olmap knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapFormat {
    /// olmap's `.olm` (exact counts).
    Olm,
    /// OctoMap's binary octree `.bt` (occupied or not: counts are read as 1 and not written).
    OctomapBt,
}

impl MapFormat {
    /// The format of a path, by extension (case-insensitive).
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "olm" => Some(MapFormat::Olm),
            "bt" => Some(MapFormat::OctomapBt),
            _ => None,
        }
    }

    /// The format of an output map path, or [`Error::InvalidArgument`] naming the path
    /// when its extension is neither `.olm` nor `.bt`: what every writer of a map checks
    /// before doing any work.
    pub fn of_output(path: &Path) -> Result<Self> {
        Self::from_path(path).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "{}: the output must be a map file (.olm or .bt)",
                path.display()
            ))
        })
    }

    /// A short human name.
    pub fn name(self) -> &'static str {
        match self {
            MapFormat::Olm => "olmap .olm",
            MapFormat::OctomapBt => "OctoMap .bt",
        }
    }
}

/// A map read from a file.
#[derive(Debug, Clone)]
pub struct LoadedMap {
    /// The occupancy list.
    pub map: OccupancyList,
    /// The file's format.
    pub format: MapFormat,
    /// For `.bt` files: the tree's node and leaf counts.
    pub bt: Option<BtStats>,
    /// The free space the file keeps (a `.bt` tree's free leaves), `None` when it keeps
    /// none: a localisation in the map checks scans against it
    /// ([`crate::align::Localizer::with_free_space`]).
    pub free: Option<FreeSpace>,
}

/// The most voxels a `.bt` file may expand to when read: 2^24 = 16,777,216, one occupied
/// leaf at depth 8 (a cube of 256 voxels a side), about 170 MiB in the map
/// ([`octomap_bt::BYTES_PER_EXPANDED_VOXEL`] each). OctoMap prunes a node whose eight
/// children are all occupied into one coarse leaf, so a small file can stand for many
/// voxels: 5 leaves at depth 8 in a 76-byte file are 84 million. Real maps stay far below
/// the limit (the shared data's `geb079.bt`: 185,673 voxels from 143,729 leaves); a tree
/// beyond it is refused with [`Error::TooLarge`] naming the expansion before anything is
/// allocated.
pub const MAX_BT_VOXELS: usize = 1 << 24;

fn unknown(path: &Path) -> Error {
    Error::UnknownFormat {
        path: path.to_path_buf(),
        reason: "not a map file; known map extensions: .olm .bt".into(),
    }
}

/// Reads a map file.
pub fn read_map(path: impl AsRef<Path>) -> Result<LoadedMap> {
    let path = path.as_ref();
    let format = MapFormat::from_path(path).ok_or_else(|| unknown(path))?;
    crate::file::parse_file(path, format.name(), |r| read_map_from(r, format))
}

/// Reads a map of a known format from a stream (no file name needed): what [`read_map`]
/// does once it has opened the file. A `.bt` tree is expanded to at most
/// [`MAX_BT_VOXELS`] voxels; its free leaves, if any, are kept as the map's free space
/// ([`LoadedMap::free`]), unexpanded.
pub fn read_map_from<R: BufRead>(reader: R, format: MapFormat) -> Result<LoadedMap, ParseError> {
    match format {
        MapFormat::Olm => Ok(LoadedMap {
            map: OccupancyList::read_olm(reader)?,
            format,
            bt: None,
            free: None,
        }),
        MapFormat::OctomapBt => {
            // Expanded straight into the map (no sorted copy): 10 bytes a voxel. Free
            // leaves are kept as boxes (24 bytes a leaf, in proportion to the file).
            let tree = octomap_bt::read_leaves_keeping(reader, true)?;
            let total = tree.expanded_voxels_within(MAX_BT_VOXELS)?;
            let mut map =
                OccupancyList::with_capacity(tree.resolution, total as usize).map_err(|e| {
                    ParseError::Malformed(e.to_string().replace("invalid argument: ", ""))
                })?;
            tree.for_each_voxel(|k| {
                map.set(k, 1)
                    .expect("OctoMap keys are within olmap's range")
            });
            Ok(LoadedMap {
                map,
                format,
                free: free_space_of(&tree),
                bt: Some(tree.stats),
            })
        }
    }
}

/// The free leaves of a tree as the map's free space, `None` when it has none.
fn free_space_of(tree: &octomap_bt::BtLeaves) -> Option<FreeSpace> {
    let mut free = FreeSpace::new(tree.resolution).ok()?;
    for (lo, hi) in tree.free_boxes() {
        free.push(lo, hi).ok()?;
    }
    (!free.is_empty()).then_some(free)
}

/// Writes a map file (format from the extension), atomically. `.bt` keeps occupancy only
/// (every stored voxel is an occupied leaf; the tree is pruned) and needs keys within
/// ±32,768 voxels of the origin.
pub fn write_map(path: impl AsRef<Path>, map: &OccupancyList) -> Result<MapFormat> {
    let path = path.as_ref();
    let format = MapFormat::from_path(path).ok_or_else(|| unknown(path))?;
    match format {
        MapFormat::Olm => map.write_olm_path(path)?,
        MapFormat::OctomapBt => {
            let keys: Vec<_> = map.sorted().into_iter().map(|(k, _)| k).collect();
            octomap_bt::write_path(path, map.resolution(), &keys)?;
        }
    }
    Ok(format)
}
