//! A transform tree built from `/tf_static`, `/tf` and odometry messages: the chain between
//! two frames at a time, with dynamic transforms interpolated between their stamps
//! (linear in translation, spherical in rotation).

use std::collections::HashMap;

use crate::geometry::Pose;

/// How far (ns) a lookup may fall outside a dynamic transform's recorded stamps and still
/// take the nearest one: 100 ms.
pub const DEFAULT_TOLERANCE_NS: i64 = 100_000_000;

#[derive(Debug, Clone)]
enum Edge {
    Static(Pose),
    /// Samples sorted by stamp (ns).
    Dynamic(Vec<(i64, Pose)>),
}

/// Transforms between named frames: each child frame has one parent.
#[derive(Debug, Clone, Default)]
pub struct TfTree {
    /// child -> (parent, transform `T_parent_child`).
    edges: HashMap<String, (String, Edge)>,
    /// Whether dynamic samples were pushed out of order since the last sort.
    unsorted: bool,
}

impl TfTree {
    /// An empty tree.
    pub fn new() -> Self {
        Self::default()
    }

    fn key(frame: &str) -> String {
        frame.trim_start_matches('/').to_string()
    }

    /// Adds a static transform `T_parent_child` (replacing an earlier one for that child).
    pub fn add_static(&mut self, parent: &str, child: &str, t: Pose) {
        self.edges
            .insert(Self::key(child), (Self::key(parent), Edge::Static(t)));
    }

    /// Adds a dynamic sample `T_parent_child` at `stamp_ns`. A child keeps the parent of
    /// its first sample; samples naming another parent are ignored (and counted as `false`).
    pub fn add_dynamic(&mut self, parent: &str, child: &str, stamp_ns: i64, t: Pose) -> bool {
        let (parent, child) = (Self::key(parent), Self::key(child));
        let entry = self
            .edges
            .entry(child)
            .or_insert_with(|| (parent.clone(), Edge::Dynamic(Vec::new())));
        if entry.0 != parent {
            return false;
        }
        match &mut entry.1 {
            Edge::Dynamic(samples) => {
                if samples.last().is_some_and(|(s, _)| *s > stamp_ns) {
                    self.unsorted = true;
                }
                samples.push((stamp_ns, t));
                true
            }
            Edge::Static(_) => false,
        }
    }

    /// Every frame named in the tree.
    pub fn frames(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .edges
            .iter()
            .flat_map(|(c, (p, _))| [c.clone(), p.clone()])
            .collect();
        v.sort();
        v.dedup();
        v
    }

    fn sort(&mut self) {
        if self.unsorted {
            for (_, e) in self.edges.values_mut() {
                if let Edge::Dynamic(s) = e {
                    s.sort_by_key(|(t, _)| *t);
                }
            }
            self.unsorted = false;
        }
    }

    /// `frame` and its ancestors, each with `T_parent_child` at `stamp`.
    fn chain(&self, frame: &str, stamp: i64, tol: i64) -> Result<Vec<(String, Pose)>, String> {
        let mut out = Vec::new();
        let mut cur = Self::key(frame);
        while let Some((parent, edge)) = self.edges.get(&cur) {
            let t = match edge {
                Edge::Static(t) => *t,
                Edge::Dynamic(s) => sample(s, stamp, tol).ok_or_else(|| {
                    format!(
                        "no transform {parent} -> {cur} within {} ms of stamp {:.3} s (recorded \
                         from {:.3} to {:.3} s)",
                        tol / 1_000_000,
                        stamp as f64 * 1e-9,
                        s.first().map_or(0.0, |x| x.0 as f64 * 1e-9),
                        s.last().map_or(0.0, |x| x.0 as f64 * 1e-9)
                    )
                })?,
            };
            out.push((cur.clone(), t));
            cur = parent.clone();
            if out.len() > 1024 {
                return Err(format!("the frames above '{frame}' form a cycle"));
            }
        }
        out.push((cur, Pose::identity()));
        Ok(out)
    }

