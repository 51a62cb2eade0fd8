//! The rotating-mirror scanner's error model (thesis §4.3.1 and §4.5): the angular errors
//! of the mirror-angle feedback, (4.7) and (4.8), and their propagation into Cartesian
//! coordinates through (4.10), equations (4.12)-(4.14).

use nalgebra::Vector3;

/// Thesis (4.7): the error in the reflected elevation `phi` due to the update rate of the
/// angle sensor, `delta phi = 4 pi / (f_m T)` radians, for an update frequency `f_m` (Hz)
/// and a mirror period `T` (s). The reflected ray turns twice as fast as the mirror, hence
/// `4 pi` rather than `2 pi`.
///
/// ```
/// use olmap::scanner::update_rate_error;
/// // A PS2 mouse at 100 Hz and a 20 s mirror period: 0.36 degrees.
/// let e = update_rate_error(100.0, 20.0).to_degrees();
/// assert!((e - 0.36).abs() < 0.005, "{e}");
/// ```
pub fn update_rate_error(update_frequency: f64, mirror_period: f64) -> f64 {
    4.0 * std::f64::consts::PI / (update_frequency * mirror_period)
}

/// Thesis (4.8): the digitisation error in `phi` of an angle sensor with `teeth` teeth on
/// its blocking wheel geared `gearing` times faster than the mirror,
/// `delta phi = 4 pi / (r_g b)` radians.
///
/// ```
/// use olmap::scanner::digitisation_error;
/// // The first-generation scanner: r_g = 25, b = 14 gives 2.1 degrees.
/// let e = digitisation_error(25.0, 14.0).to_degrees();
/// assert!((e - 2.1).abs() < 0.05, "{e}");
/// ```
pub fn digitisation_error(gearing: f64, teeth: f64) -> f64 {
    4.0 * std::f64::consts::PI / (gearing * teeth)
}

/// Thesis (4.12)-(4.14): the first-order change of the point (4.10) (2D scanner frame,
/// standard mounting) when the range `r`, scan angle `theta`, reflected elevation `phi`
/// and mirror offset `d` change by `dr`, `dtheta`, `dphi` and `dd`:
///
/// * `dx = cos phi cos theta dr - r cos phi sin theta dtheta - sin phi (r cos theta - d) dphi + (1 - cos phi) dd`
/// * `dy = sin theta dr + r cos theta dtheta`
/// * `dz = cos theta sin phi dr - r sin theta sin phi dtheta - sin phi dd + (r cos theta - d) cos phi dphi`
///
/// The error grows linearly with range (not quadratically as in triangulation, (4.6)).
/// For a worst-case bound pass the errors' magnitudes and take the absolute value of each
/// term yourself, or combine the per-term vectors.
///
/// ```
/// use olmap::scanner::cartesian_error;
/// // Only a range error: the point moves along the reflected beam.
/// let e = cartesian_error(4.0, 0.3, 1.0, 0.1, 0.02, 0.0, 0.0, 0.0);
/// assert!((e.norm() - 0.02).abs() < 1e-12);
/// ```
#[allow(clippy::too_many_arguments)]
pub fn cartesian_error(
    r: f64,
    theta: f64,
    phi: f64,
    d: f64,
    dr: f64,
    dtheta: f64,
    dphi: f64,
    dd: f64,
) -> Vector3<f64> {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    let q = r * ct - d;
    Vector3::new(
        cp * ct * dr - r * cp * st * dtheta - sp * q * dphi + (1.0 - cp) * dd,
        st * dr + r * ct * dtheta,
        ct * sp * dr - r * st * sp * dtheta - sp * dd + q * cp * dphi,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scanner::MirrorGeometry;

    #[test]
    fn propagation_matches_finite_differences_of_4_10() {
        let mut g = MirrorGeometry::standard();
        let (r, theta, phi, d) = (3.7, -0.4, 2.2, 0.1);
        let h = 1e-6;
        let p = |r: f64, t: f64, ph: f64, d: f64, g: &mut MirrorGeometry| {
            g.mirror_offset = d;
            g.point(r, t, ph / 2.0).coords
        };
        let p0 = p(r, theta, phi, d, &mut g);
        let cases = [
            (
                p(r + h, theta, phi, d, &mut g),
                cartesian_error(r, theta, phi, d, h, 0.0, 0.0, 0.0),
            ),
            (
                p(r, theta + h, phi, d, &mut g),
                cartesian_error(r, theta, phi, d, 0.0, h, 0.0, 0.0),
            ),
            (
                p(r, theta, phi + h, d, &mut g),
                cartesian_error(r, theta, phi, d, 0.0, 0.0, h, 0.0),
            ),
            (
                p(r, theta, phi, d + h, &mut g),
                cartesian_error(r, theta, phi, d, 0.0, 0.0, 0.0, h),
            ),
        ];
        for (k, (moved, lin)) in cases.iter().enumerate() {
            // Second-order remainder: about r h^2.
            assert!(((moved - p0) - lin).norm() < 1e-10, "term {k}");
        }
    }
}
