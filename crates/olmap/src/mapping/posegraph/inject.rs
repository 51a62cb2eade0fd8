//! Wrong loop closures added on purpose: the robustness check of issue 23 ("inject 5 %
//! wrong closures, trusted-looking but 2-5 m off; the result stays within bounds and the
//! report names them"), for the 3D graph as `olmap map LOG --inject-wrong-closures` does
//! for 2D logs.

use super::{GraphRefineParams, LOOP_GAP};
use crate::error::Result;
use crate::geometry::Pose;
use crate::graph::{EdgeKind, Measurement, PoseGraph};
use crate::mapping::planar::odometry::uniform;
use crate::mapping::PlacedScan;

/// One injected edge: its index in the graph, the earlier and later input scan, and how
/// far its translation lies from the scans' current relative pose, metres.
pub(super) struct Injected {
    pub edge: usize,
    pub from: usize,
    pub to: usize,
    pub offset_m: f64,
}

/// Adds `params.inject_wrong_closures` × (the pairwise edges already in `graph`) wrong loop
/// closures, rounded up: between placed scans at least [`LOOP_GAP`] apart in the input,
/// each the pair's current relative pose moved 2-5 m in a random horizontal direction
/// (rotation kept), with the information of the median pairwise edge (by trace: a closure
/// as confident as a typical real one) and `params.kernel`. Pairs and offsets come from
/// `params.inject_seed`. None when there are no pairwise edges to copy the information
/// of, or no pair far enough apart.
pub(super) fn inject_wrong_closures(
    graph: &mut PoseGraph,
    placed: &[PlacedScan],
    params: &GraphRefineParams,
) -> Result<Vec<Injected>> {
    let mut out = Vec::new();
    if params.inject_wrong_closures <= 0.0 {
        return Ok(out);
    }
    let mut informations: Vec<_> = graph
        .edges()
        .iter()
        .filter(|e| matches!(e.kind, EdgeKind::Registration | EdgeKind::LoopClosure))
        .filter_map(|e| match e.measurement {
            Measurement::Se3 { information, .. } => Some(information),
            Measurement::Se2 { .. } => None,
        })
        .collect();
    if informations.is_empty() {
        return Ok(out);
    }
    informations.sort_by(|a, b| a.trace().total_cmp(&b.trace()));
    let information = informations[informations.len() / 2];
    let count = (params.inject_wrong_closures * informations.len() as f64).ceil() as usize;
    let mut counter = 0u64;
    let mut draw = || {
        counter += 1;
        uniform(params.inject_seed ^ 0x3d_c105_u64, counter)
    };
    let n = placed.len();
    let mut tries = 0;
    while out.len() < count && tries < 100 * count {
        tries += 1;
        let a = &placed[((draw() * n as f64) as usize).min(n - 1)];
        let b = &placed[((draw() * n as f64) as usize).min(n - 1)];
        let (i, j) = if a.index < b.index { (a, b) } else { (b, a) };
        if j.index - i.index < LOOP_GAP {
            continue;
        }
        let offset_m = 2.0 + 3.0 * draw();
        let direction = std::f64::consts::TAU * draw();
        let shift = Pose::from_xyz_ypr(
            offset_m * direction.cos(),
            offset_m * direction.sin(),
            0.0,
            0.0,
            0.0,
            0.0,
        );
        let wrong = shift * (i.pose.inverse() * j.pose);
        let edge = graph.add_edge_se3(
            i.index as u64,
            j.index as u64,
            EdgeKind::LoopClosure,
            wrong,
            information,
            params.kernel,
        )?;
        out.push(Injected {
            edge,
            from: i.index,
            to: j.index,
            offset_m,
        });
    }
    Ok(out)
}
