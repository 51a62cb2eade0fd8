//! The HTML report of a map build, beside its JSON report (`olmap map --report`).

use std::path::Path;

use super::{MapBuild, MapReport};
use crate::error::Result;
use crate::report::{sections, HtmlReport};

/// Writes the HTML report of `build` to `html_path` (conventionally beside the JSON report:
/// [`crate::file::html_path_beside`]): the run's parameters, a top view with the scan
/// path, the entropy curve, the placed and rejected scans and the JSON report itself.
pub fn write_map_html(
    build: &MapBuild,
    report: &MapReport,
    max_range: f64,
    html_path: &Path,
) -> Result<()> {
    let mut page = HtmlReport::new("olmap map report");
    sections::parameters(
        &mut page,
        &[
            ("output", report.output.clone()),
            ("scans", report.scans.to_string()),
            ("placed", build.placed.len().to_string()),
            ("rejected", build.rejected.len().to_string()),
            ("registrations", build.registrations.to_string()),
            ("voxels", build.map.len().to_string()),
            ("resolution (m)", report.resolution.to_string()),
            ("max range (m)", max_range.to_string()),
            ("mapping time (s)", format!("{:.2}", build.seconds)),
        ],
    );
    page.heading("Map");
    sections::top_view(&mut page, "The map", &build.map, build.robot_paths(|_| 0))?;
    sections::entropy(&mut page, &build.entropy_after_scan, &build.joining_order())?;
    page.heading("Placed scans");
    let rows: Vec<Vec<String>> = build
        .placed
        .iter()
        .map(|p| {
            let t = p.pose.translation();
            vec![
                p.order.to_string(),
                p.name.clone(),
                format!("{:.3}, {:.3}, {:.3}", t.x, t.y, t.z),
                format!("{:.1}", p.pose.yaw_pitch_roll().0.to_degrees()),
                format!("{:.3}", p.overlap_fraction),
                p.via.label().to_string(),
            ]
        })
        .collect();
    page.table(
        &[
            "order",
            "scan",
            "x, y, z (m)",
            "yaw (°)",
            "overlap",
            "placed by",
        ],
        &rows,
    );
    if !build.rejected.is_empty() {
        page.heading("Rejected scans");
        let rows: Vec<Vec<String>> = build
            .rejected
            .iter()
            .map(|r| vec![r.name.clone(), r.reasons.join("; ")])
            .collect();
        page.table(&["scan", "reasons"], &rows);
    }
    page.heading("Report (JSON)");
    page.json(report);
    page.write(html_path)
}
