//! The incremental planar mapper: scans arrive one at a time ([`PlanarMapper::add_scan`]),
//! each is registered onto a local map of the last scans from its odometry guess, becomes
//! a node of an SE(2) pose graph with odometry and registration edges, and is tried as a
//! loop closure against earlier parts of the map; each accepted closure re-optimises the
//! graph, which moves earlier scans.

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Vector2};
use serde::Serialize;

use super::correlative::{search, CorrelativeMatch, CorrelativeParams, ScoreGrid};
use super::icp::{LineTarget, PlanarIcpParams, PlanarIcpResult};
use super::odometry::OdometryNoise;
use crate::error::Result;
use crate::graph::{EdgeKind, Init, Kernel, PoseGraph, Se2, SolveParams, SolveReport, Space};
use rustc_hash::FxHashMap as FxMap;

/// When a registration is good enough to place a scan or close a loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationGate {
    /// Least share of the scan's points within the inlier distance of a target line.
    pub min_inlier_fraction: f64,
    /// Least number of such points.
    pub min_inliers: usize,
    /// Least [`PlanarIcpResult::weakest_translation`]: how well the weakest direction is
    /// held (a corridor's direction along it is not).
    pub min_weakest_translation: f64,
}

impl RegistrationGate {
    /// Why `r` fails the gate, or `None` when it passes.
    pub fn doubt(&self, r: &PlanarIcpResult) -> Option<String> {
        if !r.converged {
            return Some(format!(
                "refinement did not converge in {} iterations",
                r.iterations
            ));
        }
        if r.inliers < self.min_inliers {
            return Some(format!("{} inliers < {}", r.inliers, self.min_inliers));
        }
        if r.inlier_fraction() < self.min_inlier_fraction {
            return Some(format!(
                "inlier fraction {:.2} < {:.2}",
                r.inlier_fraction(),
                self.min_inlier_fraction
            ));
        }
        if r.weakest_translation() < self.min_weakest_translation {
            return Some(format!(
                "translation poorly held in one direction ({:.3} < {:.3}: a corridor?)",
                r.weakest_translation(),
                self.min_weakest_translation
            ));
        }
        None
    }
}

/// How loop closures are found and accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosureParams {
    /// Candidates: earlier scans whose estimated position is within this of the new
    /// scan's, metres.
    pub radius: f64,
    /// … and that were left at least this far back along the path, metres.
    pub min_travel: f64,
    /// A closure is tried once per this much travel, metres.
    pub every_travel: f64,
    /// Most candidates tried per attempt (the nearest, from different stretches of path).
    pub max_candidates: usize,
    /// A candidate's local map: the candidate and this many scans either side.
    pub neighbourhood: usize,
    /// The correlative search around the current estimate.
    pub search: CorrelativeParams,
    /// Least correlative score (mean blurred-image value, 0 to 1).
    pub min_score: f64,
    /// Most `runner_up / best` of the correlative search: above it the place is ambiguous.
    pub max_ambiguity: f64,
    /// The refinement's gate.
    pub gate: RegistrationGate,
    /// The robust kernel of closure edges.
    pub kernel: Kernel,
    /// How fast the estimate may drift away from the truth, metres per metre travelled: the
    /// candidate radius and the search window grow by this times the *graph distance*
    /// between the candidate and the new scan: the shortest way between them through the
    /// graph, counting the path travelled along sequential edges and nothing across
    /// accepted closures (how much unchecked travel their relative pose rests on) …
    pub drift_per_metre: f64,
    /// … up to this, metres (for the window; the radius grows up to 2x this) …
    pub max_window_xy: f64,
    /// … and the heading window grows by this many degrees per metre, up to
    /// `max_window_yaw_deg`.
    pub yaw_drift_deg_per_metre: f64,
    /// See `yaw_drift_deg_per_metre`.
    pub max_window_yaw_deg: f64,
    /// A closure that passes every gate but that its kernel would down-weight at the
    /// current estimate (a correction much larger than the graph expects: the drift of a
    /// long loop, or a wrong match) is held until a second closure found within this much
    /// further travel (metres) implies the same correction; the two are then solved at full
    /// weight once (a robust kernel alone would refuse a true correction of metres), and
    /// keep their kernel afterwards.
    pub corroboration_travel: f64,
    /// Corridor closures: a closure whose only fault is that it cannot tell where along
    /// a corridor it is — the search's near-best rivals all lie on one line through the
    /// best at its heading, or the refinement holds one translation direction poorly —
    /// becomes an edge with no information along that direction (it still holds the
    /// heading and the position across the corridor, which is what a long loop's drift
    /// needs). Off: such closures are refused as ambiguous.
    pub partial: bool,
}

impl Default for ClosureParams {
    fn default() -> Self {
        ClosureParams {
            radius: 3.0,
            min_travel: 5.0,
            every_travel: 0.5,
            max_candidates: 3,
            neighbourhood: 5,
            search: CorrelativeParams::default(),
            min_score: 0.45,
            max_ambiguity: 0.85,
            gate: RegistrationGate {
                min_inlier_fraction: 0.5,
                min_inliers: 50,
                min_weakest_translation: 0.1,
            },
            kernel: Kernel::Dcs(10.0),
            drift_per_metre: 0.05,
            max_window_xy: 6.0,
            yaw_drift_deg_per_metre: 0.2,
            max_window_yaw_deg: 30.0,
            corroboration_travel: 10.0,
            partial: true,
        }
    }
}

