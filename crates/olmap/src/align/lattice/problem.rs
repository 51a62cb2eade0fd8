//! The scan and the target prepared for searching: parameter checks, the scan's voxel
//! centres per level, the lattice's origin and steps, and the region's index counts.

use nalgebra::{Point3, Vector3};

use super::Lattice;
use crate::align::params::{Dof, Region, SearchParams};
use crate::align::score::DenseGrid;
use crate::align::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::VoxelKey;
use crate::occupancy::{OccupancyList, Pyramid};

/// The scan and the target prepared for searching.
pub(crate) struct Problem<'a> {
    /// Scan voxel centres per level (sensor frame).
    pub(crate) scan: Vec<Vec<Point3<f64>>>,
    /// The target: its per-level dense cells and rows ([`SearchTarget::cells`],
    /// [`SearchTarget::rows`]), made when first needed and kept for its later searches.
    pub(crate) target: &'a SearchTarget,
    pub(crate) levels: Vec<&'a OccupancyList>,
    pub(crate) free: Vec<Option<&'a DenseGrid>>,
    pub(crate) lattice: Lattice,
    /// Finest-level target voxels and bounding volume in cells.
    pub(crate) map_voxels: u64,
    pub(crate) map_cells: f64,
}

/// Evenly spaced voxel centres (at most `max`) of a list, in key order.
fn centres(list: &OccupancyList, max: usize) -> Vec<Point3<f64>> {
    let sorted = list.sorted();
    let step = sorted.len().div_ceil(max).max(1);
    sorted
        .iter()
        .step_by(step)
        .map(|(k, _)| list.center(*k))
        .collect()
}

/// The scan voxels one level scores: `list`'s voxels with those on horizontal surfaces
/// (`horizontal`, keys at this level) thinned evenly, in key order, to at most `share` of
/// the result, then at most `max` centres ([`centres`]).
fn level_centres(
    list: &OccupancyList,
    horizontal: &rustc_hash::FxHashSet<VoxelKey>,
    share: f64,
    max: usize,
) -> Vec<Point3<f64>> {
    if share >= 1.0 || horizontal.is_empty() {
        return centres(list, max);
    }
    let flat = list.iter().filter(|(k, _)| horizontal.contains(k)).count();
    let other = list.len() - flat;
    // Keep h of the flat voxels: h <= share * (other + h).
    let keep = ((share / (1.0 - share)) * other as f64).floor().max(1.0) as usize;
    let step = flat.div_ceil(keep.max(1)).max(1);
    let mut seen = 0usize;
    let kept = list.filtered(|k, _| {
        if !horizontal.contains(&k) {
            return true;
        }
        seen += 1;
        (seen - 1).is_multiple_of(step)
    });
    centres(&kept, max)
}

/// The voxels of `list` that lie on a horizontal surface: the principal axes of the
/// occupied voxel centres in the 3 x 3 x 3 neighbourhood (at least 5 of them) have their
/// smallest spread along a direction within about 25° of vertical (`|n_z| > 0.9`), and
/// the surface is flat (smallest eigenvalue under half the middle one: a surface two voxels
/// thick, as noise makes a floor on a cell boundary, still counts).
pub(crate) fn horizontal_voxels(list: &OccupancyList) -> rustc_hash::FxHashSet<VoxelKey> {
    let sorted = list.sorted();
    sorted
        .into_iter()
        .filter(|(k, _)| {
            let mut pts = [Vector3::zeros(); 27];
            let mut n = 0;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let nk = match (
                            k.x.checked_add(dx),
                            k.y.checked_add(dy),
                            k.z.checked_add(dz),
                        ) {
                            (Some(x), Some(y), Some(z)) => VoxelKey::new(x, y, z),
                            _ => continue,
                        };
                        if list.count(nk) > 0 {
                            pts[n] = Vector3::new(dx as f64, dy as f64, dz as f64);
                            n += 1;
                        }
                    }
                }
            }
            if n < 5 {
                return false;
            }
            let mean = pts[..n].iter().sum::<Vector3<f64>>() / n as f64;
            let mut cov = nalgebra::Matrix3::zeros();
            for p in &pts[..n] {
                let d = p - mean;
                cov += d * d.transpose();
            }
            let e = nalgebra::SymmetricEigen::new(cov);
            let mut order = [0usize, 1, 2];
            order.sort_by(|&a, &b| e.eigenvalues[a].total_cmp(&e.eigenvalues[b]));
            let normal = e.eigenvectors.column(order[0]);
            normal[2].abs() > 0.9 && e.eigenvalues[order[0]] < 0.5 * e.eigenvalues[order[1]]
        })
        .map(|(k, _)| k)
        .collect()
}

