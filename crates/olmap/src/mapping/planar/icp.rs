//! Point-to-line ICP for planar scans: the refinement a 2D scan needs (the 3D
//! point-to-plane refinement sees only the scan plane's normal, along z, and holds nothing
//! in x, y and yaw).
//!
//! The target is a set of points with line normals estimated in the plane (PCA of the
//! nearest neighbours; points whose neighbourhood is not a line get no normal and are not
//! matched). Each iteration pairs every source point with its nearest target point within a
//! correspondence distance that shrinks over the iterations (1 m, then 0.5 m, then the
//! final distance), weights the signed point-to-line distance `r = n·(R p + t − q)` with a
//! Cauchy weight, and solves the 3x3 Gauss-Newton system over `(x, y, theta)`.
//!
//! The result carries the Gauss-Newton matrix `H = Σ J^T J` of the inliers at the solution,
//! which tells how well each direction is held (a corridor leaves the direction along it
//! weak) and gives the information of a pose-graph edge.

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

use crate::graph::Se2;

/// Parameters of [`LineTarget::register`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarIcpParams {
    /// Most iterations.
    pub max_iterations: usize,
    /// The correspondence distance of the last stage (nearest target point), metres.
    pub match_distance: f64,
    /// A matched point is an inlier when its point-to-line distance is below this, metres.
    pub inlier_distance: f64,
    /// Cauchy width of the residual weight, metres.
    pub cauchy_width: f64,
    /// Neighbours for a target normal …
    pub normal_k: usize,
    /// … taken within this distance, metres (far returns of a 1° scanner are 10-20 cm
    /// apart, so this must reach several of them).
    pub normal_radius: f64,
    /// A target point gets a normal when its neighbours' covariance has
    /// `λ_min / λ_max` below this (0 = a perfect line). For `k` points `s` apart along a
    /// wall scattered by `σ` across it, the ratio is `12 σ² / (s² (k² − 1))`: with the
    /// default 5 neighbours 5 cm apart, 200 σ². A local map is a stack of scans, each
    /// thinned on a 5 cm grid (about 1.4 cm of scatter by itself), with a range noise of
    /// about 1 cm and registered to 1-2 cm: 2-3 cm across its walls. The default 0.2 admits
    /// up to 3.2 cm; 0.1 (2.2 cm) left most points of a real local map (ACES: 113 of one
    /// revisit's 167 points met a target point without one), so that right loop closures
    /// matched only 20-40 % of their points.
    pub max_line_ratio: f64,
    /// Converged when a step moves less than this, metres (and this/1 m radians).
    pub step_tolerance: f64,
}

impl Default for PlanarIcpParams {
    fn default() -> Self {
        PlanarIcpParams {
            max_iterations: 50,
            match_distance: 0.3,
            inlier_distance: 0.1,
            cauchy_width: 0.05,
            normal_k: 5,
            normal_radius: 0.6,
            max_line_ratio: 0.2,
            step_tolerance: 1e-4,
        }
    }
}

/// The outcome of a point-to-line registration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarIcpResult {
    /// `T_target_source`.
    pub pose: Se2,
    /// Source points matched (within [`PlanarIcpParams::match_distance`] of a target point
    /// with a normal) whose point-to-line distance is below
    /// [`PlanarIcpParams::inlier_distance`] at the solution.
    pub inliers: usize,
    /// Source points given.
    pub source_points: usize,
    /// RMS point-to-line distance of the inliers, metres.
    pub rmse: f64,
    /// `Σ J^T J` over the inliers at the solution (unweighted), over `(x, y, theta)`.
    pub hessian: Matrix3<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the last step was below the tolerance.
    pub converged: bool,
}

impl PlanarIcpResult {
    /// Inliers over source points.
    pub fn inlier_fraction(&self) -> f64 {
        if self.source_points == 0 {
            0.0
        } else {
            self.inliers as f64 / self.source_points as f64
        }
    }

    /// How well the weakest translation direction is held: the smallest eigenvalue of the
    /// translation block of the Hessian per inlier (1 = every inlier's normal along that
    /// direction, 0 = none: a corridor along it).
    pub fn weakest_translation(&self) -> f64 {
        if self.inliers == 0 {
            return 0.0;
        }
        let t: Matrix2<f64> = self.hessian.fixed_view::<2, 2>(0, 0).into_owned();
        let e = t.symmetric_eigenvalues();
        e.min() / self.inliers as f64
    }

    /// The weakest translation direction (unit vector in the target frame): the
    /// eigenvector of the Hessian's translation block with the smallest eigenvalue (along
    /// a corridor, the corridor's direction).
    pub fn weakest_direction(&self) -> Vector2<f64> {
        let t: Matrix2<f64> = self.hessian.fixed_view::<2, 2>(0, 0).into_owned();
        let e = t.symmetric_eigen();
        let k = e.eigenvalues.imin();
        let v: Vector2<f64> = e.eigenvectors.column(k).into_owned();
        let n = v.norm();
        if n > 0.0 && n.is_finite() {
            v / n
        } else {
            Vector2::x()
        }
    }

