//! Localisation in a prior map: a scan placed in a map with no initial guess, the map
//! prepared once for every scan placed in it.
//!
//! What a map needs before a scan can be searched in it and refined against it does not
//! depend on the scan: the search's pyramid (and its dense grids, built as the searches
//! ask for them), the map's voxel centres, and those centres prepared for ICP (indexed
//! for nearest-point queries, normals estimated as they are asked for). [`Localizer`]
//! keeps them, so that each scan pays only for its own search, refinement and agreement
//! counts; [`localize`] is one scan's localisation in a map prepared for it alone.
//!
//! A map may be stored finer than localisation needs (a 0.025 m map of a large hall holds
//! 10^7 voxels, and its finest cells are smaller than a lidar's noise and its point spacing
//! at range). A scan is placed at the search's resolution (`params.search.resolution`,
//! 0.1 m by default): a finer map is read at the level of its pyramid (its voxel edge
//! doubled, as often as needed) closest to that resolution without exceeding it — searched,
//! refined against and verified there — and a map at or above it at its own voxel.

use std::borrow::Cow;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use nalgebra::Vector3;

use super::icp::IcpTarget;
use super::register::{finish, refinement_after_search, Against};
use super::search::global_search;
use super::target::SearchTarget;
use super::verify::{upright_look, upright_starts, upright_starts_after, MapSurfaces};
use super::{Alignment, Candidate, OnWindowEdge, RegisterParams, Registration, SearchParams};
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::occupancy::{FreeSpace, OccupancyList};

/// A prior map prepared for localising scans in it, one after another or from several
/// threads at once ([`Localizer::localize`] takes `&self`).
///
/// Each answer is the one [`localize`] gives for that scan alone (which prepares the map
/// the same way, for one scan), as long as the queries' parameters are those given to
/// [`Localizer::new`] (other refinement parameters are served by a preparation for the
/// query alone, other pyramid levels below the screening's by counts of the map's points).
///
/// Memory: the map's search pyramid, its voxel centres (12 bytes a voxel), their ICP
/// index with the normals estimated so far (about 40 bytes a point once asked) and its
/// surface (8 bytes a surface voxel), all at [`Localizer::resolution`]: 0.6 GB at peak for
/// a 10.6 M-voxel warehouse map read at 0.1 m (1.8 M voxels there), 1.1 GB for a 5.2
/// M-voxel one read at its own 0.05 m. A map with its free space
/// ([`Localizer::with_free_space`]) adds a bit per cell of its box at each level (the
/// libpointmatcher car's 0.1 m map: 93 -> 361 MB peak).
///
/// ```
/// use nalgebra::Point3;
/// use olmap::align::{Localizer, RegisterParams};
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::Pose;
/// use olmap::occupancy::OccupancyList;
/// // A map of an L-shaped room (floor and two walls), and a scan of it from (1, 1, 1) that
/// // saw part of it: the map is prepared once, then any number of scans are placed in it.
/// let mut points = Vec::new();
/// for i in 0..60 {
///     for j in 0..40 {
///         let (a, b) = (i as f32 * 0.05, j as f32 * 0.05);
///         points.extend([Point3::new(a, b, 0.0), Point3::new(a, 0.0, b), Point3::new(0.0, a, b)]);
///     }
/// }
/// let room = PointCloud::from_points(points);
/// let mut map = OccupancyList::new(0.1).unwrap();
/// map.add_points(&room, &Pose::identity(), 1);
/// let params = RegisterParams::default();
/// let localizer = Localizer::new(map, &params).unwrap();
/// let mut scan = room.clone();
/// scan.set_origin(Point3::new(1.0, 1.0, 1.0));
/// let placed = localizer.localize(&scan, &params).unwrap();
/// assert!(placed.pose.translation().norm() < 0.1);
/// ```
pub struct Localizer {
    /// Search targets by their number of levels (a scan's range sets how many the search
    /// uses: [`SearchParams::levels_for_source`]); the first made by [`Localizer::new`].
    targets: Mutex<Vec<Arc<SearchTarget>>>,
    /// With free space, the same targets without it, made when a global query first asks:
    /// a global search ranks poses by the map's surfaces alone ([`Localizer::localize`]).
    surface_targets: Mutex<Vec<Arc<SearchTarget>>>,
    /// The map's voxel centres, in the map frame.
    points: PointCloud,
    /// `points` prepared for the refinement (`None` when refinement is off).
    prepared: Option<IcpTarget>,
    /// The map's surface for the agreement counts.
    surfaces: MapSurfaces,
    /// The map's bounding-box extent, metres.
    extent: Vector3<f64>,
    /// The voxel edge scans are placed at, metres: the map's own, doubled while the result
    /// stays within the search's resolution.
    resolution: f64,
    /// The map's own voxel edge, metres.
    map_resolution: f64,
    /// Voxels in the map as given.
    voxels: usize,
    /// The free space known about the map, at [`Localizer::resolution`] (`None`: none).
    free: Option<Arc<FreeSpace>>,
}

