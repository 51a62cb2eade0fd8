//! Turning library results into text for people and JSON for scripts.

use olmap::cloud::CloudStats;
use olmap::geometry::Aabb;
use olmap::io::ReadReport;
use serde_json::{json, Value};

fn aabb_json(b: &Aabb) -> Value {
    json!({ "min": [b.min.x, b.min.y, b.min.z], "max": [b.max.x, b.max.y, b.max.z] })
}

/// The two text lines of a bounding box.
fn bbox_lines(b: &Aabb, line: &mut impl FnMut(&str, String)) {
    line(
        "bbox min",
        format!("({:.3}, {:.3}, {:.3}) m", b.min.x, b.min.y, b.min.z),
    );
    line(
        "bbox max",
        format!("({:.3}, {:.3}, {:.3}) m", b.max.x, b.max.y, b.max.z),
    );
}

/// The JSON object describing a read cloud.
pub fn cloud_json(path: &str, stats: &CloudStats, report: &ReadReport, origin: [f64; 3]) -> Value {
    json!({
        "path": path,
        "format": report.format.name(),
        "encoding": report.encoding,
        "compression": report.compression,
        "records": report.records,
        "points": stats.points,
        "dropped_non_finite": report.dropped_non_finite,
        "dropped_invalid": report.dropped_invalid,
        "header_lines_skipped": report.header_lines_skipped,
        "fields": report.fields,
        "organized": report.organized.map(|(w, h)| json!({"width": w, "height": h})),
        "origin": origin,
        "bbox": stats.bbox.as_ref().map(aabb_json),
        "centroid": stats.centroid.map(|c| [c.x, c.y, c.z]),
        "range": stats.range.map(|r| json!({"min": r.min, "max": r.max, "mean": r.mean, "median": r.median})),
        "intensity_range": stats.intensity_range.map(|(a, b)| [a, b]),
        "has_normals": stats.has_normals,
        "has_colors": stats.has_colors,
    })
}

/// The human-readable description of a read cloud.
pub fn cloud_text(path: &str, stats: &CloudStats, report: &ReadReport, origin: [f64; 3]) -> String {
    let mut s = String::new();
    let mut line = |k: &str, v: String| s.push_str(&format!("  {k:<14}{v}\n"));
    let mut fmt = report.format.name().to_string();
    if !report.encoding.is_empty() {
        fmt.push_str(&format!(" ({})", report.encoding));
    }
    if let Some(c) = report.compression {
        fmt.push_str(&format!(", {c}-compressed"));
    }
    line("format", fmt);
    line(
        "points",
        format!("{} of {} records", stats.points, report.records),
    );
    if report.dropped_non_finite > 0 {
        line(
            "dropped",
            format!("{} with NaN/Inf coordinates", report.dropped_non_finite),
        );
    }
    if report.dropped_invalid > 0 {
        line(
            "filtered",
            format!("{} outside the valid range", report.dropped_invalid),
        );
    }
    if report.header_lines_skipped > 0 {
        line(
            "header lines",
            format!("{} skipped", report.header_lines_skipped),
        );
    }
    if let Some((w, h)) = report.organized {
        line("organised", format!("{w} x {h}"));
    }
    line("fields", report.fields.join(" "));
    line(
        "origin",
        format!("({:.3}, {:.3}, {:.3}) m", origin[0], origin[1], origin[2]),
    );
    if let Some(b) = &stats.bbox {
        bbox_lines(b, &mut line);
        let e = b.extent();
        line("extent", format!("{:.3} x {:.3} x {:.3} m", e.x, e.y, e.z));
    }
    if let Some(r) = stats.range {
        line(
            "range",
            format!(
                "min {:.3}, median {:.3}, mean {:.3}, max {:.3} m",
                r.min, r.median, r.mean, r.max
            ),
        );
    }
    if let Some((a, b)) = stats.intensity_range {
        line("intensity", format!("{a} .. {b}"));
    }
    let mut attrs = Vec::new();
    if stats.has_normals {
        attrs.push("normals");
    }
    if stats.has_colors {
        attrs.push("colours");
    }
    if !attrs.is_empty() {
        line("attributes", attrs.join(", "));
    }
    format!("{path}\n{s}")
}

/// The JSON object describing a map file.
pub fn map_json(path: &str, format: &str, s: &olmap::occupancy::OccupancyStats) -> Value {
    json!({
        "path": path,
        "format": format,
        "resolution": s.resolution,
        "voxels": s.voxels,
        "bbox": s.bbox.as_ref().map(aabb_json),
        "total_count": s.total_count,
        "max_count": s.max_count,
        "memory_bytes": s.memory_bytes,
    })
}

/// The human-readable description of a map file.
pub fn map_text(path: &str, format: &str, s: &olmap::occupancy::OccupancyStats) -> String {
    let mut out = format!("{path}\n");
    let mut line = |k: &str, v: String| out.push_str(&format!("  {k:<14}{v}\n"));
    line("format", format.to_string());
    line("resolution", format!("{} m", s.resolution));
    line("voxels", s.voxels.to_string());
    if let Some(b) = &s.bbox {
        bbox_lines(b, &mut line);
    }
    line(
        "counts",
        format!("total {}, max {}", s.total_count, s.max_count),
    );
    line(
        "memory",
        format!(
            "{} bytes ({:.1} per voxel)",
            s.memory_bytes,
            s.bytes_per_voxel()
        ),
    );
    out
}
