//! Correlative scan matching in the plane (after Olson, "Real-time correlative scan
//! matching", ICRA 2009): an exhaustive search of `(x, y, theta)` in a window around a
//! guess, scoring each pose by how well the source points fall on a blurred image of the
//! target. It needs no good initial guess inside its window, and it sees the whole score
//! surface, so it can say how far the best answer stands out from the best *distinct* one:
//! the ambiguity a corridor or a row of identical doors creates.

use nalgebra::Vector2;

use crate::graph::Se2;

/// A blurred occupancy image of target points: each cell holds
/// `exp(−d² / 2σ²)` for `d` the distance from its centre to the nearest target point
/// (cut at 3σ).
pub struct ScoreGrid {
    origin: Vector2<f64>,
    resolution: f64,
    width: usize,
    height: usize,
    cells: Vec<f32>,
}

/// The most cells a [`ScoreGrid`] may have (64 Mi: 256 MiB of f32); a target spanning more
/// at the chosen resolution is refused by [`ScoreGrid::new`].
pub const MAX_GRID_CELLS: usize = 64 << 20;

impl ScoreGrid {
    /// The image of `points` at `resolution` metres with blur `sigma` metres; `None` when
    /// there are no points or the image would exceed [`MAX_GRID_CELLS`].
    pub fn new(points: &[Vector2<f64>], resolution: f64, sigma: f64) -> Option<ScoreGrid> {
        let first = points.first()?;
        let (mut lo, mut hi) = (*first, *first);
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let margin = 3.0 * sigma + resolution;
        lo -= Vector2::repeat(margin);
        hi += Vector2::repeat(margin);
        let width = ((hi.x - lo.x) / resolution).ceil() as usize + 1;
        let height = ((hi.y - lo.y) / resolution).ceil() as usize + 1;
        if width.checked_mul(height)? > MAX_GRID_CELLS {
            return None;
        }
        let mut cells = vec![0f32; width * height];
        let reach = (3.0 * sigma / resolution).ceil() as i64;
        let inv = 1.0 / (2.0 * sigma * sigma);
        for p in points {
            let cx = ((p.x - lo.x) / resolution).floor() as i64;
            let cy = ((p.y - lo.y) / resolution).floor() as i64;
            for dy in -reach..=reach {
                let y = cy + dy;
                if y < 0 || y >= height as i64 {
                    continue;
                }
                for dx in -reach..=reach {
                    let x = cx + dx;
                    if x < 0 || x >= width as i64 {
                        continue;
                    }
                    let centre = Vector2::new(
                        lo.x + (x as f64 + 0.5) * resolution,
                        lo.y + (y as f64 + 0.5) * resolution,
                    );
                    let v = (-(centre - p).norm_squared() * inv).exp() as f32;
                    let cell = &mut cells[y as usize * width + x as usize];
                    if v > *cell {
                        *cell = v;
                    }
                }
            }
        }
        Some(ScoreGrid {
            origin: lo,
            resolution,
            width,
            height,
            cells,
        })
    }

    /// The image's value at a point (0 outside).
    #[inline]
    pub fn value(&self, p: Vector2<f64>) -> f32 {
        let x = ((p.x - self.origin.x) / self.resolution).floor();
        let y = ((p.y - self.origin.y) / self.resolution).floor();
        if x < 0.0 || y < 0.0 || x >= self.width as f64 || y >= self.height as f64 {
            return 0.0;
        }
        self.cells[y as usize * self.width + x as usize]
    }

    /// The mean image value under `source` placed at `pose` (0 to 1).
    pub fn score(&self, source: &[Vector2<f64>], pose: &Se2) -> f64 {
        if source.is_empty() {
            return 0.0;
        }
        let (s, c) = pose.theta.sin_cos();
        let sum: f64 = source
            .iter()
            .map(|p| {
                self.value(Vector2::new(
                    c * p.x - s * p.y + pose.x,
                    s * p.x + c * p.y + pose.y,
                )) as f64
            })
            .sum();
        sum / source.len() as f64
    }
}

/// The search window and steps of [`search`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CorrelativeParams {
    /// Half-width of the window in x and y, metres.
    pub window_xy: f64,
    /// Half-width of the window in heading, degrees.
    pub window_yaw_deg: f64,
    /// Step in x and y, metres.
    pub step_xy: f64,
    /// Step in heading, degrees.
    pub step_yaw_deg: f64,
    /// Two solutions are distinct when farther apart than this in x-y (metres) …
    pub distinct_xy: f64,
    /// … or in heading (degrees).
    pub distinct_yaw_deg: f64,
}

impl Default for CorrelativeParams {
    fn default() -> Self {
        CorrelativeParams {
            window_xy: 1.0,
            window_yaw_deg: 10.0,
            step_xy: 0.05,
            step_yaw_deg: 1.0,
            distinct_xy: 0.4,
            distinct_yaw_deg: 6.0,
        }
    }
}

