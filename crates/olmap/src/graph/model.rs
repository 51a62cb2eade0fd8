//! The pose graph itself: nodes (SE(2) or SE(3) poses, some fixed), edges (a relative
//! measurement `T_i_j` with its information matrix, a kind and a robust kernel).

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Matrix6, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::{wrap_angle, Pose};

/// A node's identifier, chosen by the caller (g2o files use the vertex id).
pub type NodeId = u64;

/// Whether a graph's poses are planar (x, y, theta) or spatial (SE(3)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Space {
    /// Planar poses `(x, y, theta)`: 3 degrees of freedom per node.
    Se2,
    /// Spatial poses ([`Pose`]): 6 degrees of freedom per node.
    Se3,
}

impl Space {
    /// Degrees of freedom of one node.
    pub fn dof(self) -> usize {
        match self {
            Space::Se2 => 3,
            Space::Se3 => 6,
        }
    }
}

/// A planar pose `T_a_b`: `p_a = R(theta) p_b + (x, y)`; metres and radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Se2 {
    /// Translation along x, metres.
    pub x: f64,
    /// Translation along y, metres.
    pub y: f64,
    /// Rotation about z, radians.
    pub theta: f64,
}

impl Se2 {
    /// A planar pose from its parts.
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Se2 { x, y, theta }
    }

    /// The composition `self * other` (`T_a_b * T_b_c = T_a_c`), angle wrapped to (-pi, pi].
    pub fn compose(&self, other: &Se2) -> Se2 {
        let (s, c) = self.theta.sin_cos();
        Se2 {
            x: self.x + c * other.x - s * other.y,
            y: self.y + s * other.x + c * other.y,
            theta: wrap_angle(self.theta + other.theta),
        }
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Se2 {
        let (s, c) = self.theta.sin_cos();
        Se2 {
            x: -(c * self.x + s * self.y),
            y: -(-s * self.x + c * self.y),
            theta: wrap_angle(-self.theta),
        }
    }

    /// The same transform as an SE(3) [`Pose`] in the plane z = 0 (yaw = theta).
    pub fn to_pose(&self) -> Pose {
        Pose::from_parts(
            Vector3::new(self.x, self.y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.theta),
        )
    }

    fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }
}

/// A node's pose: planar or spatial (all nodes of one graph are of the graph's [`Space`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NodePose {
    /// A planar pose `T_world_node`.
    Se2(Se2),
    /// A spatial pose `T_world_node`.
    Se3(Pose),
}

impl NodePose {
    /// The space this pose lives in.
    pub fn space(&self) -> Space {
        match self {
            NodePose::Se2(_) => Space::Se2,
            NodePose::Se3(_) => Space::Se3,
        }
    }

    /// The pose as SE(3) (a planar pose in the plane z = 0).
    pub fn to_pose(&self) -> Pose {
        match self {
            NodePose::Se2(p) => p.to_pose(),
            NodePose::Se3(p) => *p,
        }
    }
}

/// One node of a [`PoseGraph`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Node {
    /// The caller's identifier.
    pub id: NodeId,
    /// The current estimate `T_world_node` (the initial value before a solve, the solution
    /// after it).
    pub pose: NodePose,
    /// A fixed node is not moved by the solver (it holds the gauge: the map's origin).
    pub fixed: bool,
}

/// What an edge's measurement came from. It changes nothing in the solve; reports count
/// edges by kind and name the ones the robust kernel rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EdgeKind {
    /// Odometry between a robot's consecutive poses.
    Odometry,
    /// A scan registration.
    Registration,
    /// A sighting of one robot by another (mutual localisation).
    Sighting,
    /// A loop closure: a registration onto a much earlier part of the map.
    LoopClosure,
    /// A constraint of unknown origin (a g2o file's edge).
    Generic,
}

impl EdgeKind {
    /// The kind's name in reports (`odometry`, `registration`, `sighting`, `loop_closure`,
    /// `generic`).
    pub fn name(self) -> &'static str {
        match self {
            EdgeKind::Odometry => "odometry",
            EdgeKind::Registration => "registration",
            EdgeKind::Sighting => "sighting",
            EdgeKind::LoopClosure => "loop_closure",
            EdgeKind::Generic => "generic",
        }
    }
}