impl std::fmt::Debug for Localizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Localizer")
            .field("voxels", &self.voxels)
            .field("resolution", &self.resolution)
            .field("map_resolution", &self.map_resolution)
            .field("prepared", &self.prepared)
            .finish()
    }
}

impl Localizer {
    /// Prepares `map` for localising scans in it with `params` (their search parameters,
    /// their refinement's target preparation). A map finer than `params.search.resolution`
    /// is prepared at its coarsest pyramid level within that resolution
    /// ([`working_factor`]; the module doc says why). The search's levels are chosen for
    /// scans reaching `params.search.max_range`; a scan that reaches less may need fewer,
    /// and the first such scan prepares that pyramid too.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] for invalid parameters.
    pub fn new(map: OccupancyList, params: &RegisterParams) -> Result<Self> {
        Self::build(Cow::Owned(map), None, params, None)
    }

    /// [`Localizer::new`] for a map that also says where its scans saw through (`free`, at
    /// the map's voxel edge: a `.bt` tree's free leaves, [`FreeSpace::of_log_odds`]).
    /// Scans are then searched and verified as [`super::register`] does between two
    /// scans: a pose that puts a scan's surfaces where the map saw through scores less and
    /// is contradicted on the scan's side too. Without free space only the map's side can
    /// be contradicted (by where the scan saw through), and a scan whose view is covered
    /// by a place in the map that looks alike may be trusted there, typically in a window
    /// that leaves out the true pose (the README's trust section).
    ///
    /// Memory: one bit per cell of the free space's and the map's bounding box at each
    /// pyramid level (1/7 more than the finest), up to 256 MiB a level (a level whose box
    /// is larger keeps no free space).
    ///
    /// # Errors
    /// As [`Localizer::new`]; [`crate::Error::InvalidArgument`] when the free space's voxel
    /// edge is not the map's.
    pub fn with_free_space(
        map: OccupancyList,
        free: FreeSpace,
        params: &RegisterParams,
    ) -> Result<Self> {
        Self::build(Cow::Owned(map), Some(Cow::Owned(free)), params, None)
    }

    /// [`Localizer::new`] (or [`Localizer::with_free_space`]) for one scan: the pyramid for
    /// its levels.
    fn for_one(
        map: &OccupancyList,
        free: Option<&FreeSpace>,
        params: &RegisterParams,
        source: &PointCloud,
    ) -> Result<Self> {
        Self::build(
            Cow::Borrowed(map),
            free.map(Cow::Borrowed),
            params,
            Some(source),
        )
    }

