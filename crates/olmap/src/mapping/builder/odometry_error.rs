//! How far each robot's odometry has been off lately, and the first odometry window that
//! makes worth searching.
//!
//! [`super::State::register`] searches a window around the odometry prediction, doubles it
//! twice when the result is not trusted, then searches as wide as the odometry tolerance.
//! It trusts a match only in the inner half of a window (a wider window must find a match
//! in the outer half again: [`super::register`]), so when the prediction is typically
//! farther off than half the first window, the first search, and often the second, is
//! spent. With the thesis' degraded odometry (0.35 m σ per axis and 10° per move, §6.5)
//! the default ±0.5 m window holds the truth in its inner half about a quarter of the time.
//!
//! Every placed scan with an odometry prediction leaves its *residual*, the placed pose
//! against the prediction, here, per odometry frame (robot). Odometry error grows as a
//! random walk with the moves between the scan predicted from and the scan predicted, so a
//! residual is kept per move (its square divided by the moves: the robot's own scans
//! between the two) and scaled back by the next scan's moves. From the last [`RECENT`] residuals of its frame (at least
//! [`MIN_RESIDUALS`]; before that, of every frame) a scan's expected error σ per
//! horizontal axis and in heading is the RMS; the windows smaller than [`INNER_SIGMAS`] σ in the inner half (or
//! [`HEADING_SIGMAS`] σ of heading) are skipped. The windows searched keep their sizes and
//! every trust test: skipping a window only spares a search whose answer would not be
//! trusted where the truth most likely lies.

use std::collections::VecDeque;

use crate::geometry::{wrap_angle, Pose};

/// Residuals kept per frame (the most recent).
pub(super) const RECENT: usize = 8;

/// Fewest residuals of a frame before any window is skipped.
pub(super) const MIN_RESIDUALS: usize = 3;

/// A window is searched first when its inner half (the part where a match is trusted)
/// reaches this many expected errors σ along each horizontal axis (2σ: 95 % per axis).
pub(super) const INNER_SIGMAS: f64 = 2.0;

/// ... and its heading range this many expected heading errors.
pub(super) const HEADING_SIGMAS: f64 = 2.0;

/// One residual per move: squared horizontal error per axis and squared heading error,
/// each divided by the moves the prediction spanned.
#[derive(Debug, Clone, Copy)]
struct Residual {
    axis2: f64,
    heading2: f64,
}

/// The recent odometry residuals of every frame.
#[derive(Debug, Clone, Default)]
pub(super) struct OdometryResiduals {
    by_frame: Vec<VecDeque<Residual>>,
}

impl OdometryResiduals {
    /// Records the residual of a scan of `frame` placed at `placed` where odometry
    /// predicted `predicted` over `moves` moves (at least 1).
    pub(super) fn record(&mut self, frame: usize, predicted: &Pose, placed: &Pose, moves: u64) {
        let moves = moves.max(1) as f64;
        let d = placed.translation() - predicted.translation();
        let (y0, _, _) = predicted.yaw_pitch_roll();
        let (y1, _, _) = placed.yaw_pitch_roll();
        let dy = wrap_angle(y1 - y0);
        let r = Residual {
            axis2: 0.5 * (d.x * d.x + d.y * d.y) / moves,
            heading2: dy * dy / moves,
        };
        if !(r.axis2.is_finite() && r.heading2.is_finite()) {
            return;
        }
        if self.by_frame.len() <= frame {
            self.by_frame.resize_with(frame + 1, VecDeque::new);
        }
        let q = &mut self.by_frame[frame];
        if q.len() == RECENT {
            q.pop_front();
        }
        q.push_back(r);
    }

    /// Forgets every residual (the poses they were measured on changed).
    pub(super) fn clear(&mut self) {
        self.by_frame.clear();
    }

    /// The expected error of a prediction over `moves` moves in `frame`: σ per horizontal
    /// axis (metres) and σ of heading (radians), from the frame's residuals when it has
    /// [`MIN_RESIDUALS`], else from every frame's together (a robot's first scans, taken
    /// as the team's robots drive: one team usually shares its odometry); `None` when
    /// fewer are known.
    pub(super) fn expected(&self, frame: usize, moves: u64) -> Option<(f64, f64)> {
        let own = self
            .by_frame
            .get(frame)
            .filter(|q| q.len() >= MIN_RESIDUALS);
        let residuals: Vec<Residual> = match own {
            Some(q) => q.iter().copied().collect(),
            None => self.by_frame.iter().flatten().copied().collect(),
        };
        if residuals.len() < MIN_RESIDUALS {
            return None;
        }
        let n = residuals.len() as f64;
        let moves = moves.max(1) as f64;
        let axis = (moves * residuals.iter().map(|r| r.axis2).sum::<f64>() / n).sqrt();
        let heading = (moves * residuals.iter().map(|r| r.heading2).sum::<f64>() / n).sqrt();
        Some((axis, heading))
    }
}

