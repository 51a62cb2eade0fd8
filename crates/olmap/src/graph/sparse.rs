//! A block-sparse Cholesky factorisation for the normal equations of a pose graph.
//!
//! The unknowns are blocks of `B` numbers (one per node: `B` = 3 for SE(2), 6 for SE(3), or
//! 2 / 3 for the initialisation's rotation and position problems). The ordering is a
//! minimum-degree ordering of the node graph (ties broken by the node's index, so it is
//! deterministic), computed by eliminating the graph explicitly; the elimination gives
//! the block pattern of the factor `L` at the same time. The numeric factorisation is a
//! right-looking block Cholesky over that pattern with fixed-size dense blocks.
//!
//! The matrix is assembled directly in the factor's layout: the diagonal blocks and, for
//! every pair of coupled nodes, the block in the lower triangle (row = the node
//! eliminated later).

use std::collections::BTreeSet;

use nalgebra::SMatrix;
use rayon::prelude::*;

/// Columns with at least this many off-diagonal blocks update the later columns in
/// parallel (below it the work is too small to share).
const PARALLEL_COLUMN: usize = 24;

/// The block pattern of `L` for one graph structure and its elimination order.
#[derive(Debug, Clone)]
pub(crate) struct Symbolic {
    /// `order[k]` = the variable eliminated k-th.
    pub order: Vec<usize>,
    /// `position[v]` = when variable v is eliminated.
    pub position: Vec<usize>,
    /// Column k (a position) has rows `rows[col_start[k]..col_start[k + 1]]` (positions > k,
    /// increasing).
    pub col_start: Vec<usize>,
    /// Row positions of the off-diagonal blocks, column by column.
    pub rows: Vec<usize>,
}

impl Symbolic {
    /// Orders `n` variables coupled by `pairs` (i != j; duplicates allowed) by minimum
    /// degree and computes the pattern of the factor.
    pub fn new(n: usize, pairs: impl IntoIterator<Item = (usize, usize)>) -> Symbolic {
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (i, j) in pairs {
            debug_assert!(i != j && i < n && j < n);
            adj[i].push(j);
            adj[j].push(i);
        }
        for a in &mut adj {
            a.sort_unstable();
            a.dedup();
        }
        let mut queue: BTreeSet<(usize, usize)> = (0..n).map(|v| (adj[v].len(), v)).collect();
        let mut eliminated = vec![false; n];
        let mut order = Vec::with_capacity(n);
        // The neighbours of each variable when it was eliminated (= its column's rows).
        let mut columns: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut merged = Vec::new();
        while let Some((_, v)) = queue.pop_first() {
            eliminated[v] = true;
            order.push(v);
            let nbrs = std::mem::take(&mut adj[v]);
            // The neighbours become a clique: adj[u] = (adj[u] | nbrs) - {u, v}.
            for &u in &nbrs {
                let old = adj[u].len();
                merged.clear();
                let (a, b) = (&adj[u], &nbrs);
                let (mut x, mut y) = (0, 0);
                while x < a.len() || y < b.len() {
                    let next = if y >= b.len() || (x < a.len() && a[x] <= b[y]) {
                        let t = a[x];
                        if y < b.len() && b[y] == t {
                            y += 1;
                        }
                        x += 1;
                        t
                    } else {
                        let t = b[y];
                        y += 1;
                        t
                    };
                    if next != u && next != v {
                        merged.push(next);
                    }
                }
                std::mem::swap(&mut adj[u], &mut merged);
                if adj[u].len() != old {
                    queue.remove(&(old, u));
                    queue.insert((adj[u].len(), u));
                }
            }
            columns[v] = nbrs;
        }
        debug_assert!(eliminated.iter().all(|&e| e));
        let mut position = vec![0; n];
        for (k, &v) in order.iter().enumerate() {
            position[v] = k;
        }
        let mut col_start = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        col_start.push(0);
        for &v in &order {
            let start = rows.len();
            rows.extend(columns[v].iter().map(|&u| position[u]));
            rows[start..].sort_unstable();
            col_start.push(rows.len());
        }
        Symbolic {
            order,
            position,
            col_start,
            rows,
        }
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// Number of off-diagonal blocks of `L`.
    pub fn off_diagonal_blocks(&self) -> usize {
        self.rows.len()
    }

    /// Where the block coupling variables `i` and `j` (i != j) is stored, and whether the
    /// stored block is the transpose of the `(i, j)` block (i.e. i is eliminated first).
    pub fn slot(&self, i: usize, j: usize) -> Option<(usize, bool)> {
        let (pi, pj) = (self.position[i], self.position[j]);
        let (row, col, transposed) = if pi > pj {
            (pi, pj, false)
        } else {
            (pj, pi, true)
        };
        let range = self.col_start[col]..self.col_start[col + 1];
        let k = self.rows[range.clone()].binary_search(&row).ok()?;
        Some((range.start + k, transposed))
    }
}

/// A symmetric block matrix stored in the layout of its factor: `diag[k]` and `off[s]` are
/// indexed by elimination position and slot.
#[derive(Debug, Clone)]
pub(crate) struct BlockMatrix<const B: usize> {
    pub diag: Vec<SMatrix<f64, B, B>>,
    pub off: Vec<SMatrix<f64, B, B>>,
}

impl<const B: usize> BlockMatrix<B> {
    /// A zero matrix of the symbolic pattern's shape.
    pub fn zeros(sym: &Symbolic) -> Self {
        BlockMatrix {
            diag: vec![SMatrix::zeros(); sym.len()],
            off: vec![SMatrix::zeros(); sym.off_diagonal_blocks()],
        }
    }

