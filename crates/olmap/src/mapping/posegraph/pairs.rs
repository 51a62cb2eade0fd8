//! Pairwise registration edges: each placed scan against its nearest placed neighbours.

use rayon::prelude::*;

use super::{GraphRefineParams, GraphRefineReport, LOOP_GAP};
use crate::align::icp::refine;
use crate::error::Result;
use crate::graph::{EdgeKind, PoseGraph};
use crate::mapping::{PlacedScan, ScanInput};

/// The pairs to register, `(i, j)` as positions in `placed` with `i < j`: every placed
/// scan with its `params.neighbours` nearest placed scans within `params.max_distance`
/// (ties by position in `placed`), each pair once, sorted.
pub(super) fn neighbour_pairs(
    placed: &[PlacedScan],
    params: &GraphRefineParams,
) -> Vec<(usize, usize)> {
    let mut pairs = Vec::new();
    for (a, pa) in placed.iter().enumerate() {
        let mut near: Vec<(f64, usize)> = placed
            .iter()
            .enumerate()
            .filter(|&(b, _)| b != a)
            .map(|(b, pb)| ((pb.pose.translation() - pa.pose.translation()).norm(), b))
            .filter(|&(d, _)| d <= params.max_distance)
            .collect();
        near.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        for &(_, b) in near.iter().take(params.neighbours) {
            pairs.push((a.min(b), a.max(b)));
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// Registers every neighbour pair from its current relative pose and adds the ones that
/// pass (converged, enough inliers, a correction within `params.max_correction`) as
/// edges from the earlier input scan to the later, with the ICP's information and the
/// kernel; counts the rest in `report.pairs_refused`.
pub(super) fn add_registration_edges(
    graph: &mut PoseGraph,
    scans: &[ScanInput],
    frames: &[usize],
    placed: &[PlacedScan],
    params: &GraphRefineParams,
    report: &mut GraphRefineReport,
) -> Result<()> {
    let pairs = neighbour_pairs(placed, params);
    report.pairs_tried += pairs.len();
    let results: Vec<Result<_>> = pairs
        .par_iter()
        .map(|&(a, b)| {
            // Edge from the earlier input scan (target) to the later (source).
            let (i, j) = if placed[a].index < placed[b].index {
                (&placed[a], &placed[b])
            } else {
                (&placed[b], &placed[a])
            };
            let initial = i.pose.inverse() * j.pose;
            let r = refine(
                &scans[j.index].cloud,
                &scans[i.index].cloud,
                &initial,
                &params.icp,
            )?;
            Ok((i.index, j.index, initial, r))
        })
        .collect();
    for result in results {
        let (i, j, initial, r) = result?;
        let refused = if !r.converged {
            Some("did not converge")
        } else if r.inlier_fraction < params.min_inlier_fraction {
            Some("too few inliers")
        } else {
            let change = initial.inverse() * r.pose;
            if change.translation().norm() > params.max_correction.0
                || change.rotation().angle() > params.max_correction.1
            {
                Some("correction too large")
            } else {
                None
            }
        };
        if let Some(why) = refused {
            *report.pairs_refused.entry(why.to_string()).or_default() += 1;
            continue;
        }
        let kind = if frames[i] != frames[j] || j - i >= LOOP_GAP {
            EdgeKind::LoopClosure
        } else {
            EdgeKind::Registration
        };
        let info = r.edge_information(params.sigma_floor, params.information_scale);
        graph.add_edge_se3(i as u64, j as u64, kind, r.pose, info, params.kernel)?;
    }
    Ok(())
}
