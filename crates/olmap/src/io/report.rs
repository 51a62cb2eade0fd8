//! [`CloudInfo`]: the typed description of a read point-cloud file (`olmap info`), and
//! [`ConvertReport`] with [`convert_cloud_file`]: reading, filtering and writing a cloud
//! (`olmap convert`).

use std::path::PathBuf;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::{read_cloud_with, write_cloud, ReadOptions, ReadReport, WriteOptions};
use crate::cloud::{BoxReport, CloudStats, RangeReport};
use crate::geometry::{Aabb, Pose};
use crate::{Error, Result};

/// Width and height of an organised cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct OrganizedSize {
    /// Points per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

/// The description of one point-cloud file; field order is the JSON schema of
/// `olmap info --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudInfo {
    /// The file, as shown to the user.
    pub path: String,
    /// The format's name.
    pub format: String,
    /// The encoding within the format (empty where the format has one).
    pub encoding: String,
    /// The compression the file was wrapped in (`bzip2`), if any.
    pub compression: Option<String>,
    /// Point records in the file.
    pub records: u64,
    /// Points kept.
    pub points: usize,
    /// Points dropped for a NaN or infinite coordinate.
    pub dropped_non_finite: u64,
    /// Points dropped by a validity filter.
    pub dropped_invalid: u64,
    /// Unparseable lines skipped at the top of a text file.
    pub header_lines_skipped: usize,
    /// The per-point fields the file declares.
    pub fields: Vec<String>,
    /// Width and height of an organised cloud.
    pub organized: Option<OrganizedSize>,
    /// The sensor origin, metres.
    pub origin: [f64; 3],
    /// LAS/LAZ: the point of the file's frame that the cloud's `(0, 0, 0)` stands for (file
    /// coordinates = the cloud's + this; see [`ReadReport::local_origin`]); `None` for the
    /// other formats.
    pub local_origin: Option<[f64; 3]>,
    /// The bounding box, `None` for an empty cloud.
    pub bbox: Option<BoxReport>,
    /// The mean position, `None` for an empty cloud.
    pub centroid: Option<[f64; 3]>,
    /// Ranges from the origin, `None` for an empty cloud.
    pub range: Option<RangeReport>,
    /// Smallest and largest intensity (single precision widened to double).
    pub intensity_range: Option<[f64; 2]>,
    /// Whether normals are present.
    pub has_normals: bool,
    /// Whether colours are present.
    pub has_colors: bool,
}

impl CloudInfo {
    /// The description of a cloud read from `path` (shown as given) with `report`, whose
    /// statistics are `stats` and sensor origin `origin`.
    pub fn new(path: &str, stats: &CloudStats, report: &ReadReport, origin: [f64; 3]) -> Self {
        CloudInfo {
            path: path.to_string(),
            format: report.format.name().to_string(),
            encoding: report.encoding.clone(),
            compression: report.compression.map(str::to_string),
            records: report.records,
            points: stats.points,
            dropped_non_finite: report.dropped_non_finite,
            dropped_invalid: report.dropped_invalid,
            header_lines_skipped: report.header_lines_skipped,
            fields: report.fields.clone(),
            organized: report
                .organized
                .map(|(width, height)| OrganizedSize { width, height }),
            origin,
            local_origin: report.local_origin,
            bbox: stats.bbox.as_ref().map(BoxReport::new),
            centroid: stats.centroid.map(|c| [c.x, c.y, c.z]),
            range: stats.range.map(RangeReport::from),
            intensity_range: stats.intensity_range.map(|(a, b)| [a as f64, b as f64]),
            has_normals: stats.has_normals,
            has_colors: stats.has_colors,
        }
    }

    /// Reads `path` with `options` and describes it (`shown`: the path as the user gave it).
    pub fn read(path: &std::path::Path, shown: &str, options: &ReadOptions) -> Result<Self> {
        let loaded = read_cloud_with(path, options)?;
        let stats = loaded.cloud.stats();
        let o = loaded.cloud.origin();
        Ok(CloudInfo::new(
            shown,
            &stats,
            &loaded.report,
            [o.x, o.y, o.z],
        ))
    }
}

/// What `olmap convert` does to a cloud file. Filters apply in this order: range band
/// (distance from the sensor origin), transform, box and height band (in the transformed
/// frame), voxel downsampling.
#[derive(Debug, Clone, Default)]
pub struct ConvertJob {
    /// The input file.
    pub input: PathBuf,
    /// The output file (written atomically).
    pub output: PathBuf,
    /// How to read the input.
    pub read: ReadOptions,
    /// How to write the output. A LAS/LAZ output without a local origin of its own
    /// ([`WriteOptions::las_local_origin`]) takes the input's ([`ReadReport::local_origin`]),
    /// so that LAS to LAS keeps the file's frame.
    pub write: WriteOptions,
    /// Keep points at least this far from the sensor origin (with `max_range`: both
    /// unset skips the range band; an unset bound is 0 or infinite).
    pub min_range: Option<f64>,
    /// Keep points at most this far from the sensor origin.
    pub max_range: Option<f64>,
    /// Move the cloud by this pose.
    pub transform: Option<Pose>,
    /// Keep points inside this box.
    pub crop: Option<Aabb>,
    /// Keep points at or above this height (with `z_max` as for the range band).
    pub z_min: Option<f64>,
    /// Keep points at or below this height.
    pub z_max: Option<f64>,
    /// Voxel-grid downsampling edge, metres.
    pub voxel: Option<f64>,
}