/// Parameters of the planar mapper.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarMapParams {
    /// The refinement.
    pub icp: PlanarIcpParams,
    /// Scans in the local map a new scan is registered onto.
    pub local_map_scans: usize,
    /// Grid size for thinning scans and local maps, metres.
    pub voxel: f64,
    /// The correlative search around the odometry guess that precedes each sequential
    /// refinement (it catches what a gradient method from a poor guess would not).
    pub search: CorrelativeParams,
    /// The gate of sequential registration.
    pub gate: RegistrationGate,
    /// The odometry's error model, for the information of odometry edges.
    pub odometry_noise: OdometryNoise,
    /// Registration information = `H / max(rmse, sigma_floor)² × information_scale`.
    pub information_scale: f64,
    /// See `information_scale`, metres.
    pub sigma_floor: f64,
    /// The least uncertainty a registration edge claims, `(metres, degrees)`: this
    /// covariance is added to the one from the ICP Hessian (scan matching is never better
    /// than its model: beam-angle and range biases, moving people), so a registration cannot
    /// overrule good odometry by an arbitrary factor. `(0, 0)`: none.
    pub registration_floor: (f64, f64),
    /// Loop closure; `None` = odometry and sequential registration only.
    pub closure: Option<ClosureParams>,
    /// A sequential registration refused only because one translation direction is poorly
    /// held (a corridor: [`RegistrationGate::min_weakest_translation`]) still holds the
    /// heading and the direction across: with this on, it becomes an edge with no
    /// information along the weak direction, and odometry supplies the step along it
    /// ([`PlacementSource::PartialRegistration`]). Off: such scans are placed by odometry
    /// alone.
    pub partial_registration: bool,
}

impl Default for PlanarMapParams {
    fn default() -> Self {
        PlanarMapParams {
            icp: PlanarIcpParams::default(),
            local_map_scans: 10,
            voxel: 0.05,
            search: CorrelativeParams {
                window_xy: 0.5,
                window_yaw_deg: 10.0,
                ..CorrelativeParams::default()
            },
            gate: RegistrationGate {
                min_inlier_fraction: 0.2,
                min_inliers: 25,
                min_weakest_translation: 0.02,
            },
            odometry_noise: OdometryNoise {
                distance_fraction: 0.05,
                degrees_per_unit: 2.0,
            },
            information_scale: 0.1,
            sigma_floor: 0.01,
            registration_floor: (0.0, 0.0),
            closure: Some(ClosureParams::default()),
            partial_registration: true,
        }
    }
}

/// Where a scan's pose came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlacementSource {
    /// The first scan: it defines the map frame (at its odometry pose, if any).
    First,
    /// Registration onto the local map.
    Registration,
    /// Odometry alone (the registration was refused; the reason is in `doubt`).
    Odometry,
    /// Registration across a corridor and in heading, odometry along it (see
    /// [`PlanarMapParams::partial_registration`]; the gate's doubt is in `doubt`).
    PartialRegistration,
}

/// What [`PlanarMapper::add_scan`] did with one scan.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Placement {
    /// The scan's index in arrival order.
    pub index: usize,
    /// The scan's name.
    pub name: String,
    /// Whether the scan is in the map (false: no odometry and no trusted registration).
    pub placed: bool,
    /// Its pose when placed (later closures may move it; see [`PlanarMapper::poses`]).
    pub pose: Se2,
    /// Where the pose came from.
    pub source: PlacementSource,
    /// The sequential registration's inlier fraction (0 without one).
    pub inlier_fraction: f64,
    /// Why the registration was not used, if it was not.
    pub doubt: Option<String>,
    /// Loop closures tried for this scan.
    pub closures: Vec<ClosureAttempt>,
}

/// One loop-closure attempt.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClosureAttempt {
    /// The earlier scan (the candidate's centre).
    pub from: usize,
    /// The new scan.
    pub to: usize,
    /// Whether an edge was added.
    pub accepted: bool,
    /// The correlative score and ambiguity.
    pub score: f64,
    /// `runner_up / best` of the correlative search.
    pub ambiguity: f64,
    /// The refinement's inlier fraction.
    pub inlier_fraction: f64,
    /// How far the closure moves the new scan from its estimate, metres.
    pub correction_m: f64,
    /// Why it was refused, if it was.
    pub reason: Option<String>,
    /// Whether it holds only the heading and the position across a corridor (see
    /// [`ClosureParams::partial`]).
    pub partial: bool,
    /// When this closure was a large correction confirmed by an earlier held one (see
    /// [`ClosureParams::corroboration_travel`]): that closure's earlier scan; both edges
    /// were added.
    pub corroborates: Option<usize>,
    /// The edge's index in the graph when accepted.
    #[serde(skip)]
    pub edge: Option<usize>,
}

/// A loop closure that passed every gate.
struct Closure {
    from: usize,
    to: usize,
    t_from_to: Se2,
    information: Matrix3<f64>,
    /// A corridor closure's unobserved translation direction, in the frame of `from`.
    weak: Option<Vector2<f64>>,
    /// The path travelled when it was found, metres.
    travel: f64,
}

struct StoredScan {
    name: String,
    points: Vec<Vector2<f64>>,
    odometry: Option<Se2>,
    node: Option<u64>,
    travel: f64,
}

