//! Registering one scan against the map: along its links first ([`super::linked`]), then in
//! odometry windows that grow, then globally; and the odometry trust test.

use std::sync::atomic::Ordering;

use super::odometry_error::first_growth;
use super::state::State;
use crate::align::icp::{IcpParams, IcpTarget};
use crate::align::register_preparing;
use crate::align::verify::same_solution;
use crate::align::{OnWindowEdge, Region, RegisterParams, Registration};
use crate::error::Result;
use crate::geometry::Pose;
use crate::mapping::links::Placement;

/// A registration of one scan and what found it.
#[derive(Debug, Clone)]
pub(super) struct Found {
    /// The registration.
    pub(super) registration: Registration,
    /// The search that found it: a sighting, odometry or a global search.
    pub(super) via: Placement,
}

/// Keeps `r` as the best so far when nothing is kept yet or it overlaps the map more.
pub(super) fn keep_better(best: &mut Option<Found>, r: Registration, via: Placement) {
    if best
        .as_ref()
        .is_none_or(|b| r.search.overlap > b.registration.search.overlap)
    {
        *best = Some(Found {
            registration: r,
            via,
        });
    }
}

impl State<'_> {
    /// Registers scan `s` against the map. First along the loci of its sightings of or by
    /// placed scans (mutual first). Then, with an odometry prediction: in windows around it
    /// that double twice (the incremental mapper skips those its robot's recent odometry
    /// errors make too small: [`super::odometry_error`]), then one as wide as the odometry
    /// tolerance; a global search only
    /// when `allow_global` (the batch mapper's last resort: the odometry may be wrong).
    /// Without odometry: globally. Returns the best registration and what found it.
    pub(super) fn register(&self, s: usize, allow_global: bool) -> Result<Found> {
        let mut best: Option<Found> = None;
        let links = self.placed_links(s);
        if let Some(found) = self.search_links(s, &links, &mut best)? {
            return Ok(found);
        }
        let mut params = self.params.register.clone();
        let prediction = self.predict(s);
        if let Some((prior, distance)) = prediction {
            let (xy, z, yaw) = self.params.odometry_window;
            let tolerance = self.odometry_tolerance(distance);
            // The doubling windows smaller than the frame's recent odometry error calls
            // for are skipped (their match would lie in the outer half, untrusted).
            let growths = [1.0, 2.0, 4.0];
            let first = first_growth(&growths, xy, yaw, self.expected_odometry_error(s));
            let mut windows: Vec<f64> = growths[first..].to_vec();
            if tolerance > 4.0 * xy {
                windows.push(tolerance / xy);
            }
            params.search.prior = prior;
            let last = windows.len() - 1;
            for (i, grow) in windows.into_iter().enumerate() {
                params.search.region = Region::Window {
                    xy: xy * grow,
                    z: z * grow,
                    yaw: (yaw * grow).min(std::f64::consts::PI),
                };
                // Before the last window, a search whose every hypothesis starts on the edge
                // or too far into the outer half (where a match is not trusted here) is not
                // refined: the next, wider window searches there again.
                let on_edge = if i < last {
                    OnWindowEdge::Widen { inner: 0.5 }
                } else {
                    OnWindowEdge::Refine
                };
                let mut r = self.run_or_widen(s, &params, on_edge)?;
                check_odometry(&mut r, &prior, tolerance);
                if r.trusted && in_outer_half(&r, &prior, xy * grow) {
                    if i < last {
                        distrust_outer_half(
                            &mut r,
                            &prior,
                            xy * grow,
                            "a wider window must confirm it",
                        );
                    } else {
                        // The last window: one search twice as wide must find the same pose.
                        let mut wide = params.clone();
                        wide.search.region = Region::Window {
                            xy: 2.0 * xy * grow,
                            z: 2.0 * z * grow,
                            yaw: (2.0 * yaw * grow).min(std::f64::consts::PI),
                        };
                        let w = self.run(s, &wide)?;
                        if !(w.trusted && same_solution(&w.pose, &r.pose, params.search.resolution))
                        {
                            distrust_outer_half(
                                &mut r,
                                &prior,
                                xy * grow,
                                "a search twice as wide did not confirm it",
                            );
                        }
                    }
                }
                if r.trusted {
                    return Ok(Found {
                        registration: r,
                        via: Placement::Odometry,
                    });
                }
                keep_better(&mut best, r, Placement::Odometry);
            }
            if !allow_global {
                return Ok(best.expect("at least one window"));
            }
        } else if !allow_global && !links.is_empty() {
            // Linked but no odometry in its frame yet: the loci were the search.
            return Ok(best.expect("at least one link"));
        }
        // The global search keeps the odometry prior the windows set (if any).
        params.search.region = Region::Global;
        let mut r = self.run(s, &params)?;
        if let Some((prior, distance)) = prediction {
            check_odometry(&mut r, &prior, self.odometry_tolerance(distance));
        }
        match best {
            Some(b) if !r.trusted && b.registration.search.overlap > r.search.overlap => Ok(b),
            _ => Ok(Found {
                registration: r,
                via: Placement::Global,
            }),
        }
    }

    /// Registers scan `s` in a window (the first odometry window) around `prior`: the
    /// confirmation of a cached result before the scan joins the map.
    pub(super) fn register_near(&self, s: usize, prior: Pose) -> Result<Registration> {
        let mut params = self.params.register.clone();
        let (xy, z, yaw) = self.params.odometry_window;
        params.search.prior = prior;
        params.search.region = Region::Window { xy, z, yaw };
        let mut r = self.run(s, &params)?;
        if let Some((predicted, distance)) = self.predict(s) {
            check_odometry(&mut r, &predicted, self.odometry_tolerance(distance));
        }
        Ok(r)
    }

    /// The map's points prepared for ICP with `icp`'s target parameters: once per map, not
    /// once per registration, and after the map grew by bringing the last one up to it
    /// ([`IcpTarget::updated`]). (Registrations in parallel that find it missing may each
    /// prepare it, the first from the last one and the others afresh, and keep one: the
    /// batch mapper prepares it before a parallel round. No lock is held while preparing:
    /// the work runs on the rayon pool, whose threads may be running other registrations.)
    pub(super) fn prepared_map(&self, icp: &IcpParams) -> Result<&IcpTarget> {
        if let Some(p) = self.refine_prepared.get() {
            return Ok(p);
        }
        let last = self
            .refine_stale
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        let (map, voxel) = (self.refine_points(), self.params.refine_map_voxel);
        let p = match last {
            Some(last) => last.updated(map, icp, voxel)?,
            None => IcpTarget::of_map(map, icp, voxel)?,
        };
        Ok(self.refine_prepared.get_or_init(|| p))
    }

    /// One registration of scan `s` against the map (searching with its registration
    /// cloud, refining with the whole scan), counted.
    pub(super) fn run(&self, s: usize, params: &RegisterParams) -> Result<Registration> {
        self.run_or_widen(s, params, OnWindowEdge::Refine)
    }

    /// [`State::run`], saying what a window search whose best lies on the edge does.
    pub(super) fn run_or_widen(
        &self,
        s: usize,
        params: &RegisterParams,
        on_edge: OnWindowEdge,
    ) -> Result<Registration> {
        self.registrations.fetch_add(1, Ordering::Relaxed);
        // The map's k-d tree (built after the map grew) is made beside the search.
        let prepare = || match &params.refine {
            Some(icp) => self.prepared_map(icp).map(Some),
            None => Ok(None),
        };
        register_preparing(
            self.cloud(s),
            &self.scans[s].cloud,
            &self.target,
            self.refine_points(),
            &prepare,
            params,
            on_edge,
        )
    }
}

