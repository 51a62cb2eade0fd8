//! Axis-aligned bounding boxes.

use nalgebra::{Point3, Vector3};

/// An axis-aligned box `[min, max]` (inclusive on both sides), in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Point3<f64>,
    /// Largest corner.
    pub max: Point3<f64>,
}

impl Aabb {
    /// A box from two corners; the corners are sorted per axis.
    pub fn new(a: Point3<f64>, b: Point3<f64>) -> Self {
        Aabb {
            min: a.inf(&b),
            max: a.sup(&b),
        }
    }

    /// The smallest box holding every point, or `None` for no points.
    pub fn from_points<'a, I: IntoIterator<Item = &'a Point3<f32>>>(points: I) -> Option<Self> {
        let mut it = points.into_iter();
        let first = it.next()?;
        let (mut lo, mut hi) = (*first, *first);
        for p in it {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        Some(Aabb {
            min: lo.cast(),
            max: hi.cast(),
        })
    }

    /// Whether a point lies inside (boundaries included).
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    /// `max - min`.
    pub fn extent(&self) -> Vector3<f64> {
        self.max - self.min
    }

    /// The centre of the box.
    pub fn center(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// The smallest box holding both boxes.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: self.min.inf(&other.min),
            max: self.max.sup(&other.max),
        }
    }
}
