//! The update: the damped (or, along degenerate directions, reduced) solve of the 6x6
//! normal equations.

use nalgebra::{Matrix6, Vector3, Vector6};

/// Solves `(H + μ I) δ = -g` by Cholesky with `μ = 1e-6 · mean diagonal`, growing `μ` a
/// hundredfold while the factorisation fails. `None` when nothing works. When some
/// eigenvalue of `H` is below `degenerate_fraction` of the largest, solves in the span of
/// the well-determined eigenvectors only (no motion along the degenerate ones). The
/// eigenvalues are compared with each rotation coordinate rescaled by `axis_scale` (the RMS
/// distance of the points from that axis over the common radius), so that a unit step in
/// any coordinate moves the points by about the same amount.
pub(super) fn solve(
    h: &Matrix6<f64>,
    g: &Vector6<f64>,
    degenerate_fraction: f64,
    axis_scale: &Vector3<f64>,
) -> Option<Vector6<f64>> {
    let mean_diag = h.trace() / 6.0;
    if !(mean_diag.is_finite() && mean_diag > 0.0 && g.iter().all(|v| v.is_finite())) {
        return None;
    }
    if degenerate_fraction > 0.0 {
        // δ = A u with A = diag(1 / axis_scale, 1, 1, 1): u moves points by metres RMS.
        let a = Vector6::new(
            1.0 / axis_scale.x,
            1.0 / axis_scale.y,
            1.0 / axis_scale.z,
            1.0,
            1.0,
            1.0,
        );
        let hu = Matrix6::from_fn(|i, j| a[i] * h[(i, j)] * a[j]);
        let gu = g.component_mul(&a);
        let eig = hu.symmetric_eigen();
        let max = eig.eigenvalues.max();
        let floor = degenerate_fraction * max;
        if max > 0.0 && eig.eigenvalues.iter().any(|&l| l < floor) {
            let mut u = Vector6::zeros();
            for (i, &l) in eig.eigenvalues.iter().enumerate() {
                if l >= floor {
                    let v = eig.eigenvectors.column(i);
                    u -= v * (v.dot(&gu) / l);
                }
            }
            let x = u.component_mul(&a);
            return x.iter().all(|v| v.is_finite()).then_some(x);
        }
    }
    let mut mu = 1e-6 * mean_diag;
    for _ in 0..8 {
        let a = h + Matrix6::identity() * mu;
        if let Some(chol) = a.cholesky() {
            let x = -chol.solve(g);
            if x.iter().all(|v| v.is_finite()) {
                return Some(x);
            }
        }
        mu *= 100.0;
    }
    None
}