    /// The information over `(x, y, theta)` of the registration as a pose-graph edge:
    /// `H / σ²` with σ the RMS residual (at least `sigma_floor`), times `scale` (< 1 because
    /// neighbouring beams' errors are correlated, so the points are not independent).
    pub fn information(&self, sigma_floor: f64, scale: f64) -> Matrix3<f64> {
        let s = self.rmse.max(sigma_floor);
        self.hessian * (scale / (s * s))
    }
}

/// Target points with line normals and a k-d tree, ready for [`LineTarget::register`].
pub struct LineTarget {
    points: Vec<Vector2<f64>>,
    normals: Vec<Option<Vector2<f64>>>,
    tree: ImmutableKdTree<f64, 2>,
}

impl LineTarget {
    /// Indexes target points and estimates their normals; `None` for fewer than 3 points.
    pub fn new(points: Vec<Vector2<f64>>, params: &PlanarIcpParams) -> Option<LineTarget> {
        if points.len() < 3 {
            return None;
        }
        let coords: Vec<[f64; 2]> = points.iter().map(|p| [p.x, p.y]).collect();
        let tree = ImmutableKdTree::<f64, 2>::new_from_slice(&coords).ok()?;
        let k = NonZeroUsize::new(params.normal_k.clamp(3, points.len())).expect("k >= 3");
        let normals = coords
            .iter()
            .map(|c| {
                let nn = tree
                    .query(c)
                    .nearest_n::<SquaredEuclidean<f64>>(k)
                    .execute();
                let pts: Vec<Vector2<f64>> = nn
                    .iter()
                    .filter(|r| r.distance < params.normal_radius * params.normal_radius)
                    .map(|r| points[r.item as usize])
                    .collect();
                line_normal(&pts, params.max_line_ratio)
            })
            .collect();
        Some(LineTarget {
            points,
            normals,
            tree,
        })
    }

    /// Target points.
    pub fn points(&self) -> &[Vector2<f64>] {
        &self.points
    }

    /// Registers `source` (points in the source frame) onto the target from `guess`
    /// (`T_target_source`).
    pub fn register(
        &self,
        source: &[Vector2<f64>],
        guess: Se2,
        params: &PlanarIcpParams,
    ) -> PlanarIcpResult {
        let mut pose = guess;
        let mut converged = false;
        let mut iterations = 0;
        let final_d = params.match_distance;
        let stages = [1.0f64.max(final_d), 0.5f64.max(final_d), final_d];
        let mut stage = 0;
        while iterations < params.max_iterations {
            iterations += 1;
            let d = stages[stage];
            let (h, g, _, _, _) = self.linearise(source, &pose, d, params.cauchy_width);
            let Some(step) = h.cholesky().map(|c| c.solve(&(-g))) else {
                break;
            };
            pose = Se2::new(pose.x + step.x, pose.y + step.y, pose.theta + step.z);
            pose = Se2::new(pose.x, pose.y, crate::geometry::wrap_angle(pose.theta));
            let small = step.x.hypot(step.y).max(step.z.abs()) < params.step_tolerance;
            if small {
                if stage + 1 < stages.len() {
                    stage += 1;
                } else {
                    converged = true;
                    break;
                }
            }
        }
        // Correspondences can flip between two neighbours forever, and a coarse stage can
        // use up the iterations: the pose is a solution when one more final-stage step from
        // it would move it by less than `settle` (1 cm, 0.2°).
        if !converged {
            let (h, g, _, _, _) = self.linearise(source, &pose, final_d, params.cauchy_width);
            if let Some(step) = h.cholesky().map(|c| c.solve(&(-g))) {
                let settle = 0.01f64;
                converged = step.x.hypot(step.y) < settle && step.z.abs() < 0.2f64.to_radians();
            }
        }
        let (_, _, hessian, inliers, sq) =
            self.linearise(source, &pose, final_d, -params.inlier_distance);
        PlanarIcpResult {
            pose,
            inliers,
            source_points: source.len(),
            rmse: if inliers > 0 {
                (sq / inliers as f64).sqrt()
            } else {
                f64::INFINITY
            },
            hessian,
            iterations,
            converged,
        }
    }

