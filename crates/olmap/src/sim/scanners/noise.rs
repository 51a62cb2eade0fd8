//! The range noise model shared by the scanners, and the measurement of one beam.

use nalgebra::{Point3, Vector3};

use crate::sim::{Hit, Object, SimRng, World};

/// Intensity returned by retroreflective tape hit within [`RETRO_MAX_INCIDENCE`] of its
/// normal (diffuse surfaces return at most 1).
pub const RETRO_INTENSITY: f64 = 2.0;

/// Largest incidence angle at which retroreflective tape still returns bright, radians
/// (50°, thesis §3.2).
pub const RETRO_MAX_INCIDENCE: f64 = 50.0 * std::f64::consts::PI / 180.0;

/// How a scanner's measurements depart from the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeNoise {
    /// Standard deviation of the Gaussian range noise, metres (default 0.02, thesis §4.4.1).
    pub sigma: f64,
    /// Probability that a return is lost (default 0).
    pub dropout: f64,
    /// Probability that a beam straddling a depth discontinuity returns a range uniformly
    /// between the foreground and the background (default 0, thesis §4.4.1). A beam
    /// straddles one when a sub-ray offset by half the angular step measures a range
    /// differing by more than [`RangeNoise::mixed_pixel_jump`].
    pub mixed_pixels: f64,
    /// Range difference between a beam and its sub-ray that counts as a depth
    /// discontinuity, metres (default 0.2).
    pub mixed_pixel_jump: f64,
    /// Standard deviation of the Gaussian intensity noise (default 0.01).
    pub intensity_sigma: f64,
    /// Longest range measured, metres (default 80, the LMS 200's limit); farther surfaces
    /// and misses give no return.
    pub max_range: f64,
}

impl Default for RangeNoise {
    fn default() -> Self {
        RangeNoise {
            sigma: 0.02,
            dropout: 0.0,
            mixed_pixels: 0.0,
            mixed_pixel_jump: 0.2,
            intensity_sigma: 0.01,
            max_range: 80.0,
        }
    }
}

impl RangeNoise {
    /// Exact measurements (no noise, no dropouts, no mixed pixels), range up to 80 m.
    pub fn none() -> Self {
        RangeNoise {
            sigma: 0.0,
            dropout: 0.0,
            mixed_pixels: 0.0,
            intensity_sigma: 0.0,
            ..Self::default()
        }
    }

    /// The same noise with another maximum range.
    pub fn with_max_range(self, max_range: f64) -> Self {
        RangeNoise { max_range, ..self }
    }
}

/// One beam into the world.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Beam {
    /// Where the beam leaves for the world (world frame).
    pub origin: Point3<f64>,
    /// Unit direction (world frame).
    pub dir: Vector3<f64>,
    /// Path already travelled before `origin` (the way to a mirror; 0 for a direct beam).
    pub before: f64,
}

/// A measured return.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Return {
    /// Measured range along the whole path, metres.
    pub range: f64,
    /// Measured intensity.
    pub intensity: f32,
}

impl Beam {
    fn cast(&self, world: &World, extra: &[Object], max_range: f64) -> Option<Hit> {
        let max = max_range - self.before;
        if max <= 0.0 {
            return None;
        }
        world.cast_with(extra, &self.origin, &self.dir, max)
    }
}

/// Measures one beam: casts it, applies the noise (drawing from `rng` in a fixed order so
/// the result depends only on the generator's seed) and returns the range and intensity, or
/// `None` for no return. `sub` is the neighbouring sub-ray used to detect depth edges.
pub(crate) fn measure(
    world: &World,
    extra: &[Object],
    main: &Beam,
    sub: Option<&Beam>,
    noise: &RangeNoise,
    rng: &mut SimRng,
) -> Option<Return> {
    let hit = main.cast(world, extra, noise.max_range)?;
    let lost = rng.chance(noise.dropout);
    let mix = rng.chance(noise.mixed_pixels);
    let fraction = rng.uniform();
    let dr = rng.gauss(noise.sigma);
    let di = rng.gauss(noise.intensity_sigma);
    if lost {
        return None;
    }
    let mut range = main.before + hit.distance;
    if mix {
        if let Some(other) = sub.and_then(|s| s.cast(world, extra, noise.max_range).map(|h| (s, h)))
        {
            let r2 = other.0.before + other.1.distance;
            if (r2 - range).abs() > noise.mixed_pixel_jump {
                range += fraction * (r2 - range);
            }
        }
    }
    range += dr;
    if !(range > 0.0 && range <= noise.max_range) {
        return None;
    }
    let cos_inc = hit.normal.dot(&main.dir).abs().min(1.0);
    let base = if hit.material.retroreflective && cos_inc > RETRO_MAX_INCIDENCE.cos() {
        RETRO_INTENSITY
    } else {
        hit.material.reflectivity as f64 * cos_inc
    };
    Some(Return {
        range,
        intensity: (base + di).max(0.0) as f32,
    })
}
