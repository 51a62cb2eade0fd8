//! How surprising an overlap is: the hypergeometric model of thesis §5.3.2, (5.4)-(5.5).

/// The z-score of an overlap `o` of an `n`-voxel scan with an `m`-voxel map whose bounding
/// volume holds `v` cells: `(o - mean) / sigma` with `mean = n M / V` and
/// `sigma² = n (M/V) (1 - M/V) (V - n) / (V - 1)` (thesis (5.5)): how many standard
/// deviations the overlap lies above what `n` voxels dropped at random into the map would
/// give. Returns 0 when the model is undefined (empty scan or map, `V <= 1`).
///
/// ```
/// use olmap::align::significance;
/// // 100 of 1000 cells occupied; a 50-voxel scan expects 5 hits at random.
/// let z = significance(40, 50, 100, 1000.0);
/// assert!(z > 10.0);
/// assert!(significance(5, 50, 100, 1000.0).abs() < 1e-12);
/// ```
pub fn significance(o: u64, n: u64, m: u64, v: f64) -> f64 {
    if n == 0 || m == 0 || v <= 1.0 {
        return 0.0;
    }
    let (n, m, o) = (n as f64, m as f64, o as f64);
    let p = (m / v).min(1.0);
    let mean = n * p;
    let var = n * p * (1.0 - p) * (v - n).max(0.0) / (v - 1.0);
    if var <= 0.0 {
        return 0.0;
    }
    (o - mean) / var.sqrt()
}
