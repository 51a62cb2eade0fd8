//! `olmap map LOG.log.gz --dof xy-yaw`: a CARMEN log mapped from degraded odometry, and
//! judged against the log's own (SLAM-corrected) poses.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use nalgebra::{Point3, Vector2};
use serde::Serialize;

use super::mapper::{PlacementSource, PlanarMapParams, PlanarMapper};
use super::odometry::OdometryNoise;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::{wrap_angle, PoseList};
use crate::graph::{EdgeKind, Se2};
use crate::io::carmen::{read_carmen, CarmenLog};

/// What [`run_planar_log`] does.
#[derive(Debug, Clone)]
pub struct PlanarLogJob {
    /// The CARMEN log (`.log`, `.log.gz`, `.log.bz2`).
    pub log: PathBuf,
    /// Map only the first this many scans (`None`: all).
    pub max_scans: Option<usize>,
    /// Returns beyond this are dropped, metres.
    pub max_range: f64,
    /// The odometry's degradation (applied to the log's corrected poses).
    pub noise: OdometryNoise,
    /// Seed of the degradation.
    pub noise_seed: u64,
    /// The mapper's parameters (loop closure on or off in `params.closure`).
    pub params: PlanarMapParams,
    /// Write the optimised poses here (pose list named `scan000000`, …).
    pub poses_out: Option<PathBuf>,
    /// Write the pose graph here (g2o).
    pub graph_out: Option<PathBuf>,
    /// Write the map's points here (any cloud format, z = 0).
    pub map_out: Option<PathBuf>,
    /// Write a top view of the map here (PNG, 5 cm pixels, 5 m grid), with the mapped path
    /// (first colour of the palette) and the log's path (second). Needs the `render` feature.
    pub picture_out: Option<PathBuf>,
    /// Robustness test: after mapping, add this fraction of the accepted closures again as
    /// *wrong* closures (between random scans 50 or more apart, displaced 2-5 m from their
    /// current relative pose, with a closure's information and kernel) before the final
    /// solve; the report says which of them the kernel down-weighted. 0 = none.
    pub inject_wrong_closures: f64,
}

/// A wrong loop closure injected by [`PlanarLogJob::inject_wrong_closures`] (or, in 3D,
/// by [`crate::mapping::posegraph::GraphRefineParams::inject_wrong_closures`]).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct InjectedClosure {
    /// The earlier scan.
    pub from: String,
    /// The later scan.
    pub to: String,
    /// How far the edge's translation is from the estimate's, metres.
    pub offset_m: f64,
    /// Whether the robust kernel down-weighted it at the final solve.
    pub down_weighted: bool,
}

/// Errors of planar poses against a reference.
///
/// The absolute trajectory error (ATE) is the standard one (Sturm et al., IROS 2012): the
/// estimate is first moved by the rigid motion that best fits it onto the reference
/// (least squares over the positions), so that one small heading error at the start does
/// not count at every later scan. The error with the first scan as anchor (the mapper keeps
/// it at its reference pose, no fitting) is given too.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PlanarErrors {
    /// Scans compared.
    pub scans: usize,
    /// Absolute trajectory error after the best rigid fit: RMS of the position errors, metres.
    pub ate_rmse_m: f64,
    /// Largest position error after the fit, metres.
    pub ate_max_m: f64,
    /// RMS position error with the first scan as the anchor (no fit), metres.
    pub anchored_rmse_m: f64,
    /// Largest position error with the first scan as the anchor, metres.
    pub anchored_max_m: f64,
    /// RMS heading error after the fit, degrees.
    pub yaw_rmse_deg: f64,
    /// Largest heading error after the fit, degrees.
    pub yaw_max_deg: f64,
    /// RMS relative position error over path segments of 1 m, metres.
    pub relative_1m_rmse_m: f64,
    /// RMS relative position error over path segments of 10 m, metres.
    pub relative_10m_rmse_m: f64,
}

/// A loop closure the robust kernel down-weighted at the final solution.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RejectedClosure {
    /// The earlier scan.
    pub from: String,
    /// The later scan.
    pub to: String,
    /// Its kernel weight (below 0.5).
    pub weight: f64,
}