/// The first of the window `growths` (factors of the first window `(xy, yaw)`, ascending)
/// worth searching for a prediction expected `expected` off (σ per axis, σ of heading):
/// the smallest whose inner half reaches [`INNER_SIGMAS`] σ and whose heading range
/// reaches [`HEADING_SIGMAS`] σ, else the largest. Without an expectation, the first.
pub(super) fn first_growth(
    growths: &[f64],
    xy: f64,
    yaw: f64,
    expected: Option<(f64, f64)>,
) -> usize {
    let Some((axis, heading)) = expected else {
        return 0;
    };
    growths
        .iter()
        .position(|&g| {
            0.5 * g * xy >= INNER_SIGMAS * axis
                && (g * yaw >= HEADING_SIGMAS * heading || g * yaw >= std::f64::consts::PI)
        })
        .unwrap_or(growths.len().saturating_sub(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nothing_is_expected_before_enough_residuals() {
        let mut r = OdometryResiduals::default();
        let p = Pose::identity();
        let q = Pose::from_xyz_ypr(0.3, -0.3, 0.0, 0.1, 0.0, 0.0);
        r.record(1, &p, &q, 1);
        r.record(1, &p, &q, 1);
        assert!(r.expected(1, 1).is_none());
        assert!(r.expected(0, 1).is_none());
        r.record(1, &p, &q, 1);
        let (axis, heading) = r.expected(1, 1).unwrap();
        assert!((axis - 0.3).abs() < 1e-12);
        assert!((heading - 0.1).abs() < 1e-12);
        // A frame with too few of its own borrows the team's.
        assert_eq!(r.expected(0, 1), r.expected(1, 1));
        r.record(0, &p, &p, 1);
        let (pooled, _) = r.expected(0, 1).unwrap();
        assert!((pooled - (3.0 * 0.09f64 / 4.0).sqrt()).abs() < 1e-12);
        // A random walk: four moves, twice the error.
        let (axis4, _) = r.expected(1, 4).unwrap();
        assert!((axis4 - 0.6).abs() < 1e-12);
        r.clear();
        assert!(r.expected(1, 1).is_none());
    }

    #[test]
    fn residuals_are_per_move_and_only_the_recent_ones_count() {
        let mut r = OdometryResiduals::default();
        let p = Pose::identity();
        // Two moves of 0.2 m error each along x: 0.2·√2 in all.
        let far = Pose::from_xyz_ypr(0.2 * 2f64.sqrt() * 2f64.sqrt(), 0.0, 0.0, 0.0, 0.0, 0.0);
        for _ in 0..RECENT {
            r.record(0, &p, &far, 2);
        }
        let (axis, _) = r.expected(0, 1).unwrap();
        // Per axis: 0.4² / 2 (two axes) / 2 (moves) = 0.04 → 0.2 m.
        assert!((axis - 0.2).abs() < 1e-12);
        // Newer, exact predictions push the old ones out.
        for _ in 0..RECENT {
            r.record(0, &p, &p, 1);
        }
        assert_eq!(r.expected(0, 1).unwrap(), (0.0, 0.0));
    }

    #[test]
    fn the_first_window_searched_holds_two_sigma_in_its_inner_half() {
        let growths = [1.0, 2.0, 4.0];
        let (xy, yaw) = (0.5, 10f64.to_radians());
        assert_eq!(first_growth(&growths, xy, yaw, None), 0);
        // Good odometry: the ±0.5 m window (inner ±0.25 m) holds 2 × 0.1 m.
        assert_eq!(first_growth(&growths, xy, yaw, Some((0.1, 0.02))), 0);
        // The thesis' degraded odometry, 0.35 m and 10° per move: ±2 m (inner ±1 m ≥ 0.7 m).
        assert_eq!(
            first_growth(&growths, xy, yaw, Some((0.35, 10f64.to_radians()))),
            2
        );
        // Heading alone can call for a wider window: 2 × 8° needs ±20°.
        assert_eq!(
            first_growth(&growths, xy, yaw, Some((0.05, 8f64.to_radians()))),
            1
        );
        // Worse than every window: the widest.
        assert_eq!(first_growth(&growths, xy, yaw, Some((50.0, 0.0))), 2);
    }
}