    /// Everything is made here, before any query: nothing is initialised lazily inside a
    /// query, which may run on a rayon worker that would then wait on itself.
    ///
    /// A borrowed map is copied only when it is read at its own voxel (a finer one is
    /// read from its coarser level, made from it), and a given one is dropped once that
    /// level is made.
    fn build(
        map: Cow<'_, OccupancyList>,
        free: Option<Cow<'_, FreeSpace>>,
        params: &RegisterParams,
        source: Option<&PointCloud>,
    ) -> Result<Self> {
        params.search.validate()?;
        let (map_resolution, voxels) = (map.resolution(), map.len());
        if let Some(free) = &free {
            free.check_resolution(map_resolution)?;
        }
        let factor = working_factor(map_resolution, params.search.resolution);
        let free = match free.filter(|f| !f.is_empty()) {
            Some(f) if factor > 1 => Some(Arc::new(f.coarsened(factor)?)),
            Some(f) => Some(Arc::new(f.into_owned())),
            None => None,
        };
        let map = if factor > 1 {
            map.downsample(factor)?
        } else {
            map.into_owned()
        };
        let search = search_params(params, map.resolution())?;
        let extent = map.stats().bbox.map_or(Vector3::zeros(), |b| b.extent());
        let levels = match source {
            Some(s) => search.levels_for_source(map.resolution(), extent, s),
            None => search.levels_for(extent, search.max_range),
        };
        let resolution = map.resolution();
        let points = map.to_cloud();
        let icp = params
            .refine
            .as_ref()
            .map(|p| refinement_after_search(p, resolution));
        let (target, prepared) = rayon::join(
            || -> Result<(SearchTarget, MapSurfaces)> {
                let target = target_of(map, free.as_deref(), levels)?;
                let surfaces = MapSurfaces::of(&target);
                Ok((target, surfaces))
            },
            || {
                icp.as_ref()
                    .map(|icp| IcpTarget::of_map(&points, icp, resolution))
                    .transpose()
            },
        );
        let (target, surfaces) = target?;
        Ok(Localizer {
            targets: Mutex::new(vec![Arc::new(target)]),
            surface_targets: Mutex::new(Vec::new()),
            points,
            prepared: prepared?,
            surfaces,
            extent,
            resolution,
            map_resolution,
            voxels,
            free,
        })
    }

    /// The voxel edge scans are placed at, metres: the search's finest resolution, that of
    /// the map's voxel centres ICP refines against and of the agreement counts (the map's
    /// own voxel edge unless the map is finer than the search's resolution).
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The map's own voxel edge, metres.
    pub fn map_resolution(&self) -> f64 {
        self.map_resolution
    }

    /// Voxels in the map as given (at [`Localizer::map_resolution`]).
    pub fn len(&self) -> usize {
        self.voxels
    }

    /// Whether the map has no voxel.
    pub fn is_empty(&self) -> bool {
        self.voxels == 0
    }

    /// Whether free space is known about the map ([`Localizer::with_free_space`]).
    pub fn has_free_space(&self) -> bool {
        self.free.is_some()
    }

    /// The search target with `levels` levels, made from the first one's map when no
    /// query asked for that many before.
    fn target(&self, levels: usize) -> Result<Arc<SearchTarget>> {
        find_or_make(&self.targets, levels, || {
            let first = Arc::clone(&lock(&self.targets)[0]);
            target_of(
                first.pyramid().level(0).clone(),
                self.free.as_deref(),
                levels,
            )
        })
    }

    /// The search target of `levels` levels without the map's free space (the map's
    /// surfaces alone), made from [`Localizer::target`]'s when no query asked before.
    fn surface_target(&self, levels: usize) -> Result<Arc<SearchTarget>> {
        find_or_make(&self.surface_targets, levels, || {
            Ok(self.target(levels)?.without_free_space())
        })
    }

