//! The HTML report of a team run, beside its `report.json`: top views of the team map and
//! of every robot's own map, the error histogram (thesis Figure 6.11), the entropy per
//! scan, the parameters and timings.

use std::path::Path;

use super::report::{ErrorSummaryReport, SoloRun, TeamReport};
use super::{ScanStore, TeamMap};
use crate::error::Result;
use crate::report::sections::{self, Bar};
use crate::report::HtmlReport;

fn num(x: Option<f64>) -> String {
    x.map_or("-".to_string(), |x| format!("{x:.3}"))
}

fn percent(x: Option<f64>) -> String {
    x.map_or("-".to_string(), |x| format!("{:.1}", 100.0 * x))
}

fn bars(s: Option<&ErrorSummaryReport>) -> Vec<Bar> {
    s.map(|s| {
        s.histogram
            .iter()
            .map(|b| Bar {
                from: b.from_m,
                to: b.to_m,
                count: b.count,
            })
            .collect()
    })
    .unwrap_or_default()
}

/// The run's key figures, as the page's first table.
fn parameter_rows(
    store: &ScanStore,
    team: &TeamMap,
    solo: &[SoloRun],
    report: &TeamReport,
) -> Vec<(&'static str, String)> {
    let eval = &report.evaluation;
    let (t, s) = (eval.team.as_ref(), eval.solo.as_ref());
    let triple = |s: Option<&ErrorSummaryReport>| {
        format!(
            "{} / {} / {}",
            num(s.map(|s| s.mean_m)),
            num(s.map(|s| s.median_m)),
            num(s.map(|s| s.max_m))
        )
    };
    vec![
        ("scans", store.len().to_string()),
        ("robots", store.robots().len().to_string()),
        (
            "placed in the joint map",
            team.build.placed.len().to_string(),
        ),
        ("registrations", team.build.registrations.to_string()),
        ("voxels", team.build.map.len().to_string()),
        ("resolution (m)", team.build.map.resolution().to_string()),
        (
            "team mapping time (s)",
            format!("{:.2}", team.build.seconds),
        ),
        (
            "solo mapping time (s)",
            format!(
                "{:.2}",
                solo.iter().map(|r| r.map.build.seconds).sum::<f64>()
            ),
        ),
        (
            "points of seen robots cleared",
            team.cleared_points.to_string(),
        ),
        ("team mean / median / max error (m)", triple(t)),
        ("solo mean / median / max error (m)", triple(s)),
        (
            "scans off by more than 0.3 m, team / solo (%)",
            format!(
                "{} / {}",
                percent(t.map(|t| t.share_above_gross)),
                percent(s.map(|s| s.share_above_gross))
            ),
        ),
        (
            "gross errors (> 0.3 m), solo / team",
            // No ratio when the team has no gross error.
            num(eval.gross_error_ratio_solo_over_team),
        ),
    ]
}

/// Writes the HTML report of a team run to `html_path` (conventionally beside
/// `report.json`: [`crate::file::html_path_beside`]).
pub fn write_team_html(
    store: &ScanStore,
    team: &TeamMap,
    solo: &[SoloRun],
    report: &TeamReport,
    html_path: &Path,
) -> Result<()> {
    let mut page = HtmlReport::new("olmap team report");
    sections::parameters(&mut page, &parameter_rows(store, team, solo, report));
    page.heading("Team map");
    let robot_of = |i: usize| team.keys[i].0;
    sections::top_view(
        &mut page,
        "The joint map of the team, in the first robot's first scan frame",
        &team.build.map,
        team.build.robot_paths(robot_of),
    )?;
    if !solo.is_empty() {
        page.heading("Every robot alone");
        for r in solo {
            let caption = format!(
                "{} mapping alone, in its own first scan's frame",
                store.robot_name(r.robot)
            );
            sections::top_view(
                &mut page,
                &caption,
                &r.map.build.map,
                r.map.build.robot_paths(|_| r.robot),
            )?;
        }
    }
    let eval = &report.evaluation;
    sections::error_histogram(
        &mut page,
        &bars(eval.team.as_ref()),
        &bars(eval.solo.as_ref()),
    )?;
    sections::entropy(
        &mut page,
        &team.build.entropy_after_scan,
        &team.build.joining_order(),
    )?;
    page.heading("Report (report.json)");
    page.json(report);
    page.write(html_path)
}