/// The outcome of [`search`].
#[derive(Debug, Clone, PartialEq)]
pub struct CorrelativeMatch {
    /// The best pose `T_target_source`.
    pub pose: Se2,
    /// Its score (mean blurred-image value of the source points, 0 to 1).
    pub score: f64,
    /// The best score among local maxima distinct from the best (0 when there is none).
    pub runner_up: f64,
    /// The distinct local maxima scoring at least [`RIVAL_SHARE`] of the best, best first
    /// (at most [`MAX_RIVALS`]): where the alternatives lie tells a corridor (all along
    /// one line through the best, at its heading) from a repeated place.
    pub rivals: Vec<(Se2, f64)>,
}

/// Distinct local maxima scoring at least this share of the best are kept as
/// [`CorrelativeMatch::rivals`].
pub const RIVAL_SHARE: f64 = 0.7;

/// The most rivals kept.
pub const MAX_RIVALS: usize = 32;

impl CorrelativeMatch {
    /// `runner_up / score`: 1 = as good an alternative exists, 0 = the best stands alone.
    pub fn ambiguity(&self) -> f64 {
        if self.score > 0.0 {
            self.runner_up / self.score
        } else {
            1.0
        }
    }
}

/// Searches the window around `centre` for the pose of `source` on `grid`.
pub fn search(
    grid: &ScoreGrid,
    source: &[Vector2<f64>],
    centre: Se2,
    params: &CorrelativeParams,
) -> CorrelativeMatch {
    let nxy = (params.window_xy / params.step_xy).round().max(0.0) as i64;
    let nth = (params.window_yaw_deg / params.step_yaw_deg)
        .round()
        .max(0.0) as i64;
    let side = (2 * nxy + 1) as usize;
    let layers = (2 * nth + 1) as usize;
    let mut scores = vec![0f64; side * side * layers];
    let idx = |a: usize, b: usize, k: usize| (k * side + b) * side + a;
    // Translations are whole multiples of the step: with the step a whole number of
    // cells, each rotated point's cell is found once per heading and shifted by integers.
    let cells_per_step = (params.step_xy / grid.resolution).round().max(1.0) as i64;
    let exact = ((cells_per_step as f64) * grid.resolution - params.step_xy).abs() < 1e-9;
    for k in 0..layers {
        let th = centre.theta + ((k as i64 - nth) as f64 * params.step_yaw_deg).to_radians();
        let (s, c) = th.sin_cos();
        let rotated: Vec<Vector2<f64>> = source
            .iter()
            .map(|p| Vector2::new(c * p.x - s * p.y, s * p.x + c * p.y))
            .collect();
        if exact {
            let corner = Vector2::new(
                centre.x - nxy as f64 * params.step_xy,
                centre.y - nxy as f64 * params.step_xy,
            );
            let cells: Vec<(i64, i64)> = rotated
                .iter()
                .map(|p| {
                    let q = p + corner - grid.origin;
                    (
                        (q.x / grid.resolution).floor() as i64,
                        (q.y / grid.resolution).floor() as i64,
                    )
                })
                .collect();
            let (w, h) = (grid.width as i64, grid.height as i64);
            for b in 0..side {
                let dy = b as i64 * cells_per_step;
                for a in 0..side {
                    let dx = a as i64 * cells_per_step;
                    let mut sum = 0f32;
                    for &(cx, cy) in &cells {
                        let (x, y) = (cx + dx, cy + dy);
                        if x >= 0 && y >= 0 && x < w && y < h {
                            sum += grid.cells[(y * w + x) as usize];
                        }
                    }
                    scores[idx(a, b, k)] = sum as f64 / source.len().max(1) as f64;
                }
            }
            continue;
        }
        for b in 0..side {
            let y = centre.y + (b as i64 - nxy) as f64 * params.step_xy;
            for a in 0..side {
                let x = centre.x + (a as i64 - nxy) as f64 * params.step_xy;
                let t = Vector2::new(x, y);
                let sum: f64 = rotated.iter().map(|p| grid.value(p + t) as f64).sum();
                scores[idx(a, b, k)] = sum / source.len().max(1) as f64;
            }
        }
    }
    let pose_of = |a: usize, b: usize, k: usize| {
        Se2::new(
            centre.x + (a as i64 - nxy) as f64 * params.step_xy,
            centre.y + (b as i64 - nxy) as f64 * params.step_xy,
            crate::geometry::wrap_angle(
                centre.theta + ((k as i64 - nth) as f64 * params.step_yaw_deg).to_radians(),
            ),
        )
    };
    let mut best = (0usize, 0usize, 0usize, f64::NEG_INFINITY);
    for k in 0..layers {
        for b in 0..side {
            for a in 0..side {
                let v = scores[idx(a, b, k)];
                if v > best.3 {
                    best = (a, b, k, v);
                }
            }
        }
    }
    let best_pose = pose_of(best.0, best.1, best.2);
    // The runner-up: the best local maximum (not below any of its 26 neighbours) that is
    // distinct from the best.
    let mut runner_up = 0f64;
    let mut rivals: Vec<(Se2, f64)> = Vec::new();
    let rival_floor = RIVAL_SHARE * best.3;
    for k in 0..layers {
        for b in 0..side {
            for a in 0..side {
                let v = scores[idx(a, b, k)];
                if v <= runner_up && v < rival_floor {
                    continue;
                }
                let p = pose_of(a, b, k);
                let far = (p.x - best_pose.x).hypot(p.y - best_pose.y) > params.distinct_xy
                    || crate::geometry::wrap_angle(p.theta - best_pose.theta)
                        .abs()
                        .to_degrees()
                        > params.distinct_yaw_deg;
                if !far {
                    continue;
                }
                let mut is_max = true;
                'n: for dk in -1i64..=1 {
                    for db in -1i64..=1 {
                        for da in -1i64..=1 {
                            let (na, nb, nk) = (a as i64 + da, b as i64 + db, k as i64 + dk);
                            if na < 0
                                || nb < 0
                                || nk < 0
                                || na >= side as i64
                                || nb >= side as i64
                                || nk >= layers as i64
                            {
                                continue;
                            }
                            if scores[idx(na as usize, nb as usize, nk as usize)] > v {
                                is_max = false;
                                break 'n;
                            }
                        }
                    }
                }
                if is_max {
                    runner_up = runner_up.max(v);
                    if v >= rival_floor {
                        rivals.push((p, v));
                    }
                }
            }
        }
    }
    rivals.sort_by(|x, y| y.1.total_cmp(&x.1));
    rivals.truncate(MAX_RIVALS);
    CorrelativeMatch {
        pose: best_pose,
        score: best.3.max(0.0),
        runner_up,
        rivals,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l_shape() -> Vec<Vector2<f64>> {
        let mut pts = Vec::new();
        for i in 0..80 {
            pts.push(Vector2::new(i as f64 * 0.05, 0.0));
            pts.push(Vector2::new(0.0, i as f64 * 0.05));
        }
        pts
    }

    #[test]
    fn finds_the_offset_of_a_corner_and_calls_it_unambiguous() {
        let target = l_shape();
        let grid = ScoreGrid::new(&target, 0.05, 0.05).unwrap();
        let truth = Se2::new(0.3, -0.2, 4f64.to_radians());
        let inv = truth.inverse();
        let source: Vec<Vector2<f64>> = target
            .iter()
            .map(|p| {
                let q = inv.compose(&Se2::new(p.x, p.y, 0.0));
                Vector2::new(q.x, q.y)
            })
            .collect();
        let m = search(
            &grid,
            &source,
            Se2::default(),
            &CorrelativeParams::default(),
        );
        assert!((m.pose.x - truth.x).abs() <= 0.05 + 1e-9, "{:?}", m.pose);
        assert!((m.pose.y - truth.y).abs() <= 0.05 + 1e-9, "{:?}", m.pose);
        assert!(
            (m.pose.theta - truth.theta).abs() <= 1f64.to_radians(),
            "{:?}",
            m.pose
        );
        assert!(m.ambiguity() < 0.8, "{m:?}");
    }

    #[test]
    fn parallel_walls_are_ambiguous_along_them() {
        let walls: Vec<Vector2<f64>> = (0..400)
            .flat_map(|i| {
                let x = i as f64 * 0.05 - 10.0;
                [Vector2::new(x, -1.0), Vector2::new(x, 1.0)]
            })
            .collect();
        let grid = ScoreGrid::new(&walls, 0.05, 0.05).unwrap();
        let source: Vec<Vector2<f64>> = walls[200..600].to_vec();
        let m = search(
            &grid,
            &source,
            Se2::default(),
            &CorrelativeParams::default(),
        );
        assert!(m.ambiguity() > 0.95, "{m:?}");
        // The near-best rivals lie along the walls, at the best heading.
        let near: Vec<_> = m.rivals.iter().filter(|r| r.1 > 0.95 * m.score).collect();
        assert!(!near.is_empty());
        for (p, _) in near {
            assert!(
                (p.y - m.pose.y).abs() <= 0.05 + 1e-9,
                "{p:?} vs {:?}",
                m.pose
            );
            assert!(
                (p.theta - m.pose.theta).abs() < 1e-9,
                "{p:?} vs {:?}",
                m.pose
            );
        }
    }
}
