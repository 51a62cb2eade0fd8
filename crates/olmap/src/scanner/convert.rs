//! Conversion of a rotating-mirror scanner's raw log ([`MirrorLog`]) into a 3D point cloud
//! (thesis §4.3.1-4.3.3).
//!
//! * **Mirror angle** (4.9): the encoder ticks give the mirror angle in steps of
//!   `2 pi / ticks_per_revolution`; the once-per-revolution trigger fixes the absolute
//!   angle (`trigger_angle`). Tick `k` is at mirror angle `2 pi k / ticks_per_revolution`,
//!   so the first tick after the first trigger is tick `ceil(trigger_angle / step)` (a
//!   trigger on a tick angle pins the tick nearest to it in time), the ones after it count
//!   up and the ones before it count back: a scan may start anywhere in the revolution
//!   (the thesis' "on demand scans").
//!   The mirror is taken to turn toward increasing angle. The angle at any time is the
//!   linear interpolation between the samples (the ticks and the first trigger) around
//!   it; beyond the first or last sample it is extrapolated with the neighbouring
//!   segment's speed for at most [`ConvertParams::max_extrapolation_ticks`] tick
//!   intervals.
//! * **Within-sweep correction** (§4.3.1, "13 ms ... 0.3°"): beam `i` of a sweep is
//!   converted at its own time [`Sweep::beam_time`], so `phi` advances along the sweep.
//! * **Points**: thesis (4.10) with the mirror offset `d`, turned into the sensor frame of
//!   the mounting ([`MirrorGeometry::point`]); a point cloud in the sensor frame, origin
//!   zero, with intensities when every sweep has them.
//! * **Dropped readings**, counted by reason in [`ConvertStats`]: no return; beams that
//!   miss the mirror (`|theta|` above the theta limit, the visible volume (4.11)); the
//!   mirror edge on; beams blocked (sent back into the scanner, or onto the back of a
//!   single-sided mirror); ranges beyond the maximum (thesis: 8 m) or below the minimum
//!   (4.11: 0.5 m); elevations outside an optional window; mixed pixels
//!   ([`super::mixed_pixels`]) when asked.

use std::f64::consts::TAU;

use nalgebra::Point3;

use super::pixel_mixing::{mixed_pixels, MixedPixelParams, RangeImage};
use super::{MirrorEventKind, MirrorGeometry, MirrorLog, Sweep};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};

/// How to convert a raw log.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertParams {
    /// Convert every beam at its own time (default true). False converts every beam of a
    /// sweep at the sweep's timestamp, as if the sweep were instantaneous.
    pub within_sweep_correction: bool,
    /// Longest range kept, metres; `None` (default) uses the header's `max_range`.
    pub max_range: Option<f64>,
    /// Shortest range kept, metres (default 0; the thesis' visible volume (4.11) uses 0.5).
    pub min_range: f64,
    /// Largest `|theta|` kept, radians; `None` (default) uses the header's `theta_limit`.
    /// Values above the header's do not bring back beams that miss the mirror.
    pub theta_limit: Option<f64>,
    /// Keep only reflected elevations `phi = 2 alpha` (wrapped into `[0, 2 pi)`) within
    /// `[lo, hi]`, radians (default `None`: all).
    pub elevation_window: Option<(f64, f64)>,
    /// Remove mixed pixels (default false).
    pub filter_mixed: bool,
    /// The mixed-pixel filter's thresholds.
    pub mixed: MixedPixelParams,
    /// How far beyond the first and last encoder samples the mirror angle may be
    /// extrapolated, in (mean) tick intervals (default 1). Sweeps needing more are an
    /// error.
    pub max_extrapolation_ticks: f64,
}

impl Default for ConvertParams {
    fn default() -> Self {
        ConvertParams {
            within_sweep_correction: true,
            max_range: None,
            min_range: 0.0,
            theta_limit: None,
            elevation_window: None,
            filter_mixed: false,
            mixed: MixedPixelParams::default(),
            max_extrapolation_ticks: 1.0,
        }
    }
}

