//! Parameters of the global search.

use crate::geometry::Pose;

/// Which pose parameters the search explores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Dof {
    /// x, y and yaw; z, roll and pitch stay at the prior's.
    XyYaw,
    /// x, y, z and yaw; roll and pitch stay at the prior's (gravity assumption, thesis
    /// §6.3.3). The default.
    XyzYaw,
    /// All six; roll and pitch within `±max_tilt` radians of the prior's.
    SixDof {
        /// Largest roll and pitch searched away from the prior, radians (default 15°).
        max_tilt: f64,
    },
}

impl Dof {
    /// Six degrees of freedom with the default ±15° tilt range.
    pub fn six_dof() -> Self {
        Dof::SixDof {
            max_tilt: 15f64.to_radians(),
        }
    }
}

/// Where the search looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Region {
    /// Every position inside the target's bounding box, every heading (no prior needed).
    Global,
    /// A window around a prior pose: `±xy` metres in x and y, `±z` metres in z, `±yaw`
    /// radians in heading.
    Window {
        /// Half-width in x and y, metres.
        xy: f64,
        /// Half-height in z, metres.
        z: f64,
        /// Half-range of heading, radians.
        yaw: f64,
    },
}

/// Parameters of [`super::global_search`].
#[derive(Debug, Clone, PartialEq)]
pub struct SearchParams {
    /// Finest voxel edge, metres (default 0.1).
    pub resolution: f64,
    /// Levels of the pyramid; the coarsest cell is `resolution * 2^(levels-1)`. 0 (the
    /// default) chooses: at least 5 levels (coarsest 16x the finest, as in thesis §6.4.2),
    /// more while the uniform start would exceed `max_coarse_poses` (large outdoor targets,
    /// six degrees of freedom), at most 10.
    pub levels: usize,
    /// Budget of poses for the uniform start when `levels` is chosen automatically
    /// (default 1,000,000).
    pub max_coarse_poses: u64,
    /// Degrees of freedom searched (default [`Dof::XyzYaw`]).
    pub dof: Dof,
    /// Search region (default [`Region::Global`]).
    pub region: Region,
    /// The prior pose `T_target_source`: the centre of a window, and the roll/pitch (and z
    /// for [`Dof::XyYaw`]) kept when those are not searched (default identity).
    pub prior: Pose,
    /// Poses scoring at least this fraction of the level's best survive (default 0.8,
    /// thesis §5.3.3).
    pub keep_ratio: f64,
    /// Survivor cap per level: when more poses pass `keep_ratio`, only the best
    /// `max_survivors` (by score, then by pose index) go on and the guard is reported.
    /// 0 (the default) means 300, or 50 for [`Dof::SixDof`], whose resampling makes 729
    /// poses per survivor instead of 27 or 81.
    pub max_survivors: usize,
    /// Scan voxels used per level at most (an even subsample in key order; default 3000).
    pub max_scan_voxels: usize,
    /// Source points beyond this range from the sensor are ignored; also the `R` of the
    /// angular step `dθ = cell / R` (5.6) (default 30 m, or less when the scan is smaller).
    pub max_range: f64,
    /// Two finest-level survivors farther apart than this (metres, or `ambiguity_angle`)
    /// count as distinct solutions in [`super::Alignment::ambiguity`] (default 1 m).
    pub ambiguity_distance: f64,
    /// See `ambiguity_distance` (default 10°).
    pub ambiguity_angle: f64,
}

impl SearchParams {
    /// The survivor cap in force (see `max_survivors`).
    pub fn survivor_cap(&self) -> usize {
        match (self.max_survivors, self.dof) {
            (0, Dof::SixDof { .. }) => 50,
            (0, _) => 300,
            (n, _) => n,
        }
    }

    /// The number of levels to use for a target of bounding-box `extent` (metres) and a scan
    /// reaching `range` metres: `levels` if set, else the automatic rule above.
    pub fn levels_for(&self, extent: nalgebra::Vector3<f64>, range: f64) -> usize {
        if self.levels > 0 {
            return self.levels;
        }
        let range = range.clamp(self.resolution, self.max_range);
        (5..=10)
            .find(|&l| self.coarse_poses(extent, range, l) <= self.max_coarse_poses)
            .unwrap_or(10)
    }

    /// Poses of the uniform start at `levels` levels.
    pub fn coarse_poses(&self, extent: nalgebra::Vector3<f64>, range: f64, levels: usize) -> u64 {
        let cell = self.resolution * (1u64 << (levels - 1)) as f64;
        let dth = cell / range;
        let count = |e: f64, step: f64| (e / step).ceil().max(0.0) as u64 + 1;
        let (nx, ny, nz, nyaw) = match self.region {
            Region::Global => (
                count(extent.x, cell),
                count(extent.y, cell),
                count(extent.z, cell),
                (std::f64::consts::TAU / dth).ceil() as u64,
            ),
            Region::Window { xy, z, yaw } => (
                count(2.0 * xy, cell),
                count(2.0 * xy, cell),
                count(2.0 * z, cell),
                count(2.0 * yaw, dth),
            ),
        };
        let nz = if matches!(self.dof, Dof::XyYaw) {
            1
        } else {
            nz
        };
        let ntilt = match self.dof {
            Dof::SixDof { max_tilt } => count(2.0 * max_tilt, dth),
            _ => 1,
        };
        nx * ny * nz * nyaw * ntilt * ntilt
    }
}

impl Default for SearchParams {
    fn default() -> Self {
        SearchParams {
            resolution: 0.1,
            levels: 0,
            max_coarse_poses: 1_000_000,
            dof: Dof::XyzYaw,
            region: Region::Global,
            prior: Pose::identity(),
            keep_ratio: 0.8,
            max_survivors: 0,
            max_scan_voxels: 3000,
            max_range: 30.0,
            ambiguity_distance: 1.0,
            ambiguity_angle: 10f64.to_radians(),
        }
    }
}
