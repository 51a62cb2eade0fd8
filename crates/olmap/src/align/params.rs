//! Parameters of the global search.

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
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

/// How the global search explores the poses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SearchMode {
    /// The thesis' multi-resolution search (Algorithms 3, 5, 6): poses within
    /// `keep_ratio` of each level's best survive to the next level. Fast, heuristic: the
    /// true optimum can be dropped at a coarse level. The default (see README).
    #[default]
    MultiResolution,
    /// Branch and bound over rotations and translations with bounds from max-pooled map
    /// levels: the best pose of the finest lattice, the same as the exhaustive search
    /// (Algorithm 7). A locus region falls back to the multi-resolution search.
    Exact,
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
    /// A one-parameter family of poses (thesis §6.3.3, (6.2)-(6.3)): a sighting between
    /// robots fixes a pose up to one parameter `t`, and only poses near the locus are
    /// searched. See [`Locus`].
    Locus(Locus),
}

/// A pose locus `t -> (c_x + r cos(t + phase), c_y + r sin(t + phase), z, yaw = t)`, `t` in
/// `[0, 2π)`: the poses a sighting allows (thesis (6.2)-(6.3)).
///
/// * Another robot saw this one's beacon at `B` (map frame), mounted at `o` in this robot's
///   frame: the robot's position is `B - R(t) o`, any heading: `center = B - (0, 0, o_z)`,
///   `radius = |o_xy|`, `phase = atan2(o_y, o_x) + π` ((6.2); `radius = 0` for a beacon
///   above the robot's origin).
/// * This robot saw another's beacon `B` (map frame) at `b` in its own frame: its position
///   is `B - R(t) b`: `center = B - (0, 0, b_z)`, `radius = |b_xy|`,
///   `phase = atan2(b_y, b_x) + π` ((6.3), the circle locus with coupled heading).
///
/// The height is the locus's (beacons at a known height on a flat floor), roll and pitch
/// stay at the prior's (gravity); refinement may adjust all three. The search samples `t` at the coarsest
/// level's angular step and lets the pyramid refine around the locus; `slack` widens the
/// start by whole coarse cells when it exceeds half a cell.
///
/// ```
/// use olmap::align::Locus;
/// // Seen by a robot that put our beacon (0.85 m above our origin) at (3, 1, 0.85):
/// let l = Locus::seen_at([3.0, 1.0, 0.85], [0.0, 0.0, 0.85]);
/// assert_eq!((l.center, l.radius), ([3.0, 1.0, 0.0], 0.0));
/// let p = l.pose_at(1.0);
/// assert!((p.translation().x - 3.0).abs() < 1e-12 && (p.yaw_pitch_roll().0 - 1.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Locus {
    /// The circle's centre (and the poses' height), map frame, metres.
    pub center: [f64; 3],
    /// The circle's radius, metres (0: a fixed position, heading free).
    pub radius: f64,
    /// Angle of the position on the circle at `t = 0`, radians.
    pub phase: f64,
    /// How far the true pose may lie from the locus, metres (sighting noise; default
    /// from the constructors 0.1 m).
    pub slack: f64,
}

impl Locus {
    /// (6.2): another robot saw this robot's beacon at `beacon` (map frame); the beacon
    /// sits at `mount` in this robot's frame.
    pub fn seen_at(beacon: [f64; 3], mount: [f64; 3]) -> Self {
        Self::from_offset(beacon, mount)
    }

    /// (6.3): this robot saw another's beacon, known at `beacon` (map frame), at
    /// `observed` in its own frame.
    pub fn saw_at(beacon: [f64; 3], observed: [f64; 3]) -> Self {
        Self::from_offset(beacon, observed)
    }

    fn from_offset(beacon: [f64; 3], offset: [f64; 3]) -> Self {
        Locus {
            center: [beacon[0], beacon[1], beacon[2] - offset[2]],
            radius: offset[0].hypot(offset[1]),
            phase: offset[1].atan2(offset[0]) + std::f64::consts::PI,
            slack: 0.1,
        }
    }