/// What a conversion kept and dropped, by reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ConvertStats {
    /// Sweeps converted.
    pub sweeps: usize,
    /// Beams in those sweeps.
    pub beams: usize,
    /// Points in the cloud.
    pub points: usize,
    /// Beams without a return (`inf`, NaN or a range <= 0).
    pub no_return: usize,
    /// Beams outside the theta limit (they miss the mirror or leave the visible volume).
    pub outside_mirror: usize,
    /// Beams meeting the mirror nearly edge on.
    pub edge_on: usize,
    /// Beams sent back into the scanner or onto the back of a single-sided mirror.
    pub blocked: usize,
    /// Ranges above the maximum.
    pub beyond_max_range: usize,
    /// Ranges below the minimum.
    pub below_min_range: usize,
    /// Elevations outside [`ConvertParams::elevation_window`].
    pub outside_elevation: usize,
    /// Returns removed as mixed pixels.
    pub mixed_pixels: usize,
    /// Triggers after the first whose interpolated mirror angle is more than half a tick
    /// step from the trigger angle (missed or extra ticks).
    pub trigger_mismatches: usize,
}

/// A converted scan.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertedScan {
    /// The points, sensor frame, in log order (sweep by sweep, beam by beam).
    pub cloud: PointCloud,
    /// `[sweep, beam]` of each point.
    pub sources: Vec<[u32; 2]>,
    /// What was kept and dropped.
    pub stats: ConvertStats,
}

/// The mirror angle as a function of time, from the encoder history (thesis (4.9)).
#[derive(Debug, Clone, PartialEq)]
pub struct EncoderHistory {
    times: Vec<f64>,
    angles: Vec<f64>,
    step: f64,
    trigger_mismatches: usize,
}

impl EncoderHistory {
    /// Builds the history from a log's events (see the [module documentation](self)).
    /// Errors: invalid geometry, events out of time order or not finite, no trigger, fewer
    /// than two ticks.
    pub fn from_log(log: &MirrorLog) -> Result<Self> {
        let g = &log.header;
        g.validate()?;
        let bad = |m: String| Err(Error::InvalidArgument(format!("mirror log: {m}")));
        let mut last = f64::NEG_INFINITY;
        for e in &log.events {
            if !e.time.is_finite() || e.time < last {
                return bad("mirror events must be finite and in time order".into());
            }
            last = e.time;
        }
        let ticks: Vec<f64> = log.event_times(MirrorEventKind::Tick);
        let triggers: Vec<f64> = log.event_times(MirrorEventKind::Trigger);
        let Some(&t_trig) = triggers.first() else {
            return bad("no trigger event: the absolute mirror angle is unknown".into());
        };
        if ticks.len() < 2 {
            return bad(format!(
                "{} encoder tick(s): at least two are needed to interpolate the mirror angle",
                ticks.len()
            ));
        }
        let step = TAU / g.ticks_per_revolution as f64;
        // Which tick index the trigger pins down. A trigger between ticks: the first tick
        // after it is tick ceil(trigger_angle / step). A trigger on a tick: that tick is the
        // one nearest in time (the two fire together; their order in the log is arbitrary).
        let kf = g.trigger_angle / step;
        let on_tick = (kf - kf.round()).abs() < 1e-6;
        let n_before = ticks.partition_point(|&t| t < t_trig);
        let (anchor, anchor_k) = if on_tick {
            let nearest = (0..ticks.len())
                .min_by(|&a, &b| {
                    (ticks[a] - t_trig)
                        .abs()
                        .total_cmp(&(ticks[b] - t_trig).abs())
                })
                .expect("at least two ticks");
            (nearest as i64, kf.round() as i64)
        } else {
            (n_before as i64, kf.ceil() as i64)
        };
        let mut times = Vec::with_capacity(ticks.len() + 1);
        let mut angles = Vec::with_capacity(ticks.len() + 1);
        for (j, &t) in ticks.iter().enumerate() {
            if !on_tick && j == n_before {
                times.push(t_trig);
                angles.push(g.trigger_angle);
            }
            if times.last().is_some_and(|&last| last >= t) {
                continue;
            }
            times.push(t);
            angles.push((anchor_k + j as i64 - anchor) as f64 * step);
        }
        if !on_tick && n_before == ticks.len() {
            times.push(t_trig);
            angles.push(g.trigger_angle);
        }
        if times.len() < 2 {
            return bad("the encoder ticks all share one time".into());
        }
        let mut h = EncoderHistory {
            times,
            angles,
            step,
            trigger_mismatches: 0,
        };
        // Later triggers should fall on trigger_angle + 2 pi m.
        for &t in &triggers[1..] {
            if let Some(a) = h.angle_at(t, 0.0) {
                let off = crate::geometry::wrap_angle(a - g.trigger_angle).abs();
                if off > 0.5 * step {
                    h.trigger_mismatches += 1;
                }
            }
        }
        Ok(h)
    }

