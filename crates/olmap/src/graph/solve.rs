//! The solver: sparse Levenberg-Marquardt on the manifold, with an optional chordal
//! initialisation and robust kernels (iteratively reweighted), and its report.
//!
//! Each iteration linearises every edge at the current estimate (analytic Jacobians,
//! right perturbation: see `lie.rs`), builds the normal equations `H d = -g` with the
//! kernel weights `rho'(chi2)`, damps them as Ceres does (`H + lambda diag(H)`, the
//! diagonal clamped to [1e-6, 1e32]) and solves them with the block Cholesky of
//! `sparse.rs` (minimum-degree ordering, computed once per graph structure). A step
//! is kept when it lowers the robust cost `1/2 sum rho(chi2)`; lambda follows Nielsen's
//! rule (with a decrease of up to 10x per good step). Linearisation runs on the rayon pool with results collected in edge order, and
//! every sum runs in a fixed order: the result does not depend on the thread count.

use std::time::Instant;

use nalgebra::{Matrix3, Matrix6, SMatrix, SVector, Vector2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::init::{chordal, Chordal, InitEdge};
use super::lie::{Group, S2, S3};
use super::model::{
    EdgeKind, Kernel, Measurement, NodeId, NodePose, PoseGraph, Se2, Space, OUTLIER_WEIGHT,
};
use super::sparse::{BlockMatrix, Factor, Symbolic};
use crate::error::{Error, Result};
use crate::geometry::Pose;

/// How the solver finds its starting point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Init {
    /// Start from the nodes' current poses (a warm start: the previous solution plus the
    /// new nodes' guesses).
    None,
    /// Replace the free nodes' poses by the chordal estimate first (rotations, then
    /// positions; `init.rs`). Needed on graphs such as sphere2500 when starting from
    /// odometry. When some edges have no robust kernel and those alone connect the graph,
    /// only they are used (robust edges may be wrong).
    Chordal,
}

/// Parameters of [`PoseGraph::optimise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveParams {
    /// Most Levenberg-Marquardt iterations (linearisations).
    pub max_iterations: usize,
    /// Starting point.
    pub init: Init,
    /// Stop when an accepted step lowers the cost by less than this fraction of it.
    pub function_tolerance: f64,
    /// Stop when the largest gradient entry is below this.
    pub gradient_tolerance: f64,
    /// Stop when the step (all free nodes' tangent steps as one vector) is shorter than
    /// this.
    pub step_tolerance: f64,
}

impl Default for SolveParams {
    fn default() -> Self {
        SolveParams {
            max_iterations: 100,
            init: Init::None,
            function_tolerance: 1e-12,
            gradient_tolerance: 1e-10,
            step_tolerance: 1e-12,
        }
    }
}

/// One edge after a solve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EdgeReport {
    /// The edge's index in [`PoseGraph::edges`].
    pub index: usize,
    /// Node i.
    pub from: NodeId,
    /// Node j.
    pub to: NodeId,
    /// The edge's kind.
    pub kind: EdgeKind,
    /// The edge's kernel name.
    pub kernel: String,
    /// The final residual (translation first, then rotation; see [`super::cost`]).
    pub residual: Vec<f64>,
    /// `r^T Omega r` at the solution.
    pub chi2: f64,
    /// The kernel's weight `rho'(chi2)` at the solution (1 without kernel).
    pub weight: f64,
    /// The kernel down-weighted the edge as an outlier (`weight < 0.5`).
    pub down_weighted: bool,
}