    /// Localises `source` (a scan in its sensor frame) in the map: the global search (or
    /// the window or locus `params.search.region` names) against the map (the score is
    /// the plain overlap unless free space is known: [`Localizer::with_free_space`]), then
    /// ICP against the map's voxel centres and the verdict. [`Registration::seconds`] counts this call only,
    /// not the map's preparation. Refinement parameters that prepare a target otherwise
    /// than those given to [`Localizer::new`] (another target voxel, normal source or
    /// neighbourhood) are served by a preparation for this call alone. The search runs at
    /// [`Localizer::resolution`], fixed by [`Localizer::new`] (the query's
    /// `params.search.resolution` does not choose another level).
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] for invalid parameters.
    pub fn localize(&self, source: &PointCloud, params: &RegisterParams) -> Result<Registration> {
        let start = Instant::now();
        let resolution = self.resolution();
        let search_params = search_params(params, resolution)?;
        let levels = search_params.levels_for_source(resolution, self.extent, source);
        let target = self.target(levels)?;
        // A global search in a map with free space ranks poses on the map's surfaces
        // alone, as in the map without it, so that its look-alikes are listed and
        // verified; the free space then counts against every refined pose, and the
        // verdict trusts a match only where the surfaces single it out
        // (`verdict::map_surface_doubts`). Ranked with the free space, a look-alike
        // whose lattice pose lays surfaces a step off into seen-through cells drops out
        // of the list, and in the demo lab a scan of a place the map did not hold was
        // trusted on the one look-alike left (15-24 m off).
        let global = matches!(search_params.region, super::Region::Global);
        let surface_only = match self.free.is_some() && global {
            true => Some(self.surface_target(levels)?),
            false => None,
        };
        let ranked_on: &SearchTarget = surface_only.as_deref().unwrap_or(&target);
        // With more than one thread the upright look's search runs beside the first (the
        // coarse levels of one search leave a core idle) and its starts are taken as
        // `upright_starts` would take them: the same starts, wasted when the first search
        // fails its own tests and no verification takes them. Without a refinement there
        // is no verification; on one thread the look waits until one asks for it.
        let beside = params.refine.is_some() && rayon::current_num_threads() > 1;
        let (search, look) = rayon::join(
            || global_search(source, ranked_on, &search_params),
            || {
                if beside {
                    upright_look(source, ranked_on, &search_params)
                } else {
                    Ok(None)
                }
            },
        );
        let (search, look) = (search?, look?);
        let upright = |s: &Alignment| -> Result<Vec<Candidate>> {
            match &look {
                Some(look) => Ok(upright_starts_after(look, &search_params, s)),
                None => upright_starts(source, ranked_on, &search_params, s),
            }
        };
        finish(
            source,
            Against {
                target: &target,
                points: &|| Cow::Borrowed(&self.points),
                prepared: self.prepared.as_ref(),
                surfaces: Some(&self.surfaces),
                map_free_space: self.free.is_some(),
            },
            search,
            &upright,
            params,
            start,
            OnWindowEdge::Refine,
        )
    }
}

