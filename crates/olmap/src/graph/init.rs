//! Chordal initialisation (Carlone et al., "Initialization techniques for 3D SLAM", ICRA
//! 2015): first the rotations, by linear least squares on the chordal distance
//! `sum w ||R_j - R_i R_ij||_F^2` with the gauge nodes' rotations held, each result projected
//! onto the nearest rotation; then the positions, by linear least squares on
//! `p_j - p_i = R_i t_ij` with the rotations held, weighted by the edges' translation
//! information. Both are sparse linear systems solved with the graph's own block Cholesky.
//! Plain Levenberg-Marquardt from odometry stalls in a local minimum on graphs such as
//! sphere2500; from the chordal estimate it reaches the optimum.

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, UnitQuaternion, Vector2};

use super::lie::{S2, S3};
use super::sparse::{BlockMatrix, Factor, Symbolic};

/// A state that the chordal initialisation can read and rebuild (rotations of dimension R).
pub(crate) trait Chordal<const R: usize>: Copy {
    fn rotation(&self) -> SMatrix<f64, R, R>;
    fn translation(&self) -> SVector<f64, R>;
    /// A state from a rotation and a translation.
    fn from_parts(r: &SMatrix<f64, R, R>, t: &SVector<f64, R>) -> Self;
    /// The rotation nearest to `m` (Frobenius norm).
    fn project(m: &SMatrix<f64, R, R>) -> SMatrix<f64, R, R>;
}

impl Chordal<3> for S3 {
    fn rotation(&self) -> Matrix3<f64> {
        self.q.to_rotation_matrix().into_inner()
    }
    fn translation(&self) -> SVector<f64, 3> {
        self.p
    }
    fn from_parts(r: &Matrix3<f64>, t: &SVector<f64, 3>) -> S3 {
        S3 {
            p: *t,
            q: UnitQuaternion::from_matrix(r),
        }
    }
    fn project(m: &Matrix3<f64>) -> Matrix3<f64> {
        let svd = m.svd(true, true);
        let (u, v_t) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
        let mut d = Matrix3::identity();
        d[(2, 2)] = (u * v_t).determinant().signum();
        u * d * v_t
    }
}

impl Chordal<2> for S2 {
    fn rotation(&self) -> Matrix2<f64> {
        let (s, c) = self.th.sin_cos();
        Matrix2::new(c, -s, s, c)
    }
    fn translation(&self) -> Vector2<f64> {
        self.p
    }
    fn from_parts(r: &Matrix2<f64>, t: &Vector2<f64>) -> S2 {
        S2 {
            p: *t,
            th: r[(1, 0)].atan2(r[(0, 0)]),
        }
    }
    fn project(m: &Matrix2<f64>) -> Matrix2<f64> {
        // The nearest rotation to [[a, b], [c, d]] has angle atan2(c - b, a + d).
        let th = (m[(1, 0)] - m[(0, 1)]).atan2(m[(0, 0)] + m[(1, 1)]);
        let (s, c) = th.sin_cos();
        Matrix2::new(c, -s, s, c)
    }
}

/// One edge as the initialisation sees it: measurement rotation and translation, a scalar
/// rotation weight and the translation information.
pub(crate) struct InitEdge<const R: usize> {
    pub i: usize,
    pub j: usize,
    pub r_ij: SMatrix<f64, R, R>,
    pub t_ij: SVector<f64, R>,
    pub w_rot: f64,
    pub info_t: SMatrix<f64, R, R>,
}

/// Replaces the rotations and positions of the free states (`held[v] == false`) by the
/// chordal estimate. Every connected part of the graph must hold at least one node.
/// Returns false (and changes nothing) when a linear system is singular.
pub(crate) fn chordal<const R: usize, G: Chordal<R>>(
    states: &mut [G],
    held: &[bool],
    edges: &[InitEdge<R>],
) -> bool {
    let n = states.len();
    let mut var = vec![usize::MAX; n];
    let mut free = Vec::new();
    for v in 0..n {
        if !held[v] {
            var[v] = free.len();
            free.push(v);
        }
    }
    if free.is_empty() {
        return true;
    }
    let pairs = edges
        .iter()
        .filter(|e| !held[e.i] && !held[e.j])
        .map(|e| (var[e.i], var[e.j]));
    let sym = Symbolic::new(free.len(), pairs);
    let id = SMatrix::<f64, R, R>::identity();

    // Rotations: unknown Y_v = R_v^T (its columns are the rows of R_v); each edge says
    // Y_j - R_ij^T Y_i = 0 with weight w.
    let mut a = BlockMatrix::<R>::zeros(&sym);
    let mut b = vec![SMatrix::<f64, R, R>::zeros(); free.len()];
    for e in edges {
        let w = e.w_rot;
        let (fi, fj) = (!held[e.i], !held[e.j]);
        if fi {
            a.add_diag(&sym, var[e.i], &(id * w));
        }
        if fj {
            a.add_diag(&sym, var[e.j], &(id * w));
        }
        match (fi, fj) {
            (true, true) => {
                // H_ij = A_i^T A_j w = -R_ij w.
                let slot = sym.slot(var[e.i], var[e.j]).expect("pattern");
                a.add_off(slot, &(-e.r_ij * w));
            }
            (true, false) => {
                // rhs_i -= A_i^T A_j Y_j w = R_ij Y_j w.
                let yj = states[e.j].rotation().transpose();
                b[var[e.i]] += e.r_ij * yj * w;
            }
            (false, true) => {
                let yi = states[e.i].rotation().transpose();
                b[var[e.j]] += e.r_ij.transpose() * yi * w;
            }
            (false, false) => {}
        }
    }
    let Some(f) = Factor::new(&sym, a) else {
        return false;
    };
    let y = f.solve(&sym, &b);
    let rotations: Vec<SMatrix<f64, R, R>> = y.iter().map(|y| G::project(&y.transpose())).collect();

    // Positions: p_j - p_i = R_i t_ij, weighted by W = R_i Omega_t R_i^T.
    let rot_of = |v: usize| {
        if held[v] {
            states[v].rotation()
        } else {
            rotations[var[v]]
        }
    };
    let mut a = BlockMatrix::<R>::zeros(&sym);
    let mut b = vec![SMatrix::<f64, R, 1>::zeros(); free.len()];
    for e in edges {
        let ri = rot_of(e.i);
        let w = ri * e.info_t * ri.transpose();
        let c = ri * e.t_ij;
        let (fi, fj) = (!held[e.i], !held[e.j]);
        if fi {
            a.add_diag(&sym, var[e.i], &w);
            b[var[e.i]] -= w * c;
        }
        if fj {
            a.add_diag(&sym, var[e.j], &w);
            b[var[e.j]] += w * c;
        }
        match (fi, fj) {
            (true, true) => {
                let slot = sym.slot(var[e.i], var[e.j]).expect("pattern");
                a.add_off(slot, &(-w));
            }
            (true, false) => b[var[e.i]] += w * states[e.j].translation(),
            (false, true) => b[var[e.j]] += w * states[e.i].translation(),
            (false, false) => {}
        }
    }
    let Some(f) = Factor::new(&sym, a) else {
        return false;
    };
    let p = f.solve(&sym, &b);
    for (k, &v) in free.iter().enumerate() {
        states[v] = G::from_parts(&rotations[k], &p[k]);
    }
    true
}
