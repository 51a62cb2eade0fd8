//! The placed scans made consistent by a pose graph (3D): after the batch or sequential
//! mapper has placed every scan once against the map as it was then, each scan is
//! registered again against its nearest placed neighbours (pairwise ICP from their current
//! relative pose), every such registration becomes an edge whose information comes from
//! the ICP normal equations ([`IcpResult::edge_information`]), the robots' odometry adds
//! weak edges between their consecutive scans, and one robust solve moves all poses to
//! agree (the role of 3DTK's LUM after ICP). Pairs far apart in capture order are loop
//! closures; a wrong one is held back by the kernel (dynamic covariance scaling).
//!
//! [`refine_placed`] is the entry; [`MapParams::graph`] turns it on in
//! [`build_map`]/[`build_map_linked`], which then fuse the map at the refined poses.
//!
//! [`IcpResult::edge_information`]: crate::align::IcpResult::edge_information
//! [`MapParams::graph`]: super::MapParams::graph
//! [`build_map`]: super::build_map
//! [`build_map_linked`]: super::build_map_linked

mod inject;
mod pairs;

use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

use nalgebra::Matrix6;
use serde::{Deserialize, Serialize};

use super::planar::InjectedClosure;
use super::{PlacedScan, ScanInput, ScanLink, TeamLinks};
use crate::align::icp::IcpParams;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::graph::{EdgeKind, Kernel, PoseGraph, SolveParams, Space};

/// Parameters of [`refine_placed`].
#[derive(Debug, Clone, PartialEq)]
pub struct GraphRefineParams {
    /// Each placed scan is registered against at most this many placed scans nearest to it
    /// (by the distance of their origins; default 4).
    pub neighbours: usize,
    /// Only scans whose origins are at most this far apart are paired, metres (default 6).
    pub max_distance: f64,
    /// The pairwise refinement (default: [`IcpParams::default`] with 0.1 m source and
    /// target voxels, a 1 m first correspondence distance and a 0.2 m final one: the pairs
    /// start within a few centimetres of their solution).
    pub icp: IcpParams,
    /// A pairwise registration becomes an edge only with at least this inlier fraction
    /// (default 0.3).
    pub min_inlier_fraction: f64,
    /// …and only when it moves the pair's relative pose by at most this, `(metres,
    /// radians)` (default 0.5 m, 5°): a pair that disagrees more with the mapper did not
    /// start inside its basin, or is a look-alike.
    pub max_correction: (f64, f64),
    /// A registration's σ is its inlier RMS residual, at least this, metres (default 0.01).
    pub sigma_floor: f64,
    /// Registration information = `H / σ² × information_scale` (default 0.05: a scan's
    /// neighbouring points see the same surface error, so they are far from independent;
    /// the scale makes a registration's translation σ a few millimetres to a centimetre).
    pub information_scale: f64,
    /// Odometry edges' σ, `(metres + fraction of the distance, radians + radians per
    /// metre)`, isotropic over the three axes of each (default `(0.1 m + 35 %, 2° + 10°/m)`:
    /// wheel odometry on an indoor floor, as weak as the simulator's degraded odometry);
    /// `None` = no odometry edges.
    pub odometry_sigma: Option<OdometrySigma>,
    /// Mutual sightings (thesis (6.4)) as edges, with the error model of (3.36)-(3.37);
    /// `None` = no sighting edges. Default [`SightingSigma::default`].
    pub sighting_sigma: Option<SightingSigma>,
    /// The robust kernel of the registration and sighting edges (default dynamic
    /// covariance scaling, Φ = 10).
    pub kernel: Kernel,
    /// The solve.
    pub solve: SolveParams,
    /// Robustness test: after the pairwise edges, add this fraction of them again as
    /// *wrong* loop closures (between placed scans at least [`LOOP_GAP`] apart, each the
    /// pair's relative pose moved 2-5 m sideways, with the median pairwise edge's
    /// information and [`GraphRefineParams::kernel`]) before the solve;
    /// [`GraphRefineReport::injected`] says which the kernel down-weighted. Default 0
    /// (none); at most 1.
    pub inject_wrong_closures: f64,
    /// Seed of the injected closures' pairs and offsets (default 0).
    pub inject_seed: u64,
}

