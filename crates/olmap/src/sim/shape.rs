//! The simulator's solid shapes, their materials, and ray intersection with each.

use nalgebra::{Point3, Unit, Vector3};

use crate::geometry::Aabb;

/// How a surface returns laser light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Diffuse reflectivity in `[0, 1]`: the intensity a scanner reports at normal
    /// incidence (it falls with the cosine of the incidence angle).
    pub reflectivity: f32,
    /// Retroreflective tape: returns a bright intensity (above 1) whatever the incidence
    /// up to 50° (thesis §3.2, retroreflection fails beyond about 50°).
    pub retroreflective: bool,
}

impl Material {
    /// Painted walls, floor and ceiling.
    pub const WALL: Material = Material {
        reflectivity: 0.6,
        retroreflective: false,
    };
    /// Furniture and clutter.
    pub const FURNITURE: Material = Material {
        reflectivity: 0.4,
        retroreflective: false,
    };
    /// A robot's body.
    pub const ROBOT: Material = Material {
        reflectivity: 0.3,
        retroreflective: false,
    };
    /// Retroreflective beacon tape.
    pub const BEACON: Material = Material {
        reflectivity: 0.9,
        retroreflective: true,
    };
}

/// A solid.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A box of half-extents `half` centred at `center`, turned by `yaw` (radians) about
    /// the vertical through its centre.
    Box {
        /// Centre.
        center: Point3<f64>,
        /// Half the size along its own x, y, z.
        half: Vector3<f64>,
        /// Turn about z, radians.
        yaw: f64,
    },
    /// A vertical cylinder standing on `base` (centre of its bottom disc).
    Cylinder {
        /// Centre of the bottom disc.
        base: Point3<f64>,
        /// Radius, metres.
        radius: f64,
        /// Height, metres.
        height: f64,
    },
    /// An unbounded plane `normal . x = offset` (floors, ceilings).
    Plane {
        /// Unit normal.
        normal: Unit<Vector3<f64>>,
        /// Offset along the normal.
        offset: f64,
    },
}

/// A shape with a material and an id (robots' shapes carry their robot's id).
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// The solid.
    pub shape: Shape,
    /// Its surface.
    pub material: Material,
    /// An id (0 for the static world; robot `k` uses `ROBOT_ID_BASE + k`).
    pub id: u32,
}

/// Ids at and above this belong to robots (`ROBOT_ID_BASE + robot index`).
pub const ROBOT_ID_BASE: u32 = 1 << 20;

/// Where a ray met a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray, metres.
    pub distance: f64,
    /// Unit surface normal at the hit, facing the ray's origin.
    pub normal: Vector3<f64>,
    /// The surface.
    pub material: Material,
    /// The object's id.
    pub id: u32,
}

/// Rays start this far past their origin, so a ray leaving a surface does not hit it.
pub const RAY_EPSILON: f64 = 1e-9;

impl Shape {
    /// An axis-aligned box from its corners.
    pub fn aabb_box(min: Point3<f64>, max: Point3<f64>) -> Shape {
        Shape::Box {
            center: nalgebra::center(&min, &max),
            half: (max - min) * 0.5,
            yaw: 0.0,
        }
    }

    /// The horizontal plane `z = height`.
    pub fn horizontal_plane(height: f64) -> Shape {
        Shape::Plane {
            normal: Vector3::z_axis(),
            offset: height,
        }
    }

    /// The nearest intersection of the ray `origin + t dir` (`dir` unit) with
    /// `RAY_EPSILON < t < max`: the distance and the outward normal, flipped to face the ray.
    pub fn intersect(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max: f64,
    ) -> Option<(f64, Vector3<f64>)> {
        let (t, n) = match self {
            Shape::Box { center, half, yaw } => {
                let (s, c) = yaw.sin_cos();
                // Into the box frame: rotate by -yaw about the centre.
                let rel = origin - center;
                let o = Vector3::new(c * rel.x + s * rel.y, -s * rel.x + c * rel.y, rel.z);
                let d = Vector3::new(c * dir.x + s * dir.y, -s * dir.x + c * dir.y, dir.z);
                let (t, axis, sign) = slab(&o, &d, half)?;
                let mut local = Vector3::zeros();
                local[axis] = sign;
                (
                    t,
                    Vector3::new(
                        c * local.x - s * local.y,
                        s * local.x + c * local.y,
                        local.z,
                    ),
                )
            }
            Shape::Cylinder {
                base,
                radius,
                height,
            } => cylinder(origin, dir, base, *radius, *height)?,
            Shape::Plane { normal, offset } => {
                let denom = normal.dot(dir);
                if denom.abs() < 1e-15 {
                    return None;
                }
                let t = (offset - normal.dot(&origin.coords)) / denom;
                (t, normal.into_inner())
            }
        };
        if t > RAY_EPSILON && t < max {
            let n = if n.dot(dir) > 0.0 { -n } else { n };
            Some((t, n))
        } else {
            None
        }
    }

