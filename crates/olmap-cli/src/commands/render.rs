//! `olmap render`: pictures of a map (top view, depth image, overlap surface).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use nalgebra::Point3;
use olmap::geometry::{Pose, PoseList};
use olmap::occupancy::{self, OccupancyList};
use olmap::render::{
    overlap_surface, render_depth, render_top_view, write_png, Camera, DepthReport, OverlapReport,
    OverlapSurfaceParams, RenderReport, TopViewOptions, TopViewReport,
};

use crate::args::parse_numbers;

/// Views `olmap render` draws.
#[derive(Clone, Copy, ValueEnum)]
pub enum ViewArg {
    /// From above, voxels coloured by height.
    Top,
    /// A depth image from a viewpoint (--from), near light and far dark.
    Depth,
    /// The overlap surface of a scan (--scan) around a pose (--from): the best-heading
    /// overlap over x, y as a heat map (thesis Figure 6.6).
    Overlap,
}

/// Cameras of the depth view.
#[derive(Clone, Copy, ValueEnum)]
pub enum CameraArg {
    /// A pinhole camera; --fov is horizontal.
    Pinhole,
    /// A full-turn cylindrical panorama; --fov is vertical.
    Panoramic,
}

/// Arguments of `olmap render`.
#[derive(Args)]
pub struct RenderArgs {
    /// The map (.olm or OctoMap .bt).
    pub map: PathBuf,
    /// Output PNG image.
    #[arg(short, long)]
    pub output: PathBuf,
    /// What to draw.
    #[arg(long, value_enum, default_value = "top")]
    pub view: ViewArg,
    /// Viewpoint of the depth view, or centre of the overlap surface: x,y,z (m) and yaw
    /// (degrees), level.
    #[arg(long, value_name = "X,Y,Z,YAW", allow_hyphen_values = true)]
    pub from: Option<String>,
    /// Camera of the depth view.
    #[arg(long, value_enum, default_value = "pinhole")]
    pub camera: CameraArg,
    /// Field of view of the depth view, degrees (pinhole: horizontal; panoramic: vertical).
    #[arg(long, default_value_t = 90.0)]
    pub fov: f64,
    /// Size of the depth image, WIDTHxHEIGHT pixels (default 640x480, panoramic 1440x360).
    #[arg(long, value_name = "WxH")]
    pub size: Option<String>,
    /// Top view: only voxels with centres between these heights, metres (e.g. 2.3,2.9, the
    /// thesis' structure band).
    #[arg(long, value_name = "ZMIN,ZMAX", allow_hyphen_values = true)]
    pub band: Option<String>,
    /// Top view: grid line spacing in metres (0: no grid).
    #[arg(long, default_value_t = 1.0)]
    pub grid: f64,
    /// Top view: metres per pixel (default: the map's resolution).
    #[arg(long)]
    pub pixel: Option<f64>,
    /// Top view: a pose list whose positions are drawn as a path.
    #[arg(long, value_name = "FILE")]
    pub poses: Option<PathBuf>,
    /// Overlap view: the scan (any point-cloud format, its own frame), voxelised at the
    /// map's resolution.
    #[arg(long, value_name = "FILE")]
    pub scan: Option<PathBuf>,
    /// Overlap view: the surface covers the centre ± this many metres in x and y.
    #[arg(long, default_value_t = 2.0)]
    pub half_width: f64,
    /// Overlap view: headings tried per position (evenly over the full turn).
    #[arg(long, default_value_t = 36)]
    pub headings: u32,
    /// Only voxels with at least this count.
    #[arg(long, default_value_t = 1)]
    pub min_count: u16,
    /// Depth view: rays reach at most this far, metres.
    #[arg(long, default_value_t = 30.0)]
    pub max_range: f64,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

pub(super) fn parse_band(s: &str, what: &str) -> anyhow::Result<(f64, f64)> {
    let [lo, hi] = parse_numbers::<2>(s, what)?;
    if lo > hi {
        bail!("{what}: ZMIN must not be above ZMAX, got {s}");
    }
    Ok((lo, hi))
}

fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("--size: expected WIDTHxHEIGHT, got '{s}'"))?;
    let w: u32 = w
        .trim()
        .parse()
        .with_context(|| format!("--size: bad width in '{s}'"))?;
    let h: u32 = h
        .trim()
        .parse()
        .with_context(|| format!("--size: bad height in '{s}'"))?;
    Ok((w, h))
}

