//! Pictures of maps and results (thesis Figures 5.6-5.11, 6.6-6.11), as PNG images:
//!
//! * [`render_top_view`]: a map seen from above, voxels coloured by height, with an optional
//!   metre grid, scan positions, robot paths and a height band (Figures 5.9, 5.11, 6.9);
//! * [`render_depth`]: a depth image ray cast into the occupancy list from a pinhole or
//!   panoramic camera (Figure 5.6);
//! * [`overlap_surface`]: the best-heading overlap of a scan over a grid of x, y
//!   positions, drawn as a heat map (Figure 6.6);
//! * [`bar_chart`], [`level_chart`] and [`line_chart`]: histograms (solo vs team errors,
//!   Figure 6.11; particles per search level) and curves (map entropy per scan).
//!
//! [`height_coloured_cloud`] gives the voxels as a point cloud coloured by height for
//! 3D viewers (written as PLY with colours).
//!
//! Images are [`image::RgbImage`]s; [`png_bytes`] encodes one and [`write_png`] writes it
//! atomically. Charts are drawn with `plotters`' bitmap backend and carry no text (no font
//! dependencies): captions, axes and numbers go in the HTML report beside them
//! ([`crate::report`]).

mod chart;
mod colour;
mod coloured_cloud;
mod depth;
mod overlap_surface;
mod png;
mod report;
mod top_view;

pub use chart::{bar_chart, level_chart, line_chart, Series};
pub use colour::{heat_colour, height_colour, PALETTE};
pub use coloured_cloud::height_coloured_cloud;
pub use depth::{render_depth, Camera, DepthImage};
pub use image::{Rgb, RgbImage};
pub use overlap_surface::{overlap_surface, OverlapSurface, OverlapSurfaceParams, MAX_HEADINGS};
pub use png::{png_bytes, write_png};
pub use report::{DepthReport, OverlapReport, PeakReport, RenderReport, TopViewReport};
pub use top_view::{render_top_view, TopView, TopViewOptions, BACKGROUND, GRID_COLOUR};

/// The largest image side this module draws, in pixels.
pub const MAX_SIDE: u32 = 8192;

fn check_size(width: u32, height: u32) -> crate::Result<()> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        Err(crate::Error::InvalidArgument(format!(
            "image size must be 1..={MAX_SIDE} pixels a side, got {width} x {height}"
        )))
    } else {
        Ok(())
    }
}

fn draw_error(e: impl std::fmt::Display) -> crate::Error {
    crate::Error::InvalidArgument(format!("drawing failed: {e}"))
}