/// A robust kernel `rho(s)` applied to an edge's squared Mahalanobis error
/// `s = chi2 = r^T Omega r`; the edge contributes `rho(s) / 2` to the cost. The width is
/// in chi2 units (squared standard deviations), so one width fits SE(2) and SE(3) edges
/// alike. An edge whose weight `rho'(s)` falls below [`OUTLIER_WEIGHT`] at the solution is
/// reported as down-weighted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", content = "width", rename_all = "lowercase")]
pub enum Kernel {
    /// Plain least squares: `rho(s) = s`.
    None,
    /// Huber: quadratic up to `s = width`, linear in the error beyond
    /// (`rho(s) = 2 sqrt(width s) - width`).
    Huber(f64),
    /// Cauchy: `rho(s) = width ln(1 + s / width)`.
    Cauchy(f64),
    /// Dynamic covariance scaling (Agarwal et al. 2013) with `Phi = width`: the edge's
    /// information is scaled by `min(1, 2 Phi / (Phi + s))^2`, which is the kernel
    /// `rho(s) = s` up to `Phi` and `Phi (3 s - Phi) / (Phi + s)` beyond: bounded (at most
    /// `3 Phi`), so a wrong loop closure cannot pull with more than a fixed force.
    Dcs(f64),
}

/// An edge whose kernel weight at the solution is below this is reported as down-weighted
/// (an outlier): it pulls with less than half of its nominal information.
pub const OUTLIER_WEIGHT: f64 = 0.5;

impl Kernel {
    /// `(rho(s), rho'(s))` for a squared error `s >= 0`.
    pub fn rho(self, s: f64) -> (f64, f64) {
        match self {
            Kernel::None => (s, 1.0),
            Kernel::Huber(w) => {
                if s <= w {
                    (s, 1.0)
                } else {
                    let r = s.sqrt();
                    let d = w.sqrt();
                    (2.0 * d * r - w, d / r)
                }
            }
            Kernel::Cauchy(w) => {
                let a = 1.0 + s / w;
                (w * a.ln(), 1.0 / a)
            }
            Kernel::Dcs(phi) => {
                if s <= phi {
                    (s, 1.0)
                } else {
                    let scale = 2.0 * phi / (phi + s);
                    (phi * (3.0 * s - phi) / (phi + s), scale * scale)
                }
            }
        }
    }

    /// The kernel's name (`none`, `huber`, `cauchy`, `dcs`).
    pub fn name(self) -> &'static str {
        match self {
            Kernel::None => "none",
            Kernel::Huber(_) => "huber",
            Kernel::Cauchy(_) => "cauchy",
            Kernel::Dcs(_) => "dcs",
        }
    }

    fn check(self) -> Result<()> {
        match self {
            Kernel::None => Ok(()),
            Kernel::Huber(w) | Kernel::Cauchy(w) | Kernel::Dcs(w) => {
                if w.is_finite() && w > 0.0 {
                    Ok(())
                } else {
                    Err(Error::InvalidArgument(format!(
                        "the {} kernel's width must be a positive number (chi2 units), got {w}",
                        self.name()
                    )))
                }
            }
        }
    }
}

/// An edge's measurement `T_i_j` (the pose of node j in the frame of node i) and its
/// information matrix (inverse covariance), translation first, then rotation: g2o's order.
// The SE(3) variant is 4x larger than the SE(2) one; a graph holds one kind, and boxing
// the information would cost an allocation per edge for nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Measurement {
    /// A planar measurement; information over `(x, y, theta)`.
    Se2 {
        /// `T_i_j`.
        t_i_j: Se2,
        /// 3x3 information over `(x, y, theta)`.
        information: Matrix3<f64>,
    },
    /// A spatial measurement; information over `(x, y, z, rx, ry, rz)` (rotation as a
    /// rotation vector, radians).
    Se3 {
        /// `T_i_j`.
        t_i_j: Pose,
        /// 6x6 information over `(x, y, z, rx, ry, rz)`.
        information: Matrix6<f64>,
    },
}

