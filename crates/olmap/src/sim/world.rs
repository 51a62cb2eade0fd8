//! A static world of solids with a bounding-volume hierarchy for fast ray casting.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::shape::{Hit, Object, Shape};
use crate::geometry::Aabb;

/// A world: named, made of solids, ray cast through a BVH over the bounded ones (unbounded
/// planes are tested on every ray).
///
/// ```
/// use nalgebra::{Point3, Vector3};
/// use olmap::sim::{Material, Object, Shape, World};
/// let wall = Object {
///     shape: Shape::aabb_box(Point3::new(5.0, -5.0, 0.0), Point3::new(5.2, 5.0, 3.0)),
///     material: Material::WALL,
///     id: 0,
/// };
/// let world = World::new("one wall", vec![wall]);
/// let hit = world.cast(&Point3::new(0.0, 0.0, 1.0), &Vector3::x(), 30.0).unwrap();
/// assert!((hit.distance - 5.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone)]
pub struct World {
    name: String,
    objects: Vec<Object>,
    /// Indices of unbounded objects.
    unbounded: Vec<u32>,
    nodes: Vec<Node>,
    /// Object indices in leaf order.
    order: Vec<u32>,
    /// A closed tour through the world's free space (x, y corners; the last joins the
    /// first), empty for worlds robots roam at random.
    route: Vec<(f64, f64)>,
}

#[derive(Debug, Clone)]
struct Node {
    min: [f64; 3],
    max: [f64; 3],
    /// Leaf: `first..first + count` in `order`; inner: children `first` and `first + 1`
    /// (count 0).
    first: u32,
    count: u32,
}

const LEAF_SIZE: usize = 4;

impl World {
    /// A world from its objects.
    pub fn new(name: impl Into<String>, objects: Vec<Object>) -> World {
        let mut bounded: Vec<(u32, Aabb)> = Vec::new();
        let mut unbounded = Vec::new();
        for (i, o) in objects.iter().enumerate() {
            match o.shape.bounds() {
                Some(b) => bounded.push((i as u32, b)),
                None => unbounded.push(i as u32),
            }
        }
        let mut w = World {
            name: name.into(),
            objects,
            unbounded,
            nodes: Vec::new(),
            order: Vec::new(),
            route: Vec::new(),
        };
        if !bounded.is_empty() {
            w.nodes.push(Node {
                min: [0.0; 3],
                max: [0.0; 3],
                first: 0,
                count: 0,
            });
            w.build(0, &mut bounded);
        }
        w
    }

