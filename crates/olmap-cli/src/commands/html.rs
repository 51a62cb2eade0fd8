//! The HTML reports of `olmap map --report`, `olmap team` and `olmap demo`: one
//! self-contained file beside the JSON report, with top views of the maps, the error
//! histogram (thesis Figure 6.11), the map entropy per scan (thesis (7.4)), the parameters
//! and the timings.

use std::path::Path;

use nalgebra::Point3;
use olmap::mapping::MapBuild;
use olmap::occupancy::OccupancyList;
use olmap::render::{bar_chart, line_chart, render_top_view, Series, TopViewOptions, PALETTE};
use olmap::report::HtmlReport;
use serde_json::Value;

/// Height band of the top views: above the floor, below a 3 m ceiling.
const TOP_BAND: (f64, f64) = (0.1, 2.7);

/// Adds a top view of `map` with robot paths (one polyline per robot) to the report.
pub fn top_view(
    report: &mut HtmlReport,
    caption: &str,
    map: &OccupancyList,
    paths: Vec<Vec<Point3<f64>>>,
) -> anyhow::Result<()> {
    let positions = paths.iter().flatten().copied().collect();
    let view = render_top_view(
        map,
        &TopViewOptions {
            band: Some(TOP_BAND),
            paths,
            positions,
            ..TopViewOptions::default()
        },
    )?;
    report.image(
        &format!(
            "{caption}: voxels between {} and {} m coloured by height (blue low, red high), 1 m grid, scan positions (black) and paths",
            TOP_BAND.0, TOP_BAND.1
        ),
        &view.image,
    )?;
    Ok(())
}

/// Adds the entropy-per-scan curve and its table.
pub fn entropy(report: &mut HtmlReport, build: &MapBuild) -> anyhow::Result<()> {
    let h = &build.entropy_after_scan;
    if h.is_empty() {
        return Ok(());
    }
    report.heading("Map entropy after each scan");
    let img = line_chart(
        &[Series {
            values: h.clone(),
            colour: PALETTE[2],
        }],
        600,
        220,
    )?;
    report.image(
        "Map entropy (thesis (7.4), nats; p0 = 0.5, one log-odds unit per count, volume term left out) after each scan joined the map, in joining order",
        &img,
    )?;
    let rows: Vec<Vec<String>> = build
        .placed
        .iter()
        .zip(h)
        .map(|(p, e)| vec![p.order.to_string(), p.name.clone(), format!("{e:.1}")])
        .collect();
    report.table(&["order", "scan", "entropy (nats)"], &rows);
    Ok(())
}

/// Adds the solo vs team error histogram (Figure 6.11) from the team report's JSON
/// summaries.
pub fn error_histogram(report: &mut HtmlReport, team: &Value, solo: &Value) -> anyhow::Result<()> {
    let bins = |s: &Value| -> Vec<(String, f64)> {
        s["histogram"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|b| {
                        let from = b["from_m"].as_f64().unwrap_or(0.0);
                        let label = match b["to_m"].as_f64() {
                            Some(to) => format!("{from:.1}-{to:.1}"),
                            None => format!(">= {from:.1}"),
                        };
                        (label, b["count"].as_f64().unwrap_or(0.0))
                    })
                    .collect()
            })
            .unwrap_or_default()
    };
    let (t, s) = (bins(team), bins(solo));
    if t.is_empty() && s.is_empty() {
        return Ok(());
    }
    report.heading("Position errors: team vs each robot alone (thesis Figure 6.11)");
    let mut series = Vec::new();
    if !t.is_empty() {
        series.push(Series {
            values: t.iter().map(|b| b.1).collect(),
            colour: PALETTE[0],
        });
    }
    if !s.is_empty() {
        series.push(Series {
            values: s.iter().map(|b| b.1).collect(),
            colour: PALETTE[1],
        });
    }
    let img = bar_chart(&series, 700, 260, false)?;
    report.image(
        "Scans per position-error bin (0.1 m bins, last bin open): team blue, solo red",
        &img,
    )?;
    let labels = if t.len() >= s.len() { &t } else { &s };
    let rows: Vec<Vec<String>> = labels
        .iter()
        .enumerate()
        .map(|(i, (label, _))| {
            let get = |v: &Vec<(String, f64)>| v.get(i).map_or("".into(), |b| format!("{}", b.1));
            vec![label.clone(), get(&t), get(&s)]
        })
        .collect();
    report.table(&["error (m)", "team", "solo"], &rows);
    Ok(())
}

/// The scan positions of a build, one path per robot: `robot_of` gives a placed scan's
/// robot (paths follow the scans' names, which sort in capture order).
pub fn paths(build: &MapBuild, robot_of: impl Fn(usize) -> u32) -> Vec<Vec<Point3<f64>>> {
    let mut by_robot: std::collections::BTreeMap<u32, Vec<(String, Point3<f64>)>> =
        Default::default();
    for p in &build.placed {
        by_robot
            .entry(robot_of(p.index))
            .or_default()
            .push((p.name.clone(), Point3::from(p.pose.translation())));
    }
    by_robot
        .into_values()
        .map(|mut v| {
            v.sort_by(|a, b| a.0.cmp(&b.0));
            v.into_iter().map(|(_, p)| p).collect()
        })
        .collect()
}

/// The parameters and timings table of a run.
pub fn parameters(report: &mut HtmlReport, rows: &[(&str, String)]) {
    report.heading("Run");
    report.key_values(rows);
}

/// Writes the report beside `json_path` (same name, extension `html`; `report.html` when
/// the JSON file itself ends in `.html`); returns its path.
pub fn write_beside(report: &HtmlReport, json_path: &Path) -> anyhow::Result<std::path::PathBuf> {
    let mut path = json_path.with_extension("html");
    if path == json_path {
        path = json_path.with_extension("report.html");
    }
    report.write(&path)?;
    Ok(path)
}