impl Measurement {
    /// The space this measurement lives in.
    pub fn space(&self) -> Space {
        match self {
            Measurement::Se2 { .. } => Space::Se2,
            Measurement::Se3 { .. } => Space::Se3,
        }
    }
}

/// One edge of a [`PoseGraph`]: node `from` = i, node `to` = j, measurement `T_i_j`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Node i.
    pub from: NodeId,
    /// Node j.
    pub to: NodeId,
    /// Where the measurement came from.
    pub kind: EdgeKind,
    /// `T_i_j` with its information.
    pub measurement: Measurement,
    /// The robust kernel applied to this edge.
    pub kernel: Kernel,
}

/// A pose graph: nodes are poses (all SE(2) or all SE(3)), edges relative measurements
/// between two nodes. Build it incrementally ([`PoseGraph::add_node`],
/// [`PoseGraph::add_edge`]), solve it with [`PoseGraph::optimise`] (which starts from the
/// current poses: a warm start after adding a few nodes and edges) and read the poses back
/// ([`PoseGraph::pose`], [`PoseGraph::nodes`]).
///
/// ```
/// use olmap::graph::{EdgeKind, Kernel, PoseGraph, Se2, Space, SolveParams};
/// use nalgebra::Matrix3;
/// let mut g = PoseGraph::new(Space::Se2);
/// g.add_node_se2(0, Se2::new(0.0, 0.0, 0.0)).unwrap();
/// g.add_node_se2(1, Se2::new(0.8, 0.1, 0.0)).unwrap();
/// g.set_fixed(0, true).unwrap();
/// let info = Matrix3::identity() * 100.0;
/// g.add_edge_se2(0, 1, EdgeKind::Odometry, Se2::new(1.0, 0.0, 0.0), info, Kernel::None).unwrap();
/// let report = g.optimise(&SolveParams::default()).unwrap();
/// assert!(report.final_cost < 1e-12);
/// let p = g.pose_se2(1).unwrap();
/// assert!((p.x - 1.0).abs() < 1e-9 && p.y.abs() < 1e-9);
/// ```
#[derive(Debug, Clone)]
pub struct PoseGraph {
    space: Space,
    nodes: Vec<Node>,
    index: BTreeMap<NodeId, usize>,
    edges: Vec<Edge>,
}

/// Largest |R^T R - I| accepted in a measurement's or node's rotation (they are
/// renormalised): a quaternion read from a file with 6 decimals is well within.
const ROTATION_TOLERANCE: f64 = 1e-3;

impl PoseGraph {
    /// An empty graph of planar or spatial poses.
    pub fn new(space: Space) -> Self {
        PoseGraph {
            space,
            nodes: Vec::new(),
            index: BTreeMap::new(),
            edges: Vec::new(),
        }
    }

    /// Planar or spatial.
    pub fn space(&self) -> Space {
        self.space
    }

    /// The nodes, in the order they were added.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// The edges, in the order they were added (an edge's index in this slice is the
    /// index the solver's per-edge report uses).
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The node with this id.
    pub fn node(&self, id: NodeId) -> Option<&Node> {
        self.index.get(&id).map(|&i| &self.nodes[i])
    }

    /// The position of a node in [`PoseGraph::nodes`].
    pub fn node_index(&self, id: NodeId) -> Option<usize> {
        self.index.get(&id).copied()
    }

    /// A node's pose as SE(3) (a planar pose lies in the plane z = 0).
    pub fn pose(&self, id: NodeId) -> Option<Pose> {
        self.node(id).map(|n| n.pose.to_pose())
    }

    /// A node's planar pose (`None` when there is no such node or the graph is SE(3)).
    pub fn pose_se2(&self, id: NodeId) -> Option<Se2> {
        match self.node(id)?.pose {
            NodePose::Se2(p) => Some(p),
            NodePose::Se3(_) => None,
        }
    }