/// The incremental planar mapper (see the module documentation).
///
/// ```
/// use nalgebra::Vector2;
/// use olmap::graph::Se2;
/// use olmap::mapping::planar::{PlanarMapParams, PlanarMapper};
/// // A robot driving 2 m along a room 6 m x 4 m, seeing its four walls.
/// let walls: Vec<Vector2<f64>> = (0..120)
///     .flat_map(|i| {
///         let s = i as f64 * 0.05;
///         [Vector2::new(s - 3.0, -2.0), Vector2::new(s - 3.0, 2.0),
///          Vector2::new(-3.0, s / 1.5 - 2.0), Vector2::new(3.0, s / 1.5 - 2.0)]
///     })
///     .collect();
/// let mut mapper = PlanarMapper::new(PlanarMapParams { closure: None, ..Default::default() });
/// for k in 0..5 {
///     let truth = Se2::new(0.5 * k as f64 - 1.0, 0.0, 0.0);
///     let seen: Vec<Vector2<f64>> = walls.iter().map(|p| p - Vector2::new(truth.x, truth.y)).collect();
///     // Odometry that under-reads by 10 %: registration corrects it.
///     let odometry = Se2::new(0.45 * k as f64 - 1.0, 0.0, 0.0);
///     let placed = mapper.add_scan(format!("s{k}"), seen, Some(odometry)).unwrap();
///     assert!(placed.placed);
/// }
/// let last = mapper.poses()[4].1;
/// assert!((last.x - 1.0).abs() < 0.01, "{last:?}");
/// ```
pub struct PlanarMapper {
    params: PlanarMapParams,
    graph: PoseGraph,
    scans: Vec<StoredScan>,
    last_placed: Option<usize>,
    node_to_scan: FxMap<u64, usize>,
    closure_attempts_at: f64,
    /// Per scan: its graph neighbours and the travel between them (0 across a closure).
    links: Vec<Vec<(usize, f64)>>,
    /// Closures that passed every gate but are large corrections, waiting for a second.
    held: Vec<Closure>,
    optimisations: usize,
}

