//! The rotating-mirror 3D scanner of thesis §4.3: a 2D scanner whose sweeps a turning mirror
//! tilts to a new elevation, simulated beam by beam with the true mirror angle at each
//! beam's own time, with the raw log its sensors would write.

use nalgebra::Point3;
use rayon::prelude::*;

use super::lidar::collect_cloud;
use super::noise::{measure, Beam, RangeNoise};
use crate::cloud::PointCloud;
use crate::geometry::Pose;
use crate::scanner::{MirrorEvent, MirrorEventKind, MirrorGeometry, MirrorLog, Sweep};
use crate::sim::{Object, SimRng, World};

/// A rotating-mirror 3D scanner (geometry and frames: [`crate::scanner`]).
///
/// The scan lasts `revolutions * mirror_period` seconds from `t = 0`. The mirror turns at
/// constant speed, `alpha(t) = start_phase + 2 pi t / mirror_period`; sweep `k` starts at
/// `k / sweep_rate` and its beam `i` (of `geometry.scan_beams`) fires at
/// `k / sweep_rate + sweep_duration i / (scan_beams - 1)`, so the mirror moves within a
/// sweep. Sweeps start while `t < revolutions * mirror_period`.
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorScanner {
    /// The scanner's geometry.
    pub geometry: MirrorGeometry,
    /// Seconds per mirror revolution.
    pub mirror_period: f64,
    /// 2D sweeps per second.
    pub sweep_rate: f64,
    /// Time from a sweep's first beam to its last, seconds.
    pub sweep_duration: f64,
    /// Mirror angle at `t = 0`, radians (a scan can start anywhere in the revolution).
    pub start_phase: f64,
    /// Length of the scan in mirror revolutions.
    pub revolutions: f64,
    /// Range noise; the scanner measures up to the smaller of its `max_range` and the
    /// geometry's.
    pub noise: RangeNoise,
}

impl MirrorScanner {
    /// The first-generation scanner (§4.3.1-4.3.2): [`MirrorGeometry::standard`] (double
    /// sided, d = 0.1 m), mirror period 40 s, 13 sweeps per second over the serial link,
    /// 13 ms per sweep (180° at 1°), half a revolution per 3D scan (20 s: the thesis's
    /// 0.05 Hz), default noise (2 cm) up to 8 m.
    pub fn standard() -> Self {
        MirrorScanner {
            geometry: MirrorGeometry::standard(),
            mirror_period: 40.0,
            sweep_rate: 13.0,
            sweep_duration: 0.013,
            start_phase: 0.0,
            revolutions: 0.5,
            noise: RangeNoise::default().with_max_range(8.0),
        }
    }

    /// The enhanced scanner (§4.3.3): [`MirrorGeometry::enhanced`] (facing up, double
    /// sided), 75 sweeps per second over RS422, 13 ms per sweep, mirror period 9.6 s and half
    /// a revolution per 3D scan: 4.8 s and 360 sweeps, so the reflected elevation advances
    /// 1° per sweep, matching the 1° horizontal step (the thesis's "360/75 = 4.8 seconds").
    /// Default noise (2 cm) up to 8 m.
    pub fn enhanced() -> Self {
        MirrorScanner {
            geometry: MirrorGeometry::enhanced(),
            mirror_period: 9.6,
            sweep_rate: 75.0,
            sweep_duration: 0.013,
            start_phase: 0.0,
            revolutions: 0.5,
            noise: RangeNoise::default().with_max_range(8.0),
        }
    }

    /// Length of the scan, seconds.
    pub fn duration(&self) -> f64 {
        self.revolutions * self.mirror_period
    }

    /// Number of sweeps in the scan.
    pub fn sweeps(&self) -> usize {
        ((self.duration() * self.sweep_rate - 1e-9).ceil()).max(0.0) as usize
    }

    /// Start time of sweep `k`, seconds.
    pub fn sweep_time(&self, k: usize) -> f64 {
        k as f64 / self.sweep_rate
    }

    /// Time at which beam `i` of sweep `k` fires, seconds.
    pub fn beam_time(&self, k: usize, i: usize) -> f64 {
        let n = self.geometry.scan_beams;
        let within = if n > 1 {
            self.sweep_duration * i as f64 / (n - 1) as f64
        } else {
            0.0
        };
        self.sweep_time(k) + within
    }

    /// The true mirror angle at time `t`, radians (not wrapped).
    pub fn mirror_angle(&self, t: f64) -> f64 {
        self.start_phase + std::f64::consts::TAU * t / self.mirror_period
    }