pub(super) fn read(path: &PathBuf) -> anyhow::Result<OccupancyList> {
    Ok(occupancy::read_map(path)?.map)
}

/// Runs `olmap render`.
pub fn run(a: &RenderArgs) -> anyhow::Result<ExitCode> {
    olmap::file::check_output(&a.output, "PNG image")?;
    let map = read(&a.map)?;
    let shown = a.output.display().to_string();
    let summary = match a.view {
        ViewArg::Top => {
            let poses = match &a.poses {
                Some(p) => PoseList::read_path(p)?,
                None => PoseList::default(),
            };
            let path: Vec<Point3<f64>> = poses
                .poses
                .iter()
                .map(|p| Point3::from(p.pose.translation()))
                .collect();
            let options = TopViewOptions {
                pixel_size: a.pixel,
                band: a
                    .band
                    .as_deref()
                    .map(|s| parse_band(s, "--band"))
                    .transpose()?,
                grid_step: (a.grid > 0.0).then_some(a.grid),
                positions: path.clone(),
                paths: if path.len() > 1 {
                    vec![path]
                } else {
                    Vec::new()
                },
                min_count: a.min_count,
                ..TopViewOptions::default()
            };
            let view = render_top_view(&map, &options)?;
            write_png(&a.output, &view.image)?;
            RenderReport::Top(TopViewReport::new(&shown, &view))
        }
        ViewArg::Depth => {
            let from = a
                .from
                .as_deref()
                .context("--view depth needs --from X,Y,Z,YAW")?;
            let [x, y, z, yaw] = parse_numbers::<4>(from, "--from")?;
            let pose = Pose::from_xyz_ypr(x, y, z, yaw.to_radians(), 0.0, 0.0);
            let fov = a.fov.to_radians();
            let camera = match a.camera {
                CameraArg::Pinhole => {
                    let (width, height) = a
                        .size
                        .as_deref()
                        .map(parse_size)
                        .transpose()?
                        .unwrap_or((640, 480));
                    Camera::Pinhole {
                        width,
                        height,
                        fov_x: fov,
                    }
                }
                CameraArg::Panoramic => {
                    let (width, height) = a
                        .size
                        .as_deref()
                        .map(parse_size)
                        .transpose()?
                        .unwrap_or((1440, 360));
                    Camera::Panoramic {
                        width,
                        height,
                        fov_y: fov,
                    }
                }
            };
            let depth = render_depth(&map, &pose, &camera, a.max_range, a.min_count)?;
            write_png(&a.output, &depth.to_image())?;
            RenderReport::Depth(DepthReport::new(&shown, &camera, &depth))
        }
        ViewArg::Overlap => {
            let scan_path = a
                .scan
                .as_ref()
                .context("--view overlap needs --scan FILE")?;
            let from = a
                .from
                .as_deref()
                .context("--view overlap needs --from X,Y,Z,YAW (the surface's centre)")?;
            let [x, y, z, yaw] = parse_numbers::<4>(from, "--from")?;
            let cloud = olmap::io::read_cloud(scan_path)?.cloud;
            let scan = OccupancyList::from_cloud(&cloud, map.resolution())?;
            let params = OverlapSurfaceParams {
                half_width: a.half_width,
                stride: 1,
                headings: a.headings,
            };
            let centre = Pose::from_xyz_ypr(x, y, z, yaw.to_radians(), 0.0, 0.0);
            let surface = overlap_surface(&map.threshold(a.min_count), &scan, &centre, &params)?;
            let img = surface.to_image(4);
            write_png(&a.output, &img)?;
            RenderReport::Overlap(OverlapReport::new(
                &shown,
                img.width(),
                img.height(),
                &surface,
                scan.len(),
            ))
        }
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        let (width, height) = summary.size();
        println!(
            "{} view {} x {} -> {}",
            summary.view(),
            width,
            height,
            a.output.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}