impl PlanarMapper {
    /// An empty mapper.
    pub fn new(params: PlanarMapParams) -> PlanarMapper {
        PlanarMapper {
            params,
            graph: PoseGraph::new(Space::Se2),
            scans: Vec::new(),
            last_placed: None,
            node_to_scan: FxMap::default(),
            closure_attempts_at: f64::NEG_INFINITY,
            links: Vec::new(),
            held: Vec::new(),
            optimisations: 0,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &PlanarMapParams {
        &self.params
    }

    /// The pose graph (nodes = placed scans by index, edges by kind).
    pub fn graph(&self) -> &PoseGraph {
        &self.graph
    }

    /// Graph solves run so far (one per scan that closed a loop).
    pub fn optimisations(&self) -> usize {
        self.optimisations
    }

    /// The current poses of the placed scans, `(name, T_map_scan)`, in arrival order.
    pub fn poses(&self) -> Vec<(String, Se2)> {
        self.scans
            .iter()
            .filter_map(|s| {
                let id = s.node?;
                Some((s.name.clone(), self.graph.pose_se2(id)?))
            })
            .collect()
    }

    /// The map: every placed scan's (thinned) points in the map frame.
    pub fn map_points(&self) -> Vec<Vector2<f64>> {
        let mut out = Vec::new();
        for s in &self.scans {
            let Some(pose) = s.node.and_then(|id| self.graph.pose_se2(id)) else {
                continue;
            };
            out.extend(s.points.iter().map(|p| transform(&pose, p)));
        }
        out
    }

    /// Re-solves the whole graph (warm start) and returns the solver's final cost.
    pub fn optimise(&mut self) -> Result<f64> {
        Ok(self.optimise_report()?.final_cost)
    }

    /// [`PlanarMapper::optimise`] with the solver's whole report (costs, per-edge weights).
    pub fn optimise_report(&mut self) -> Result<SolveReport> {
        self.optimisations += 1;
        self.graph.optimise(&solve_params())
    }

    /// Places one scan: `points` in the scan's frame (metres), `odometry` its odometry
    /// pose if the robot has one (`T_odom_scan`; only differences between scans are used).
    pub fn add_scan(
        &mut self,
        name: String,
        points: Vec<Vector2<f64>>,
        odometry: Option<Se2>,
    ) -> Result<Placement> {
        let index = self.scans.len();
        let points = thin(&points, self.params.voxel);
        let mut placement = Placement {
            index,
            name: name.clone(),
            placed: false,
            pose: Se2::default(),
            source: PlacementSource::First,
            inlier_fraction: 0.0,
            doubt: None,
            closures: Vec::new(),
        };
        let Some(prev) = self.last_placed else {
            let pose = odometry.unwrap_or_default();
            let id = index as u64;
            self.graph.add_node_se2(id, pose)?;
            self.graph.set_fixed(id, true)?;
            self.node_to_scan.insert(id, index);
            self.links.push(Vec::new());
            self.scans.push(StoredScan {
                name,
                points,
                odometry,
                node: Some(id),
                travel: 0.0,
            });
            self.last_placed = Some(index);
            placement.placed = true;
            placement.pose = pose;
            return Ok(placement);
        };
        let prev_id = self.scans[prev].node.expect("placed");
        let prev_pose = self.graph.pose_se2(prev_id).expect("node");
        let odo_step = match (self.scans[prev].odometry, odometry) {
            (Some(a), Some(b)) => Some(a.inverse().compose(&b)),
            _ => None,
        };
        // Register onto the local map, expressed in the previous scan's frame.
        let local = self.local_map(prev, &prev_pose);
        let guess = odo_step.unwrap_or_default();
        let reg = self.register(&local, &points, guess, &self.params.search);
        let reg = reg.map(|(r, _)| r);
        let doubt = match &reg {
            None => Some("the local map has too few points".to_string()),
            Some(r) => self.params.gate.doubt(r),
        };
        placement.inlier_fraction = reg.as_ref().map_or(0.0, |r| r.inlier_fraction());
        let partial = match (&reg, &doubt, odo_step) {
            (Some(r), Some(_), Some(o)) if self.params.partial_registration => {
                let relaxed = RegistrationGate {
                    min_weakest_translation: 0.0,
                    ..self.params.gate
                };
                relaxed.doubt(r).is_none().then(|| partial_step(r, &o))
            }
            _ => None,
        };
        let step = match (&reg, &doubt, odo_step, partial) {
            (Some(r), None, _, _) => {
                placement.source = PlacementSource::Registration;
                r.pose
            }
            (_, _, _, Some((p, _))) => {
                placement.source = PlacementSource::PartialRegistration;
                p
            }
            (_, _, Some(o), None) => {
                placement.source = PlacementSource::Odometry;
                o
            }
            _ => {
                placement.doubt = doubt;
                self.links.push(Vec::new());
                self.scans.push(StoredScan {
                    name,
                    points,
                    odometry,
                    node: None,
                    travel: self.scans[prev].travel,
                });
                return Ok(placement);
            }
        };
        placement.doubt = doubt.clone();
        let pose = prev_pose.compose(&step);
        let id = index as u64;
        self.graph.add_node_se2(id, pose)?;
        self.node_to_scan.insert(id, index);
        if let Some(o) = odo_step {
            let info = self.params.odometry_noise.information(&o);
            self.graph
                .add_edge_se2(prev_id, id, EdgeKind::Odometry, o, info, Kernel::None)?;
        }
        if let (Some(r), None) = (&reg, &doubt) {
            let info = self.registration_information(r);
            self.graph.add_edge_se2(
                prev_id,
                id,
                EdgeKind::Registration,
                r.pose,
                info,
                Kernel::None,
            )?;
        } else if let (Some(r), Some((measured, weak))) = (&reg, partial) {
            let info = without_direction(&self.registration_information(r), &weak);
            self.graph.add_edge_se2(
                prev_id,
                id,
                EdgeKind::Registration,
                measured,
                info,
                Kernel::None,
            )?;
        }
        let travel = self.scans[prev].travel + step.x.hypot(step.y);
        self.links.push(vec![(prev, step.x.hypot(step.y))]);
        self.links[prev].push((index, step.x.hypot(step.y)));
        self.scans.push(StoredScan {
            name,
            points,
            odometry,
            node: Some(id),
            travel,
        });
        self.last_placed = Some(index);
        placement.placed = true;
        placement.pose = pose;
        if let Some(cp) = self.params.closure {
            if travel - self.closure_attempts_at >= cp.every_travel {
                self.closure_attempts_at = travel;
                placement.closures = self.try_closures(index, &cp)?;
                if placement.closures.iter().any(|c| c.accepted) {
                    self.optimise()?;
                }
            }
        }
        Ok(placement)
    }

    /// Points of the last `local_map_scans` placed scans up to `last`, in the frame of
    /// `last` (whose pose is `last_pose`), thinned.
    fn local_map(&self, last: usize, last_pose: &Se2) -> Vec<Vector2<f64>> {
        let inv = last_pose.inverse();
        let mut pts = Vec::new();
        let mut taken = 0;
        for s in self.scans[..=last].iter().rev() {
            if taken == self.params.local_map_scans {
                break;
            }
            let Some(pose) = s.node.and_then(|id| self.graph.pose_se2(id)) else {
                continue;
            };
            let rel = inv.compose(&pose);
            pts.extend(s.points.iter().map(|p| transform(&rel, p)));
            taken += 1;
        }
        thin(&pts, self.params.voxel)
    }

    /// The information of a registration edge: the ICP's, with
    /// [`PlanarMapParams::registration_floor`] added to its covariance.
    fn registration_information(&self, r: &PlanarIcpResult) -> Matrix3<f64> {
        let info = symmetric(r.information(self.params.sigma_floor, self.params.information_scale));
        let (fxy, fth) = self.params.registration_floor;
        if fxy <= 0.0 && fth <= 0.0 {
            return info;
        }
        let floor = Matrix3::from_diagonal(&nalgebra::Vector3::new(
            fxy * fxy,
            fxy * fxy,
            fth.to_radians().powi(2),
        ));
        match info.try_inverse() {
            Some(cov) => (cov + floor).try_inverse().map_or(info, symmetric),
            None => info,
        }
    }

    /// Correlative search of `source` on `target` around `guess`, then point-to-line ICP
    /// from its best pose; `None` when the target is too small to use.
    fn register(
        &self,
        target: &[Vector2<f64>],
        source: &[Vector2<f64>],
        guess: Se2,
        search_params: &CorrelativeParams,
    ) -> Option<(PlanarIcpResult, CorrelativeMatch)> {
        let fine_sigma = 2.0 * self.params.voxel;
        let grid = ScoreGrid::new(target, self.params.voxel, fine_sigma)?;
        let lines = LineTarget::new(target.to_vec(), &self.params.icp)?;
        let m = if search_params.step_xy > fine_sigma {
            // Coarse steps: search a blur as wide as the step (so no peak falls between
            // steps), then search the best coarse cell finely. The ambiguity is the coarse
            // surface's: that is where distinct alternatives across the window show.
            let coarse_grid =
                ScoreGrid::new(target, self.params.voxel, search_params.step_xy / 1.5)?;
            let coarse = search(&coarse_grid, source, guess, search_params);
            let fine = CorrelativeParams {
                window_xy: search_params.step_xy,
                window_yaw_deg: search_params.step_yaw_deg,
                step_xy: self.params.voxel,
                step_yaw_deg: 0.5,
                ..*search_params
            };
            let m = search(&grid, source, coarse.pose, &fine);
            // The coarse rivals, moved with the best by the fine step and scored on the
            // fine scale.
            let (dx, dy) = (m.pose.x - coarse.pose.x, m.pose.y - coarse.pose.y);
            let dth = m.pose.theta - coarse.pose.theta;
            let rescale = if coarse.score > 0.0 {
                m.score / coarse.score
            } else {
                0.0
            };
            let rivals = coarse
                .rivals
                .iter()
                .map(|(p, v)| {
                    let q = Se2::new(
                        p.x + dx,
                        p.y + dy,
                        crate::geometry::wrap_angle(p.theta + dth),
                    );
                    (q, v * rescale)
                })
                .collect();
            CorrelativeMatch {
                runner_up: m.score * coarse.ambiguity(),
                rivals,
                ..m
            }
        } else {
            search(&grid, source, guess, search_params)
        };
        Some((lines.register(source, m.pose, &self.params.icp), m))
    }

    /// The closure search window for a candidate `path` metres back along the path: the
    /// base window grown with the drift that path may have gathered, with coarser steps
    /// when it grows large so the search stays cheap (the refinement takes the answer to
    /// full precision).
    fn closure_window(&self, path: f64, cp: &ClosureParams) -> CorrelativeParams {
        let since = path.max(0.0);
        let mut w = cp.search;
        w.window_xy =
            (w.window_xy + cp.drift_per_metre * since).min(cp.max_window_xy.max(w.window_xy));
        w.window_yaw_deg = (w.window_yaw_deg + cp.yaw_drift_deg_per_metre * since)
            .min(cp.max_window_yaw_deg.max(w.window_yaw_deg));
        // Keep about 41 steps across in x-y and 31 in heading.
        let cells = (w.window_xy / 20.0 / self.params.voxel).ceil().max(1.0);
        w.step_xy = w.step_xy.max(cells * self.params.voxel);
        w.step_yaw_deg = w.step_yaw_deg.max(w.window_yaw_deg / 15.0);
        w
    }

    /// The graph distance (see [`ClosureParams::drift_per_metre`]) from scan `i` to every
    /// scan, metres; beyond the distance at which the closure window stops growing the
    /// search stops and reports that distance.
    fn graph_distances(&self, i: usize, cp: &ClosureParams) -> Vec<f64> {
        let grow_xy = (cp.max_window_xy - cp.search.window_xy).max(0.0);
        let grow_yaw = (cp.max_window_yaw_deg - cp.search.window_yaw_deg).max(0.0);
        let cap = (grow_xy / cp.drift_per_metre.max(1e-9))
            .max(grow_yaw / cp.yaw_drift_deg_per_metre.max(1e-9));
        let mut dist = vec![cap; self.links.len()];
        let mut heap = std::collections::BinaryHeap::new();
        dist[i] = 0.0;
        heap.push((std::cmp::Reverse(OrdF64(0.0)), i));
        while let Some((std::cmp::Reverse(OrdF64(d)), k)) = heap.pop() {
            if d > dist[k] {
                continue;
            }
            for &(m, w) in &self.links[k] {
                let nd = d + w;
                if nd < dist[m] {
                    dist[m] = nd;
                    heap.push((std::cmp::Reverse(OrdF64(nd)), m));
                }
            }
        }
        dist
    }

    /// Tries loop closures from scan `i` onto earlier stretches of the path.
    fn try_closures(&mut self, i: usize, cp: &ClosureParams) -> Result<Vec<ClosureAttempt>> {
        let node_i = self.scans[i].node.expect("placed");
        let pose_i = self.graph.pose_se2(node_i).expect("node");
        let travel_i = self.scans[i].travel;
        let apart = self.graph_distances(i, cp);
        let mut candidates: Vec<(f64, usize)> = self
            .scans
            .iter()
            .enumerate()
            .filter(|(_, s)| s.node.is_some() && travel_i - s.travel >= cp.min_travel)
            .filter_map(|(j, s)| {
                let p = self.graph.pose_se2(s.node?)?;
                let d = (p.x - pose_i.x).hypot(p.y - pose_i.y);
                let window = self.closure_window(apart[j], cp).window_xy;
                let radius = cp.radius + (window - cp.search.window_xy);
                (d <= radius).then_some((d, j))
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut chosen: Vec<usize> = Vec::new();
        for (_, j) in candidates {
            if chosen.len() == cp.max_candidates {
                break;
            }
            if chosen.iter().all(|&c| c.abs_diff(j) > 2 * cp.neighbourhood) {
                chosen.push(j);
            }
        }
        let mut attempts = Vec::new();
        for j in chosen {
            let search = self.closure_window(apart[j], cp);
            attempts.push(self.try_closure(j, i, &pose_i, cp, &search)?);
        }
        Ok(attempts)
    }

    fn try_closure(
        &mut self,
        j: usize,
        i: usize,
        pose_i: &Se2,
        cp: &ClosureParams,
        window: &CorrelativeParams,
    ) -> Result<ClosureAttempt> {
        let node_j = self.scans[j].node.expect("placed");
        let pose_j = self.graph.pose_se2(node_j).expect("node");
        let inv_j = pose_j.inverse();
        let travel_i = self.scans[i].travel;
        let lo = j.saturating_sub(cp.neighbourhood);
        let hi = (j + cp.neighbourhood).min(self.scans.len() - 1);
        let mut pts = Vec::new();
        for s in &self.scans[lo..=hi] {
            if travel_i - s.travel < cp.min_travel / 2.0 {
                continue;
            }
            let Some(p) = s.node.and_then(|id| self.graph.pose_se2(id)) else {
                continue;
            };
            let rel = inv_j.compose(&p);
            pts.extend(s.points.iter().map(|q| transform(&rel, q)));
        }
        let pts = thin(&pts, self.params.voxel);
        let guess = inv_j.compose(pose_i);
        let mut attempt = ClosureAttempt {
            from: j,
            to: i,
            accepted: false,
            score: 0.0,
            ambiguity: 1.0,
            inlier_fraction: 0.0,
            correction_m: 0.0,
            reason: None,
            partial: false,
            corroborates: None,
            edge: None,
        };
        let Some((r, m)) = self.register(&pts, &self.scans[i].points, guess, window) else {
            attempt.reason = Some("the candidate's local map is empty".into());
            return Ok(attempt);
        };
        attempt.score = m.score;
        attempt.ambiguity = m.ambiguity();
        attempt.inlier_fraction = r.inlier_fraction();
        attempt.correction_m = (r.pose.x - guess.x).hypot(r.pose.y - guess.y);
        // A corridor: the search's near-best rivals all lie on one line through the best
        // at its heading, or the refinement holds one translation direction poorly. The
        // closure still holds the heading and the position across that direction.
        let corridor = if !cp.partial || m.score < cp.min_score {
            None
        } else if m.ambiguity() > cp.max_ambiguity {
            corridor_direction(&m, cp.max_ambiguity, window)
        } else {
            Some(r.weakest_direction())
        };
        let relaxed = RegistrationGate {
            min_weakest_translation: 0.0,
            ..cp.gate
        };
        let mut weak = None;
        attempt.reason = if m.score < cp.min_score {
            Some(format!("score {:.2} < {:.2}", m.score, cp.min_score))
        } else if m.ambiguity() > cp.max_ambiguity {
            match (corridor, relaxed.doubt(&r)) {
                (Some(u), None) => {
                    weak = Some(u);
                    None
                }
                _ => Some(format!(
                    "ambiguous: a distinct pose scores {:.0} % of the best",
                    100.0 * m.ambiguity()
                )),
            }
        } else {
            match (cp.gate.doubt(&r), corridor, relaxed.doubt(&r)) {
                (Some(_), Some(u), None) => {
                    weak = Some(u);
                    None
                }
                (doubt, _, _) => doubt,
            }
        };
        attempt.partial = weak.is_some();
        if attempt.reason.is_none() {
            let closure = Closure {
                from: j,
                to: i,
                t_from_to: r.pose,
                information: match &weak {
                    Some(u) => without_direction(&self.registration_information(&r), u),
                    None => self.registration_information(&r),
                },
                weak,
                travel: travel_i,
            };
            self.apply_or_hold(closure, &mut attempt, cp)?;
        }
        Ok(attempt)
    }

    /// A closure that passed every gate: one its kernel keeps at the current estimate is
    /// added at once; one it would down-weight (a large correction: the drift of a long
    /// loop, or a wrong match) waits until a second closure agrees with it, and the two are
    /// then solved at full weight before their kernel returns.
    fn apply_or_hold(
        &mut self,
        closure: Closure,
        attempt: &mut ClosureAttempt,
        cp: &ClosureParams,
    ) -> Result<()> {
        let chi2 = self.chi2(&closure);
        // The kernel's own weight at this error, at least a quarter (DCS: χ² ≤ 3Φ).
        if cp.kernel.rho(chi2).1 >= 0.25 {
            attempt.edge = Some(self.add_closure(&closure, cp.kernel)?);
            attempt.accepted = true;
            return Ok(());
        }
        self.held
            .retain(|h| closure.travel - h.travel <= cp.corroboration_travel);
        // Two bare corridors side by side look alike from inside, and each corridor closure
        // from one onto the other would "confirm" the last: a corridor closure confirms
        // nothing, and a held one is confirmed only by a full closure (evidence from a
        // place that tells itself apart), compared across the corridor and in heading.
        let agreeing = match closure.weak {
            Some(_) => None,
            None => self
                .held
                .iter()
                .position(|h| h.from != closure.from && self.agree(h, &closure)),
        };
        let Some(k) = agreeing else {
            attempt.reason = Some(format!(
                "large correction (chi2 {chi2:.0} at the current estimate): held until a second closure agrees"
            ));
            self.held.push(closure);
            return Ok(());
        };
        let first = self.held.remove(k);
        let e1 = self.add_closure(&first, Kernel::None)?;
        let e2 = self.add_closure(&closure, Kernel::None)?;
        self.optimise()?;
        self.graph.set_kernel(e1, cp.kernel)?;
        self.graph.set_kernel(e2, cp.kernel)?;
        attempt.edge = Some(e2);
        attempt.accepted = true;
        attempt.corroborates = Some(first.from);
        Ok(())
    }

    /// Adds a closure's edge and its graph-distance link.
    fn add_closure(&mut self, c: &Closure, kernel: Kernel) -> Result<usize> {
        let (a, b) = (
            self.scans[c.from].node.expect("placed"),
            self.scans[c.to].node.expect("placed"),
        );
        let e = self.graph.add_edge_se2(
            a,
            b,
            EdgeKind::LoopClosure,
            c.t_from_to,
            c.information,
            kernel,
        )?;
        self.links[c.from].push((c.to, 0.0));
        self.links[c.to].push((c.from, 0.0));
        Ok(e)
    }

    /// The closure's squared error at the current estimate.
    fn chi2(&self, c: &Closure) -> f64 {
        let (Some(a), Some(b)) = (self.pose_of(c.from), self.pose_of(c.to)) else {
            return f64::INFINITY;
        };
        let rel = a.inverse().compose(&b);
        let r = nalgebra::Vector3::new(
            rel.x - c.t_from_to.x,
            rel.y - c.t_from_to.y,
            crate::geometry::wrap_angle(rel.theta - c.t_from_to.theta),
        );
        (r.transpose() * c.information * r)[0]
    }

    /// Whether two held closures tell the same story: the pose of `b.to` they imply (via
    /// `a`, then the current estimate from `a.to` to `b.to`; and via `b`) agree within
    /// 0.3 m and 3° plus the drift of the path between the two new scans.
    fn agree(&self, a: &Closure, b: &Closure) -> bool {
        let poses = (
            self.pose_of(a.from),
            self.pose_of(a.to),
            self.pose_of(b.from),
            self.pose_of(b.to),
        );
        let (Some(af), Some(at), Some(bf), Some(bt)) = poses else {
            return false;
        };
        let via_a = af.compose(&a.t_from_to).compose(&at.inverse().compose(&bt));
        let via_b = bf.compose(&b.t_from_to);
        let path = (b.travel - a.travel).abs();
        // A held corridor closure says nothing along its corridor: compare across it.
        let mut d = Vector2::new(via_a.x - via_b.x, via_a.y - via_b.y);
        if let Some(u) = a.weak {
            let u = transform(&Se2::new(0.0, 0.0, af.theta), &u);
            d -= u * u.dot(&d);
        }
        let dxy = d.norm();
        let dth = crate::geometry::wrap_angle(via_a.theta - via_b.theta)
            .abs()
            .to_degrees();
        dxy <= 0.3 + 0.05 * path && dth <= 3.0 + 0.5 * path
    }

    /// Adds a loop-closure edge `T_from_to` by hand, with the information and kernel the
    /// accepted closures get (the first accepted full closure's information, not a
    /// corridor closure's; `None` when no full closure was accepted yet). For robustness
    /// tests: a wrong closure injected this way must be down-weighted by the kernel at the
    /// next solve.
    pub fn add_closure_edge(
        &mut self,
        from: usize,
        to: usize,
        t_from_to: Se2,
    ) -> Result<Option<usize>> {
        let Some(cp) = self.params.closure else {
            return Ok(None);
        };
        let info = self
            .graph
            .edges()
            .iter()
            .find_map(|e| match (e.kind, e.measurement) {
                (EdgeKind::LoopClosure, crate::graph::Measurement::Se2 { information, .. })
                    if !is_partial(&information) =>
                {
                    Some(information)
                }
                _ => None,
            });
        let (Some(info), Some(a), Some(b)) = (info, self.scans[from].node, self.scans[to].node)
        else {
            return Ok(None);
        };
        Ok(Some(self.graph.add_edge_se2(
            a,
            b,
            EdgeKind::LoopClosure,
            t_from_to,
            info,
            cp.kernel,
        )?))
    }

    /// The current pose of scan `index`, if placed.
    pub fn pose_of(&self, index: usize) -> Option<Se2> {
        self.graph.pose_se2(self.scans.get(index)?.node?)
    }

    /// Edge counts by kind.
    pub fn edge_counts(&self) -> BTreeMap<EdgeKind, usize> {
        self.graph.edge_counts()
    }

    /// The scan index of a graph node.
    pub fn scan_of_node(&self, node: u64) -> Option<usize> {
        self.node_to_scan.get(&node).copied()
    }
}

fn solve_params() -> SolveParams {
    SolveParams {
        max_iterations: 30,
        init: Init::None,
        function_tolerance: 1e-9,
        ..Default::default()
    }
}

/// An `f64` ordered by `total_cmp`, for the graph-distance heap.
#[derive(Clone, Copy, PartialEq)]
struct OrdF64(f64);

impl Eq for OrdF64 {}

impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// The step of a registration that holds all but its weakest translation direction `u`:
/// the registration's heading and translation across `u`, the odometry's along `u`; and `u`.
fn partial_step(r: &PlanarIcpResult, odometry: &Se2) -> (Se2, Vector2<f64>) {
    let u = r.weakest_direction();
    let t = Vector2::new(r.pose.x, r.pose.y);
    let along = (Vector2::new(odometry.x, odometry.y) - t).dot(&u);
    let t = t + u * along;
    (Se2::new(t.x, t.y, r.pose.theta), u)
}

/// The direction of a corridor from a correlative search's near-best rivals (those above
/// `max_ambiguity` of the best): `Some(u)` when they all lie on one line through the best
/// pose at its heading (within one and a half search steps), `None` when any stands off
/// that line or turned, or when there are none.
fn corridor_direction(
    m: &CorrelativeMatch,
    max_ambiguity: f64,
    window: &CorrelativeParams,
) -> Option<Vector2<f64>> {
    let near: Vec<(Vector2<f64>, f64)> = m
        .rivals
        .iter()
        .filter(|(_, v)| *v > max_ambiguity * m.score)
        .map(|(p, _)| {
            (
                Vector2::new(p.x - m.pose.x, p.y - m.pose.y),
                crate::geometry::wrap_angle(p.theta - m.pose.theta).to_degrees(),
            )
        })
        .collect();
    let far = near
        .iter()
        .max_by(|a, b| a.0.norm_squared().total_cmp(&b.0.norm_squared()))?;
    if far.0.norm() <= window.distinct_xy {
        return None;
    }
    let u = far.0.normalize();
    let cross_tol = 1.5 * window.step_xy + 0.05;
    let yaw_tol = 1.5 * window.step_yaw_deg + 0.5;
    near.iter()
        .all(|(d, yaw)| (d.x * u.y - d.y * u.x).abs() <= cross_tol && yaw.abs() <= yaw_tol)
        .then_some(u)
}

/// `info` with nothing left along the translation direction `u` (the projection
/// `P·info·P`, `P = I − [u 0][u 0]ᵀ`).
fn without_direction(info: &Matrix3<f64>, u: &Vector2<f64>) -> Matrix3<f64> {
    let w = nalgebra::Vector3::new(u.x, u.y, 0.0);
    let p = Matrix3::identity() - w * w.transpose();
    symmetric(p * info * p)
}

/// Whether an edge's information holds nothing along some translation direction (a
/// corridor closure's, [`without_direction`]).
fn is_partial(info: &Matrix3<f64>) -> bool {
    let t: nalgebra::Matrix2<f64> = info.fixed_view::<2, 2>(0, 0).into_owned();
    let e = t.symmetric_eigenvalues();
    e.min() <= 1e-9 * e.max().abs().max(f64::MIN_POSITIVE)
}

fn symmetric(m: Matrix3<f64>) -> Matrix3<f64> {
    (m + m.transpose()) * 0.5
}

fn transform(pose: &Se2, p: &Vector2<f64>) -> Vector2<f64> {
    let (s, c) = pose.theta.sin_cos();
    Vector2::new(c * p.x - s * p.y + pose.x, s * p.x + c * p.y + pose.y)
}

/// One point per occupied `voxel` cell (the first one met), order kept.
pub fn thin(points: &[Vector2<f64>], voxel: f64) -> Vec<Vector2<f64>> {
    if voxel <= 0.0 {
        return points.to_vec();
    }
    let mut seen = rustc_hash::FxHashSet::default();
    points
        .iter()
        .filter(|p| seen.insert(((p.x / voxel).floor() as i64, (p.y / voxel).floor() as i64)))
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_corridor_edge_keeps_no_information_along_the_corridor() {
        // A registration in a corridor along (1, 1)/√2: strong across, weak along,
        // correlated with heading across.
        let along = Vector2::new(1.0, 1.0) / 2f64.sqrt();
        let across = Vector2::new(-along.y, along.x);
        let a = nalgebra::Vector3::new(across.x, across.y, 0.0);
        let l = nalgebra::Vector3::new(along.x, along.y, 0.0);
        let h = a * a.transpose() * 400.0
            + l * l.transpose() * 3.0
            + Matrix3::new(0.0, 0.0, 5.0, 0.0, 0.0, 5.0, 5.0, 5.0, 90.0);
        let p = without_direction(&h, &along);
        // Nothing along the corridor, in translation or coupled with heading …
        assert!((p * l).norm() < 1e-9, "{p}");
        // … and everything across and in heading kept.
        assert!(((a.transpose() * p * a)[0] - (a.transpose() * h * a)[0]).abs() < 1e-9);
        assert!((p[(2, 2)] - h[(2, 2)]).abs() < 1e-9);
    }

    #[test]
    fn a_corridor_is_told_from_a_repeated_place_by_where_the_rivals_lie() {
        let window = CorrelativeParams {
            step_xy: 0.1,
            step_yaw_deg: 1.0,
            ..CorrelativeParams::default()
        };
        let best = Se2::new(2.0, 1.0, 0.3);
        let along = Vector2::new(0.6, 0.8);
        let m = |rivals: Vec<(Se2, f64)>| CorrelativeMatch {
            pose: best,
            score: 0.9,
            runner_up: rivals.iter().map(|r| r.1).fold(0.0, f64::max),
            rivals,
        };
        let at = |s: f64, across: f64, dyaw_deg: f64| {
            Se2::new(
                best.x + s * along.x - across * along.y,
                best.y + s * along.y + across * along.x,
                best.theta + dyaw_deg.to_radians(),
            )
        };
        // Rivals 1.5 m and 3 m either way along one line, within a step of it: a corridor.
        let corridor = m(vec![
            (at(1.5, 0.05, 0.0), 0.88),
            (at(-3.0, -0.1, 1.0), 0.87),
            (at(3.0, 0.0, 0.0), 0.86),
        ]);
        let u = corridor_direction(&corridor, 0.85, &window).expect("a corridor");
        assert!(u.dot(&along).abs() > 0.999, "{u}");
        // A weak rival off the line does not count (below the ambiguity) …
        let mut weak_off = corridor.clone();
        weak_off.rivals.push((at(1.0, 2.0, 0.0), 0.70));
        assert!(corridor_direction(&weak_off, 0.85, &window).is_some());
        // … a strong one does: a second place, not a corridor.
        let mut off = corridor.clone();
        off.rivals.push((at(1.0, 2.0, 0.0), 0.80));
        assert!(corridor_direction(&off, 0.85, &window).is_none());
        // A rival on the line but turned 6°: not the same corridor view.
        let turned = m(vec![(at(2.0, 0.0, 6.0), 0.88)]);
        assert!(corridor_direction(&turned, 0.85, &window).is_none());
        // Only a rival in heading (no translation along anything): not a corridor.
        let spun = m(vec![(at(0.1, 0.0, 8.0), 0.88)]);
        assert!(corridor_direction(&spun, 0.85, &window).is_none());
    }

    #[test]
    fn graph_distances_count_travel_and_nothing_across_closures() {
        let mut m = PlanarMapper::new(PlanarMapParams::default());
        // A chain 0-1-2-3-4 with 2 m steps, and a closure 4-0.
        m.links = vec![
            vec![(1, 2.0)],
            vec![(0, 2.0), (2, 2.0)],
            vec![(1, 2.0), (3, 2.0)],
            vec![(2, 2.0), (4, 2.0)],
            vec![(3, 2.0)],
        ];
        let cp = ClosureParams::default();
        let d = m.graph_distances(4, &cp);
        assert_eq!(d, vec![8.0, 6.0, 4.0, 2.0, 0.0]);
        m.links[4].push((0, 0.0));
        m.links[0].push((4, 0.0));
        let d = m.graph_distances(4, &cp);
        assert_eq!(d, vec![0.0, 2.0, 4.0, 2.0, 0.0]);
    }
}