    /// Adds a node; its pose is the initial value for the next solve.
    ///
    /// Errors: [`Error::InvalidArgument`] for an id already present, a pose of the other
    /// space or a non-finite or non-rotation pose.
    pub fn add_node(&mut self, id: NodeId, pose: NodePose) -> Result<()> {
        if self.index.contains_key(&id) {
            return Err(Error::InvalidArgument(format!(
                "pose graph: node {id} is already present"
            )));
        }
        let pose = self.checked_pose(pose, &format!("node {id}"))?;
        self.index.insert(id, self.nodes.len());
        self.nodes.push(Node {
            id,
            pose,
            fixed: false,
        });
        Ok(())
    }

    /// Adds a planar node (see [`PoseGraph::add_node`]).
    pub fn add_node_se2(&mut self, id: NodeId, pose: Se2) -> Result<()> {
        self.add_node(id, NodePose::Se2(pose))
    }

    /// Adds a spatial node (see [`PoseGraph::add_node`]).
    pub fn add_node_se3(&mut self, id: NodeId, pose: Pose) -> Result<()> {
        self.add_node(id, NodePose::Se3(pose))
    }

    /// Replaces a node's pose (a new initial value, e.g. from a better guess).
    pub fn set_pose(&mut self, id: NodeId, pose: NodePose) -> Result<()> {
        let i = self.require(id)?;
        self.nodes[i].pose = self.checked_pose(pose, &format!("node {id}"))?;
        Ok(())
    }

    /// Fixes a node (the solver does not move it) or frees it. A connected part of the
    /// graph without any fixed node is held by its first-added node during a solve.
    pub fn set_fixed(&mut self, id: NodeId, fixed: bool) -> Result<()> {
        let i = self.require(id)?;
        self.nodes[i].fixed = fixed;
        Ok(())
    }

    /// Adds an edge and returns its index in [`PoseGraph::edges`].
    ///
    /// Errors: [`Error::NotFound`] for an unknown node; [`Error::InvalidArgument`] for an
    /// edge from a node to itself, a measurement of the other space, a non-finite value, an
    /// information matrix that is not symmetric positive semi-definite, or a bad kernel
    /// width.
    pub fn add_edge(&mut self, edge: Edge) -> Result<usize> {
        self.require(edge.from)?;
        self.require(edge.to)?;
        let what = format!("edge {} -> {}", edge.from, edge.to);
        if edge.from == edge.to {
            return Err(Error::InvalidArgument(format!(
                "pose graph: {what} joins a node to itself"
            )));
        }
        edge.kernel.check()?;
        let measurement = self.checked_measurement(edge.measurement, &what)?;
        self.edges.push(Edge {
            measurement,
            ..edge
        });
        Ok(self.edges.len() - 1)
    }

    /// Adds a planar edge (see [`PoseGraph::add_edge`]).
    pub fn add_edge_se2(
        &mut self,
        from: NodeId,
        to: NodeId,
        kind: EdgeKind,
        t_i_j: Se2,
        information: Matrix3<f64>,
        kernel: Kernel,
    ) -> Result<usize> {
        self.add_edge(Edge {
            from,
            to,
            kind,
            measurement: Measurement::Se2 { t_i_j, information },
            kernel,
        })
    }

    /// Adds a spatial edge (see [`PoseGraph::add_edge`]).
    pub fn add_edge_se3(
        &mut self,
        from: NodeId,
        to: NodeId,
        kind: EdgeKind,
        t_i_j: Pose,
        information: Matrix6<f64>,
        kernel: Kernel,
    ) -> Result<usize> {
        self.add_edge(Edge {
            from,
            to,
            kind,
            measurement: Measurement::Se3 { t_i_j, information },
            kernel,
        })
    }

    /// Sets the robust kernel of every edge (e.g. from the command line).
    pub fn set_kernel_all(&mut self, kernel: Kernel) -> Result<()> {
        kernel.check()?;
        for e in &mut self.edges {
            e.kernel = kernel;
        }
        Ok(())
    }

    /// Sets one edge's robust kernel.
    pub fn set_kernel(&mut self, edge: usize, kernel: Kernel) -> Result<()> {
        kernel.check()?;
        let n = self.edges.len();
        let e = self.edges.get_mut(edge).ok_or_else(|| Error::NotFound {
            what: format!("pose graph edge {edge} (the graph has {n})"),
        })?;
        e.kernel = kernel;
        Ok(())
    }