/// The σ of an odometry edge between two scans `d` metres apart:
/// `σ_t = metres + fraction · d`, `σ_r = radians + radians_per_metre · d`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OdometrySigma {
    /// Constant translation σ, metres.
    pub metres: f64,
    /// Translation σ per metre moved.
    pub fraction: f64,
    /// Constant rotation σ, radians.
    pub radians: f64,
    /// Rotation σ per metre moved, radians.
    pub radians_per_metre: f64,
}

/// The error model of a mutual sighting edge (thesis §3.5, (3.36)-(3.37)): for robots
/// `a` metres apart the position error is at most `Δa + a Δα + (a / b) Δd` with `a ≈ b`
/// (range error, bearing error over the separation, beacon offset error), taken as the
/// position σ; the heading `θ − β + π` carries both bearings' errors, `σ_θ = 2 Δα`. The
/// two robots stand on one floor: the relative height, roll and pitch get `level_m` and
/// `level_rad`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SightingSigma {
    /// Range error `Δa`, metres (default 0.02, thesis (3.35)).
    pub range_m: f64,
    /// Bearing error `Δα`, radians (default 0.5°: a 5 cm beacon seen by 1° beams).
    pub bearing_rad: f64,
    /// Beacon offset error `Δd`, metres (default 0.01).
    pub offset_m: f64,
    /// σ of the relative height, metres (default 0.05).
    pub level_m: f64,
    /// σ of the relative roll and pitch, radians (default 1°).
    pub level_rad: f64,
}

impl Default for SightingSigma {
    fn default() -> Self {
        SightingSigma {
            range_m: 0.02,
            bearing_rad: 0.5f64.to_radians(),
            offset_m: 0.01,
            level_m: 0.05,
            level_rad: 1f64.to_radians(),
        }
    }
}

impl SightingSigma {
    /// The information over `(x, y, z, rx, ry, rz)` of a mutual sighting edge whose
    /// relative pose is `t_other_this` (the measurement's frame is the other robot's:
    /// x and y get the position σ, rz the heading σ).
    pub fn information(&self, t_other_this: &Pose) -> Matrix6<f64> {
        let a = t_other_this.translation().xy().norm();
        let position = self.range_m + a * self.bearing_rad + self.offset_m;
        let heading = 2.0 * self.bearing_rad;
        let sigmas = [
            position,
            position,
            self.level_m,
            self.level_rad,
            self.level_rad,
            heading,
        ];
        Matrix6::from_diagonal(&nalgebra::Vector6::from_fn(|k, _| {
            1.0 / (sigmas[k] * sigmas[k])
        }))
    }

    fn valid(&self) -> bool {
        [
            self.range_m,
            self.bearing_rad,
            self.offset_m,
            self.level_m,
            self.level_rad,
        ]
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0)
            && self.range_m + self.offset_m > 0.0
            && self.bearing_rad > 0.0
            && self.level_m > 0.0
            && self.level_rad > 0.0
    }
}

impl Default for GraphRefineParams {
    fn default() -> Self {
        GraphRefineParams {
            neighbours: 4,
            max_distance: 6.0,
            icp: IcpParams {
                source_voxel: 0.1,
                target_voxel: 0.1,
                max_distance_start: 1.0,
                max_distance_end: 0.2,
                ..IcpParams::default()
            },
            min_inlier_fraction: 0.3,
            max_correction: (0.5, 5f64.to_radians()),
            sigma_floor: 0.01,
            information_scale: 0.05,
            odometry_sigma: Some(OdometrySigma {
                metres: 0.1,
                fraction: 0.35,
                radians: 2f64.to_radians(),
                radians_per_metre: 10f64.to_radians(),
            }),
            sighting_sigma: Some(SightingSigma::default()),
            kernel: Kernel::Dcs(10.0),
            solve: SolveParams::default(),
            inject_wrong_closures: 0.0,
            inject_seed: 0,
        }
    }
}

