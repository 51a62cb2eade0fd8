//! ROS 2 bags without ROS: rosbag2 folders (`metadata.yaml` + one or more `.mcap` files,
//! split bags too) and single `.mcap` files, read with the `mcap` crate and olmap's own CDR
//! decoding; maps written back as MCAP for Foxglove and the rosbag2 tools.
//!
//! | piece | what |
//! |---|---|
//! | [`Bag`] | opens a bag and streams its messages in order, each with its topic, type and index on the topic |
//! | [`bag_info`] | topics, counts, stamps, frames (`olmap bag info`) |
//! | [`messages`] | `PointCloud2`, `LaserScan`, `Odometry`, `TFMessage`, `PoseStamped`, `Path`, decoded and encoded directly |
//! | [`pointcloud2`] | any `PointCloud2` layout to an olmap cloud |
//! | [`schema`], [`dynamic`] | any message decoded from the `ros2msg` definition the bag carries |
//! | [`TfTree`] | `/tf_static`, `/tf` and odometry chains, interpolated at a stamp |
//! | [`extract_scans`], [`write_extraction`] | scans with odometry, in memory or as a folder `olmap map` reads |
//! | [`write_map_mcap`] | a map and its poses as an MCAP file |
//!
//! **Bounds.** A record claiming more bytes than its file has left is damage (the reader's
//! buffer never grows past what the file holds); a record or decompressed chunk may hold at most
//! [`crate::io::max_decompressed_bytes`] of its file's size (64 times it, at least 32 MiB),
//! and never more than [`MAX_RECORD_BYTES`]; every count in a message is checked against the bytes left before anything is
//! allocated; chunk CRCs are checked before a chunk's messages are used. A damaged or
//! truncated file stops the reading at the damage with a [`BagError::Container`] (or
//! [`BagInfo::stopped_early`]), after delivering every message before it; a message that
//! does not decode is named by topic, index and type.
//!
//! **Compression.** zstd chunks through the `zstd` crate, lz4 chunks through the pure-Rust
//! `lz4_flex` ([`lz4`]), so no C lz4 library is linked. The SQLite storage (`.db3`) is not
//! read: convert such bags with `ros2 bag convert`.

pub mod cdr;
mod container;
pub mod dynamic;
mod error;
mod extract;
mod info;
pub mod lz4;
pub mod messages;
pub mod pointcloud2;
pub mod schema;
mod tf;
mod write;

pub use container::{Bag, BagMessage, SchemaInfo, MAX_RECORD_BYTES};
pub use error::BagError;
pub use extract::{
    extract_scans, extract_scans_with, write_extraction, BagScan, ExtractOptions, ExtractReport,
    Extraction, ScanSpec, LASER_SCAN, ODOMETRY, POINT_CLOUD2, TF_MESSAGE,
};
#[cfg(any(test, feature = "test-support"))]
pub(crate) use info::bag_info_of_bytes;
pub use info::{bag_info, BagInfo, TopicInfo, MAX_PROBLEMS};
pub use tf::{interpolate, TfTree, DEFAULT_TOLERANCE_NS};
#[cfg(any(test, feature = "test-support"))]
pub(crate) use write::map_mcap_bytes;
pub use write::{write_map_mcap, MapBag};

/// Whether `path` looks like a bag: an `.mcap` file, or a folder holding `metadata.yaml`
/// or `.mcap` files.
pub fn is_bag_path(path: &std::path::Path) -> bool {
    if path.is_file() {
        return path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    }
    path.is_dir()
        && (path.join("metadata.yaml").is_file()
            || std::fs::read_dir(path).is_ok_and(|mut d| {
                d.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x == "mcap")))
            }))
}