/// The report of [`run_planar_log`].
#[derive(Debug, Clone, Serialize)]
pub struct PlanarLogReport {
    /// The log.
    pub log: String,
    /// Scans mapped.
    pub scans: usize,
    /// Scans placed.
    pub placed: usize,
    /// Placements by source (`first`, `registration`, `odometry`).
    pub sources: BTreeMap<String, usize>,
    /// Sequential registrations refused, by reason (the reason's first words); those
    /// scans were placed on odometry.
    pub registrations_refused: BTreeMap<String, usize>,
    /// Graph edges by kind.
    pub edges: BTreeMap<String, usize>,
    /// Whether loop closure was on.
    pub loop_closure: bool,
    /// Loop closures tried.
    pub closures_tried: usize,
    /// Loop closures accepted as edges.
    pub closures_accepted: usize,
    /// Accepted closure attempts that hold only the heading and the position across a
    /// corridor ([`super::mapper::ClosureParams::partial`]).
    pub closures_partial: usize,
    /// Refused closure attempts by reason (the reason's first words).
    pub closures_refused: BTreeMap<String, usize>,
    /// Accepted closures that the robust kernel down-weighted at the end.
    pub closures_down_weighted: Vec<RejectedClosure>,
    /// Wrong closures injected before the final solve (robustness test), with their fate.
    pub injected_closures: Vec<InjectedClosure>,
    /// Graph solves during mapping.
    pub optimisations: usize,
    /// Cost of the final solve, before and after.
    pub initial_cost: f64,
    /// See `initial_cost`.
    pub final_cost: f64,
    /// The odometry model and seed.
    pub noise: OdometryNoise,
    /// See `noise`.
    pub noise_seed: u64,
    /// The mapped poses against the log's poses.
    pub errors: PlanarErrors,
    /// The degraded odometry alone against the log's poses.
    pub odometry_errors: PlanarErrors,
    /// Wall time of mapping (reading excluded), seconds.
    pub seconds: f64,
    /// Mean mapping time per scan (placement, closures and their solves), milliseconds.
    pub ms_per_scan: f64,
    /// The slowest scan's time, milliseconds.
    pub max_ms_per_scan: f64,
}