pub(crate) fn prepare<'a>(
    source: &PointCloud,
    target: &'a SearchTarget,
    params: &SearchParams,
) -> Result<Problem<'a>> {
    params.validate()?;
    let pyramid = &target.pyramid;
    // The target alone fixes the finest resolution (`params.resolution` only built it).
    let res = target.resolution();
    let scan_cloud = source.range_band(0.0, params.max_range);
    if scan_cloud.is_empty() {
        return Err(Error::EmptyInput {
            what: format!(
                "the source has no point within {} m of its sensor",
                params.max_range
            ),
        });
    }
    let bbox = pyramid
        .base()
        .stats()
        .bbox
        .ok_or_else(|| Error::EmptyInput {
            what: "the target".into(),
        })?;
    let base_scan = OccupancyList::from_cloud(&scan_cloud, res)?;
    // Gravity-aligned searches thin the horizontal surfaces (`horizontal_share`), each
    // level judged at its own resolution; a finest voxel also counts as horizontal when its
    // parent does (far from the sensor a floor's returns are too sparse at the finest
    // level to show their plane).
    let thin = params.horizontal_share < 1.0 && !matches!(params.dof, Dof::SixDof { .. });
    let lists: Vec<OccupancyList> = (0..pyramid.levels())
        .map(|level| base_scan.downsample(1 << level))
        .collect::<Result<_>>()?;
    let mut flat: Vec<rustc_hash::FxHashSet<VoxelKey>> = if thin {
        lists.iter().map(horizontal_voxels).collect()
    } else {
        vec![Default::default(); lists.len()]
    };
    if thin && lists.len() > 1 {
        let parents = std::mem::take(&mut flat[1]);
        for (k, _) in lists[0].iter() {
            let up = VoxelKey::new(k.x.div_euclid(2), k.y.div_euclid(2), k.z.div_euclid(2));
            if parents.contains(&up) {
                flat[0].insert(k);
            }
        }
        flat[1] = parents;
    }
    let scan: Vec<Vec<Point3<f64>>> = lists
        .iter()
        .zip(&flat)
        .map(|(l, f)| level_centres(l, f, params.horizontal_share, params.max_scan_voxels))
        .collect();
    let reach = scan_cloud.stats().range.map_or(params.max_range, |r| r.max);
    let range = reach.clamp(res, params.max_range);
    let prior = &params.prior;
    let pt = prior.translation();
    let (yaw_p, pitch_p, roll_p) = prior.yaw_pitch_roll();
    let tilt = match params.dof {
        Dof::SixDof { max_tilt } => Some(max_tilt),
        _ => None,
    };
    // A locus fixes the height (beacon height on a flat floor, thesis §6.3.3).
    let search_z = !matches!(params.dof, Dof::XyYaw) && !matches!(params.region, Region::Locus(_));
    let (t0, angle0_yaw) = match params.region {
        Region::Global => (
            Vector3::new(
                bbox.min.x,
                bbox.min.y,
                if search_z { bbox.min.z } else { pt.z },
            ),
            0.0,
        ),
        Region::Window { xy, z, yaw } => (
            Vector3::new(pt.x - xy, pt.y - xy, if search_z { pt.z - z } else { pt.z }),
            yaw_p - yaw,
        ),
        // The lattice is anchored at the locus's centre: a fixed position (6.2) is a
        // lattice point at every level.
        Region::Locus(l) => (Vector3::new(l.center[0], l.center[1], l.center[2]), 0.0),
    };
    let lattice = Lattice {
        t0,
        angle0: [
            angle0_yaw,
            pitch_p - tilt.unwrap_or(0.0),
            roll_p - tilt.unwrap_or(0.0),
        ],
        finest: res,
        range,
        searched_t: [true, true, search_z],
        searched_r: [true, tilt.is_some(), tilt.is_some()],
        bounds: match params.region {
            Region::Window { xy, z, yaw } => {
                let tilt_extent = tilt.map(|t| 2.0 * t);
                Some((
                    [2.0 * xy, 2.0 * xy, if search_z { 2.0 * z } else { 0.0 }],
                    [
                        (yaw < std::f64::consts::PI).then_some(2.0 * yaw),
                        tilt_extent,
                        tilt_extent,
                    ],
                ))
            }
            _ => None,
        },
    };
    let e = bbox.extent();
    Ok(Problem {
        scan,
        target,
        levels: (0..pyramid.levels()).map(|l| pyramid.level(l)).collect(),
        free: target.free.iter().map(Option::as_ref).collect(),
        lattice,
        map_voxels: pyramid.base().len() as u64,
        map_cells: (e.x / res).max(1.0) * (e.y / res).max(1.0) * (e.z / res).max(1.0),
    })
}

/// The lattice indices of the region at `level`: rotation counts (yaw, pitch, roll) and
/// translation counts (x, y, z); indices run from 0 to the count. `None` for a locus.
pub(crate) fn region_counts(
    problem: &Problem,
    params: &SearchParams,
    target: &Pyramid,
    level: usize,
) -> Option<([i32; 3], [i32; 3])> {
    let l = &problem.lattice;
    let cell = l.cell(level);
    let dth = l.dtheta(level);
    // Saturating: a window of 1e20 m is refused by its memory estimate, not by an
    // overflow here.
    let count = |extent: f64, step: f64| ((extent / step).ceil() as i32).max(0).saturating_add(1);
    let ext = target
        .base()
        .stats()
        .bbox
        .map_or(Vector3::zeros(), |b| b.extent());
    let ntilt = match params.dof {
        Dof::SixDof { max_tilt } => count(2.0 * max_tilt, dth),
        _ => 1,
    };
    let (nx, ny, nz, nyaw) = match params.region {
        Region::Global => (
            count(ext.x, cell),
            count(ext.y, cell),
            count(ext.z, cell),
            ((std::f64::consts::TAU / dth).ceil() as i32).max(1),
        ),
        Region::Window { xy, z, yaw } => (
            count(2.0 * xy, cell),
            count(2.0 * xy, cell),
            count(2.0 * z, cell),
            count(2.0 * yaw, dth),
        ),
        Region::Locus(_) => return None,
    };
    let nz = if l.searched_t[2] { nz } else { 1 };
    Some(([nyaw, ntilt, ntilt], [nx, ny, nz]))
}