    /// The 3D scan: exact simulated points (noisy ranges through thesis (4.10) with the
    /// true mirror angle of each beam) in the sensor frame, origin zero, with intensities,
    /// in firing order. Beam `i` of sweep `k` draws its noise from
    /// `SimRng::for_item(seed, stream, k * scan_beams + i)`.
    pub fn scan(
        &self,
        world: &World,
        extra: &[Object],
        t_world_sensor: &Pose,
        seed: u64,
        stream: u64,
    ) -> PointCloud {
        self.scan_raw(world, extra, t_world_sensor, seed, stream).0
    }

    /// [`MirrorScanner::scan`] and the raw log the scanner would write: every sweep's
    /// ranges as the 2D scanner measures them (the whole optical path, `inf` for no return
    /// and for beams that miss the mirror or are blinded by it), the encoder ticks at the
    /// times the mirror passes each tick angle and the trigger each time it passes the
    /// trigger angle, from `t = 0` to the last beam (or the scan's end if later).
    pub fn scan_raw(
        &self,
        world: &World,
        extra: &[Object],
        t_world_sensor: &Pose,
        seed: u64,
        stream: u64,
    ) -> (PointCloud, MirrorLog) {
        let g = &self.geometry;
        let n = g.scan_beams;
        let n_sweeps = self.sweeps();
        let noise = self
            .noise
            .with_max_range(self.noise.max_range.min(g.max_range));
        let to_world = |b: crate::scanner::MirrorBeam| Beam {
            origin: t_world_sensor.transform_point(&b.origin),
            dir: t_world_sensor.transform_vector(&b.direction),
            before: b.path_to_mirror,
        };
        let results: Vec<Option<(Point3<f32>, f32, f64)>> = (0..n_sweeps * n)
            .into_par_iter()
            .with_min_len(256)
            .map(|j| {
                let (k, i) = (j / n, j % n);
                let alpha = self.mirror_angle(self.beam_time(k, i));
                let theta = g.scan_angle(i);
                let main = to_world(g.beam(theta, alpha)?);
                let sub = g.beam(theta + 0.5 * g.scan_angle_step, alpha).map(to_world);
                let mut rng = SimRng::for_item(seed, stream, j as u64);
                let r = measure(world, extra, &main, sub.as_ref(), &noise, &mut rng)?;
                let p = g.point(r.range, theta, alpha);
                Some((
                    Point3::new(p.x as f32, p.y as f32, p.z as f32),
                    r.intensity,
                    r.range,
                ))
            })
            .collect();
        let mut sweeps = Vec::with_capacity(n_sweeps);
        for k in 0..n_sweeps {
            let row = &results[k * n..(k + 1) * n];
            sweeps.push(Sweep {
                time: self.sweep_time(k),
                duration: self.sweep_duration,
                angle_min: g.scan_angle_min,
                angle_step: g.scan_angle_step,
                ranges: row
                    .iter()
                    .map(|r| r.map_or(f32::INFINITY, |r| r.2 as f32))
                    .collect(),
                intensities: Some(row.iter().map(|r| r.map_or(0.0, |r| r.1)).collect()),
            });
        }
        let t_end = if n_sweeps > 0 {
            self.beam_time(n_sweeps - 1, n - 1).max(self.duration())
        } else {
            self.duration()
        };
        let events = self.events(t_end);
        let cloud = collect_cloud(results.into_iter().map(|r| r.map(|r| (r.0, r.1))).collect());
        let log = MirrorLog {
            header: g.clone(),
            sweeps,
            events,
        };
        (cloud, log)
    }

    /// Encoder ticks and triggers from `t = 0` to `t_end`, in time order (a tick before a
    /// trigger at the same time).
    fn events(&self, t_end: f64) -> Vec<MirrorEvent> {
        use std::f64::consts::TAU;
        let omega = TAU / self.mirror_period;
        let a0 = self.start_phase;
        let a1 = self.mirror_angle(t_end);
        let mut events = Vec::new();
        let tick = TAU / self.geometry.ticks_per_revolution as f64;
        let (k0, k1) = ((a0 / tick).ceil() as i64, (a1 / tick).floor() as i64);
        for k in k0..=k1 {
            let time = (k as f64 * tick - a0) / omega;
            if (0.0..=t_end).contains(&time) {
                events.push(MirrorEvent {
                    time,
                    kind: MirrorEventKind::Tick,
                });
            }
        }
        let trig = self.geometry.trigger_angle;
        let (m0, m1) = (
            ((a0 - trig) / TAU).ceil() as i64,
            ((a1 - trig) / TAU).floor() as i64,
        );
        for m in m0..=m1 {
            let time = (trig + m as f64 * TAU - a0) / omega;
            if (0.0..=t_end).contains(&time) {
                events.push(MirrorEvent {
                    time,
                    kind: MirrorEventKind::Trigger,
                });
            }
        }
        events.sort_by(|a, b| a.time.total_cmp(&b.time));
        events
    }
}