    /// The pose at parameter `t` (roll and pitch zero).
    pub fn pose_at(&self, t: f64) -> Pose {
        let [cx, cy, z] = self.center;
        let a = t + self.phase;
        Pose::from_xyz_ypr(
            cx + self.radius * a.cos(),
            cy + self.radius * a.sin(),
            z,
            crate::geometry::wrap_angle(t),
            0.0,
            0.0,
        )
    }

    /// Extra coarse cells searched on each side of the locus: the slack in cells, rounded
    /// (a lattice cell and the pyramid's resampling already cover half a cell).
    pub(crate) fn slack_cells(&self, cell: f64) -> u64 {
        (self.slack / cell).round() as u64
    }

    /// How many samples of `t` the search starts from at a coarse cell `cell` and angular
    /// step `dtheta`: fine enough in heading and along the circle.
    pub(crate) fn samples(&self, cell: f64, dtheta: f64) -> usize {
        let step = if self.radius > 0.0 {
            dtheta.min(cell / self.radius)
        } else {
            dtheta
        };
        ((std::f64::consts::TAU / step).ceil() as usize).max(1)
    }
}

/// Parameters of [`super::global_search`].
#[derive(Debug, Clone, PartialEq)]
pub struct SearchParams {
    /// Finest voxel edge, metres (default 0.1), used to BUILD a target
    /// ([`super::align_clouds`], [`super::register()`]), to choose the level a finer map is
    /// localised at ([`super::Localizer`], [`super::working_factor`]) and by the level rule
    /// ([`SearchParams::levels_for_source`]). A search takes its finest resolution from its
    /// [`super::SearchTarget`] only ([`super::SearchTarget::resolution`]); there this field
    /// is only checked to be a finite number > 0, so a target built at another resolution
    /// is searched at the target's.
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
    /// count as distinct solutions in [`super::Alignment::ambiguity`] and as distinct
    /// hypotheses ([`Self::distinct_hypotheses`]); also the margin a window search's answer
    /// must keep from the window's edge ([`super::verdict`], test 7) (default 0.5 m: rows
    /// of desks and shelves repeat every 0.5-2 m, and a coarser value merged a look-alike
    /// 0.5 m away into the best's cluster).
    pub ambiguity_distance: f64,
    /// See `ambiguity_distance` (default 5°).
    pub ambiguity_angle: f64,
    /// Distinct hypotheses the multi-resolution search carries from every level to the next
    /// besides the poses within `keep_ratio` (default 8): the best poses of the level that
    /// lie farther apart than `ambiguity_distance` / `ambiguity_angle` (or two of the level's
    /// cells or angular steps, when coarser). They cost a few dozen poses per level and let
    /// the search measure the best *distinct* solution at the finest level
    /// ([`super::Alignment::runner_up`]), which a coarse level would otherwise drop: a
    /// place that repeats then shows two solutions of similar score instead of one.
    pub distinct_hypotheses: usize,
    /// How the poses are explored (default [`SearchMode::MultiResolution`]).
    pub search: SearchMode,
    /// In a gravity-aligned search ([`Dof::XyYaw`], [`Dof::XyzYaw`]) the scan's voxels on
    /// horizontal surfaces (floors, ceilings, table tops) are thinned to at most this share
    /// of the voxels scored at each level (default 1: off; 0.25 made a synthetic hall slide
    /// 0.42 m, see the stop note of issue 22). A horizontal
    /// surface says nothing about x, y or heading, and its density, highest under the
    /// sensor, pulls the overlap towards poses that put one scan's near field on the
    /// other's: in the simulated office and lab, two scans 0.5-3 m apart that share 30-45 %
    /// of their voxels scored higher at "the robot did not move" (floor and ceiling hits)
    /// than at the truth (wall and furniture hits). What is kept still fixes the height.
    /// Six-degree-of-freedom searches keep every voxel (horizontal surfaces fix roll and
    /// pitch). With the default, a registration over every pose also runs the search a
    /// second time at 0.1 (the *upright look*; a six-degree-of-freedom one at the prior's
    /// roll and pitch, a search finer than 0.1 m from its 0.1 m level) and verifies its
    /// best poses beside the first's, the fit choosing
    /// ([`super::verify::Origin::UprightLook`]).
    pub horizontal_share: f64,
    /// The most work the exact search may do, in voxel bounds (a node bounded over one scan
    /// voxel; default [`super::EXACT_MAX_WORK`]): past it the search stops with
    /// [`crate::Error::TooLarge`] instead of running for hours on a scene where every pose
    /// scores alike.
    pub exact_max_work: u64,
}

