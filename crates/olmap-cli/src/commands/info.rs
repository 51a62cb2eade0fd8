//! `olmap info`: describe point-cloud files.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::cloud::BoxReport;
use olmap::io::{CloudFormat, CloudInfo, ReadOptions};
use olmap::occupancy::{describe_file, FileInfo, MapInfo};

/// Arguments of `olmap info`.
#[derive(Args)]
pub struct InfoArgs {
    /// Point-cloud files (.pcd .ply .xyz .txt .dat .asc .pts .3d .csv .bin .graph .las .laz,
    /// optionally .bz2) and map files (.olm, OctoMap .bt). Every file is described even when
    /// an earlier one fails. LAS/LAZ points are shown relative to their local origin.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Read every file as this format (pcd, ply, xyz, 3d, csv, kitti, graph, las) instead of
    /// guessing it from the file name.
    #[arg(long, value_parser = parse_format)]
    pub format: Option<CloudFormat>,
    /// 3DTK .3d files: keep only returns between 20 cm and 3270 cm (drops near-sensor echoes
    /// and the max-range sentinel).
    #[arg(long = "3dtk-valid")]
    pub threedtk_valid: bool,
    /// Print one JSON array (one object per file) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Parses a format name for clap.
pub fn parse_format(s: &str) -> Result<CloudFormat, String> {
    CloudFormat::from_name(s).ok_or_else(|| {
        format!("unknown format '{s}'; known: pcd, ply, xyz, 3d, csv, kitti, graph, las, laz")
    })
}

/// Runs the command.
pub fn run(args: &InfoArgs) -> anyhow::Result<ExitCode> {
    let options = ReadOptions {
        format: args.format,
        uos_valid_only: args.threedtk_valid,
        ..Default::default()
    };
    let mut json = Vec::new();
    let mut failed = false;
    for path in &args.files {
        let shown = path.display().to_string();
        let info = describe_file(path, &shown, &options);
        match &info {
            FileInfo::Error(e) => {
                failed = true;
                if !args.json {
                    eprintln!("error: {}", e.error);
                }
            }
            FileInfo::Cloud(c) if !args.json => print!("{}", cloud_text(c)),
            FileInfo::Map(m) if !args.json => print!("{}", map_text(m)),
            _ => {}
        }
        if args.json {
            json.push(info);
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&json)?);
    }
    Ok(if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}

/// The two text lines of a bounding box.
fn bbox_lines(b: &BoxReport, line: &mut impl FnMut(&str, String)) {
    line(
        "bbox min",
        format!("({:.3}, {:.3}, {:.3}) m", b.min[0], b.min[1], b.min[2]),
    );
    line(
        "bbox max",
        format!("({:.3}, {:.3}, {:.3}) m", b.max[0], b.max[1], b.max[2]),
    );
}

/// The human-readable description of a read cloud.
fn cloud_text(c: &CloudInfo) -> String {
    let mut s = String::new();
    let mut line = |k: &str, v: String| s.push_str(&format!("  {k:<14}{v}\n"));
    let mut fmt = c.format.clone();
    if !c.encoding.is_empty() {
        fmt.push_str(&format!(" ({})", c.encoding));
    }
    if let Some(z) = &c.compression {
        fmt.push_str(&format!(", {z}-compressed"));
    }
    line("format", fmt);
    line("points", format!("{} of {} records", c.points, c.records));
    if c.dropped_non_finite > 0 {
        line(
            "dropped",
            format!("{} with NaN/Inf coordinates", c.dropped_non_finite),
        );
    }
    if c.dropped_invalid > 0 {
        line(
            "filtered",
            format!("{} outside the valid range", c.dropped_invalid),
        );
    }
    if c.header_lines_skipped > 0 {
        line(
            "header lines",
            format!("{} skipped", c.header_lines_skipped),
        );
    }
    if let Some(o) = c.organized {
        line("organised", format!("{} x {}", o.width, o.height));
    }
    line("fields", c.fields.join(" "));
    let origin = c.origin;
    line(
        "origin",
        format!("({:.3}, {:.3}, {:.3}) m", origin[0], origin[1], origin[2]),
    );
    if let Some(o) = c.local_origin {
        line(
            "local origin",
            format!(
                "({:.3}, {:.3}, {:.3}): file coordinates = points + it",
                o[0], o[1], o[2]
            ),
        );
    }
    if let Some(b) = &c.bbox {
        bbox_lines(b, &mut line);
        let e = b.extent();
        line(
            "extent",
            format!("{:.3} x {:.3} x {:.3} m", e[0], e[1], e[2]),
        );
    }
    if let Some(r) = c.range {
        line(
            "range",
            format!(
                "min {:.3}, median {:.3}, mean {:.3}, max {:.3} m",
                r.min, r.median, r.mean, r.max
            ),
        );
    }
    if let Some([a, b]) = c.intensity_range {
        // Intensities are single precision: shown as read (the widening is exact).
        line("intensity", format!("{} .. {}", a as f32, b as f32));
    }
    let mut attrs = Vec::new();
    if c.has_normals {
        attrs.push("normals");
    }
    if c.has_colors {
        attrs.push("colours");
    }
    if !attrs.is_empty() {
        line("attributes", attrs.join(", "));
    }
    format!("{}\n{s}", c.path)
}

/// The human-readable description of a map file.
fn map_text(m: &MapInfo) -> String {
    let mut out = format!("{}\n", m.path);
    let mut line = |k: &str, v: String| out.push_str(&format!("  {k:<14}{v}\n"));
    line("format", m.format.clone());
    line("resolution", format!("{} m", m.resolution));
    line("voxels", m.voxels.to_string());
    if let Some(b) = &m.bbox {
        bbox_lines(b, &mut line);
    }
    line(
        "counts",
        format!("total {}, max {}", m.total_count, m.max_count),
    );
    line(
        "memory",
        format!(
            "{} bytes ({:.1} per voxel)",
            m.memory_bytes,
            m.bytes_per_voxel()
        ),
    );
    if let Some(bt) = &m.octree {
        out.push_str(&format!(
            "  {:<14}{} nodes, {} occupied and {} free leaves\n",
            "octree", bt.nodes, bt.occupied_leaves, bt.free_leaves
        ));
    }
    out
}