/// What [`PoseGraph::optimise`] did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolveReport {
    /// Planar or spatial.
    pub space: Space,
    /// Nodes in the graph.
    pub nodes: usize,
    /// Edges in the graph.
    pub edges: usize,
    /// Nodes the solver moved.
    pub free_nodes: usize,
    /// Nodes held because their connected part of the graph had no fixed node (the first
    /// node added of each such part).
    pub gauge_nodes: Vec<NodeId>,
    /// The initialisation asked for.
    pub init: Init,
    /// Whether the initialisation succeeded (false: its linear system was singular and the
    /// solve started from the given poses).
    pub init_applied: bool,
    /// The solver's cost `1/2 sum rho(chi2)` at the given poses.
    pub initial_cost: f64,
    /// The solver's cost after the initialisation.
    pub initialised_cost: f64,
    /// The solver's cost at the solution.
    pub final_cost: f64,
    /// Linearisations done.
    pub iterations: usize,
    /// Whether a convergence test was met (otherwise the iteration limit or a stall).
    pub converged: bool,
    /// Why the solver stopped.
    pub termination: String,
    /// Off-diagonal blocks of the Cholesky factor (fill-in measure).
    pub factor_blocks: usize,
    /// Wall-clock time of the solve, seconds.
    pub seconds: f64,
    /// Every edge at the solution.
    pub edge_reports: Vec<EdgeReport>,
}

impl SolveReport {
    /// The edges the robust kernels down-weighted as outliers.
    pub fn down_weighted(&self) -> impl Iterator<Item = &EdgeReport> {
        self.edge_reports.iter().filter(|e| e.down_weighted)
    }
}

/// A solver state that can be read from and written to a graph's nodes and edges.
trait GraphState<const D: usize, const R: usize>: Group<D> + Chordal<R> {
    fn from_node(p: &NodePose) -> Self;
    fn to_node(&self) -> NodePose;
    fn from_measurement(m: &Measurement) -> (Self, SMatrix<f64, D, D>);
}

impl GraphState<6, 3> for S3 {
    fn from_node(p: &NodePose) -> S3 {
        let p = p.to_pose();
        S3 {
            p: p.translation(),
            q: p.rotation(),
        }
    }
    fn to_node(&self) -> NodePose {
        NodePose::Se3(Pose::from_parts(self.p, self.q))
    }
    fn from_measurement(m: &Measurement) -> (S3, Matrix6<f64>) {
        match m {
            Measurement::Se3 { t_i_j, information } => (
                S3 {
                    p: t_i_j.translation(),
                    q: t_i_j.rotation(),
                },
                *information,
            ),
            Measurement::Se2 { t_i_j, information } => {
                // Not reached: a graph holds one space (checked when edges are added).
                let mut info = Matrix6::identity();
                info.fixed_view_mut::<2, 2>(0, 0)
                    .copy_from(&information.fixed_view::<2, 2>(0, 0));
                let p = t_i_j.to_pose();
                (
                    S3 {
                        p: p.translation(),
                        q: p.rotation(),
                    },
                    info,
                )
            }
        }
    }
}

impl GraphState<3, 2> for S2 {
    fn from_node(p: &NodePose) -> S2 {
        match p {
            NodePose::Se2(p) => S2 {
                p: Vector2::new(p.x, p.y),
                th: p.theta,
            },
            NodePose::Se3(p) => {
                let t = p.translation();
                S2 {
                    p: Vector2::new(t.x, t.y),
                    th: p.yaw_pitch_roll().0,
                }
            }
        }
    }
    fn to_node(&self) -> NodePose {
        NodePose::Se2(Se2::new(self.p.x, self.p.y, self.th))
    }
    fn from_measurement(m: &Measurement) -> (S2, Matrix3<f64>) {
        match m {
            Measurement::Se2 { t_i_j, information } => (
                S2 {
                    p: Vector2::new(t_i_j.x, t_i_j.y),
                    th: t_i_j.theta,
                },
                *information,
            ),
            Measurement::Se3 { t_i_j, .. } => {
                // Not reached: a graph holds one space (checked when edges are added).
                let t = t_i_j.translation();
                (
                    S2 {
                        p: Vector2::new(t.x, t.y),
                        th: t_i_j.yaw_pitch_roll().0,
                    },
                    Matrix3::identity(),
                )
            }
        }
    }
}

