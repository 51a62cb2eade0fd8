//! [`RenderReport`]: the typed summary of `olmap render --json`, one per view (top view,
//! depth image, overlap surface).

use serde::{Deserialize, Serialize};

use super::{Camera, DepthImage, OverlapSurface, TopView};

/// The summary of a top view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopViewReport {
    /// The PNG written.
    pub output: String,
    /// `"top"`.
    pub view: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Map columns drawn.
    pub columns: usize,
    /// x of the image's left edge, metres.
    pub x_min_m: f64,
    /// y of the image's top edge, metres.
    pub y_max_m: f64,
    /// Pixel edge, metres.
    pub pixel_m: f64,
    /// The heights the colours span `[low, high]`, metres.
    pub z_range_m: [f64; 2],
}

impl TopViewReport {
    /// The summary of `view` written to `output`.
    pub fn new(output: &str, view: &TopView) -> Self {
        TopViewReport {
            output: output.to_string(),
            view: "top".to_string(),
            width: view.image.width(),
            height: view.image.height(),
            columns: view.columns,
            x_min_m: view.x_min,
            y_max_m: view.y_max,
            pixel_m: view.pixel_size,
            z_range_m: [view.z_range.0, view.z_range.1],
        }
    }
}

/// The summary of a depth image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthReport {
    /// The PNG written.
    pub output: String,
    /// `"depth"`.
    pub view: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Pixels whose ray hit a voxel.
    pub hits: usize,
    /// Range at the image centre, metres (`null`: no hit).
    pub centre_range_m: Option<f64>,
}

impl DepthReport {
    /// The summary of `depth`, taken by `camera`, written to `output`.
    pub fn new(output: &str, camera: &Camera, depth: &DepthImage) -> Self {
        let (w, h) = camera.size();
        DepthReport {
            output: output.to_string(),
            view: "depth".to_string(),
            width: w,
            height: h,
            hits: depth.hits(),
            centre_range_m: depth.range(w / 2, h / 2),
        }
    }
}

/// The best pose of an overlap surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeakReport {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Best heading there, degrees.
    pub yaw_deg: f64,
    /// The overlap there.
    pub overlap: u64,
}

/// The summary of an overlap surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OverlapReport {
    /// The PNG written.
    pub output: String,
    /// `"overlap"`.
    pub view: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Samples per side of the surface.
    pub samples_per_side: usize,
    /// Sample spacing, metres.
    pub step_m: f64,
    /// x of the first sample, metres.
    pub x0_m: f64,
    /// y of the first sample, metres.
    pub y0_m: f64,
    /// Voxels of the scan.
    pub scan_voxels: usize,
    /// The best sample.
    pub peak: PeakReport,
}

impl OverlapReport {
    /// The summary of `surface` of a scan of `scan_voxels` voxels, drawn as a
    /// `width` x `height` image written to `output`.
    pub fn new(
        output: &str,
        width: u32,
        height: u32,
        surface: &OverlapSurface,
        scan_voxels: usize,
    ) -> Self {
        let (px, py, pyaw, best) = surface.peak();
        OverlapReport {
            output: output.to_string(),
            view: "overlap".to_string(),
            width,
            height,
            samples_per_side: surface.n,
            step_m: surface.step,
            x0_m: surface.x0,
            y0_m: surface.y0,
            scan_voxels,
            peak: PeakReport {
                x_m: px,
                y_m: py,
                yaw_deg: pyaw.to_degrees(),
                overlap: best,
            },
        }
    }
}

/// The summary of one `olmap render` run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum RenderReport {
    /// A top view.
    Top(TopViewReport),
    /// A depth image.
    Depth(DepthReport),
    /// An overlap surface.
    Overlap(OverlapReport),
}

impl RenderReport {
    /// The view's name (`top`, `depth`, `overlap`).
    pub fn view(&self) -> &str {
        match self {
            RenderReport::Top(r) => &r.view,
            RenderReport::Depth(r) => &r.view,
            RenderReport::Overlap(r) => &r.view,
        }
    }

    /// Image width and height, pixels.
    pub fn size(&self) -> (u32, u32) {
        match self {
            RenderReport::Top(r) => (r.width, r.height),
            RenderReport::Depth(r) => (r.width, r.height),
            RenderReport::Overlap(r) => (r.width, r.height),
        }
    }
}