impl GraphRefineParams {
    /// Checks every parameter ([`Error::InvalidArgument`] naming the one out of range).
    pub fn validate(&self) -> Result<()> {
        self.icp.validate()?;
        let bad = |what: String| Err(Error::InvalidArgument(format!("graph refinement: {what}")));
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if self.neighbours == 0 || self.neighbours > 64 {
            return bad(format!(
                "neighbours must be 1 to 64, got {}",
                self.neighbours
            ));
        }
        if !positive(self.max_distance) {
            return bad(format!(
                "max_distance must be > 0 m, got {}",
                self.max_distance
            ));
        }
        if !(0.0..=1.0).contains(&self.min_inlier_fraction) {
            return bad(format!(
                "min_inlier_fraction must be in [0, 1], got {}",
                self.min_inlier_fraction
            ));
        }
        let (m, r) = self.max_correction;
        if !(positive(m) && positive(r)) {
            return bad(format!("max_correction must be > 0, got ({m} m, {r} rad)"));
        }
        if !(positive(self.sigma_floor) && positive(self.information_scale)) {
            return bad(format!(
                "sigma_floor and information_scale must be > 0, got {} and {}",
                self.sigma_floor, self.information_scale
            ));
        }
        if !(0.0..=1.0).contains(&self.inject_wrong_closures) {
            return bad(format!(
                "the fraction of wrong closures to inject must be in [0, 1], got {}",
                self.inject_wrong_closures
            ));
        }
        if let Some(o) = self.odometry_sigma {
            let ok = [o.metres, o.fraction, o.radians, o.radians_per_metre]
                .iter()
                .all(|v| v.is_finite() && *v >= 0.0)
                && o.metres + o.fraction > 0.0
                && o.radians + o.radians_per_metre > 0.0;
            if !ok {
                return bad(format!(
                    "odometry σ must be finite, >= 0 and not all zero, got {o:?}"
                ));
            }
        }
        if let Some(s) = self.sighting_sigma {
            if !s.valid() {
                return bad(format!(
                    "sighting σ must be finite and > 0 (range or offset, bearing, level), got {s:?}"
                ));
            }
        }
        Ok(())
    }
}

/// A registration edge the robust kernel down-weighted at the solution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DownWeighted {
    /// The scan the edge starts from.
    pub from: String,
    /// The scan it ends at.
    pub to: String,
    /// The kernel's weight at the solution (below 0.5).
    pub weight: f64,
}

/// What [`refine_placed`] did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GraphRefineReport {
    /// Pairwise registrations run.
    pub pairs_tried: usize,
    /// Graph edges by kind (`odometry`, `registration`, `loop_closure`, `sighting`).
    pub edges: BTreeMap<String, usize>,
    /// Pairs that did not become edges, by reason.
    pub pairs_refused: BTreeMap<String, usize>,
    /// Registration, loop-closure and sighting edges the kernel down-weighted at the
    /// solution.
    pub down_weighted: Vec<DownWeighted>,
    /// The solver's cost at the mapper's poses and at the solution.
    pub initial_cost: f64,
    /// See `initial_cost`.
    pub final_cost: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// The largest position change of a scan, metres.
    pub largest_move_m: f64,
    /// Wall time (registrations and solve), seconds.
    pub seconds: f64,
    /// The wrong closures [`GraphRefineParams::inject_wrong_closures`] added, each with
    /// whether the kernel down-weighted it (empty without injection).
    #[serde(default)]
    pub injected: Vec<InjectedClosure>,
}

/// The result of [`refine_placed`].
#[derive(Debug, Clone)]
pub struct GraphRefinement {
    /// The refined `T_map_scan` of each entry of the `placed` given, in that order.
    pub poses: Vec<Pose>,
    /// The solved graph (node id = the scan's input index), e.g. to write as g2o.
    pub graph: PoseGraph,
    /// What was done.
    pub report: GraphRefineReport,
}