/// An edge in the solver's terms: node indices, measurement, information, kernel.
struct SEdge<const D: usize, G> {
    i: usize,
    j: usize,
    m: G,
    info: SMatrix<f64, D, D>,
    kernel: Kernel,
}

impl PoseGraph {
    /// Optimises the free nodes' poses (in place) and reports the outcome. The solve
    /// starts from the current poses (after the chordal initialisation when
    /// `params.init` asks for it). Fixed nodes hold the gauge; a connected part without one
    /// is held by its first-added node (named in [`SolveReport::gauge_nodes`]).
    ///
    /// A solve that stops at the iteration limit still writes its best estimate and says so
    /// in [`SolveReport::converged`]. Errors: [`Error::EmptyInput`] for a graph without
    /// nodes, [`Error::InvalidArgument`] for bad parameters.
    pub fn optimise(&mut self, params: &SolveParams) -> Result<SolveReport> {
        if self.nodes().is_empty() {
            return Err(Error::EmptyInput {
                what: "pose graph without nodes".into(),
            });
        }
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        if !(ok(params.function_tolerance)
            && ok(params.gradient_tolerance)
            && ok(params.step_tolerance))
        {
            return Err(Error::InvalidArgument(
                "solver tolerances must be finite and non-negative".into(),
            ));
        }
        match self.space() {
            Space::Se2 => solve::<3, 2, S2>(self, params),
            Space::Se3 => solve::<6, 3, S3>(self, params),
        }
    }
}

impl PoseGraph {
    /// Replaces the free nodes' poses by an initial estimate (nothing for [`Init::None`]);
    /// returns whether it was applied (false: its linear system was singular, poses
    /// unchanged). [`PoseGraph::optimise`] does this itself when asked; this is for a
    /// caller that wants to look at the initial estimate.
    pub fn initialise(&mut self, init: Init) -> Result<bool> {
        if self.nodes().is_empty() {
            return Err(Error::EmptyInput {
                what: "pose graph without nodes".into(),
            });
        }
        Ok(match (init, self.space()) {
            (Init::None, _) => false,
            (Init::Chordal, Space::Se2) => initialise::<3, 2, S2>(self),
            (Init::Chordal, Space::Se3) => initialise::<6, 3, S3>(self),
        })
    }
}