/// Maps a CARMEN log: reads it, degrades the odometry, places every scan with
/// [`PlanarMapper`], solves the graph once more at the end, writes what was asked and
/// compares with the log's poses. `progress(done, total)` is called per scan.
///
/// ```no_run
/// use olmap::mapping::planar::{run_planar_log, OdometryNoise, PlanarLogJob, PlanarMapParams};
/// let job = PlanarLogJob {
///     log: "intel-corrected.log.gz".into(),
///     max_scans: None,
///     max_range: 30.0,
///     noise: OdometryNoise { distance_fraction: 0.05, degrees_per_unit: 2.0 },
///     noise_seed: 1,
///     params: PlanarMapParams::default(),
///     poses_out: Some("intel-poses.txt".into()),
///     graph_out: None,
///     map_out: None,
///     picture_out: None,
///     inject_wrong_closures: 0.0,
/// };
/// let report = run_planar_log(&job, &mut |_, _| {})?;
/// println!("ATE RMSE {:.3} m", report.errors.ate_rmse_m);
/// # Ok::<(), olmap::Error>(())
/// ```
pub fn run_planar_log(
    job: &PlanarLogJob,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PlanarLogReport> {
    if !(job.max_range.is_finite() && job.max_range > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "the maximum range must be a positive number of metres, got {}",
            job.max_range
        )));
    }
    for (what, v) in [
        ("distance fraction", job.noise.distance_fraction),
        ("degrees per metre and radian", job.noise.degrees_per_unit),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "the odometry noise's {what} must be a number >= 0, got {v}"
            )));
        }
    }
    if job.max_scans == Some(0) {
        return Err(Error::InvalidArgument(
            "the number of scans to map must be at least 1, got 0".into(),
        ));
    }
    if !(0.0..=1.0).contains(&job.inject_wrong_closures) {
        return Err(Error::InvalidArgument(format!(
            "the fraction of wrong closures to inject must be between 0 and 1, got {}",
            job.inject_wrong_closures
        )));
    }
    for out in [
        &job.poses_out,
        &job.graph_out,
        &job.map_out,
        &job.picture_out,
    ]
    .into_iter()
    .flatten()
    {
        crate::file::check_output(out, "output")?;
    }
    if let Some(path) = &job.map_out {
        crate::io::output_format(path, &Default::default())?;
    }
    let log = read_carmen(&job.log)?;
    let n = job.max_scans.unwrap_or(usize::MAX).min(log.scans.len());
    let reference: Vec<Se2> = log.scans[..n]
        .iter()
        .map(|s| Se2::new(s.pose[0], s.pose[1], s.pose[2]))
        .collect();
    let odometry = job.noise.degrade(&reference, job.noise_seed);
    let no_return = log.max_range.min(job.max_range + 1e-9) - 1e-6;
    let start = Instant::now();
    // The odometry edges' information follows the noise the odometry really has.
    let mut params = job.params;
    params.odometry_noise = job.noise;
    let mut mapper = PlanarMapper::new(params);
    let mut sources: BTreeMap<String, usize> = BTreeMap::new();
    let (mut tried, mut accepted, mut partial) = (0, 0, 0);
    let mut max_ms = 0f64;
    let mut refused: BTreeMap<String, usize> = BTreeMap::new();
    let mut reg_refused: BTreeMap<String, usize> = BTreeMap::new();
    for (i, scan) in log.scans[..n].iter().enumerate() {
        let points = scan.points(no_return, 0.05);
        let t0 = Instant::now();
        let p = mapper.add_scan(CarmenLog::scan_name(i), points, Some(odometry[i]))?;
        max_ms = max_ms.max(1e3 * t0.elapsed().as_secs_f64());
        if p.placed {
            let key = match p.source {
                PlacementSource::First => "first",
                PlacementSource::Registration => "registration",
                PlacementSource::Odometry => "odometry",
                PlacementSource::PartialRegistration => "partial_registration",
            };
            *sources.entry(key.into()).or_default() += 1;
        }
        if let Some(d) = &p.doubt {
            *reg_refused.entry(reason_head(d)).or_default() += 1;
        }
        for c in &p.closures {
            tried += 1;
            if c.accepted {
                accepted += 1 + usize::from(c.corroborates.is_some());
                partial += usize::from(c.partial);
            } else if let Some(r) = &c.reason {
                *refused.entry(reason_head(r)).or_default() += 1;
            }
        }
        progress(i + 1, n);
    }
    let injected = inject(&mut mapper, n, accepted, job)?;
    let solve = mapper.optimise_report()?;
    let injected_closures: Vec<InjectedClosure> = injected
        .into_iter()
        .map(|(edge, from, to, offset_m)| InjectedClosure {
            from: CarmenLog::scan_name(from),
            to: CarmenLog::scan_name(to),
            offset_m,
            down_weighted: solve
                .edge_reports
                .get(edge)
                .is_some_and(|e| e.down_weighted),
        })
        .collect();
    let seconds = start.elapsed().as_secs_f64();
    let mut down = Vec::new();
    for e in solve.down_weighted() {
        if e.kind == EdgeKind::LoopClosure {
            down.push(RejectedClosure {
                from: CarmenLog::scan_name(e.from as usize),
                to: CarmenLog::scan_name(e.to as usize),
                weight: e.weight,
            });
        }
    }
    let poses = mapper.poses();
    let estimated: Vec<Option<Se2>> = {
        let by_name: BTreeMap<&str, Se2> = poses.iter().map(|(n, p)| (n.as_str(), *p)).collect();
        (0..n)
            .map(|i| by_name.get(CarmenLog::scan_name(i).as_str()).copied())
            .collect()
    };
    let errors = planar_errors(&estimated, &reference);
    let odo: Vec<Option<Se2>> = odometry.iter().copied().map(Some).collect();
    let odometry_errors = planar_errors(&odo, &reference);
    if let Some(path) = &job.poses_out {
        let mut list = PoseList::default();
        for (name, p) in &poses {
            list.push(name.clone(), p.to_pose());
        }
        list.write_path(path)?;
    }
    if let Some(path) = &job.graph_out {
        crate::graph::write_g2o(path, mapper.graph())?;
    }
    let cloud = || {
        PointCloud::from_points(
            mapper
                .map_points()
                .iter()
                .map(|p| Point3::new(p.x as f32, p.y as f32, 0.0))
                .collect(),
        )
    };
    if let Some(path) = &job.map_out {
        crate::io::write_cloud(path, &cloud(), &Default::default())?;
    }
    if let Some(path) = &job.picture_out {
        let mapped: Vec<Point3<f64>> = poses
            .iter()
            .map(|(_, p)| Point3::new(p.x, p.y, 0.0))
            .collect();
        let truth: Vec<Point3<f64>> = reference
            .iter()
            .map(|p| Point3::new(p.x, p.y, 0.0))
            .collect();
        write_picture(path, &cloud(), mapped, truth)?;
    }
    Ok(PlanarLogReport {
        log: job.log.display().to_string(),
        scans: n,
        placed: poses.len(),
        sources,
        registrations_refused: reg_refused,
        edges: mapper
            .edge_counts()
            .into_iter()
            .map(|(k, v)| (k.name().to_string(), v))
            .collect(),
        loop_closure: job.params.closure.is_some(),
        closures_tried: tried,
        closures_accepted: accepted,
        closures_partial: partial,
        closures_refused: refused,
        closures_down_weighted: down,
        injected_closures,
        optimisations: mapper.optimisations(),
        initial_cost: solve.initial_cost,
        final_cost: solve.final_cost,
        noise: job.noise,
        noise_seed: job.noise_seed,
        errors,
        odometry_errors,
        seconds,
        ms_per_scan: 1e3 * seconds / n.max(1) as f64,
        max_ms_per_scan: max_ms,
    })
}