/// Makes placed scans consistent (see the [module documentation](self)): pairs each
/// placed scan with its nearest placed neighbours, registers every pair by ICP from the
/// pair's current relative pose, adds the trusted ones as edges (a loop closure when the
/// two scans are from different robots or more than [`LOOP_GAP`] scans apart in the
/// input), adds odometry edges between each robot's consecutive placed scans
/// (`frames[i]` = the robot of input scan `i`), and solves with the first placed scan
/// fixed. With [`GraphRefineParams::sighting_sigma`], every mutual sighting (6.4) between
/// two placed scans in `team.links` is an edge too. `team.frame[i]` is the robot of input
/// scan `i` ([`TeamLinks::none`] for one robot). Scans are `scans[p.index]` for each `p`
/// in `placed`.
///
/// ```
/// use olmap::geometry::Pose;
/// use olmap::mapping::posegraph::{refine_placed, GraphRefineParams};
/// use olmap::mapping::{build_map, MapParams, ScanInput, TeamLinks};
/// # use olmap::cloud::PointCloud;
/// # use nalgebra::Point3;
/// # // Two scans of one box room, 0.5 m apart.
/// # let room = |dx: f64| {
/// #     let mut c = PointCloud::new();
/// #     for i in 0..60 { for j in 0..30 {
/// #         let (u, v) = (i as f64 * 0.1 - 3.0, j as f64 * 0.1);
/// #         for p in [(u - dx, -2.0, v), (u - dx, 2.5, v), (-3.0 - dx, u * 0.6, v), (3.5 - dx, u * 0.6, v), (u - dx, u * 0.6 + 0.3 * v, 0.0)] {
/// #             c.push(Point3::new(p.0 as f32, p.1 as f32, p.2 as f32));
/// #         }
/// #     } }
/// #     c
/// # };
/// let scans = vec![
///     ScanInput { name: "a".into(), cloud: room(0.0), odometry: None },
///     ScanInput { name: "b".into(), cloud: room(0.5), odometry: None },
/// ];
/// let build = build_map(&scans, &MapParams::default(), |_, _| {})?;
/// let team = TeamLinks::none(scans.len());
/// let refined = refine_placed(&scans, &team, &build.placed, &GraphRefineParams::default())?;
/// assert_eq!(refined.poses.len(), build.placed.len());
/// # Ok::<(), olmap::Error>(())
/// ```
pub fn refine_placed(
    scans: &[ScanInput],
    team: &TeamLinks,
    placed: &[PlacedScan],
    params: &GraphRefineParams,
) -> Result<GraphRefinement> {
    let start = Instant::now();
    params.validate()?;
    let frames = &team.frame;
    if frames.len() != scans.len()
        || team.links.len() != scans.len()
        || placed.iter().any(|p| p.index >= scans.len())
    {
        return Err(Error::InvalidArgument(format!(
            "graph refinement: {} frames, {} link lists and placed indices up to {:?} for {} \
             scans",
            frames.len(),
            team.links.len(),
            placed.iter().map(|p| p.index).max(),
            scans.len()
        )));
    }
    let mut graph = PoseGraph::new(Space::Se3);
    for p in placed {
        graph.add_node_se3(p.index as u64, p.pose)?;
    }
    if let Some(first) = placed.first() {
        graph.set_fixed(first.index as u64, true)?;
    }
    let mut report = GraphRefineReport {
        pairs_tried: 0,
        edges: BTreeMap::new(),
        pairs_refused: BTreeMap::new(),
        down_weighted: Vec::new(),
        initial_cost: 0.0,
        final_cost: 0.0,
        iterations: 0,
        largest_move_m: 0.0,
        seconds: 0.0,
        injected: Vec::new(),
    };
    if let Some(sigma) = params.odometry_sigma {
        add_odometry_edges(&mut graph, scans, frames, placed, sigma)?;
    }
    if let Some(sigma) = params.sighting_sigma {
        add_sighting_edges(&mut graph, team, placed, sigma, params.kernel)?;
    }
    pairs::add_registration_edges(&mut graph, scans, frames, placed, params, &mut report)?;
    let injected = inject::inject_wrong_closures(&mut graph, placed, params)?;
    let solved = graph.optimise(&params.solve)?;
    report.injected = injected
        .into_iter()
        .map(|w| InjectedClosure {
            from: scans[w.from].name.clone(),
            to: scans[w.to].name.clone(),
            offset_m: w.offset_m,
            down_weighted: solved
                .edge_reports
                .get(w.edge)
                .is_some_and(|e| e.down_weighted),
        })
        .collect();
    report.initial_cost = solved.initial_cost;
    report.final_cost = solved.final_cost;
    report.iterations = solved.iterations;
    for e in solved.down_weighted() {
        report.down_weighted.push(DownWeighted {
            from: scans[e.from as usize].name.clone(),
            to: scans[e.to as usize].name.clone(),
            weight: e.weight,
        });
    }
    report.edges = graph
        .edge_counts()
        .into_iter()
        .map(|(k, n)| (k.name().to_string(), n))
        .collect();
    let mut poses = Vec::with_capacity(placed.len());
    for p in placed {
        let pose = graph.pose(p.index as u64).expect("added above");
        let moved = (pose.translation() - p.pose.translation()).norm();
        report.largest_move_m = report.largest_move_m.max(moved);
        poses.push(pose);
    }
    report.seconds = start.elapsed().as_secs_f64();
    Ok(GraphRefinement {
        poses,
        graph,
        report,
    })
}

