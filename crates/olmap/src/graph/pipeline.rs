//! The `olmap graph` pipelines: optimise a g2o file ([`run_graph_optimise`]) and describe
//! one ([`describe_g2o`]), with their typed reports.

use std::path::PathBuf;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::cost::{cost, CostConvention};
use super::g2o::{read_g2o, write_g2o};
use super::model::{EdgeKind, Kernel, Space};
use super::solve::{Init, SolveParams};
use crate::error::{Error, Result};

/// What `olmap graph optimise` does.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphOptimiseJob {
    /// The g2o file to read.
    pub input: PathBuf,
    /// The g2o file to write the optimised graph to (atomically).
    pub output: PathBuf,
    /// Solver parameters (iterations, initialisation).
    pub params: SolveParams,
    /// A kernel for every edge (`None`: keep the file's, i.e. plain least squares).
    pub kernel: Option<Kernel>,
    /// The convention of the reported `initial_cost` and `final_cost`.
    pub convention: CostConvention,
}

/// An edge the robust kernel down-weighted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DownWeightedEdge {
    /// The edge's position in the file (0 = first edge line).
    pub index: usize,
    /// Vertex i.
    pub from: u64,
    /// Vertex j.
    pub to: u64,
    /// `r^T Omega r` at the solution.
    pub chi2: f64,
    /// The kernel's weight at the solution.
    pub weight: f64,
}

/// The report of `olmap graph optimise --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GraphOptimiseReport {
    /// The file read.
    pub input: String,
    /// The file written.
    pub output: String,
    /// `se2` or `se3`.
    pub space: Space,
    /// Vertices.
    pub nodes: usize,
    /// Edges.
    pub edges: usize,
    /// Vertices fixed by the file.
    pub fixed_nodes: usize,
    /// Vertices held as the gauge of a connected part without a fixed vertex.
    pub gauge_nodes: Vec<u64>,
    /// The convention of `initial_cost` and `final_cost` (see [`super::cost`]).
    pub cost_convention: CostConvention,
    /// `1/2 sum r^T Omega r` at the file's poses, in `cost_convention` (no kernel).
    pub initial_cost: f64,
    /// The same at the written poses.
    pub final_cost: f64,
    /// The starting point used (`none` or `chordal`).
    pub init: Init,
    /// The cost after the initialisation, in `cost_convention`.
    pub initialised_cost: f64,
    /// The kernel applied to every edge (`none`, `huber`, `cauchy`, `dcs`).
    pub kernel: String,
    /// The kernel's width, chi2 units (0 without kernel).
    pub kernel_width: f64,
    /// The robust cost the solver minimised (its own convention, [`CostConvention::Log`]
    /// with kernels), at the solution.
    pub solver_final_cost: f64,
    /// Levenberg-Marquardt iterations.
    pub iterations: usize,
    /// Whether a convergence test was met.
    pub converged: bool,
    /// Why the solver stopped.
    pub termination: String,
    /// Off-diagonal blocks of the Cholesky factor (fill-in).
    pub factor_blocks: usize,
    /// Solve time (initialisation and iterations; cost evaluations included), seconds.
    pub seconds: f64,
    /// Read, solve and write, seconds.
    pub total_seconds: f64,
    /// Edges the kernel down-weighted as outliers (weight < 0.5).
    pub down_weighted_edges: Vec<DownWeightedEdge>,
}

/// Reads `job.input`, optimises it, writes `job.output` and reports costs in
/// `job.convention` before and after. The output must end in `.g2o`.
pub fn run_graph_optimise(job: &GraphOptimiseJob) -> Result<GraphOptimiseReport> {
    let start = Instant::now();
    if job.output.extension().and_then(|e| e.to_str()) != Some("g2o") {
        return Err(Error::InvalidArgument(format!(
            "{}: the output must be a .g2o file",
            job.output.display()
        )));
    }
    let mut graph = read_g2o(&job.input)?;
    if let Some(k) = job.kernel {
        graph.set_kernel_all(k)?;
    }
    let solve_start = Instant::now();
    let initial_cost = cost(&graph, job.convention);
    let fixed_nodes = graph.nodes().iter().filter(|n| n.fixed).count();
    graph.initialise(job.params.init)?;
    let initialised_cost = cost(&graph, job.convention);
    let solve = graph.optimise(&SolveParams {
        init: Init::None,
        ..job.params
    })?;
    let seconds = solve_start.elapsed().as_secs_f64();
    let final_cost = cost(&graph, job.convention);
    write_g2o(&job.output, &graph)?;
    let (kernel, kernel_width) = match job.kernel.unwrap_or(Kernel::None) {
        Kernel::None => ("none", 0.0),
        k @ (Kernel::Huber(w) | Kernel::Cauchy(w) | Kernel::Dcs(w)) => (k.name(), w),
    };
    Ok(GraphOptimiseReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        space: graph.space(),
        nodes: solve.nodes,
        edges: solve.edges,
        fixed_nodes,
        gauge_nodes: solve.gauge_nodes.clone(),
        cost_convention: job.convention,
        initial_cost,
        final_cost,
        init: job.params.init,
        initialised_cost,
        kernel: kernel.to_string(),
        kernel_width,
        solver_final_cost: solve.final_cost,
        iterations: solve.iterations,
        converged: solve.converged,
        termination: solve.termination.clone(),
        factor_blocks: solve.factor_blocks,
        seconds,
        total_seconds: start.elapsed().as_secs_f64(),
        down_weighted_edges: solve
            .down_weighted()
            .map(|e| DownWeightedEdge {
                index: e.index,
                from: e.from,
                to: e.to,
                chi2: e.chi2,
                weight: e.weight,
            })
            .collect(),
    })
}

/// The report of `olmap graph info --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GraphInfo {
    /// The file read.
    pub input: String,
    /// `se2` or `se3`.
    pub space: Space,
    /// Vertices.
    pub nodes: usize,
    /// Edges.
    pub edges: usize,
    /// Vertices fixed by the file.
    pub fixed_nodes: usize,
    /// Connected parts of the graph.
    pub connected_parts: usize,
    /// Edges by kind (a g2o file's are all `generic`).
    pub edge_kinds: Vec<(EdgeKind, usize)>,
    /// `1/2 sum r^T Omega r` at the file's poses in Ceres' convention.
    pub cost_ceres: f64,
    /// The same in the solver's convention ([`CostConvention::Log`]).
    pub cost_log: f64,
}

/// Reads a g2o file and describes it.
pub fn describe_g2o(path: &std::path::Path) -> Result<GraphInfo> {
    let graph = read_g2o(path)?;
    let n = graph.nodes().len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let mut parts = n;
    for e in graph.edges() {
        let i = graph.node_index(e.from).expect("checked when added");
        let j = graph.node_index(e.to).expect("checked when added");
        let (a, b) = (find(&mut parent, i), find(&mut parent, j));
        if a != b {
            parent[a.max(b)] = a.min(b);
            parts -= 1;
        }
    }
    Ok(GraphInfo {
        input: path.display().to_string(),
        space: graph.space(),
        nodes: n,
        edges: graph.edges().len(),
        fixed_nodes: graph.nodes().iter().filter(|n| n.fixed).count(),
        connected_parts: parts,
        edge_kinds: graph.edge_counts().into_iter().collect(),
        cost_ceres: cost(&graph, CostConvention::Ceres),
        cost_log: cost(&graph, CostConvention::Log),
    })
}