    /// The first and last sample times, seconds.
    pub fn span(&self) -> (f64, f64) {
        (self.times[0], self.times[self.times.len() - 1])
    }

    /// Mean time per tick step over the history, seconds.
    pub fn mean_tick_interval(&self) -> f64 {
        let n = self.times.len() - 1;
        (self.times[n] - self.times[0]) / (self.angles[n] - self.angles[0]) * self.step
    }

    /// The mirror angle (radians, not wrapped) at time `t` by linear interpolation (4.9);
    /// up to `max_extrapolation` seconds beyond the history it is extrapolated with the
    /// end segment's speed, beyond that `None`.
    pub fn angle_at(&self, t: f64, max_extrapolation: f64) -> Option<f64> {
        let (t0, t1) = self.span();
        if !(t >= t0 - max_extrapolation && t <= t1 + max_extrapolation) {
            return None;
        }
        let n = self.times.len();
        let j = self.times.partition_point(|&s| s <= t).clamp(1, n - 1);
        let (ta, tb) = (self.times[j - 1], self.times[j]);
        let (aa, ab) = (self.angles[j - 1], self.angles[j]);
        Some(aa + (t - ta) / (tb - ta) * (ab - aa))
    }
}

/// Why a beam gives no point, before range limits.
enum Blind {
    Outside,
    EdgeOn,
    Blocked,
}

fn blind(g: &MirrorGeometry, theta_limit: f64, theta: f64, alpha: f64) -> Option<Blind> {
    if !(theta.abs() <= theta_limit && theta.cos() > 0.0) {
        return Some(Blind::Outside);
    }
    let s = alpha.sin();
    if s.abs() < g.edge_on_margin.sin() {
        return Some(Blind::EdgeOn);
    }
    if g.sides == 1 && s <= 0.0 {
        return Some(Blind::Blocked);
    }
    let phi = MirrorGeometry::reflected_elevation(alpha);
    if crate::geometry::wrap_angle(phi - std::f64::consts::PI).abs() < g.back_margin {
        return Some(Blind::Blocked);
    }
    None
}

/// Converts a raw log into a 3D cloud in the sensor frame (see the
/// [module documentation](self)).
///
/// Errors (never panics): invalid geometry or parameters, no trigger, fewer than two
/// ticks, events or sweeps out of time order, a sweep with mismatched intensities or
/// beams outside the encoder history (beyond the allowed extrapolation).
pub fn convert_log(log: &MirrorLog, params: &ConvertParams) -> Result<ConvertedScan> {
    let g = &log.header;
    let history = EncoderHistory::from_log(log)?;
    let bad = |m: String| Err(Error::InvalidArgument(format!("mirror log: {m}")));
    let max_range = params.max_range.unwrap_or(g.max_range);
    let theta_limit = params
        .theta_limit
        .unwrap_or(g.theta_limit)
        .min(g.theta_limit);
    if max_range.is_nan()
        || max_range <= 0.0
        || params.min_range.is_nan()
        || params.max_extrapolation_ticks.is_nan()
        || params.max_extrapolation_ticks < 0.0
    {
        return bad("conversion: max_range must be > 0, min_range and extrapolation >= 0".into());
    }
    let conversion = Conversion {
        log,
        params,
        extrapolation: params.max_extrapolation_ticks * history.mean_tick_interval(),
        history,
        max_range,
        theta_limit,
        cols: log.sweeps.iter().map(|s| s.ranges.len()).max().unwrap_or(0),
        with_intensity: !log.sweeps.is_empty()
            && log.sweeps.iter().all(|s| s.intensities.is_some()),
    };
    let mut stats = ConvertStats {
        sweeps: log.sweeps.len(),
        trigger_mismatches: conversion.history.trigger_mismatches,
        ..ConvertStats::default()
    };
    let cand = conversion.candidates(&mut stats)?;
    let mixed = conversion.mixed(&cand)?;
    let (cloud, sources) = conversion.points(cand, mixed, &mut stats)?;
    stats.points = cloud.len();
    Ok(ConvertedScan {
        cloud,
        sources,
        stats,
    })
}

/// A return after the geometric checks: (sweep, beam, point, intensity, range beyond the
/// mirror, mirror angle).
type Candidate = (u32, u32, Point3<f64>, f32, f64, f64);