    /// Sets every block to zero.
    pub fn clear(&mut self) {
        self.diag.iter_mut().for_each(|m| m.fill(0.0));
        self.off.iter_mut().for_each(|m| m.fill(0.0));
    }

    /// Adds `m` to the diagonal block of variable `v`.
    pub fn add_diag(&mut self, sym: &Symbolic, v: usize, m: &SMatrix<f64, B, B>) {
        self.diag[sym.position[v]] += m;
    }

    /// Adds `m` to the block `(i, j)` (and so `m^T` to `(j, i)`) at a slot from
    /// [`Symbolic::slot`].
    pub fn add_off(&mut self, slot: (usize, bool), m: &SMatrix<f64, B, B>) {
        if slot.1 {
            self.off[slot.0] += m.transpose();
        } else {
            self.off[slot.0] += m;
        }
    }
}

/// The Cholesky factor `L` (lower, `A = L L^T` in elimination order), with the inverses
/// of its diagonal blocks.
#[derive(Debug, Clone)]
pub(crate) struct Factor<const B: usize> {
    diag_inv: Vec<SMatrix<f64, B, B>>,
    off: Vec<SMatrix<f64, B, B>>,
}

/// The Cholesky factor of a small dense block, or `None` when it is not positive definite.
fn dense_cholesky<const B: usize>(a: &SMatrix<f64, B, B>) -> Option<SMatrix<f64, B, B>> {
    let mut l = SMatrix::<f64, B, B>::zeros();
    for j in 0..B {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let d = d.sqrt();
        l[(j, j)] = d;
        for i in j + 1..B {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / d;
        }
    }
    Some(l)
}

/// The inverse of a lower-triangular block with a positive diagonal.
fn lower_inverse<const B: usize>(l: &SMatrix<f64, B, B>) -> SMatrix<f64, B, B> {
    let mut inv = SMatrix::<f64, B, B>::zeros();
    for j in 0..B {
        inv[(j, j)] = 1.0 / l[(j, j)];
        for i in j + 1..B {
            let mut s = 0.0;
            for k in j..i {
                s -= l[(i, k)] * inv[(k, j)];
            }
            inv[(i, j)] = s / l[(i, i)];
        }
    }
    inv
}

impl<const B: usize> Factor<B> {
    /// Factors `a` (consumed as the workspace). `None` when `a` is not positive definite.
    ///
    /// Column k's update of the later columns touches one column per row of column k, each
    /// a different one: those updates run in parallel when the column is long. Every
    /// block still receives its updates in the same order (column by column), so the
    /// result does not depend on the thread count.
    pub fn new(sym: &Symbolic, a: BlockMatrix<B>) -> Option<Factor<B>> {
        let BlockMatrix { mut diag, mut off } = a;
        let n = sym.len();
        let mut diag_inv = Vec::with_capacity(n);
        for k in 0..n {
            let l = dense_cholesky(&diag[k])?;
            let linv = lower_inverse(&l);
            let linv_t = linv.transpose();
            let (s0, s1) = (sym.col_start[k], sym.col_start[k + 1]);
            for block in &mut off[s0..s1] {
                *block *= linv_t;
            }
            diag_inv.push(linv);
            if s0 == s1 {
                continue;
            }
            // Right-looking update of the later columns: A_rc -= L_rk L_ck^T. Split the
            // storage into column k (read) and the target columns (written).
            let (head, tail) = off.split_at_mut(s1);
            let col_k = &head[s0..s1];
            let rows_k = &sym.rows[s0..s1];
            let mut targets = Vec::with_capacity(s1 - s0);
            let mut rest = tail;
            let mut offset = s1;
            let (_, mut diag_rest) = diag.split_at_mut(k + 1);
            let mut diag_offset = k + 1;
            for &r in rows_k {
                let (c0, c1) = (sym.col_start[r], sym.col_start[r + 1]);
                let (_, after) = rest.split_at_mut(c0 - offset);
                let (col, after) = after.split_at_mut(c1 - c0);
                rest = after;
                offset = c1;
                let (_, d_after) = diag_rest.split_at_mut(r - diag_offset);
                let (d, d_after) = d_after.split_at_mut(1);
                diag_rest = d_after;
                diag_offset = r + 1;
                targets.push((r, &mut d[0], col));
            }
            let update = |a: usize,
                          (r, d, col): (
                usize,
                &mut SMatrix<f64, B, B>,
                &mut [SMatrix<f64, B, B>],
            )| {
                let lak_t = col_k[a].transpose();
                *d -= col_k[a] * lak_t;
                // Column r holds every row r_b (b > a) of column k: walk it in step.
                let rows_r = &sym.rows[sym.col_start[r]..sym.col_start[r + 1]];
                let mut p = 0;
                for b in a + 1..rows_k.len() {
                    let rb = rows_k[b];
                    while rows_r[p] < rb {
                        p += 1;
                    }
                    col[p] -= col_k[b] * lak_t;
                }
            };
            if rows_k.len() >= PARALLEL_COLUMN {
                targets
                    .into_par_iter()
                    .enumerate()
                    .for_each(|(a, t)| update(a, t));
            } else {
                for (a, t) in targets.into_iter().enumerate() {
                    update(a, t);
                }
            }
        }
        Some(Factor { diag_inv, off })
    }

