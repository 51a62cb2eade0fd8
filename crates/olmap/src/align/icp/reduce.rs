//! Correspondences and the normal-equation accumulation: one pass over the source pairs
//! each point with its nearest target point and sums the weighted Gauss-Newton system, in
//! fixed-size chunks added in chunk order (the same sums for any number of threads).

use nalgebra::{Isometry3, Matrix3, Matrix6, Vector3, Vector6};
use rayon::prelude::*;

use super::nearest::{nearest, NearestCache};
use super::target::{Source, Target};
use super::{Degeneracy, IcpParams};

/// Source points per parallel work item. The chunk sums are added in chunk order, so results
/// do not depend on the number of threads; the value only trades scheduling overhead against
/// load balance.
const CHUNK: usize = 256;

/// Sums over correspondences. Added chunk by chunk in a fixed order.
#[derive(Clone)]
pub(super) struct Acc {
    /// Weighted Gauss-Newton matrix `Σ w J Jᵀ` (centred, scaled coordinates).
    pub(super) h: Matrix6<f64>,
    /// `Σ w r J`.
    pub(super) g: Vector6<f64>,
    /// Correspondences within the distance whose target point has a normal.
    pub(super) matched: usize,
    /// Of those, the ones with `|r| <` the kernel scale.
    pub(super) inliers: usize,
    /// `Σ r²` over inliers.
    pub(super) sum_r2: f64,
    /// Unweighted `Σ J₀ J₀ᵀ` over inliers with `J₀ = (p × n, n)` about the frame origin
    /// (final pass only).
    pub(super) info: Matrix6<f64>,
    /// `Σ p` over inliers (final pass only).
    pub(super) sum_p: Vector3<f64>,
    /// `Σ p pᵀ` over inliers (final pass only).
    pub(super) sum_ppt: Matrix3<f64>,
}

impl Acc {
    fn zero() -> Self {
        Acc {
            h: Matrix6::zeros(),
            g: Vector6::zeros(),
            matched: 0,
            inliers: 0,
            sum_r2: 0.0,
            info: Matrix6::zeros(),
            sum_p: Vector3::zeros(),
            sum_ppt: Matrix3::zeros(),
        }
    }

    fn add(&mut self, o: &Acc) {
        self.h += o.h;
        self.g += o.g;
        self.matched += o.matched;
        self.inliers += o.inliers;
        self.sum_r2 += o.sum_r2;
        self.info += o.info;
        self.sum_p += o.sum_p;
        self.sum_ppt += o.sum_ppt;
    }

    /// The degeneracy report from the final pass's inlier moments: the information matrix is
    /// moved from the origin to the inlier centroid `c` (`(p - c) × n = p × n - [c]× n`), each
    /// rotation coordinate is scaled by the RMS distance of the inliers from that axis through
    /// `c`, and the whole is divided by the inlier count.
    pub(super) fn degeneracy(&self, weak_fraction: f64) -> Degeneracy {
        if self.inliers < 6 {
            return Degeneracy::unconstrained();
        }
        let n = self.inliers as f64;
        let c = self.sum_p / n;
        let mut s = Matrix6::<f64>::identity();
        s.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-c.cross_matrix()));
        let mut m = s * self.info * s.transpose() / n;
        // Covariance of the inliers; the mean squared distance from axis k is its trace minus
        // its k-th diagonal element.
        let cov = self.sum_ppt / n - c * c.transpose();
        let mut scale = [1.0; 6];
        for (k, sk) in scale.iter_mut().take(3).enumerate() {
            *sk = 1.0 / (cov.trace() - cov[(k, k)]).max(1e-6).sqrt();
        }
        for i in 0..6 {
            for j in 0..6 {
                m[(i, j)] *= scale[i] * scale[j];
            }
        }
        Degeneracy::from_information(&m, weak_fraction)
    }
}