/// Errors of `estimated` (None = not placed, skipped) against `reference`, index by index.
/// Relative errors: for each scan, the first later scan at least 1 m (10 m) further along
/// the reference path; the difference of the two relative displacements.
pub fn planar_errors(estimated: &[Option<Se2>], reference: &[Se2]) -> PlanarErrors {
    let pairs: Vec<(usize, Se2, Se2)> = estimated
        .iter()
        .zip(reference)
        .enumerate()
        .filter_map(|(i, (e, r))| Some((i, (*e)?, *r)))
        .collect();
    let k = pairs.len().max(1) as f64;
    // The best rigid fit of the estimated positions onto the reference ones.
    let (mut ce, mut cr) = (Vector2::zeros(), Vector2::zeros());
    for (_, e, r) in &pairs {
        ce += Vector2::new(e.x, e.y);
        cr += Vector2::new(r.x, r.y);
    }
    ce /= k;
    cr /= k;
    let (mut dot, mut cross) = (0.0, 0.0);
    for (_, e, r) in &pairs {
        let a = Vector2::new(e.x, e.y) - ce;
        let b = Vector2::new(r.x, r.y) - cr;
        dot += a.dot(&b);
        cross += a.x * b.y - a.y * b.x;
    }
    let fit_angle = cross.atan2(dot);
    let (fs, fc) = fit_angle.sin_cos();
    let (mut sq, mut max, mut ysq, mut ymax) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut asq, mut amax) = (0.0f64, 0.0f64);
    for (_, e, r) in &pairs {
        let a = Vector2::new(e.x, e.y) - ce;
        let moved = Vector2::new(fc * a.x - fs * a.y, fs * a.x + fc * a.y) + cr;
        let d = (moved - Vector2::new(r.x, r.y)).norm();
        let y = wrap_angle(e.theta + fit_angle - r.theta).abs().to_degrees();
        sq += d * d;
        max = max.max(d);
        ysq += y * y;
        ymax = ymax.max(y);
        let anchored = (e.x - r.x).hypot(e.y - r.y);
        asq += anchored * anchored;
        amax = amax.max(anchored);
    }
    let mut travel = vec![0.0; reference.len()];
    for i in 1..reference.len() {
        travel[i] = travel[i - 1]
            + (reference[i].x - reference[i - 1].x).hypot(reference[i].y - reference[i - 1].y);
    }
    let relative = |segment: f64| {
        let (mut s, mut c) = (0.0, 0usize);
        let mut b = 0;
        for a in 0..pairs.len() {
            let ia = pairs[a].0;
            b = b.max(a + 1);
            while b < pairs.len() && travel[pairs[b].0] - travel[ia] < segment {
                b += 1;
            }
            if b >= pairs.len() {
                break;
            }
            let (_, ea, ra) = pairs[a];
            let (_, eb, rb) = pairs[b];
            let de = ea.inverse().compose(&eb);
            let dr = ra.inverse().compose(&rb);
            s += (de.x - dr.x).powi(2) + (de.y - dr.y).powi(2);
            c += 1;
        }
        if c == 0 {
            0.0
        } else {
            (s / c as f64).sqrt()
        }
    };
    PlanarErrors {
        scans: pairs.len(),
        ate_rmse_m: (sq / k).sqrt(),
        ate_max_m: max,
        anchored_rmse_m: (asq / k).sqrt(),
        anchored_max_m: amax,
        yaw_rmse_deg: (ysq / k).sqrt(),
        yaw_max_deg: ymax,
        relative_1m_rmse_m: relative(1.0),
        relative_10m_rmse_m: relative(10.0),
    }
}