/// Whether a registration lies in the outer half of an odometry window (`half` metres in
/// x and y around `prior`). In a place that repeats (rows of desks), a truth just outside
/// the window leaves a look-alike one period away as the best inside, refined and verified
/// without a rival (seen in the demo: a scan trusted 2.6 m from its prediction in a ±3 m
/// window, 0.52 m off, the truth outside). A match in the inner half has its whole
/// neighbourhood, and the look-alikes one period away, inside the window. The mapper trusts
/// a match in the outer half only when a wider search finds it again.
fn in_outer_half(r: &Registration, prior: &Pose, half: f64) -> bool {
    let d = r.pose.translation() - prior.translation();
    d.x.abs() > 0.5 * half || d.y.abs() > 0.5 * half
}

/// Marks a match in the outer half of its window untrusted, saying `why`.
fn distrust_outer_half(r: &mut Registration, prior: &Pose, half: f64, why: &str) {
    let d = r.pose.translation() - prior.translation();
    r.trusted = false;
    r.doubts.push(format!(
        "the match lies in the outer half of its odometry window ({:+.2}, {:+.2} m from the \
         prediction, window ±{half:.2} m): {why}",
        d.x, d.y
    ));
}

/// Distrusts a registration farther than `tolerance` metres from the odometry prediction
/// `prior` (a window search snaps to coarse cells and can end past its nominal edge).
fn check_odometry(r: &mut Registration, prior: &Pose, tolerance: f64) {
    let off = (r.pose.translation() - prior.translation()).norm();
    if r.trusted && off > tolerance {
        r.trusted = false;
        r.doubts.push(format!(
            "the match is {off:.2} m from the odometry prediction (tolerance {tolerance:.2} m)"
        ));
    }
}
