//! How well an alignment constrains each degree of freedom: the eigen-decomposition of the
//! point-to-plane information matrix ([`Degeneracy`]).

use nalgebra::{Matrix6, SymmetricEigen};

/// Names of the six coordinates `(ωx, ωy, ωz, vx, vy, vz)` used in [`Degeneracy::weak`].
const AXIS_NAMES: [&str; 6] = [
    "rotation about x",
    "rotation about y",
    "rotation about z",
    "translation along x",
    "translation along y",
    "translation along z",
];

/// The smallest eigenvalue of the strongest horizontal direction for it to be the reference
/// of [`Degeneracy::free_searched_axes`]: one thousandth of the inliers' squared normal
/// components lying in the horizontal plane.
pub const MIN_HORIZONTAL: f64 = 1e-3;

/// How well the final alignment constrains each of the six degrees of freedom.
///
/// From the unweighted point-to-plane information matrix `(1/N) Σ J Jᵀ` over the `N` inliers
/// at the final estimate, in the coordinates `(ωx·Lx, ωy·Ly, ωz·Lz, vx, vy, vz)`: `ω` rotates
/// about the target frame's axes through the inliers' centroid, `Lk` is the RMS distance of
/// the inliers from axis `k`, and `v` translates along the target frame's axes. A unit step
/// in these coordinates moves the inliers by one metre RMS; the eigenvalue of a direction is
/// the mean squared residual change that step causes, in `[0, 1]` for the coordinate axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Degeneracy {
    /// The eigenvalues, ascending.
    pub eigenvalues: [f64; 6],
    /// `eigenvectors[i]` is the unit eigenvector of `eigenvalues[i]` in the coordinates
    /// `(ωx·Lx, ωy·Ly, ωz·Lz, vx, vy, vz)`, signed so that its largest component is positive.
    pub eigenvectors: [[f64; 6]; 6],
    /// `max / min` eigenvalue (infinite when the smallest is zero).
    pub condition: f64,
    /// The directions whose eigenvalue is below [`super::IcpParams::weak_fraction`] of the largest,
    /// weakest first, each named by its dominant component and that component's magnitude,
    /// e.g. `"translation along x (0.98)"`.
    pub weak: Vec<String>,
    /// The fraction of the largest eigenvalue below which a direction is weak (the
    /// [`super::IcpParams::weak_fraction`] in force).
    pub weak_fraction: f64,
}

impl Degeneracy {
    /// The report for no data at all: every direction unconstrained.
    pub(super) fn unconstrained() -> Self {
        let mut eigenvectors = [[0.0; 6]; 6];
        for (i, v) in eigenvectors.iter_mut().enumerate() {
            v[i] = 1.0;
        }
        Degeneracy {
            eigenvalues: [0.0; 6],
            eigenvectors,
            condition: f64::INFINITY,
            weak: AXIS_NAMES.iter().map(|n| format!("{n} (1.00)")).collect(),
            weak_fraction: 1.0,
        }
    }

    /// The names of the coordinate axes (`"translation along x"`, ...) that weak directions
    /// leave free, among those `searched` (`(ωx, ωy, ωz, vx, vy, vz)`): a weak direction
    /// counts when most of it (squared components summing to at least one half) lies on
    /// searched axes, and is named by its largest searched component. Each name once.
    ///
    /// "Weak" is measured against the strongest *horizontal* direction (one dominated by
    /// the heading or a horizontal translation), not against the strongest of all: the
    /// floor and ceiling of an indoor scan make height, roll and pitch dozens of times
    /// stronger than anything horizontal, and measured against them every room looked like
    /// a corridor (a simulated lab with most inliers on its floor was refused for "y
    /// unconstrained"). With no horizontal direction stronger than [`MIN_HORIZONTAL`]
    /// (a floor alone), every searched horizontal axis is free.
    pub fn free_searched_axes(&self, searched: [bool; 6]) -> Vec<&'static str> {
        let dominant = |v: &[f64; 6]| {
            (0..6)
                .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
                .unwrap_or(0)
        };
        let horizontal = (0..6)
            .filter(|&k| (2..=4).contains(&dominant(&self.eigenvectors[k])))
            .map(|k| self.eigenvalues[k])
            .fold(0.0, f64::max);
        let max = if horizontal >= MIN_HORIZONTAL {
            horizontal
        } else {
            self.eigenvalues[5]
        };
        let mut out: Vec<&'static str> = Vec::new();
        for k in 0..6 {
            if !(self.eigenvalues[k] < self.weak_fraction * max || max <= 0.0) {
                continue;
            }
            let v = &self.eigenvectors[k];
            let on_searched: f64 = (0..6).filter(|&j| searched[j]).map(|j| v[j] * v[j]).sum();
            if on_searched < 0.5 {
                continue;
            }
            let j = (0..6)
                .filter(|&j| searched[j])
                .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
                .unwrap_or(0);
            if !out.contains(&AXIS_NAMES[j]) {
                out.push(AXIS_NAMES[j]);
            }
        }
        out
    }

    /// Eigen-decomposition of a normalised information matrix.
    pub(super) fn from_information(m: &Matrix6<f64>, weak_fraction: f64) -> Self {
        let eig = SymmetricEigen::new(*m);
        // nalgebra does not sort the eigenvalues.
        let mut order: [usize; 6] = [0, 1, 2, 3, 4, 5];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let mut eigenvalues = [0.0; 6];
        let mut eigenvectors = [[0.0; 6]; 6];
        for (k, &i) in order.iter().enumerate() {
            eigenvalues[k] = eig.eigenvalues[i].max(0.0);
            let col = eig.eigenvectors.column(i);
            let dominant = (0..6)
                .max_by(|&a, &b| col[a].abs().total_cmp(&col[b].abs()))
                .unwrap_or(0);
            let sign = if col[dominant] < 0.0 { -1.0 } else { 1.0 };
            for j in 0..6 {
                eigenvectors[k][j] = sign * col[j];
            }
        }
        let (min, max) = (eigenvalues[0], eigenvalues[5]);
        let condition = if min > 0.0 { max / min } else { f64::INFINITY };
        let weak = (0..6)
            .filter(|&k| eigenvalues[k] < weak_fraction * max || max <= 0.0)
            .map(|k| {
                let v = &eigenvectors[k];
                let j = (0..6)
                    .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
                    .unwrap_or(0);
                format!("{} ({:.2})", AXIS_NAMES[j], v[j].abs())
            })
            .collect();
        Degeneracy {
            eigenvalues,
            eigenvectors,
            condition,
            weak,
            weak_fraction,
        }
    }
}