/// One conversion's inputs and settings, resolved from the log's header and the
/// parameters.
struct Conversion<'a> {
    log: &'a MirrorLog,
    params: &'a ConvertParams,
    history: EncoderHistory,
    /// Longest range kept, metres.
    max_range: f64,
    /// Largest `|theta|` kept, radians.
    theta_limit: f64,
    /// How far beyond the encoder history the mirror angle may be extrapolated, seconds.
    extrapolation: f64,
    /// The most beams in a sweep: the width of the range image.
    cols: usize,
    /// Whether every sweep has intensities (and there is at least one).
    with_intensity: bool,
}

impl Conversion<'_> {
    /// The candidates after the geometric checks, sweep by sweep, beam by beam. Range and
    /// elevation limits are applied after the mixed-pixel filter has seen every return.
    fn candidates(&self, stats: &mut ConvertStats) -> Result<Vec<Candidate>> {
        let mut cand: Vec<Candidate> = Vec::new();
        let mut last_time = f64::NEG_INFINITY;
        for (k, s) in self.log.sweeps.iter().enumerate() {
            check_sweep(s, k, &mut last_time)?;
            stats.beams += s.ranges.len();
            self.sweep_candidates(k, s, stats, &mut cand)?;
        }
        Ok(cand)
    }

    /// Adds sweep `k`'s candidates to `cand`, counting the dropped beams. Errors when the
    /// sweep lies outside the encoder history.
    fn sweep_candidates(
        &self,
        k: usize,
        s: &Sweep,
        stats: &mut ConvertStats,
        cand: &mut Vec<Candidate>,
    ) -> Result<()> {
        let (g, history, extrapolation) = (&self.log.header, &self.history, self.extrapolation);
        let time_of = |i: usize| {
            if self.params.within_sweep_correction {
                s.beam_time(i)
            } else {
                s.time
            }
        };
        let n = s.ranges.len();
        for t in [time_of(0), time_of(n.saturating_sub(1))] {
            if history.angle_at(t, extrapolation).is_none() {
                let (a, b) = history.span();
                return Err(Error::InvalidArgument(format!(
                    "mirror log: sweep {k} (t = {t}) lies outside the encoder history [{a}, {b}]"
                )));
            }
        }
        for i in 0..n {
            let r = s.ranges[i] as f64;
            if !(r.is_finite() && r > 0.0) {
                stats.no_return += 1;
                continue;
            }
            let theta = s.angle(i);
            let alpha = history
                .angle_at(time_of(i), extrapolation)
                .expect("checked at the sweep's ends");
            match blind(g, self.theta_limit, theta, alpha) {
                Some(Blind::Outside) => stats.outside_mirror += 1,
                Some(Blind::EdgeOn) => stats.edge_on += 1,
                Some(Blind::Blocked) => stats.blocked += 1,
                None => {
                    let intensity = s.intensities.as_ref().map_or(0.0, |v| v[i]);
                    let beyond = r - g.mirror_offset / theta.cos();
                    cand.push((
                        k as u32,
                        i as u32,
                        g.point(r, theta, alpha),
                        intensity,
                        beyond,
                        alpha,
                    ));
                }
            }
        }
        Ok(())
    }

    /// The mixed-pixel mask over the range image (`sweep * cols + beam`) of the
    /// candidates' ranges beyond the mirror, when asked for.
    fn mixed(&self, cand: &[Candidate]) -> Result<Option<Vec<bool>>> {
        if !self.params.filter_mixed {
            return Ok(None);
        }
        let (sweeps, cols) = (self.log.sweeps.len(), self.cols);
        let mut ranges = vec![f32::INFINITY; sweeps * cols];
        for c in cand {
            ranges[c.0 as usize * cols + c.1 as usize] = c.4 as f32;
        }
        let image = RangeImage::new(sweeps, cols, ranges)?;
        Ok(Some(mixed_pixels(&image, &self.params.mixed)?))
    }

    /// The cloud (with intensities when every sweep has them) and the sources of the
    /// candidates within the range and elevation limits and not mixed pixels, counting
    /// the dropped ones.
    fn points(
        &self,
        cand: Vec<Candidate>,
        mixed: Option<Vec<bool>>,
        stats: &mut ConvertStats,
    ) -> Result<(PointCloud, Vec<[u32; 2]>)> {
        let (params, cols, with_intensity) = (self.params, self.cols, self.with_intensity);
        let mut cloud = PointCloud::with_capacity(cand.len());
        let mut intensity = Vec::with_capacity(if with_intensity { cand.len() } else { 0 });
        let mut sources = Vec::with_capacity(cand.len());
        for (k, i, p, v, _, alpha) in cand {
            let s = &self.log.sweeps[k as usize];
            let r = s.ranges[i as usize] as f64;
            if r > self.max_range {
                stats.beyond_max_range += 1;
                continue;
            }
            if r < params.min_range {
                stats.below_min_range += 1;
                continue;
            }
            if let Some((lo, hi)) = params.elevation_window {
                let phi = MirrorGeometry::reflected_elevation(alpha).rem_euclid(TAU);
                if !(phi >= lo && phi <= hi) {
                    stats.outside_elevation += 1;
                    continue;
                }
            }
            if let Some(m) = &mixed {
                if m[k as usize * cols + i as usize] {
                    stats.mixed_pixels += 1;
                    continue;
                }
            }
            cloud.push(Point3::new(p.x as f32, p.y as f32, p.z as f32));
            if with_intensity {
                intensity.push(v);
            }
            sources.push([k, i]);
        }
        if with_intensity {
            cloud.set_intensity(Some(intensity))?;
        }
        Ok((cloud, sources))
    }
}