/// The summary of `olmap convert --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConvertReport {
    /// The input file.
    pub input: String,
    /// The input's format name.
    pub input_format: String,
    /// The output file.
    pub output: String,
    /// Points read.
    pub points_read: usize,
    /// Points written (after the filters).
    pub points_written: usize,
    /// Points dropped on reading for a NaN or infinite coordinate.
    pub dropped_non_finite: u64,
    /// Points dropped on reading by a validity filter.
    pub dropped_invalid: u64,
    /// LAS/LAZ input: its local origin (input file coordinates = the points + this); an
    /// output in another format holds the points relative to it.
    pub local_origin: Option<[f64; 3]>,
    /// Wall time from `start` to the written file, seconds.
    pub seconds: f64,
}

impl ConvertJob {
    /// Checks the filters before anything is read ([`Error::InvalidArgument`] naming the
    /// filter): ranges finite (an unset maximum is infinite) and `>= 0`, heights not NaN,
    /// the box finite, the voxel edge finite and `> 0`, and no filter inverted (`min_range`
    /// above `max_range`, `z_min` above `z_max`, a box whose minimum corner is above its
    /// maximum on some axis): an inverted filter keeps nothing, and writing an empty cloud
    /// for it would hide the mistake.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidArgument(what));
        for (name, v) in [("min_range", self.min_range), ("max_range", self.max_range)] {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0) {
                    return bad(format!(
                        "{name} must be a finite number of metres >= 0, got {v}"
                    ));
                }
            }
        }
        if let (Some(lo), Some(hi)) = (self.min_range, self.max_range) {
            if lo > hi {
                return bad(format!(
                    "min_range ({lo} m) is above max_range ({hi} m): no point could pass"
                ));
            }
        }
        for (name, v) in [("z_min", self.z_min), ("z_max", self.z_max)] {
            if v.is_some_and(f64::is_nan) {
                return bad(format!("{name} must be a number of metres, got NaN"));
            }
        }
        if let (Some(lo), Some(hi)) = (self.z_min, self.z_max) {
            if lo > hi {
                return bad(format!(
                    "z_min ({lo} m) is above z_max ({hi} m): no point could pass"
                ));
            }
        }
        if let Some(b) = &self.crop {
            if !b.min.iter().chain(b.max.iter()).all(|v| v.is_finite()) {
                return bad(format!(
                    "the box must be finite, got {:?} .. {:?}",
                    b.min, b.max
                ));
            }
            if let Some(i) = (0..3).find(|&i| b.min[i] > b.max[i]) {
                let axis = ["x", "y", "z"][i];
                return bad(format!(
                    "the box is inverted: {axis} min {} is above {axis} max {}: no point \
                     could pass",
                    b.min[i], b.max[i]
                ));
            }
        }
        if let Some(v) = self.voxel {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!(
                    "the voxel edge must be a finite number of metres > 0, got {v}"
                ));
            }
        }
        if let Some(t) = &self.transform {
            let iso = t.isometry();
            if !iso
                .translation
                .vector
                .iter()
                .chain(iso.rotation.coords.iter())
                .all(|v| v.is_finite())
            {
                return bad("the transform must be finite".into());
            }
        }
        Ok(())
    }
}

/// Reads, filters and writes a cloud as `job` says ([`ConvertJob::validate`] first);
/// `start` is when the command began (the report's `seconds` count from it). An output
/// that cannot be written is refused before the input is read.
pub fn convert_cloud_file(job: &ConvertJob, start: Instant) -> Result<ConvertReport> {
    job.validate()?;
    crate::file::check_output(&job.output, "point cloud")?;
    let loaded = read_cloud_with(&job.input, &job.read)?;
    let read_points = loaded.cloud.len();
    let mut cloud = loaded.cloud;
    if job.min_range.is_some() || job.max_range.is_some() {
        cloud = cloud.range_band(
            job.min_range.unwrap_or(0.0),
            job.max_range.unwrap_or(f64::INFINITY),
        );
    }
    if let Some(t) = &job.transform {
        cloud = cloud.transformed(t);
    }
    if let Some(b) = &job.crop {
        cloud = cloud.crop_box(b);
    }
    if job.z_min.is_some() || job.z_max.is_some() {
        cloud = cloud.z_band(
            job.z_min.unwrap_or(f64::NEG_INFINITY),
            job.z_max.unwrap_or(f64::INFINITY),
        );
    }
    if let Some(v) = job.voxel {
        cloud = cloud.voxel_downsample(v)?;
    }
    let mut write = job.write.clone();
    if write.las_local_origin.is_none() {
        write.las_local_origin = loaded.report.local_origin;
    }
    write_cloud(&job.output, &cloud, &write)?;
    Ok(ConvertReport {
        input: job.input.display().to_string(),
        input_format: loaded.report.format.name().to_string(),
        output: job.output.display().to_string(),
        points_read: read_points,
        points_written: cloud.len(),
        dropped_non_finite: loaded.report.dropped_non_finite,
        dropped_invalid: loaded.report.dropped_invalid,
        local_origin: loaded.report.local_origin,
        seconds: start.elapsed().as_secs_f64(),
    })
}