/// One pass over the source `src`: correspondences at distance `d` for the pose `pose`,
/// and the normal-equation sums linearised about the mapped source centroid with rotation
/// scaled by the source's RMS radius; `cache` remembers each point's nearest target point
/// between passes ([`super::nearest`]).
pub(super) fn accumulate(
    src: &Source,
    tgt: &Target,
    pose: &Isometry3<f64>,
    d: f64,
    params: &IcpParams,
    final_pass: bool,
    cache: &mut NearestCache,
) -> Acc {
    let (points, centre, radius) = (&src.points, pose * src.centroid, src.radius);
    let scale = params.kernel_scale * d;
    let kernel = params.kernel;
    let partial: Vec<Acc> = points
        .par_chunks(CHUNK)
        .zip(cache.entries.par_chunks_mut(CHUNK))
        .map(|(chunk, memos)| {
            let mut acc = Acc::zero();
            for (p, memo) in chunk.iter().zip(memos) {
                let q = pose * p;
                let Some((i, _)) = nearest(tgt, &q, memo, d) else {
                    continue;
                };
                let n = tgt.normal(i);
                if n == Vector3::zeros() {
                    continue;
                }
                let r = n.dot(&(q - tgt.points[i]));
                acc.matched += 1;
                let w = kernel.weight(r, scale);
                if w > 0.0 {
                    let a = (q - centre).cross(&n) / radius;
                    let j = Vector6::new(a.x, a.y, a.z, n.x, n.y, n.z);
                    acc.h += (w * j) * j.transpose();
                    acc.g += (w * r) * j;
                }
                if r.abs() < scale {
                    acc.inliers += 1;
                    acc.sum_r2 += r * r;
                    if final_pass {
                        let a = q.coords.cross(&n);
                        let j = Vector6::new(a.x, a.y, a.z, n.x, n.y, n.z);
                        acc.info += j * j.transpose();
                        acc.sum_p += q.coords;
                        acc.sum_ppt += q.coords * q.coords.transpose();
                    }
                }
            }
            acc
        })
        .collect();
    let mut total = Acc::zero();
    for a in &partial {
        total.add(a);
    }
    total
}

/// The inlier statistics and the degeneracy of a final pose (see [`super::IcpResult`]).
pub(super) struct Statistics {
    /// RMS point-to-plane residual of the inliers, metres.
    pub(super) inlier_rms: f64,
    /// Inliers over source points.
    pub(super) inlier_fraction: f64,
    /// Source points with a usable target neighbour within the final distance.
    pub(super) correspondences: usize,
    /// How well the pose is constrained.
    pub(super) degeneracy: Degeneracy,
    /// Unweighted `Σ J₀ J₀ᵀ` over the inliers, `J₀ = (q × n, n)` about the target origin.
    pub(super) hessian: Matrix6<f64>,
    /// Inliers.
    pub(super) inliers: usize,
}

/// The statistics and degeneracy at `pose` and the final correspondence distance
/// (unconstrained, with no inlier, when there is no target or no source point), with
/// `cache` remembering `src`'s nearest target points.
pub(super) fn statistics(
    src: &Source,
    tgt: Option<&Target>,
    pose: &Isometry3<f64>,
    params: &IcpParams,
    cache: &mut NearestCache,
) -> Statistics {
    let pose = *pose;
    let (inlier_rms, inlier_fraction, correspondences, degeneracy, hessian, inliers) = match tgt {
        Some(tgt) if !src.points.is_empty() => {
            let acc = accumulate(
                src,
                tgt,
                &pose,
                params.max_distance_end,
                params,
                true,
                cache,
            );
            let rms = if acc.inliers > 0 {
                (acc.sum_r2 / acc.inliers as f64).sqrt()
            } else {
                0.0
            };
            let fraction = acc.inliers as f64 / src.points.len() as f64;
            (
                rms,
                fraction,
                acc.matched,
                acc.degeneracy(params.weak_fraction),
                acc.info,
                acc.inliers,
            )
        }
        _ => (
            0.0,
            0.0,
            0,
            Degeneracy::unconstrained(),
            Matrix6::zeros(),
            0,
        ),
    };
    Statistics {
        inlier_rms,
        inlier_fraction,
        correspondences,
        degeneracy,
        hessian,
        inliers,
    }
}