/// The targets in `slot`, locked (a query that panicked holding it left it whole: targets
/// are only pushed).
fn lock(slot: &Mutex<Vec<Arc<SearchTarget>>>) -> std::sync::MutexGuard<'_, Vec<Arc<SearchTarget>>> {
    slot.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The target of `levels` levels in `slot`, or one `make` makes without the lock (other
/// queries go on meanwhile), kept unless another query made the same meanwhile.
fn find_or_make(
    slot: &Mutex<Vec<Arc<SearchTarget>>>,
    levels: usize,
    make: impl FnOnce() -> Result<SearchTarget>,
) -> Result<Arc<SearchTarget>> {
    let find = |targets: &[Arc<SearchTarget>]| {
        targets
            .iter()
            .find(|t| t.pyramid().levels() == levels)
            .cloned()
    };
    if let Some(t) = find(&lock(slot)) {
        return Ok(t);
    }
    let made = Arc::new(make()?);
    let mut targets = lock(slot);
    if let Some(t) = find(&targets) {
        return Ok(t);
    }
    targets.push(Arc::clone(&made));
    Ok(made)
}

/// A search target of `levels` levels from a map (at the working resolution) and the free
/// space known about it (at the same voxel edge).
fn target_of(map: OccupancyList, free: Option<&FreeSpace>, levels: usize) -> Result<SearchTarget> {
    match free {
        Some(free) => SearchTarget::from_map_and_free(map, free, levels),
        None => SearchTarget::from_map(map, levels),
    }
}

/// The factor (a power of two) a map of voxel edge `map_resolution` is coarsened by to be
/// searched at `resolution` (both metres, finite and > 0, as a map's and a validated
/// search's are): the largest whose coarsened edge does not exceed `resolution`, up to a
/// relative 1e-9 (1 for a map at or above it; at most 2^16, the most
/// [`OccupancyList::downsample`] takes). The search's lattice has no use for cells finer
/// than it was asked for, while a finer map costs more to search, refine against and
/// count in.
///
/// ```
/// use olmap::align::working_factor;
/// assert_eq!(working_factor(0.025, 0.1), 4);
/// assert_eq!(working_factor(0.028, 0.1), 2);
/// assert_eq!(working_factor(0.05, 0.1), 2);
/// assert_eq!(working_factor(0.1, 0.1), 1);
/// assert_eq!(working_factor(0.2, 0.1), 1);
/// ```
pub fn working_factor(map_resolution: f64, resolution: f64) -> u32 {
    let mut factor = 1u32;
    // A relative slack so that 0.05 doubled equals 0.1 despite rounding.
    while factor < 1 << 16 && map_resolution * f64::from(factor * 2) <= resolution * (1.0 + 1e-9) {
        factor *= 2;
    }
    factor
}

/// `params`' search at the prepared map's `resolution` (the search's finest is the map's;
/// the parameters say so too, so that their check is of the value in use).
fn search_params(params: &RegisterParams, resolution: f64) -> Result<SearchParams> {
    let mut search = params.search.clone();
    search.resolution = resolution;
    search.validate()?;
    Ok(search)
}

/// Localises a scan in a prior map: [`Localizer::localize`] in a map prepared for this
/// scan alone (the pyramid its range asks for; a map finer than `params.search.resolution`
/// read at its level within that resolution, as [`Localizer::new`] does).
/// [`Registration::seconds`] includes that preparation. To place many scans in one map,
/// prepare it once with [`Localizer::new`].
///
/// # Errors
/// [`crate::Error::InvalidArgument`] for invalid parameters.
pub fn localize(
    source: &PointCloud,
    map: &OccupancyList,
    params: &RegisterParams,
) -> Result<Registration> {
    localize_in(source, map, None, params)
}

/// [`localize`] in a map with the free space known about it (at the map's voxel edge; see
/// [`Localizer::with_free_space`]), `None` for none.
///
/// # Errors
/// As [`localize`]; [`crate::Error::InvalidArgument`] when the free space's voxel edge is
/// not the map's.
pub fn localize_in(
    source: &PointCloud,
    map: &OccupancyList,
    free: Option<&FreeSpace>,
    params: &RegisterParams,
) -> Result<Registration> {
    let start = Instant::now();
    let localizer = Localizer::for_one(map, free, params, source)?;
    let mut r = localizer.localize(source, params)?;
    r.seconds = start.elapsed().as_secs_f64();
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{pose_error, simulate, SimConfig};

    /// A map prepared once places held-out scans of the simulated lab as a map prepared
    /// for each scan does (the same pose and verdict), right where trusted; a query
    /// asking for a pyramid of other levels gets one made from the map.
    #[test]
    fn a_map_prepared_once_places_scans_as_one_prepared_for_each() {
        let data = simulate(&SimConfig::demo_lab(3, 1, 10), |_, _| {}).unwrap();
        let robot = &data.robots[0];
        let held_out = [2, 7];
        let mut map = OccupancyList::new(0.1).unwrap();
        for (i, (scan, pose)) in robot.scans.iter().zip(&robot.truth).enumerate() {
            if !held_out.contains(&i) {
                map.add_points(scan, pose, 1);
            }
        }
        let params = RegisterParams::default();
        let localizer = Localizer::new(map.clone(), &params).unwrap();
        assert_eq!(localizer.len(), map.len());
        let mut trusted = 0;
        for i in held_out {
            let once = localizer.localize(&robot.scans[i], &params).unwrap();
            let each = localize(&robot.scans[i], &map, &params).unwrap();
            assert_eq!(
                once.trusted, each.trusted,
                "{:?} / {:?}",
                once.doubts, each.doubts
            );
            let (dt, dr) = pose_error(&once.pose, &each.pose);
            assert!(
                dt < 1e-3 && dr.to_degrees() < 0.01,
                "{dt} m, {dr} rad apart"
            );
            if once.trusted {
                let (dt, dr) = pose_error(&once.pose, &robot.truth[i]);
                assert!(dt < 0.1 && dr.to_degrees() < 1.0, "{dt} m, {dr} rad off");
                trusted += 1;
            }
        }
        assert!(trusted >= 1, "held-out scans of a mapped lab are placed");
        let first = localizer.target(5).unwrap();
        let other = localizer.target(7).unwrap();
        assert_eq!(other.pyramid().levels(), 7);
        assert_eq!(other.pyramid().level(0).len(), map.len());
        assert!(
            Arc::ptr_eq(&first, &localizer.target(5).unwrap()),
            "kept, not made again"
        );
        assert_eq!(localizer.targets.lock().unwrap().len(), 2);
    }

    /// A map finer than the search's resolution is localised in as the map coarsened to
    /// that resolution (the same pose and verdict, exactly), right where trusted; asked for
    /// its own resolution it is read at its own voxel.
    #[test]
    fn a_map_finer_than_the_search_is_read_at_its_level_within_the_search_resolution() {
        let data = simulate(&SimConfig::demo_lab(5, 1, 10), |_, _| {}).unwrap();
        let robot = &data.robots[0];
        let held_out = 4;
        let mut fine = OccupancyList::new(0.05).unwrap();
        for (i, (scan, pose)) in robot.scans.iter().zip(&robot.truth).enumerate() {
            if i != held_out {
                fine.add_points(scan, pose, 1);
            }
        }
        let params = RegisterParams::default();
        assert_eq!(params.search.resolution, 0.1);
        let read_coarse = Localizer::new(fine.clone(), &params).unwrap();
        assert_eq!(read_coarse.resolution(), 0.1);
        assert_eq!(read_coarse.map_resolution(), 0.05);
        assert_eq!(read_coarse.len(), fine.len());
        let coarse = Localizer::new(fine.downsample(2).unwrap(), &params).unwrap();
        assert!(coarse.len() < fine.len());
        let scan = &robot.scans[held_out];
        let a = read_coarse.localize(scan, &params).unwrap();
        let b = coarse.localize(scan, &params).unwrap();
        assert_eq!(a.pose, b.pose);
        assert_eq!((a.trusted, &a.doubts), (b.trusted, &b.doubts));
        assert!(a.trusted, "{:?}", a.doubts);
        let (dt, dr) = pose_error(&a.pose, &robot.truth[held_out]);
        assert!(dt < 0.1 && dr.to_degrees() < 1.0, "{dt} m, {dr} rad off");
        let own = RegisterParams {
            search: SearchParams {
                resolution: 0.05,
                ..Default::default()
            },
            ..Default::default()
        };
        let at_own = Localizer::new(fine.clone(), &own).unwrap();
        assert_eq!(at_own.resolution(), 0.05);
        let c = at_own.localize(scan, &own).unwrap();
        let finest = |r: &Registration| {
            r.search
                .levels
                .iter()
                .map(|l| l.resolution)
                .fold(f64::INFINITY, f64::min)
        };
        assert_eq!((finest(&a), finest(&c)), (0.1, 0.05));
    }
}
