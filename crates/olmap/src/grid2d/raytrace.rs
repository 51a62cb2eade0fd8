//! Bresenham's line over grid cells: the cells a beam crosses (thesis §3.3.3, the ray-trace
//! sensor model).
//!
//! The line from cell `a` to cell `b` visits one cell per step along its major axis (the
//! axis of the larger difference), `max(|dx|, |dy|) + 1` cells in all, each 8-connected to
//! the previous one. At major step `k` of `n` the minor coordinate is the one nearest the
//! ideal line through the two cell centres, `minor_a + k dminor / n`, with ties rounded
//! toward +minor after ordering the ends by their major coordinate; so the line does not
//! depend on the direction it is traced in: `bresenham(b, a)` visits the cells of
//! `bresenham(a, b)` in reverse order. Only integer arithmetic is used.

/// The cells of the line from `from` to `to`, both included, in order from `from`.
///
/// ```
/// use olmap::grid2d::bresenham;
/// let cells: Vec<_> = bresenham((0, 0), (4, -2)).collect();
/// // Ties (x = 1 and 3 lie half way between two rows) go to the upper row.
/// assert_eq!(cells, [(0, 0), (1, 0), (2, -1), (3, -1), (4, -2)]);
/// let mut back: Vec<_> = bresenham((4, -2), (0, 0)).collect();
/// back.reverse();
/// assert_eq!(back, cells);
/// ```
pub fn bresenham(from: (i64, i64), to: (i64, i64)) -> Bresenham {
    let dx = to.0 - from.0;
    let dy = to.1 - from.1;
    let x_major = dx.abs() >= dy.abs();
    let (fm, fn_, tm, tn) = if x_major {
        (from.0, from.1, to.0, to.1)
    } else {
        (from.1, from.0, to.1, to.0)
    };
    // Order the ends by their major coordinate: the canonical start `s`.
    let forward = fm <= tm;
    let (s_major, s_minor, e_major, e_minor) = if forward {
        (fm, fn_, tm, tn)
    } else {
        (tm, tn, fm, fn_)
    };
    let n = e_major - s_major;
    Bresenham {
        x_major,
        s_major,
        s_minor,
        d_minor: e_minor - s_minor,
        n,
        k: if forward { 0 } else { n },
        forward,
        left: n as u64 + 1,
    }
}

/// Iterator over the cells of a line; see [`bresenham`].
#[derive(Debug, Clone)]
pub struct Bresenham {
    x_major: bool,
    s_major: i64,
    s_minor: i64,
    d_minor: i64,
    n: i64,
    k: i64,
    forward: bool,
    left: u64,
}

impl Iterator for Bresenham {
    type Item = (i64, i64);

    fn next(&mut self) -> Option<(i64, i64)> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        let k = self.k;
        let minor = if self.n == 0 {
            self.s_minor
        } else {
            // Nearest integer to s_minor + k d / n, halves rounded up: floor((2kd + n) / 2n).
            self.s_minor + (2 * k * self.d_minor + self.n).div_euclid(2 * self.n)
        };
        let major = self.s_major + k;
        if self.forward {
            self.k += 1;
        } else {
            self.k -= 1;
        }
        Some(if self.x_major {
            (major, minor)
        } else {
            (minor, major)
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.left as usize, Some(self.left as usize))
    }
}

impl ExactSizeIterator for Bresenham {}