/// The most pyramid levels a search may ask for.
pub const MAX_LEVELS: usize = 12;

impl SearchParams {
    /// Checks every parameter against its documented range, naming the parameter, the
    /// valid range and the value ([`Error::InvalidArgument`]); the searches and
    /// [`super::register()`], [`super::localize`] call it before using them.
    ///
    /// Beyond each value's own range: `resolution` must not exceed `max_range` (the
    /// angular step is `resolution / range`), a window's yaw half-range and the six-degree
    /// tilt are at most 180°.
    ///
    /// ```
    /// use olmap::align::SearchParams;
    /// assert!(SearchParams::default().validate().is_ok());
    /// let p = SearchParams { resolution: 40.0, ..Default::default() };
    /// let e = p.validate().unwrap_err().to_string();
    /// assert!(e.contains("resolution") && e.contains("max_range"), "{e}");
    /// ```
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidArgument(format!("search parameters: {what}")));
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                bad(format!("{name} must be a finite number > 0, got {v}"))
            }
        };
        positive("resolution (m)", self.resolution)?;
        positive("max_range (m)", self.max_range)?;
        if self.resolution > self.max_range {
            return bad(format!(
                "resolution ({} m) must not exceed max_range ({} m): the angular step is \
                 resolution / range",
                self.resolution, self.max_range
            ));
        }
        if self.levels > MAX_LEVELS {
            return bad(format!(
                "levels must be 0 (automatic) to {MAX_LEVELS}, got {}",
                self.levels
            ));
        }
        if self.max_coarse_poses == 0 {
            return bad("max_coarse_poses must be at least 1".into());
        }
        if !(self.keep_ratio > 0.0 && self.keep_ratio <= 1.0) {
            return bad(format!(
                "keep_ratio must be in (0, 1], got {}",
                self.keep_ratio
            ));
        }
        if self.max_scan_voxels == 0 {
            return bad("max_scan_voxels must be at least 1".into());
        }
        if !(self.horizontal_share > 0.0 && self.horizontal_share <= 1.0) {
            return bad(format!(
                "horizontal_share must be in (0, 1], got {}",
                self.horizontal_share
            ));
        }
        if self.exact_max_work == 0 {
            return bad("exact_max_work must be at least 1".into());
        }
        if !(self.ambiguity_distance.is_finite() && self.ambiguity_distance >= 0.0) {
            return bad(format!(
                "ambiguity_distance must be a finite number >= 0 m, got {}",
                self.ambiguity_distance
            ));
        }
        if !(self.ambiguity_angle.is_finite() && self.ambiguity_angle >= 0.0) {
            return bad(format!(
                "ambiguity_angle must be a finite number >= 0 rad, got {}",
                self.ambiguity_angle
            ));
        }
        let pose = self.prior.isometry();
        let finite = pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite());
        if !finite {
            return bad("the prior pose must be finite".into());
        }
        let half_turn = std::f64::consts::PI;
        match self.region {
            Region::Global => {}
            Region::Window { xy, z, yaw } => {
                for (name, v) in [("xy (m)", xy), ("z (m)", z)] {
                    if !(v.is_finite() && v >= 0.0) {
                        return bad(format!(
                            "the window's half-width {name} must be a finite number >= 0, \
                             got {v}"
                        ));
                    }
                }
                if !((0.0..=half_turn).contains(&yaw)) {
                    return bad(format!(
                        "the window's yaw half-range must be 0 to 180 degrees, got {} degrees",
                        yaw.to_degrees()
                    ));
                }
            }
            Region::Locus(l) => {
                let values = [
                    l.center[0],
                    l.center[1],
                    l.center[2],
                    l.radius,
                    l.phase,
                    l.slack,
                ];
                if values.iter().any(|v| !v.is_finite()) || l.radius < 0.0 || l.slack < 0.0 {
                    return bad(
                        "a locus needs a finite centre and phase, radius >= 0 and slack >= 0"
                            .into(),
                    );
                }
            }
        }
        if let Dof::SixDof { max_tilt } = self.dof {
            if !((0.0..=half_turn).contains(&max_tilt)) {
                return bad(format!(
                    "max_tilt must be 0 to 180 degrees, got {} degrees",
                    max_tilt.to_degrees()
                ));
            }
        }
        Ok(())
    }

    /// The survivor cap in force (see `max_survivors`).
    pub fn survivor_cap(&self) -> usize {
        match (self.max_survivors, self.dof) {
            (0, Dof::SixDof { .. }) => 50,
            (0, _) => 300,
            (n, _) => n,
        }
    }

    /// The level rule, the one home of "levels from extent": the number of pyramid levels
    /// for a target of bounding-box `target_extent` (metres) built at `resolution` (metres)
    /// and a `source` scan, whose farthest point from its sensor (or `max_range` when it has
    /// none) is the range of the angular step. `levels` if set, else the automatic rule of
    /// [`SearchParams::levels`].
    pub fn levels_for_source(
        &self,
        resolution: f64,
        target_extent: nalgebra::Vector3<f64>,
        source: &PointCloud,
    ) -> usize {
        let range = source.stats().range.map_or(self.max_range, |r| r.max);
        self.levels_at(resolution, target_extent, range)
    }

    /// The number of levels to use for a target of bounding-box `extent` (metres) and a scan
    /// reaching `range` metres: `levels` if set, else the automatic rule above (at
    /// [`SearchParams::resolution`]; see [`SearchParams::levels_for_source`]).
    pub fn levels_for(&self, extent: nalgebra::Vector3<f64>, range: f64) -> usize {
        self.levels_at(self.resolution, extent, range)
    }

    /// [`SearchParams::levels_for`] for a target built at `resolution`.
    fn levels_at(&self, resolution: f64, extent: nalgebra::Vector3<f64>, range: f64) -> usize {
        if self.levels > 0 {
            return self.levels;
        }
        // Not `clamp`: that panics on parameters `validate` refuses (resolution above
        // max_range, NaN), and this rule runs before the searches check them.
        let range = range.max(resolution).min(self.max_range);
        (5..=10)
            .find(|&l| self.coarse_poses_at(resolution, extent, range, l) <= self.max_coarse_poses)
            .unwrap_or(10)
    }

    /// Poses of the uniform start at `levels` levels (at [`SearchParams::resolution`]).
    pub fn coarse_poses(&self, extent: nalgebra::Vector3<f64>, range: f64, levels: usize) -> u64 {
        self.coarse_poses_at(self.resolution, extent, range, levels)
    }

    /// [`SearchParams::coarse_poses`] for a target built at `resolution`.
    fn coarse_poses_at(
        &self,
        resolution: f64,
        extent: nalgebra::Vector3<f64>,
        range: f64,
        levels: usize,
    ) -> u64 {
        let cell = resolution * (1u64 << levels.saturating_sub(1).min(63)) as f64;
        let dth = cell / range;
        let count = |e: f64, step: f64| ((e / step).ceil().max(0.0) as u64).saturating_add(1);
        let (nx, ny, nz, nyaw) = match self.region {
            Region::Global => (
                count(extent.x, cell),
                count(extent.y, cell),
                count(extent.z, cell),
                (std::f64::consts::TAU / dth).ceil().max(1.0) as u64,
            ),
            Region::Window { xy, z, yaw } => (
                count(2.0 * xy, cell),
                count(2.0 * xy, cell),
                count(2.0 * z, cell),
                count(2.0 * yaw, dth),
            ),
            Region::Locus(l) => {
                let k = 2 * l.slack_cells(cell) + 1;
                (k, k, 1, l.samples(cell, dth) as u64)
            }
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
        [ny, nz, nyaw, ntilt, ntilt]
            .into_iter()
            .fold(nx, u64::saturating_mul)
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
            ambiguity_distance: 0.5,
            ambiguity_angle: 5f64.to_radians(),
            distinct_hypotheses: 8,
            search: SearchMode::MultiResolution,
            horizontal_share: 1.0,
            exact_max_work: super::EXACT_MAX_WORK,
        }
    }
}