    /// Solves `A x = b` for `C` right-hand sides; `b` and the result are indexed by
    /// variable (not by position).
    pub fn solve<const C: usize>(
        &self,
        sym: &Symbolic,
        b: &[SMatrix<f64, B, C>],
    ) -> Vec<SMatrix<f64, B, C>> {
        let n = sym.len();
        let mut x: Vec<SMatrix<f64, B, C>> = sym.order.iter().map(|&v| b[v]).collect();
        // Forward: L y = b.
        for k in 0..n {
            let yk = self.diag_inv[k] * x[k];
            x[k] = yk;
            for s in sym.col_start[k]..sym.col_start[k + 1] {
                let r = sym.rows[s];
                x[r] -= self.off[s] * yk;
            }
        }
        // Backward: L^T x = y.
        for k in (0..n).rev() {
            let mut acc = x[k];
            for s in sym.col_start[k]..sym.col_start[k + 1] {
                acc -= self.off[s].transpose() * x[sym.rows[s]];
            }
            x[k] = self.diag_inv[k].transpose() * acc;
        }
        let mut out = vec![SMatrix::<f64, B, C>::zeros(); n];
        for (k, &v) in sym.order.iter().enumerate() {
            out[v] = x[k];
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

    /// An SPD block matrix on the graph `pairs`, solved by the sparse factor and by a dense
    /// Cholesky; returns the sparse solution's largest difference and the longest column.
    fn sparse_against_dense(n: usize, pairs: &[(usize, usize)], seed: u64) -> (f64, usize) {
        let sym = Symbolic::new(n, pairs.iter().copied());
        let mut a = BlockMatrix::<3>::zeros(&sym);
        let mut dense = DMatrix::<f64>::zeros(3 * n, 3 * n);
        let mut seed = seed;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for &(i, j) in pairs {
            // A sum of terms [M M^T + I, -M; -M^T, M^T M + I]-like blocks stays SPD.
            let m = Matrix3::from_fn(|_, _| rnd());
            let aii = m * m.transpose() + Matrix3::identity();
            let ajj = m.transpose() * m + Matrix3::identity();
            let aij = -m;
            a.add_diag(&sym, i, &aii);
            a.add_diag(&sym, j, &ajj);
            a.add_off(sym.slot(i, j).unwrap(), &aij);
            for r in 0..3 {
                for c in 0..3 {
                    dense[(3 * i + r, 3 * i + c)] += aii[(r, c)];
                    dense[(3 * j + r, 3 * j + c)] += ajj[(r, c)];
                    dense[(3 * i + r, 3 * j + c)] += aij[(r, c)];
                    dense[(3 * j + c, 3 * i + r)] += aij[(r, c)];
                }
            }
        }
        let longest = (0..n)
            .map(|k| sym.col_start[k + 1] - sym.col_start[k])
            .max()
            .unwrap();
        let b: Vec<SMatrix<f64, 3, 1>> =
            (0..n).map(|_| Vector3::new(rnd(), rnd(), rnd())).collect();
        let f = Factor::new(&sym, a).expect("SPD");
        let x = f.solve(&sym, &b);
        let bd = DVector::from_iterator(3 * n, b.iter().flat_map(|v| v.iter().copied()));
        let xd = dense.cholesky().expect("SPD").solve(&bd);
        let mut worst = 0.0f64;
        for v in 0..n {
            for r in 0..3 {
                worst = worst.max((x[v][r] - xd[3 * v + r]).abs() / (1.0 + xd[3 * v + r].abs()));
            }
        }
        (worst, longest)
    }

    #[test]
    fn sparse_block_cholesky_matches_dense_solve() {
        // A cycle with two chords (serial updates).
        let pairs = [
            (0, 1),
            (1, 2),
            (2, 3),
            (3, 4),
            (4, 5),
            (5, 6),
            (6, 7),
            (7, 8),
            (8, 0),
            (2, 6),
            (1, 7),
        ];
        let (worst, _) = sparse_against_dense(9, &pairs, 7);
        assert!(worst < 1e-10, "{worst}");
        // A random graph with much fill: long columns take the parallel update.
        let n = 80;
        let mut pairs = Vec::new();
        let mut s = 11u64;
        for i in 0..n {
            pairs.push((i, (i + 1) % n));
            for _ in 0..3 {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let j = (s >> 33) as usize % n;
                if j != i {
                    pairs.push((i, j));
                }
            }
        }
        let (worst, longest) = sparse_against_dense(n, &pairs, 3);
        assert!(longest >= PARALLEL_COLUMN, "longest column {longest}");
        assert!(worst < 1e-9, "{worst}");
    }

    #[test]
    fn minimum_degree_leaves_a_star_without_fill() {
        // A star: eliminating the centre first would make the leaves a clique (15 blocks);
        // minimum degree takes leaves first and the factor keeps the star's 5 blocks.
        let sym = Symbolic::new(6, (1..6).map(|i| (0, i)));
        assert_ne!(sym.order[0], 0);
        assert_eq!(sym.off_diagonal_blocks(), 5);
    }
}