/// The first two words of a reason, to count reasons by kind.
fn reason_head(reason: &str) -> String {
    reason
        .split_whitespace()
        .take(2)
        .collect::<Vec<_>>()
        .join(" ")
}

/// Adds `job.inject_wrong_closures × accepted` wrong closures (see
/// [`PlanarLogJob::inject_wrong_closures`]); returns `(edge, from, to, offset)` of each.
fn inject(
    mapper: &mut PlanarMapper,
    n: usize,
    accepted: usize,
    job: &PlanarLogJob,
) -> Result<Vec<(usize, usize, usize, f64)>> {
    let count = (job.inject_wrong_closures * accepted as f64).ceil() as usize;
    let mut out = Vec::new();
    if count == 0 || n < 60 {
        return Ok(out);
    }
    let seed = job.noise_seed ^ 0x5eed_c105_u64;
    let mut counter = 0u64;
    let mut draw = || {
        counter += 1;
        super::odometry::uniform(seed, counter)
    };
    let mut tries = 0;
    while out.len() < count && tries < 100 * count {
        tries += 1;
        let a = (draw() * n as f64) as usize;
        let b = (draw() * n as f64) as usize;
        let (from, to) = (a.min(b), a.max(b));
        if to - from < 50 {
            continue;
        }
        let (Some(pa), Some(pb)) = (mapper.pose_of(from), mapper.pose_of(to)) else {
            continue;
        };
        let rel = pa.inverse().compose(&pb);
        let offset = 2.0 + 3.0 * draw();
        let dir = std::f64::consts::TAU * draw();
        let wrong = Se2::new(
            rel.x + offset * dir.cos(),
            rel.y + offset * dir.sin(),
            rel.theta,
        );
        if let Some(edge) = mapper.add_closure_edge(from, to, wrong)? {
            out.push((edge, from, to, offset));
        }
    }
    Ok(out)
}

/// The top view of [`PlanarLogJob::picture_out`].
#[cfg(feature = "render")]
fn write_picture(
    path: &std::path::Path,
    cloud: &PointCloud,
    mapped: Vec<Point3<f64>>,
    reference: Vec<Point3<f64>>,
) -> Result<()> {
    use crate::render::{render_top_view, write_png, TopViewOptions};
    let map = crate::occupancy::OccupancyList::from_cloud(cloud, 0.05)?;
    let view = render_top_view(
        &map,
        &TopViewOptions {
            pixel_size: Some(0.05),
            grid_step: Some(5.0),
            paths: vec![mapped, reference],
            ..Default::default()
        },
    )?;
    write_png(path, &view.image)
}

#[cfg(not(feature = "render"))]
fn write_picture(
    path: &std::path::Path,
    _cloud: &PointCloud,
    _mapped: Vec<Point3<f64>>,
    _reference: Vec<Point3<f64>>,
) -> Result<()> {
    Err(Error::InvalidArgument(format!(
        "{}: pictures need olmap built with the `render` feature",
        path.display()
    )))
}