    /// Number of edges of each kind, sorted by kind.
    pub fn edge_counts(&self) -> BTreeMap<EdgeKind, usize> {
        let mut m = BTreeMap::new();
        for e in &self.edges {
            *m.entry(e.kind).or_insert(0) += 1;
        }
        m
    }

    pub(crate) fn nodes_mut(&mut self) -> &mut [Node] {
        &mut self.nodes
    }

    fn require(&self, id: NodeId) -> Result<usize> {
        self.index.get(&id).copied().ok_or_else(|| Error::NotFound {
            what: format!("pose graph node {id}"),
        })
    }

    fn checked_pose(&self, pose: NodePose, what: &str) -> Result<NodePose> {
        if pose.space() != self.space {
            return Err(Error::InvalidArgument(format!(
                "pose graph: {what} is {:?} but the graph is {:?}",
                pose.space(),
                self.space
            )));
        }
        match pose {
            NodePose::Se2(p) => {
                if !p.is_finite() {
                    return Err(Error::InvalidArgument(format!(
                        "pose graph: {what} has a non-finite pose"
                    )));
                }
                Ok(NodePose::Se2(Se2 {
                    theta: wrap_angle(p.theta),
                    ..p
                }))
            }
            NodePose::Se3(p) => Ok(NodePose::Se3(checked_pose3(&p, what)?)),
        }
    }

    fn checked_measurement(&self, m: Measurement, what: &str) -> Result<Measurement> {
        if m.space() != self.space {
            return Err(Error::InvalidArgument(format!(
                "pose graph: {what} is {:?} but the graph is {:?}",
                m.space(),
                self.space
            )));
        }
        match m {
            Measurement::Se2 { t_i_j, information } => {
                if !t_i_j.is_finite() {
                    return Err(Error::InvalidArgument(format!(
                        "pose graph: {what} has a non-finite measurement"
                    )));
                }
                check_information(information.as_slice(), 3, what)?;
                Ok(Measurement::Se2 {
                    t_i_j: Se2 {
                        theta: wrap_angle(t_i_j.theta),
                        ..t_i_j
                    },
                    information,
                })
            }
            Measurement::Se3 { t_i_j, information } => {
                let t_i_j = checked_pose3(&t_i_j, what)?;
                check_information(information.as_slice(), 6, what)?;
                Ok(Measurement::Se3 { t_i_j, information })
            }
        }
    }
}

/// A finite pose with a unit rotation (renormalised; a quaternion further than
/// [`ROTATION_TOLERANCE`] from unit length is an error).
fn checked_pose3(p: &Pose, what: &str) -> Result<Pose> {
    let q = p.rotation().into_inner();
    let t = p.translation();
    if q.coords.iter().chain(t.iter()).any(|v| !v.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "pose graph: {what} has a non-finite pose"
        )));
    }
    let n = q.norm();
    if (n - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(Error::InvalidArgument(format!(
            "pose graph: {what} has a rotation quaternion of norm {n}, expected 1"
        )));
    }
    Ok(Pose::from_parts(t, UnitQuaternion::new_normalize(q)))
}

/// An information matrix must be finite, symmetric and positive semi-definite.
pub(crate) fn check_information(m: &[f64], n: usize, what: &str) -> Result<()> {
    let bad = |why: &str| {
        Err(Error::InvalidArgument(format!(
            "pose graph: {what}: the information matrix {why}"
        )))
    };
    if m.iter().any(|v| !v.is_finite()) {
        return bad("holds a non-finite number");
    }
    let scale = m.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for r in 0..n {
        for c in 0..r {
            if (m[r * n + c] - m[c * n + r]).abs() > 1e-9 * scale.max(1.0) {
                return bad("is not symmetric");
            }
        }
    }
    let dm = nalgebra::DMatrix::from_column_slice(n, n, m);
    let eig = nalgebra::SymmetricEigen::new(dm);
    let min = eig.eigenvalues.iter().fold(f64::INFINITY, |a, &v| a.min(v));
    if scale == 0.0 || min < -1e-9 * scale {
        return bad("is not positive semi-definite (or is zero)");
    }
    Ok(())
}
