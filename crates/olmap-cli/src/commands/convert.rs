//! `olmap convert`: convert a point cloud between formats, with optional filters.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, ValueEnum};
use nalgebra::Point3;
use olmap::geometry::Aabb;
use olmap::io::{
    self, CloudFormat, ConvertJob, PcdEncoding, PlyEncoding, ReadOptions, WriteOptions,
};

use super::info::parse_format;
use crate::args::{parse_numbers, parse_pose};

/// PCD encodings on the command line.
#[derive(Clone, Copy, ValueEnum)]
pub enum PcdEncodingArg {
    /// Text.
    Ascii,
    /// Packed binary records.
    Binary,
    /// LZF-compressed binary.
    BinaryCompressed,
}

/// Arguments of `olmap convert`.
///
/// Filters apply in this order: range band (distance from the sensor origin), transform,
/// box and height band (in the transformed frame), voxel downsampling.
#[derive(Args)]
pub struct ConvertArgs {
    /// Input point-cloud file (format from its name; see `olmap info --help`).
    pub input: PathBuf,
    /// Output file; its extension picks the format (.pcd .ply .xyz .3d .csv .bin .graph .las
    /// .laz). Written atomically: on error no partial file is left. LAS/LAZ output has a 1 mm
    /// scale and, from a LAS/LAZ input, the input's local origin as its offset (the file
    /// keeps the input's map frame).
    pub output: PathBuf,
    /// Read the input as this format (pcd, ply, xyz, 3d, csv, kitti, graph, las).
    #[arg(long, value_parser = parse_format)]
    pub in_format: Option<CloudFormat>,
    /// Write the output as this format whatever its extension.
    #[arg(long, value_parser = parse_format)]
    pub out_format: Option<CloudFormat>,
    /// Encoding of PCD output.
    #[arg(long, value_enum, default_value = "binary")]
    pub pcd_encoding: PcdEncodingArg,
    /// Write PLY as text instead of binary little-endian.
    #[arg(long)]
    pub ply_ascii: bool,
    /// 3DTK .3d input: keep only returns between 20 cm and 3270 cm.
    #[arg(long = "3dtk-valid")]
    pub threedtk_valid: bool,
    /// Drop points closer than this to the sensor origin, metres.
    #[arg(long, value_name = "M")]
    pub min_range: Option<f64>,
    /// Drop points farther than this from the sensor origin, metres.
    #[arg(long, value_name = "M")]
    pub max_range: Option<f64>,
    /// Move the cloud by a pose `x,y,z,yaw,pitch,roll` (metres, degrees; ZYX Euler), i.e.
    /// express it in the frame where the sensor frame has this pose.
    #[arg(long, value_name = "X,Y,Z,YAW,PITCH,ROLL", allow_hyphen_values = true)]
    pub transform: Option<String>,
    /// Keep points inside the box `xmin,ymin,zmin,xmax,ymax,zmax` (metres).
    #[arg(
        long = "box",
        value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
        allow_hyphen_values = true
    )]
    pub crop: Option<String>,
    /// Keep points at or above this height, metres.
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    pub z_min: Option<f64>,
    /// Keep points at or below this height, metres.
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    pub z_max: Option<f64>,
    /// Voxel-grid downsample: one point (the centroid) per voxel of this edge, metres.
    #[arg(long, value_name = "M")]
    pub voxel: Option<f64>,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command.
pub fn run(a: &ConvertArgs) -> anyhow::Result<ExitCode> {
    let start = Instant::now();
    let transform = a
        .transform
        .as_deref()
        .map(|s| parse_pose(s, "--transform"))
        .transpose()?;
    // The corners as given (not sorted): the library refuses an inverted box.
    let crop = a
        .crop
        .as_deref()
        .map(|s| parse_numbers::<6>(s, "--box"))
        .transpose()?
        .map(|v| Aabb {
            min: Point3::new(v[0], v[1], v[2]),
            max: Point3::new(v[3], v[4], v[5]),
        });
    let job = ConvertJob {
        input: a.input.clone(),
        output: a.output.clone(),
        read: ReadOptions {
            format: a.in_format,
            uos_valid_only: a.threedtk_valid,
            ..Default::default()
        },
        write: WriteOptions {
            format: a.out_format,
            pcd_encoding: match a.pcd_encoding {
                PcdEncodingArg::Ascii => PcdEncoding::Ascii,
                PcdEncodingArg::Binary => PcdEncoding::Binary,
                PcdEncodingArg::BinaryCompressed => PcdEncoding::BinaryCompressed,
            },
            ply_encoding: if a.ply_ascii {
                PlyEncoding::Ascii
            } else {
                PlyEncoding::BinaryLittleEndian
            },
            ..Default::default()
        },
        min_range: a.min_range,
        max_range: a.max_range,
        transform,
        crop,
        z_min: a.z_min,
        z_max: a.z_max,
        voxel: a.voxel,
    };
    let r = io::convert_cloud_file(&job, start)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{} ({}, {} points) -> {} ({} points) in {:.2} s",
            r.input, r.input_format, r.points_read, r.output, r.points_written, r.seconds
        );
        if let Some(o) = r.local_origin {
            println!(
                "input local origin ({:.3}, {:.3}, {:.3}): input file coordinates = points + it",
                o[0], o[1], o[2]
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