    /// The weighted normal equations at `pose` with correspondences within `d`, plus the
    /// unweighted `Σ J^T J`, the match count and the sum of squared residuals. A negative
    /// `cauchy` means no weight and only residuals within `|cauchy|` (the inliers).
    fn linearise(
        &self,
        source: &[Vector2<f64>],
        pose: &Se2,
        d: f64,
        cauchy: f64,
    ) -> (Matrix3<f64>, Vector3<f64>, Matrix3<f64>, usize, f64) {
        let (s, c) = pose.theta.sin_cos();
        let rot = Matrix2::new(c, -s, s, c);
        let t = Vector2::new(pose.x, pose.y);
        let mut h = Matrix3::zeros();
        let mut g = Vector3::zeros();
        let mut h_plain = Matrix3::zeros();
        let mut n_match = 0usize;
        let mut sq = 0.0;
        // Levenberg damping keeps a weak direction from jumping.
        h += Matrix3::identity() * 1e-6;
        for p in source {
            let rp = rot * p;
            let q = rp + t;
            let nn = self
                .tree
                .query(&[q.x, q.y])
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute();
            if nn.distance.is_nan() || nn.distance > d * d {
                continue;
            }
            let i = nn.item as usize;
            let Some(n) = self.normals[i] else {
                continue;
            };
            let r = n.dot(&(q - self.points[i]));
            let j = Vector3::new(n.x, n.y, n.x * -rp.y + n.y * rp.x);
            let w = if cauchy > 0.0 {
                1.0 / (1.0 + (r / cauchy).powi(2))
            } else if r.abs() <= -cauchy {
                1.0
            } else {
                continue;
            };
            h += j * j.transpose() * w;
            g += j * (w * r);
            h_plain += j * j.transpose();
            n_match += 1;
            sq += r * r;
        }
        (h, g, h_plain, n_match, sq)
    }
}

/// The unit normal of a set of points lying on a line, or `None` when they are fewer than
/// 3 or not line-like (`λ_min / λ_max` of their covariance above `max_ratio`).
fn line_normal(pts: &[Vector2<f64>], max_ratio: f64) -> Option<Vector2<f64>> {
    if pts.len() < 3 {
        return None;
    }
    let mean = pts.iter().fold(Vector2::zeros(), |s, p| s + p) / pts.len() as f64;
    let mut cov = Matrix2::zeros();
    for p in pts {
        let d = p - mean;
        cov += d * d.transpose();
    }
    let eig = cov.symmetric_eigen();
    let (small, large) = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    if eig.eigenvalues[large] <= 0.0 || eig.eigenvalues[small] > max_ratio * eig.eigenvalues[large]
    {
        return None;
    }
    let n = eig.eigenvectors.column(small).into_owned();
    Some(n / n.norm())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points along the walls of a 6 m × 4 m room with a pillar, seen from (1, 0.5).
    fn room() -> Vec<Vector2<f64>> {
        let mut pts = Vec::new();
        let mut i = 0.0;
        while i <= 6.0 {
            pts.push(Vector2::new(i - 3.0, -2.0));
            pts.push(Vector2::new(i - 3.0, 2.0));
            i += 0.05;
        }
        let mut j = 0.0;
        while j <= 4.0 {
            pts.push(Vector2::new(-3.0, j - 2.0));
            pts.push(Vector2::new(3.0, j - 2.0));
            j += 0.05;
        }
        pts
    }

    #[test]
    fn recovers_a_planar_offset_and_holds_a_room_in_every_direction() {
        let params = PlanarIcpParams::default();
        let target = LineTarget::new(room(), &params).unwrap();
        let truth = Se2::new(0.2, -0.15, 0.06);
        // Source = room seen from `truth`: p_source = truth^-1 p_target.
        let inv = truth.inverse();
        let source: Vec<Vector2<f64>> = room()
            .iter()
            .map(|p| {
                let q = inv.compose(&Se2::new(p.x, p.y, 0.0));
                Vector2::new(q.x, q.y)
            })
            .collect();
        let r = target.register(&source, Se2::default(), &params);
        assert!(r.converged);
        assert!((r.pose.x - truth.x).abs() < 1e-4, "{:?}", r.pose);
        assert!((r.pose.y - truth.y).abs() < 1e-4, "{:?}", r.pose);
        assert!((r.pose.theta - truth.theta).abs() < 1e-5, "{:?}", r.pose);
        assert!(r.inlier_fraction() > 0.95);
        // Half the wall points hold x, half hold y.
        assert!(r.weakest_translation() > 0.3, "{}", r.weakest_translation());
    }

    #[test]
    fn a_corridor_leaves_its_direction_weak() {
        let params = PlanarIcpParams::default();
        let walls: Vec<Vector2<f64>> = (0..400)
            .flat_map(|i| {
                let x = i as f64 * 0.05 - 10.0;
                [Vector2::new(x, -1.0), Vector2::new(x, 1.0)]
            })
            .collect();
        let target = LineTarget::new(walls.clone(), &params).unwrap();
        let r = target.register(&walls, Se2::new(0.0, 0.05, 0.0), &params);
        assert!(r.pose.y.abs() < 1e-4);
        assert!(
            r.weakest_translation() < 1e-3,
            "{}",
            r.weakest_translation()
        );
        // The weak direction is the corridor's (x), either sign.
        assert!(
            r.weakest_direction().x.abs() > 0.999,
            "{}",
            r.weakest_direction()
        );
    }
}