    /// `T_target_source` at `stamp_ns`: maps points in `source` into `target`. Dynamic
    /// links are interpolated; outside their recorded span by at most `tolerance_ns` the
    /// nearest sample is used, farther is an error naming the link.
    pub fn lookup(
        &mut self,
        target: &str,
        source: &str,
        stamp_ns: i64,
        tolerance_ns: i64,
    ) -> Result<Pose, String> {
        self.sort();
        let up_s = self.chain(source, stamp_ns, tolerance_ns)?;
        let up_t = self.chain(target, stamp_ns, tolerance_ns)?;
        // T_ancestor_frame for each ancestor along the chain.
        let to_root = |chain: &[(String, Pose)]| -> Vec<(String, Pose)> {
            let mut acc = Pose::identity();
            let mut out = vec![(chain[0].0.clone(), acc)];
            for w in chain.windows(2) {
                acc = w[0].1 * acc;
                out.push((w[1].0.clone(), acc));
            }
            out
        };
        let (s, t) = (to_root(&up_s), to_root(&up_t));
        for (frame, t_anc_src) in &s {
            if let Some((_, t_anc_tgt)) = t.iter().find(|(f, _)| f == frame) {
                return Ok(t_anc_tgt.inverse() * *t_anc_src);
            }
        }
        Err(format!(
            "frames '{source}' and '{target}' are not connected (known frames: {})",
            self.frames().join(", ")
        ))
    }
}

/// The sample at `t`, interpolated between its neighbours.
fn sample(s: &[(i64, Pose)], t: i64, tol: i64) -> Option<Pose> {
    let (first, last) = (s.first()?, s.last()?);
    if t <= first.0 {
        return (first.0 - t <= tol).then_some(first.1);
    }
    if t >= last.0 {
        return (t - last.0 <= tol).then_some(last.1);
    }
    let k = s.partition_point(|(st, _)| *st <= t);
    let (a, b) = (&s[k - 1], &s[k]);
    if a.0 == t {
        return Some(a.1);
    }
    let f = (t - a.0) as f64 / (b.0 - a.0) as f64;
    Some(interpolate(&a.1, &b.1, f))
}

/// Linear in translation, slerp in rotation.
pub fn interpolate(a: &Pose, b: &Pose, f: f64) -> Pose {
    let t = a.translation() + (b.translation() - a.translation()) * f;
    let q = a
        .rotation()
        .try_slerp(&b.rotation(), f, 1e-12)
        .unwrap_or_else(|| a.rotation());
    Pose::from_parts(t, q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};

    #[test]
    fn chains_compose_and_interpolate() {
        let mut tf = TfTree::new();
        tf.add_static(
            "base_link",
            "laser",
            Pose::from_translation(Vector3::new(0.2, 0.0, 0.5)),
        );
        tf.add_dynamic("odom", "base_link", 0, Pose::identity());
        tf.add_dynamic(
            "odom",
            "base_link",
            1_000_000_000,
            Pose::from_xyz_ypr(2.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0),
        );
        let t = tf.lookup("odom", "laser", 500_000_000, 0).unwrap();
        // Halfway: base at x = 1, yaw 45°; the laser 0.2 m ahead of it.
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let p = t.transform_point(&Point3::origin());
        assert!(
            (p - Point3::new(1.0 + 0.2 * c, 0.2 * c, 0.5)).norm() < 1e-12,
            "{p}"
        );
        let back = tf.lookup("laser", "odom", 500_000_000, 0).unwrap();
        assert!(((back * t).translation()).norm() < 1e-12);
        assert!(tf.lookup("odom", "laser", 2_000_000_000, 100).is_err());
        assert!(tf
            .lookup("odom", "camera", 0, 0)
            .unwrap_err()
            .contains("not connected"));
    }
}