/// Marks one node per connected part without a fixed node as held; returns those nodes.
fn gauge(n: usize, fixed: &[bool], pairs: &[(usize, usize)]) -> (Vec<bool>, Vec<usize>) {
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    for &(i, j) in pairs {
        let (a, b) = (find(&mut parent, i), find(&mut parent, j));
        if a != b {
            // The smaller index becomes the root: the root is each part's first node.
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut part_fixed = vec![false; n];
    for (v, _) in fixed.iter().enumerate().filter(|(_, f)| **f) {
        let r = find(&mut parent, v);
        part_fixed[r] = true;
    }
    let mut held = fixed.to_vec();
    let mut gauges = Vec::new();
    for v in 0..n {
        let r = find(&mut parent, v);
        if r == v && !part_fixed[v] {
            held[v] = true;
            gauges.push(v);
        }
    }
    (held, gauges)
}

/// Number of connected parts.
fn parts(n: usize, pairs: impl Iterator<Item = (usize, usize)>) -> usize {
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let mut count = n;
    for (i, j) in pairs {
        let (a, b) = (find(&mut parent, i), find(&mut parent, j));
        if a != b {
            parent[a.max(b)] = a.min(b);
            count -= 1;
        }
    }
    count
}

/// Runs the chordal initialisation on the free states; false when it could not.
fn initialise_states<const D: usize, const R: usize, G: GraphState<D, R>>(
    states: &mut [G],
    held: &[bool],
    edges: &[SEdge<D, G>],
) -> bool {
    let n = states.len();
    let plain: Vec<&SEdge<D, G>> = edges.iter().filter(|e| e.kernel == Kernel::None).collect();
    let all_parts = parts(n, edges.iter().map(|e| (e.i, e.j)));
    let use_plain = !plain.is_empty() && parts(n, plain.iter().map(|e| (e.i, e.j))) == all_parts;
    let chosen: Vec<&SEdge<D, G>> = if use_plain {
        plain
    } else {
        edges.iter().collect()
    };
    let init_edges: Vec<InitEdge<R>> = chosen
        .iter()
        .map(|e| {
            let mut w_rot = 0.0;
            for k in R..D {
                w_rot += e.info[(k, k)];
            }
            InitEdge {
                i: e.i,
                j: e.j,
                r_ij: e.m.rotation(),
                t_ij: e.m.translation(),
                w_rot: w_rot / (D - R) as f64,
                info_t: e.info.fixed_view::<R, R>(0, 0).into_owned(),
            }
        })
        .collect();
    chordal::<R, G>(states, held, &init_edges)
}

/// The solver's view of a graph: states, fixed flags, edges, held nodes and gauges.
type Prepared<const D: usize, G> = (Vec<G>, Vec<bool>, Vec<SEdge<D, G>>, Vec<bool>, Vec<usize>);

fn prepare<const D: usize, const R: usize, G: GraphState<D, R>>(
    graph: &PoseGraph,
) -> Prepared<D, G> {
    let n = graph.nodes().len();
    let states: Vec<G> = graph
        .nodes()
        .iter()
        .map(|nd| G::from_node(&nd.pose))
        .collect();
    let fixed: Vec<bool> = graph.nodes().iter().map(|nd| nd.fixed).collect();
    let edges: Vec<SEdge<D, G>> = graph
        .edges()
        .iter()
        .map(|e| {
            let (m, info) = G::from_measurement(&e.measurement);
            SEdge {
                i: graph.node_index(e.from).expect("checked when added"),
                j: graph.node_index(e.to).expect("checked when added"),
                m,
                info,
                kernel: e.kernel,
            }
        })
        .collect();
    let pairs: Vec<(usize, usize)> = edges.iter().map(|e| (e.i, e.j)).collect();
    let (held, gauges) = gauge(n, &fixed, &pairs);
    (states, fixed, edges, held, gauges)
}

fn write_back<const D: usize, const R: usize, G: GraphState<D, R>>(
    graph: &mut PoseGraph,
    states: &[G],
) {
    for (node, s) in graph.nodes_mut().iter_mut().zip(states) {
        if !node.fixed {
            node.pose = s.to_node();
        }
    }
}

fn initialise<const D: usize, const R: usize, G: GraphState<D, R>>(graph: &mut PoseGraph) -> bool {
    let (mut states, _, edges, held, _) = prepare::<D, R, G>(graph);
    let ok = initialise_states(&mut states, &held, &edges);
    if ok {
        write_back::<D, R, G>(graph, &states);
    }
    ok
}

fn edge_cost<const D: usize, G: Group<D>>(e: &SEdge<D, G>, states: &[G]) -> f64 {
    let r = G::residual(&states[e.i], &states[e.j], &e.m);
    let chi2 = (r.transpose() * e.info * r)[0].max(0.0);
    e.kernel.rho(chi2).0
}

fn total_cost<const D: usize, G: Group<D>>(edges: &[SEdge<D, G>], states: &[G]) -> f64 {
    let per_edge: Vec<f64> = edges.par_iter().map(|e| edge_cost(e, states)).collect();
    0.5 * per_edge.iter().sum::<f64>()
}

fn solve<const D: usize, const R: usize, G: GraphState<D, R>>(
    graph: &mut PoseGraph,
    params: &SolveParams,
) -> Result<SolveReport> {
    let start = Instant::now();
    let n = graph.nodes().len();
    let (mut states, _, edges, held, gauges) = prepare::<D, R, G>(graph);
    let initial_cost = total_cost(&edges, &states);
    let init_applied =
        params.init == Init::Chordal && initialise_states(&mut states, &held, &edges);
    let initialised_cost = total_cost(&edges, &states);

    let outcome = levenberg_marquardt(&mut states, &held, &edges, params);
    write_back::<D, R, G>(graph, &states);
    let edge_reports = graph
        .edges()
        .iter()
        .zip(&edges)
        .enumerate()
        .map(|(index, (e, se))| {
            let r = G::residual(&states[se.i], &states[se.j], &se.m);
            let chi2 = (r.transpose() * se.info * r)[0].max(0.0);
            let weight = se.kernel.rho(chi2).1;
            EdgeReport {
                index,
                from: e.from,
                to: e.to,
                kind: e.kind,
                kernel: e.kernel.name().to_string(),
                residual: r.iter().copied().collect(),
                chi2,
                weight,
                down_weighted: weight < OUTLIER_WEIGHT,
            }
        })
        .collect();
    Ok(SolveReport {
        space: graph.space(),
        nodes: n,
        edges: edges.len(),
        free_nodes: held.iter().filter(|h| !**h).count(),
        gauge_nodes: gauges.iter().map(|&v| graph.nodes()[v].id).collect(),
        init: params.init,
        init_applied,
        initial_cost,
        initialised_cost,
        final_cost: outcome.cost,
        iterations: outcome.iterations,
        converged: outcome.converged,
        termination: outcome.termination.to_string(),
        factor_blocks: outcome.factor_blocks,
        seconds: start.elapsed().as_secs_f64(),
        edge_reports,
    })
}

struct Outcome {
    cost: f64,
    iterations: usize,
    converged: bool,
    termination: &'static str,
    factor_blocks: usize,
}

/// One edge linearised: its blocks of `H` and `g` (already weighted).
struct Linearised<const D: usize> {
    hii: SMatrix<f64, D, D>,
    hjj: SMatrix<f64, D, D>,
    hij: SMatrix<f64, D, D>,
    gi: SVector<f64, D>,
    gj: SVector<f64, D>,
}

fn levenberg_marquardt<const D: usize, G: Group<D>>(
    states: &mut [G],
    held: &[bool],
    edges: &[SEdge<D, G>],
    params: &SolveParams,
) -> Outcome {
    let n = states.len();
    let mut var = vec![usize::MAX; n];
    let mut free = Vec::new();
    for v in 0..n {
        if !held[v] {
            var[v] = free.len();
            free.push(v);
        }
    }
    let mut cost = total_cost(edges, states);
    let done = |cost, iterations, converged, termination, blocks| Outcome {
        cost,
        iterations,
        converged,
        termination,
        factor_blocks: blocks,
    };
    if free.is_empty() || edges.is_empty() {
        return done(cost, 0, true, "nothing to optimise", 0);
    }
    let sym = Symbolic::new(
        free.len(),
        edges
            .iter()
            .filter(|e| !held[e.i] && !held[e.j])
            .map(|e| (var[e.i], var[e.j])),
    );
    let slots: Vec<Option<(usize, bool)>> = edges
        .iter()
        .map(|e| {
            if held[e.i] || held[e.j] {
                None
            } else {
                sym.slot(var[e.i], var[e.j])
            }
        })
        .collect();
    let blocks = sym.off_diagonal_blocks();
    let mut h = BlockMatrix::<D>::zeros(&sym);
    let mut g = vec![SVector::<f64, D>::zeros(); free.len()];
    // Start close to Gauss-Newton: from a good initial estimate (chordal, or the previous
    // solution) full steps are what converges fastest; a failed step raises lambda.
    let mut lambda = 1e-6;
    let mut nu = 2.0;
    let mut iterations = 0;
    while iterations < params.max_iterations {
        iterations += 1;
        // Linearise (in parallel, collected in edge order) and assemble (in order).
        let lin: Vec<Linearised<D>> = edges
            .par_iter()
            .map(|e| {
                let (r, ji, jj) = G::linearize(&states[e.i], &states[e.j], &e.m);
                let chi2 = (r.transpose() * e.info * r)[0].max(0.0);
                let w = e.kernel.rho(chi2).1;
                let wi = e.info * w;
                let ji_t_w = ji.transpose() * wi;
                let jj_t_w = jj.transpose() * wi;
                Linearised {
                    hii: ji_t_w * ji,
                    hjj: jj_t_w * jj,
                    hij: ji_t_w * jj,
                    gi: ji_t_w * r,
                    gj: jj_t_w * r,
                }
            })
            .collect();
        h.clear();
        g.iter_mut().for_each(|v| v.fill(0.0));
        for ((e, l), slot) in edges.iter().zip(&lin).zip(&slots) {
            if !held[e.i] {
                h.add_diag(&sym, var[e.i], &l.hii);
                g[var[e.i]] += l.gi;
            }
            if !held[e.j] {
                h.add_diag(&sym, var[e.j], &l.hjj);
                g[var[e.j]] += l.gj;
            }
            if let Some(slot) = slot {
                h.add_off(*slot, &l.hij);
            }
        }
        let gmax = g.iter().map(|v| v.amax()).fold(0.0, f64::max);
        if gmax <= params.gradient_tolerance {
            return done(cost, iterations, true, "gradient tolerance", blocks);
        }
        // Try steps until one lowers the cost.
        loop {
            let mut a = h.clone();
            let mut dscale = Vec::with_capacity(free.len());
            for (k, dblock) in a.diag.iter_mut().enumerate() {
                let hk = h.diag[k];
                let mut s = SVector::<f64, D>::zeros();
                for d in 0..D {
                    s[d] = hk[(d, d)].clamp(1e-6, 1e32);
                    dblock[(d, d)] += lambda * s[d];
                }
                dscale.push(s);
            }
            let neg_g: Vec<SMatrix<f64, D, 1>> = g.iter().map(|v| -v).collect();
            let step = Factor::new(&sym, a).map(|f| f.solve(&sym, &neg_g));
            let Some(step) = step else {
                lambda *= nu;
                nu *= 2.0;
                if lambda > 1e32 {
                    return done(cost, iterations, false, "not positive definite", blocks);
                }
                continue;
            };
            // dscale is indexed by position; step by variable.
            let mut pred = 0.0;
            let mut step_norm2 = 0.0;
            for (v, d) in step.iter().enumerate() {
                let s = dscale[sym.position[v]];
                for k in 0..D {
                    pred += d[k] * (lambda * s[k] * d[k] - g[v][k]);
                }
                step_norm2 += d.norm_squared();
            }
            pred *= 0.5;
            if step_norm2.sqrt() <= params.step_tolerance {
                return done(cost, iterations, true, "step tolerance", blocks);
            }
            let mut trial: Vec<G> = states.to_vec();
            for (k, &v) in free.iter().enumerate() {
                trial[v] = states[v].retract(&step[k]);
            }
            let new_cost = total_cost(edges, &trial);
            let rho = if pred > 0.0 {
                (cost - new_cost) / pred
            } else {
                -1.0
            };
            if rho > 0.0 && new_cost.is_finite() {
                let decrease = cost - new_cost;
                states.copy_from_slice(&trial);
                cost = new_cost;
                lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(0.1);
                lambda = lambda.max(1e-16);
                nu = 2.0;
                if decrease <= params.function_tolerance * cost.max(f64::MIN_POSITIVE) {
                    return done(cost, iterations, true, "function tolerance", blocks);
                }
                break;
            }
            lambda *= nu;
            nu *= 2.0;
            if lambda > 1e32 {
                return done(cost, iterations, false, "no further decrease", blocks);
            }
        }
    }
    done(cost, iterations, false, "iteration limit", blocks)
}
