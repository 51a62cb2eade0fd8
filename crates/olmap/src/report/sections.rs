//! The blocks the map and team reports share: top views with robot paths, the map entropy
//! per scan (thesis (7.4)), the position-error histogram (thesis Figure 6.11), a
//! parameters table, and where the page is written.

use nalgebra::Point3;

use super::HtmlReport;
use crate::error::Result;
use crate::occupancy::OccupancyList;
use crate::render::{bar_chart, line_chart, render_top_view, Series, TopViewOptions, PALETTE};

/// Height band of the top views, metres: above the floor, below a 3 m ceiling.
pub const TOP_VIEW_BAND: (f64, f64) = (0.1, 2.7);

/// Adds a top view of `map` with robot paths (one polyline per robot) to the report.
pub fn top_view(
    report: &mut HtmlReport,
    caption: &str,
    map: &OccupancyList,
    paths: Vec<Vec<Point3<f64>>>,
) -> Result<()> {
    let positions = paths.iter().flatten().copied().collect();
    let view = render_top_view(
        map,
        &TopViewOptions {
            band: Some(TOP_VIEW_BAND),
            paths,
            positions,
            ..TopViewOptions::default()
        },
    )?;
    report.image(
        &format!(
            "{caption}: voxels between {} and {} m coloured by height (blue low, red high), 1 m grid, scan positions (black) and paths",
            TOP_VIEW_BAND.0, TOP_VIEW_BAND.1
        ),
        &view.image,
    )?;
    Ok(())
}

/// Adds the entropy-per-scan curve and its table: `entropy[i]` is the map entropy after
/// the scan `scans[i] = (order, name)` joined.
pub fn entropy(report: &mut HtmlReport, entropy: &[f64], scans: &[(usize, &str)]) -> Result<()> {
    if entropy.is_empty() {
        return Ok(());
    }
    report.heading("Map entropy after each scan");
    let img = line_chart(
        &[Series {
            values: entropy.to_vec(),
            colour: PALETTE[2],
        }],
        600,
        220,
    )?;
    report.image(
        "Map entropy (thesis (7.4), nats; p0 = 0.5, one log-odds unit per count, volume term left out) after each scan joined the map, in joining order",
        &img,
    )?;
    let rows: Vec<Vec<String>> = scans
        .iter()
        .zip(entropy)
        .map(|((order, name), e)| vec![order.to_string(), name.to_string(), format!("{e:.1}")])
        .collect();
    report.table(&["order", "scan", "entropy (nats)"], &rows);
    Ok(())
}

/// One bar of an error histogram as a report shows it: `[from, to)` metres (`to = None`:
/// the open last bar) and its count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bar {
    /// Lower edge, metres.
    pub from: f64,
    /// Upper edge, metres; `None` for the open last bar.
    pub to: Option<f64>,
    /// Errors in the bar.
    pub count: usize,
}

/// Adds the solo vs team error histogram (Figure 6.11); either side may be missing.
pub fn error_histogram(report: &mut HtmlReport, team: &[Bar], solo: &[Bar]) -> Result<()> {
    let bins = |bars: &[Bar]| -> Vec<(String, f64)> {
        bars.iter()
            .map(|b| {
                let label = match b.to {
                    Some(to) => format!("{:.1}-{to:.1}", b.from),
                    None => format!(">= {:.1}", b.from),
                };
                (label, b.count as f64)
            })
            .collect()
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

/// The parameters and timings table of a run.
pub fn parameters(report: &mut HtmlReport, rows: &[(&str, String)]) {
    report.heading("Run");
    report.key_values(rows);
}

pub use crate::file::html_path_beside;