    fn build(&mut self, node: usize, items: &mut [(u32, Aabb)]) {
        let mut min = [f64::INFINITY; 3];
        let mut max = [f64::NEG_INFINITY; 3];
        for (_, b) in items.iter() {
            for a in 0..3 {
                min[a] = min[a].min(b.min[a]);
                max[a] = max[a].max(b.max[a]);
            }
        }
        self.nodes[node].min = min;
        self.nodes[node].max = max;
        if items.len() <= LEAF_SIZE {
            self.nodes[node].first = self.order.len() as u32;
            self.nodes[node].count = items.len() as u32;
            self.order.extend(items.iter().map(|(i, _)| *i));
            return;
        }
        // Split at the median centre along the longest axis of the centres' spread.
        let axis = (0..3)
            .max_by(|&a, &b| {
                let spread = |k: usize| {
                    let (lo, hi) =
                        items
                            .iter()
                            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (_, bb)| {
                                let c = 0.5 * (bb.min[k] + bb.max[k]);
                                (l.min(c), h.max(c))
                            });
                    hi - lo
                };
                spread(a).total_cmp(&spread(b))
            })
            .unwrap_or(0);
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |(ia, a), (ib, b)| {
            (a.min[axis] + a.max[axis])
                .total_cmp(&(b.min[axis] + b.max[axis]))
                .then(ia.cmp(ib))
        });
        let left = self.nodes.len();
        for _ in 0..2 {
            self.nodes.push(Node {
                min: [0.0; 3],
                max: [0.0; 3],
                first: 0,
                count: 0,
            });
        }
        self.nodes[node].first = left as u32;
        self.nodes[node].count = 0;
        let (a, b) = items.split_at_mut(mid);
        self.build(left, a);
        self.build(left + 1, b);
    }

    /// The world with a closed route robots drive round (x, y corners in metres, the
    /// last joined to the first) instead of a random walk: see
    /// [`crate::sim::plan_trajectories`].
    pub fn with_route(mut self, corners: Vec<(f64, f64)>) -> World {
        self.route = corners;
        self
    }

    /// The closed route robots drive round (empty: they roam at random).
    pub fn route(&self) -> &[(f64, f64)] {
        &self.route
    }

    /// The world's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Its objects.
    pub fn objects(&self) -> &[Object] {
        &self.objects
    }

    /// The box around its bounded objects (`None` if it has none).
    pub fn bounds(&self) -> Option<Aabb> {
        self.nodes
            .first()
            .map(|n| Aabb::new(Point3::from(n.min), Point3::from(n.max)))
    }

    /// The first surface along the ray `origin + t dir` (`dir` unit), `t < max`.
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max: f64) -> Option<Hit> {
        self.cast_with(&[], origin, dir, max)
    }

    /// [`World::cast`] with extra (moving) objects, e.g. the other robots.
    pub fn cast_with(
        &self,
        extra: &[Object],
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max: f64,
    ) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut limit = max;
        let test = |o: &Object, limit: &mut f64, best: &mut Option<Hit>| {
            if let Some((t, n)) = o.shape.intersect(origin, dir, *limit) {
                *limit = t;
                *best = Some(Hit {
                    distance: t,
                    normal: n,
                    material: o.material,
                    id: o.id,
                });
            }
        };
        for &i in &self.unbounded {
            test(&self.objects[i as usize], &mut limit, &mut best);
        }
        for o in extra {
            test(o, &mut limit, &mut best);
        }
        if self.nodes.is_empty() {
            return best;
        }
        let inv = Vector3::new(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z);
        let mut stack = [0u32; 64];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if !ray_box(origin, &inv, &node.min, &node.max, limit) {
                continue;
            }
            if node.count > 0 {
                for k in node.first..node.first + node.count {
                    let i = self.order[k as usize] as usize;
                    test(&self.objects[i], &mut limit, &mut best);
                }
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
            }
        }
        best
    }

    /// Casts many rays (origin, unit direction) in parallel; the result is in input order.
    pub fn cast_many(
        &self,
        extra: &[Object],
        rays: &[(Point3<f64>, Vector3<f64>)],
        max: f64,
    ) -> Vec<Option<Hit>> {
        rays.par_iter()
            .with_min_len(256)
            .map(|(o, d)| self.cast_with(extra, o, d, max))
            .collect()
    }

    /// Whether a robot footprint of radius `clearance` at `(x, y)` keeps clear of every
    /// object reaching into the height band `[z_lo, z_hi]`.
    pub fn is_clear(&self, x: f64, y: f64, clearance: f64, z_lo: f64, z_hi: f64) -> bool {
        self.objects.iter().all(|o| {
            o.shape
                .footprint_distance(x, y, z_lo, z_hi)
                .is_none_or(|d| d >= clearance)
        })
    }

    /// Whether the straight path from `a` to `b` (x, y) keeps `clearance` from every
    /// object in the band (checked every 5 cm).
    pub fn path_is_clear(
        &self,
        a: (f64, f64),
        b: (f64, f64),
        clearance: f64,
        z_lo: f64,
        z_hi: f64,
    ) -> bool {
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let steps = (len / 0.05).ceil().max(1.0) as usize;
        (0..=steps).all(|k| {
            let f = k as f64 / steps as f64;
            self.is_clear(
                a.0 + f * (b.0 - a.0),
                a.1 + f * (b.1 - a.1),
                clearance,
                z_lo,
                z_hi,
            )
        })
    }
}

/// Slab test of a ray (inverse direction given) against a box, up to `limit`.
fn ray_box(
    o: &Point3<f64>,
    inv: &Vector3<f64>,
    min: &[f64; 3],
    max: &[f64; 3],
    limit: f64,
) -> bool {
    let (mut t0, mut t1) = (0.0f64, limit);
    for a in 0..3 {
        if inv[a].is_infinite() {
            // Parallel to the slab: inside it (faces included) or a miss. The product
            // below would be NaN for an origin on a face.
            if o[a] < min[a] || o[a] > max[a] {
                return false;
            }
            continue;
        }
        let (mut ta, mut tb) = ((min[a] - o[a]) * inv[a], (max[a] - o[a]) * inv[a]);
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        t0 = t0.max(ta);
        t1 = t1.min(tb);
        if t0 > t1 {
            return false;
        }
    }
    true
}

/// Objects of a box with open inside: the floor and four walls (and the ceiling when
/// `ceiling`), `thickness` thick, inner corner at `min`, inner size `size`.
pub fn room_shell(
    min: Point3<f64>,
    size: Vector3<f64>,
    thickness: f64,
    ceiling: bool,
) -> Vec<Shape> {
    let t = thickness;
    let max = min + size;
    let mut s = vec![
        Shape::aabb_box(
            Point3::new(min.x - t, min.y - t, min.z - t),
            Point3::new(max.x + t, max.y + t, min.z),
        ),
        Shape::aabb_box(
            Point3::new(min.x - t, min.y - t, min.z),
            Point3::new(min.x, max.y + t, max.z),
        ),
        Shape::aabb_box(
            Point3::new(max.x, min.y - t, min.z),
            Point3::new(max.x + t, max.y + t, max.z),
        ),
        Shape::aabb_box(
            Point3::new(min.x, min.y - t, min.z),
            Point3::new(max.x, min.y, max.z),
        ),
        Shape::aabb_box(
            Point3::new(min.x, max.y, min.z),
            Point3::new(max.x, max.y + t, max.z),
        ),
    ];
    if ceiling {
        s.push(Shape::aabb_box(
            Point3::new(min.x - t, min.y - t, max.z),
            Point3::new(max.x + t, max.y + t, max.z + t),
        ));
    }
    s
}
