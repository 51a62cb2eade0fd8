//! `olmap graph`: pose-graph files (g2o): optimise one, or describe it.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand, ValueEnum};
use olmap::graph::{
    describe_g2o, run_graph_optimise, CostConvention, GraphOptimiseJob, Init, Kernel, SolveParams,
};

/// Arguments of `olmap graph`.
#[derive(Args)]
pub struct GraphArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: GraphCommand,
}

/// The `olmap graph` subcommands.
#[derive(Subcommand)]
pub enum GraphCommand {
    /// Optimise a pose graph (g2o: VERTEX_SE2/EDGE_SE2 or VERTEX_SE3:QUAT/EDGE_SE3:QUAT, FIX)
    /// with sparse Levenberg-Marquardt on the manifold, and write the result as g2o.
    Optimise(OptimiseArgs),
    /// Describe a pose graph: nodes, edges, fixed nodes, connected parts, cost.
    Info(InfoArgs),
}

/// Starting point of the solve.
#[derive(Clone, Copy, ValueEnum)]
pub enum InitArg {
    /// Chordal relaxation: rotations first, then positions (robust on sphere-like graphs).
    Chordal,
    /// The file's poses as they are.
    None,
}

/// Robust kernel applied to every edge.
#[derive(Clone, Copy, ValueEnum)]
pub enum KernelArg {
    /// Plain least squares.
    None,
    /// Huber: linear beyond --kernel-width.
    Huber,
    /// Cauchy.
    Cauchy,
    /// Dynamic covariance scaling: a bounded pull for outliers.
    Dcs,
}

/// Residual convention of the reported costs.
#[derive(Clone, Copy, ValueEnum)]
pub enum ConventionArg {
    /// Ceres' pose-graph examples (quaternion error 2 vec(q)): the published benchmark costs.
    Ceres,
    /// The solver's own (rotation vector error).
    Log,
}

/// Arguments of `olmap graph optimise`.
///
/// The costs reported are 1/2 sum r^T Omega r in the chosen convention (default Ceres',
/// the convention of the published benchmark numbers). Fixed vertices (FIX) hold the
/// gauge; a connected part without one is held by its first vertex.
#[derive(Args)]
pub struct OptimiseArgs {
    /// The g2o file to optimise.
    pub input: PathBuf,
    /// The g2o file to write (.g2o).
    #[arg(short, long, value_name = "OUT.g2o")]
    pub output: PathBuf,
    /// Most Levenberg-Marquardt iterations.
    #[arg(long, default_value_t = 100)]
    pub iterations: usize,
    /// Starting point.
    #[arg(long, value_enum, default_value = "chordal")]
    pub init: InitArg,
    /// Robust kernel on every edge.
    #[arg(long, value_enum, default_value = "none")]
    pub kernel: KernelArg,
    /// The kernel's width in chi2 units (squared standard deviations).
    #[arg(long, default_value_t = 10.0, value_name = "CHI2")]
    pub kernel_width: f64,
    /// Convention of the reported costs.
    #[arg(long, value_enum, default_value = "ceres")]
    pub cost_convention: ConventionArg,
    /// Print a JSON report.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `olmap graph info`.
#[derive(Args)]
pub struct InfoArgs {
    /// The g2o file.
    pub input: PathBuf,
    /// Print a JSON report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap graph`.
pub fn run(a: &GraphArgs) -> anyhow::Result<ExitCode> {
    match &a.command {
        GraphCommand::Optimise(o) => optimise(o),
        GraphCommand::Info(i) => info(i),
    }
}

fn optimise(a: &OptimiseArgs) -> anyhow::Result<ExitCode> {
    let w = a.kernel_width;
    let kernel = match a.kernel {
        KernelArg::None => None,
        KernelArg::Huber => Some(Kernel::Huber(w)),
        KernelArg::Cauchy => Some(Kernel::Cauchy(w)),
        KernelArg::Dcs => Some(Kernel::Dcs(w)),
    };
    let r = run_graph_optimise(&GraphOptimiseJob {
        input: a.input.clone(),
        output: a.output.clone(),
        params: SolveParams {
            max_iterations: a.iterations,
            init: match a.init {
                InitArg::Chordal => Init::Chordal,
                InitArg::None => Init::None,
            },
            ..SolveParams::default()
        },
        kernel,
        convention: match a.cost_convention {
            ConventionArg::Ceres => CostConvention::Ceres,
            ConventionArg::Log => CostConvention::Log,
        },
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {:?}, {} nodes, {} edges; cost ({}) {:.6} -> {:.6} in {} iterations, {:.3} s ({}{}) -> {}",
            r.input,
            r.space,
            r.nodes,
            r.edges,
            r.cost_convention.name(),
            r.initial_cost,
            r.final_cost,
            r.iterations,
            r.seconds,
            if r.converged { "converged: " } else { "not converged: " },
            r.termination,
            r.output
        );
        if !r.down_weighted_edges.is_empty() {
            println!(
                "{} edges down-weighted by the {} kernel:",
                r.down_weighted_edges.len(),
                r.kernel
            );
            for e in &r.down_weighted_edges {
                println!(
                    "  edge {} ({} -> {}): chi2 {:.3}, weight {:.4}",
                    e.index, e.from, e.to, e.chi2, e.weight
                );
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn info(a: &InfoArgs) -> anyhow::Result<ExitCode> {
    let r = describe_g2o(&a.input)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{}: {:?}, {} nodes ({} fixed), {} edges, {} connected part(s); cost {:.6} (ceres), {:.6} (log)",
            r.input,
            r.space,
            r.nodes,
            r.fixed_nodes,
            r.edges,
            r.connected_parts,
            r.cost_ceres,
            r.cost_log
        );
    }
    Ok(ExitCode::SUCCESS)
}