fn check_sweep(s: &Sweep, k: usize, last_time: &mut f64) -> Result<()> {
    let bad = |m: String| {
        Err(Error::InvalidArgument(format!(
            "mirror log: sweep {k}: {m}"
        )))
    };
    if !(s.time.is_finite() && s.duration.is_finite() && s.duration >= 0.0) {
        return bad("time and duration must be finite, the duration >= 0".into());
    }
    if s.time < *last_time {
        return bad("sweeps must be in time order".into());
    }
    *last_time = s.time;
    if !(s.angle_min.is_finite() && s.angle_step.is_finite()) {
        return bad("scan angles must be finite".into());
    }
    if let Some(v) = &s.intensities {
        if v.len() != s.ranges.len() {
            return bad(format!(
                "{} ranges but {} intensities",
                s.ranges.len(),
                v.len()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scanner::MirrorEvent;

    /// Events of a mirror turning at `omega` from angle `a0` over `[0, t_end]`.
    fn events(g: &MirrorGeometry, a0: f64, omega: f64, t_end: f64) -> Vec<MirrorEvent> {
        let step = TAU / g.ticks_per_revolution as f64;
        let mut ev = Vec::new();
        let a1 = a0 + omega * t_end;
        for k in (a0 / step).ceil() as i64..=(a1 / step).floor() as i64 {
            ev.push(MirrorEvent {
                time: (k as f64 * step - a0) / omega,
                kind: MirrorEventKind::Tick,
            });
        }
        let m0 = ((a0 - g.trigger_angle) / TAU).ceil() as i64;
        let m1 = ((a1 - g.trigger_angle) / TAU).floor() as i64;
        for m in m0..=m1 {
            ev.push(MirrorEvent {
                time: (g.trigger_angle + m as f64 * TAU - a0) / omega,
                kind: MirrorEventKind::Trigger,
            });
        }
        ev.sort_by(|a, b| a.time.total_cmp(&b.time));
        ev
    }

    #[test]
    fn interpolated_angle_is_exact_for_a_steady_mirror_from_any_phase() {
        for trigger_on_tick in [false, true] {
            let mut g = MirrorGeometry::standard();
            let step = TAU / g.ticks_per_revolution as f64;
            if trigger_on_tick {
                g.trigger_angle = 17.0 * step;
            }
            for a0 in [0.0, 0.2, g.trigger_angle, 3.0, 5.9, 7.5] {
                let omega = 0.37;
                let t_end = 1.3 * TAU / omega;
                let log = MirrorLog {
                    header: g.clone(),
                    sweeps: Vec::new(),
                    events: events(&g, a0, omega, t_end),
                };
                let h = EncoderHistory::from_log(&log).unwrap();
                assert_eq!(h.trigger_mismatches, 0);
                let (t0, t1) = h.span();
                for k in 0..=200 {
                    let t = t0 + (t1 - t0) * k as f64 / 200.0;
                    let a = h.angle_at(t, 0.0).unwrap();
                    // The absolute angle is known modulo a full turn.
                    let off = crate::geometry::wrap_angle(a - (a0 + omega * t));
                    assert!(off.abs() < 1e-9, "a0 {a0} t {t}: {off}");
                }
                assert!(h.angle_at(t1 + 10.0, 1.0).is_none());
            }
        }
    }
}