/// Two scans of one robot at least this many scans apart in the input (or of two robots)
/// make a loop-closure edge rather than a registration edge.
pub const LOOP_GAP: usize = 5;

/// An edge per mutual sighting (6.4) between two placed scans, from the earlier input scan
/// to the later, with the (3.37) information.
fn add_sighting_edges(
    graph: &mut PoseGraph,
    team: &TeamLinks,
    placed: &[PlacedScan],
    sigma: SightingSigma,
    kernel: Kernel,
) -> Result<()> {
    let is_placed: BTreeSet<usize> = placed.iter().map(|p| p.index).collect();
    for (this, links) in team.links.iter().enumerate() {
        for link in links {
            let ScanLink::Mutual { other, relative } = link else {
                continue;
            };
            // Each two-way sighting is listed from both scans: add it once.
            if *other >= this || !is_placed.contains(&this) || !is_placed.contains(other) {
                continue;
            }
            let info = sigma.information(relative);
            graph.add_edge_se3(
                *other as u64,
                this as u64,
                EdgeKind::Sighting,
                *relative,
                info,
                kernel,
            )?;
        }
    }
    Ok(())
}

/// Odometry edges between each robot's consecutive placed scans with odometry (input order).
fn add_odometry_edges(
    graph: &mut PoseGraph,
    scans: &[ScanInput],
    frames: &[usize],
    placed: &[PlacedScan],
    sigma: OdometrySigma,
) -> Result<()> {
    let mut indices: Vec<usize> = placed
        .iter()
        .map(|p| p.index)
        .filter(|&i| scans[i].odometry.is_some())
        .collect();
    indices.sort_unstable_by_key(|&i| (frames[i], i));
    for w in indices.windows(2) {
        let (a, b) = (w[0], w[1]);
        if frames[a] != frames[b] {
            continue;
        }
        let (Some(oa), Some(ob)) = (scans[a].odometry, scans[b].odometry) else {
            continue;
        };
        let motion = oa.inverse() * ob;
        let d = motion.translation().norm();
        let st = sigma.metres + sigma.fraction * d;
        let sr = sigma.radians + sigma.radians_per_metre * d;
        let mut info = Matrix6::<f64>::zeros();
        for k in 0..3 {
            info[(k, k)] = 1.0 / (st * st);
            info[(k + 3, k + 3)] = 1.0 / (sr * sr);
        }
        graph.add_edge_se3(
            a as u64,
            b as u64,
            EdgeKind::Odometry,
            motion,
            info,
            Kernel::None,
        )?;
    }
    Ok(())
}