    /// The shape's bounding box (`None` for an unbounded plane).
    pub fn bounds(&self) -> Option<Aabb> {
        match self {
            Shape::Box { center, half, yaw } => {
                let (s, c) = yaw.sin_cos();
                let ex = (c * half.x).abs() + (s * half.y).abs();
                let ey = (s * half.x).abs() + (c * half.y).abs();
                let e = Vector3::new(ex, ey, half.z);
                Some(Aabb::new(center - e, center + e))
            }
            Shape::Cylinder {
                base,
                radius,
                height,
            } => Some(Aabb::new(
                base - Vector3::new(*radius, *radius, 0.0),
                base + Vector3::new(*radius, *radius, *height),
            )),
            Shape::Plane { .. } => None,
        }
    }

    /// Horizontal distance from `(x, y)` to the shape's footprint when the shape reaches
    /// into the height band `[z_lo, z_hi]` (`None` when it does not, e.g. a floor): what a
    /// robot of that height must keep clear of. Negative inside.
    pub fn footprint_distance(&self, x: f64, y: f64, z_lo: f64, z_hi: f64) -> Option<f64> {
        match self {
            Shape::Box { center, half, yaw } => {
                if center.z + half.z < z_lo || center.z - half.z > z_hi {
                    return None;
                }
                let (s, c) = yaw.sin_cos();
                let (rx, ry) = (x - center.x, y - center.y);
                let (lx, ly) = (c * rx + s * ry, -s * rx + c * ry);
                let (dx, dy) = (lx.abs() - half.x, ly.abs() - half.y);
                let outside = (dx.max(0.0).powi(2) + dy.max(0.0).powi(2)).sqrt();
                Some(outside + dx.max(dy).min(0.0))
            }
            Shape::Cylinder {
                base,
                radius,
                height,
            } => {
                if base.z + height < z_lo || base.z > z_hi {
                    return None;
                }
                Some(((x - base.x).powi(2) + (y - base.y).powi(2)).sqrt() - radius)
            }
            Shape::Plane { normal, offset } => {
                if normal.z.abs() > 1e-9 {
                    return None;
                }
                Some((normal.x * x + normal.y * y - offset).abs())
            }
        }
    }
}

/// Slab test of a ray against the box `[-half, half]`: the first positive crossing, the
/// axis of the face it crosses and the sign of that face.
fn slab(o: &Vector3<f64>, d: &Vector3<f64>, half: &Vector3<f64>) -> Option<(f64, usize, f64)> {
    let (mut t_near, mut t_far) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut near_axis, mut far_axis) = (0usize, 0usize);
    for a in 0..3 {
        if d[a].abs() < 1e-15 {
            if o[a].abs() > half[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[a];
        let (mut t0, mut t1) = ((-half[a] - o[a]) * inv, (half[a] - o[a]) * inv);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        if t0 > t_near {
            t_near = t0;
            near_axis = a;
        }
        if t1 < t_far {
            t_far = t1;
            far_axis = a;
        }
        if t_near > t_far {
            return None;
        }
    }
    if t_near > RAY_EPSILON {
        Some((t_near, near_axis, -d[near_axis].signum()))
    } else if t_far > RAY_EPSILON {
        // From inside: the exit face.
        Some((t_far, far_axis, d[far_axis].signum()))
    } else {
        None
    }
}

/// Ray against a vertical cylinder with caps.
fn cylinder(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    base: &Point3<f64>,
    r: f64,
    h: f64,
) -> Option<(f64, Vector3<f64>)> {
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let mut consider = |t: f64, n: Vector3<f64>| {
        if t > RAY_EPSILON && best.is_none_or(|(b, _)| t < b) {
            best = Some((t, n));
        }
    };
    let (ox, oy) = (o.x - base.x, o.y - base.y);
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-15 {
        let b = ox * d.x + oy * d.y;
        let c = ox * ox + oy * oy - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            for t in [(-b - sq) / a, (-b + sq) / a] {
                let z = o.z + t * d.z;
                if z >= base.z && z <= base.z + h {
                    let (px, py) = (ox + t * d.x, oy + t * d.y);
                    consider(t, Vector3::new(px / r, py / r, 0.0));
                }
            }
        }
    }
    if d.z.abs() > 1e-15 {
        for (zc, nz) in [(base.z, -1.0), (base.z + h, 1.0)] {
            let t = (zc - o.z) / d.z;
            let (px, py) = (ox + t * d.x, oy + t * d.y);
            if px * px + py * py <= r * r {
                consider(t, Vector3::new(0.0, 0.0, nz));
            }
        }
    }
    best
}
