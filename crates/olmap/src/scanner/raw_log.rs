//! The raw log of a rotating-mirror scanner: what its 2D scanner and its mirror sensors
//! report, before any conversion to points.
//!
//! A text file, one record per line, in time order (seconds from any fixed epoch):
//!
//! ```text
//! # olmap mirror log v1
//! # mounting standard
//! # mirror_offset 0.1
//! # sides 2
//! # ticks_per_revolution 350
//! # trigger_angle 0.3
//! # scan_angle_min -1.5707963267948966
//! # scan_angle_step 0.017453292519943295
//! # scan_beams 181
//! # theta_limit 1.0471975511965976
//! # edge_on_margin 0.08726646259971647
//! # back_margin 0.2617993877991494
//! # max_range 8.0
//! S 0.0 0.013 -1.5707963267948966 0.017453292519943295 3 2.5 inf 3.25 0.6 0.0 0.41
//! E 0.0021 tick
//! E 0.0307 trigger
//! ```
//!
//! * The first line is `# olmap mirror log v1`. Then the header: `# key value` lines with
//!   every field of [`MirrorGeometry`] (angles in radians, lengths in metres; `mounting` is
//!   `standard` or `enhanced`). Header lines with other keys are ignored, as are `#` lines
//!   after the header and blank lines.
//! * `S time duration start step n r_1 .. r_n [i_1 .. i_n]`: one sweep of the 2D scanner.
//!   `time` is when its first beam fired, `duration` the time from the first beam to the
//!   last (beam `k` fires at `time + duration k / (n - 1)`: the sweep is not
//!   instantaneous), `start` and `step` the scan angles of the first beam and between beams,
//!   `n` the beam count, then `n` ranges (metres along the whole optical path, `inf` for no
//!   return) and optionally `n` intensities.
//! * `E time tick`: the mirror passed an encoder tick (tick `k` is at mirror angle
//!   `2 pi k / ticks_per_revolution`; the tick index is not reported, as with a real
//!   incremental encoder). `E time trigger`: the once-per-revolution trigger fired (mirror
//!   angle `trigger_angle`).
//!
//! Times never decrease from one record to the next. Numbers are written in Rust's
//! shortest round-trip form, so reading a written log gives it back bit for bit. Reading a
//! malformed log gives a [`ParseError`] naming the line.

use std::io::{BufRead, Write};
use std::path::Path;

use super::{MirrorGeometry, Mounting};
use crate::error::{ParseError, Result};
use crate::file::text::for_each_line;

/// The first line of a mirror log.
const MAGIC: &str = "# olmap mirror log v1";
/// The format name used in errors.
const FORMAT: &str = "olmap mirror log";

/// One sweep of the 2D scanner.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// When the first beam fired, seconds.
    pub time: f64,
    /// Time from the first beam to the last, seconds.
    pub duration: f64,
    /// Scan angle of the first beam, radians.
    pub angle_min: f64,
    /// Scan angle between consecutive beams, radians.
    pub angle_step: f64,
    /// Ranges along the whole optical path, metres; `f32::INFINITY` for no return.
    pub ranges: Vec<f32>,
    /// Intensities, one per range, if the scanner reports them.
    pub intensities: Option<Vec<f32>>,
}

impl Sweep {
    /// When beam `i` fired.
    pub fn beam_time(&self, i: usize) -> f64 {
        if self.ranges.len() > 1 {
            self.time + self.duration * i as f64 / (self.ranges.len() - 1) as f64
        } else {
            self.time
        }
    }

    /// Scan angle of beam `i`.
    pub fn angle(&self, i: usize) -> f64 {
        self.angle_min + i as f64 * self.angle_step
    }
}

/// What a mirror sensor reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MirrorEventKind {
    /// The mirror passed an encoder tick.
    Tick,
    /// The once-per-revolution trigger fired.
    Trigger,
}

/// A mirror sensor event.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MirrorEvent {
    /// When it happened, seconds.
    pub time: f64,
    /// What happened.
    pub kind: MirrorEventKind,
}

/// A raw log: the scanner's geometry, its sweeps and its mirror events, each in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorLog {
    /// The scanner's geometry.
    pub header: MirrorGeometry,
    /// The sweeps, in time order.
    pub sweeps: Vec<Sweep>,
    /// The mirror events, in time order.
    pub events: Vec<MirrorEvent>,
}

fn invalid_input(msg: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, msg)
}

impl MirrorLog {
    /// The times of the events of one kind, in log order.
    pub fn event_times(&self, kind: MirrorEventKind) -> Vec<f64> {
        self.events
            .iter()
            .filter(|e| e.kind == kind)
            .map(|e| e.time)
            .collect()
    }

    /// Writes the log (see the module documentation). Fails when the sweeps or the events
    /// are not in time order or a sweep's intensities do not match its ranges.
    pub fn write<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        let g = &self.header;
        writeln!(w, "{MAGIC}")?;
        writeln!(w, "# mounting {}", g.mounting.name())?;
        writeln!(w, "# mirror_offset {:?}", g.mirror_offset)?;
        writeln!(w, "# sides {}", g.sides)?;
        writeln!(w, "# ticks_per_revolution {}", g.ticks_per_revolution)?;
        writeln!(w, "# trigger_angle {:?}", g.trigger_angle)?;
        writeln!(w, "# scan_angle_min {:?}", g.scan_angle_min)?;
        writeln!(w, "# scan_angle_step {:?}", g.scan_angle_step)?;
        writeln!(w, "# scan_beams {}", g.scan_beams)?;
        writeln!(w, "# theta_limit {:?}", g.theta_limit)?;
        writeln!(w, "# edge_on_margin {:?}", g.edge_on_margin)?;
        writeln!(w, "# back_margin {:?}", g.back_margin)?;
        writeln!(w, "# max_range {:?}", g.max_range)?;
        fn sorted(mut t: impl Iterator<Item = f64>) -> bool {
            let mut last = f64::NEG_INFINITY;
            t.all(|x| {
                let ok = x >= last;
                last = x;
                ok
            })
        }
        if !sorted(self.sweeps.iter().map(|s| s.time))
            || !sorted(self.events.iter().map(|e| e.time))
        {
            return Err(invalid_input(
                "mirror log: sweeps and events must be in time order".into(),
            ));
        }
        let (mut i, mut j) = (0, 0);
        while i < self.sweeps.len() || j < self.events.len() {
            // At equal times the sweep comes first.
            let take_sweep = j >= self.events.len()
                || (i < self.sweeps.len() && self.sweeps[i].time <= self.events[j].time);
            if take_sweep {
                let s = &self.sweeps[i];
                write!(
                    w,
                    "S {:?} {:?} {:?} {:?} {}",
                    s.time,
                    s.duration,
                    s.angle_min,
                    s.angle_step,
                    s.ranges.len()
                )?;
                for r in &s.ranges {
                    write!(w, " {r:?}")?;
                }
                if let Some(ints) = &s.intensities {
                    if ints.len() != s.ranges.len() {
                        return Err(invalid_input(format!(
                            "mirror log: sweep {i} has {} ranges but {} intensities",
                            s.ranges.len(),
                            ints.len()
                        )));
                    }
                    for v in ints {
                        write!(w, " {v:?}")?;
                    }
                }
                writeln!(w)?;
                i += 1;
            } else {
                let e = &self.events[j];
                let kind = match e.kind {
                    MirrorEventKind::Tick => "tick",
                    MirrorEventKind::Trigger => "trigger",
                };
                writeln!(w, "E {:?} {kind}", e.time)?;
                j += 1;
            }
        }
        Ok(())
    }

    /// Reads a log (see the module documentation).
    pub fn read<R: BufRead>(reader: R) -> Result<Self, ParseError> {
        let mut state = LogReader {
            keys: Vec::new(),
            header: None,
            sweeps: Vec::new(),
            events: Vec::new(),
            seen_magic: false,
            last_time: f64::NEG_INFINITY,
        };
        for_each_line(reader, |n, line| state.line(n, line))?;
        state.finish()
    }

    /// Writes the log to a file atomically.
    pub fn write_path(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), FORMAT, |w| self.write(w))
    }

    /// Reads a log from a file; errors name the file and the line.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self> {
        crate::file::parse_file(path.as_ref(), FORMAT, Self::read)
    }
}

/// What [`MirrorLog::read`] has read so far.
struct LogReader {
    /// The header's `key value` pairs with their line numbers.
    keys: Vec<(String, String, usize)>,
    /// The geometry, once the first record has ended the header.
    header: Option<MirrorGeometry>,
    sweeps: Vec<Sweep>,
    events: Vec<MirrorEvent>,
    /// Whether the first line (the magic) has been read.
    seen_magic: bool,
    /// The previous record's time.
    last_time: f64,
}

impl LogReader {
    /// Reads line `n`: the magic, a header or comment line, a blank line or a record.
    fn line(&mut self, n: usize, line: &str) -> Result<(), ParseError> {
        let t = line.trim();
        if !self.seen_magic {
            if t != MAGIC {
                return Err(ParseError::line(
                    n,
                    format!("expected the first line '{MAGIC}', found '{t}'"),
                ));
            }
            self.seen_magic = true;
            return Ok(());
        }
        if t.is_empty() {
            return Ok(());
        }
        if let Some(rest) = t.strip_prefix('#') {
            if self.header.is_none() {
                let mut it = rest.split_whitespace();
                if let (Some(k), Some(v), None) = (it.next(), it.next(), it.next()) {
                    self.keys.push((k.to_string(), v.to_string(), n));
                }
            }
            return Ok(());
        }
        if self.header.is_none() {
            self.header = Some(geometry_from_keys(&self.keys, n)?);
        }
        self.record(n, t)
    }

    /// Reads the record `t` on line `n`: a sweep or an event, in time order.
    fn record(&mut self, n: usize, t: &str) -> Result<(), ParseError> {
        let fields: Vec<&str> = t.split_whitespace().collect();
        let time = number(&fields, n, 1, "time")?;
        if !time.is_finite() {
            return Err(ParseError::line(n, "time must be finite"));
        }
        if time < self.last_time {
            return Err(ParseError::line(
                n,
                format!(
                    "time {time} is before the previous record's {}",
                    self.last_time
                ),
            ));
        }
        self.last_time = time;
        match fields[0] {
            "S" => self.sweeps.push(sweep_record(&fields, n, time)?),
            "E" => self.events.push(event_record(&fields, n, time)?),
            other => {
                return Err(ParseError::line(
                    n,
                    format!("unknown record '{other}': expected S (sweep) or E (event)"),
                ))
            }
        }
        Ok(())
    }

    /// The log, once every line is read.
    fn finish(self) -> Result<MirrorLog, ParseError> {
        if !self.seen_magic {
            return Err(ParseError::Empty);
        }
        let header = match self.header {
            Some(h) => h,
            None => geometry_from_keys(&self.keys, 0)?,
        };
        Ok(MirrorLog {
            header,
            sweeps: self.sweeps,
            events: self.events,
        })
    }
}

/// Field `k` of the record on line `n`, a number (`what` names it in errors).
fn number(fields: &[&str], n: usize, k: usize, what: &str) -> Result<f64, ParseError> {
    let s = fields
        .get(k)
        .ok_or_else(|| ParseError::line(n, format!("missing {what} (field {})", k + 1)))?;
    s.parse::<f64>()
        .map_err(|_| ParseError::line(n, format!("{what} is not a number: '{s}'")))
}

/// The sweep of the `S` record `fields` on line `n`, at `time`.
fn sweep_record(fields: &[&str], n: usize, time: f64) -> Result<Sweep, ParseError> {
    let duration = number(fields, n, 2, "duration")?;
    let angle_min = number(fields, n, 3, "start angle")?;
    let angle_step = number(fields, n, 4, "angle step")?;
    let count = fields.get(5).and_then(|s| s.parse::<usize>().ok());
    let count = count.ok_or_else(|| ParseError::line(n, "field 6 must be the beam count"))?;
    let rest = &fields[6..];
    // A count near usize::MAX must not overflow in the doubling: it matches no line.
    let with_int = if rest.len() == count {
        false
    } else if Some(rest.len()) == count.checked_mul(2) {
        true
    } else {
        return Err(ParseError::line(
            n,
            format!(
                "a sweep of {count} beams needs {count} ranges or {} ranges and intensities, found {} values",
                count.saturating_mul(2),
                rest.len()
            ),
        ));
    };
    let mut vals = Vec::with_capacity(rest.len());
    for (k, s) in rest.iter().enumerate() {
        let v = s
            .parse::<f32>()
            .map_err(|_| ParseError::line(n, format!("value {} is not a number: '{s}'", k + 1)))?;
        vals.push(v);
    }
    let intensities = with_int.then(|| vals.split_off(count));
    Ok(Sweep {
        time,
        duration,
        angle_min,
        angle_step,
        ranges: vals,
        intensities,
    })
}

/// The event of the `E` record `fields` on line `n`, at `time`.
fn event_record(fields: &[&str], n: usize, time: f64) -> Result<MirrorEvent, ParseError> {
    let kind = match (fields.get(2).copied(), fields.len()) {
        (Some("tick"), 3) => MirrorEventKind::Tick,
        (Some("trigger"), 3) => MirrorEventKind::Trigger,
        _ => {
            return Err(ParseError::line(
                n,
                "an event is 'E time tick' or 'E time trigger'",
            ))
        }
    };
    Ok(MirrorEvent { time, kind })
}

/// Builds the geometry from the header's `key value` pairs; `line` is the first record's
/// line (0 at the end of the file), for errors about missing keys.
fn geometry_from_keys(
    keys: &[(String, String, usize)],
    line: usize,
) -> Result<MirrorGeometry, ParseError> {
    let get = |k: &str| -> Result<(&str, usize), ParseError> {
        keys.iter()
            .rev()
            .find(|(key, _, _)| key == k)
            .map(|(_, v, n)| (v.as_str(), *n))
            .ok_or_else(|| {
                let msg = format!("the header lacks '# {k} <value>'");
                if line > 0 {
                    ParseError::line(line, format!("{msg} before the first record"))
                } else {
                    ParseError::Malformed(msg)
                }
            })
    };
    fn parse<T: std::str::FromStr>(k: &str, (v, n): (&str, usize)) -> Result<T, ParseError> {
        v.parse::<T>()
            .map_err(|_| ParseError::line(n, format!("header '{k}': bad value '{v}'")))
    }
    let (m, mn) = get("mounting")?;
    let mounting = Mounting::from_name(m).ok_or_else(|| {
        ParseError::line(
            mn,
            format!("mounting must be standard or enhanced, not '{m}'"),
        )
    })?;
    let g = MirrorGeometry {
        mounting,
        mirror_offset: parse("mirror_offset", get("mirror_offset")?)?,
        sides: parse("sides", get("sides")?)?,
        ticks_per_revolution: parse("ticks_per_revolution", get("ticks_per_revolution")?)?,
        trigger_angle: parse("trigger_angle", get("trigger_angle")?)?,
        scan_angle_min: parse("scan_angle_min", get("scan_angle_min")?)?,
        scan_angle_step: parse("scan_angle_step", get("scan_angle_step")?)?,
        scan_beams: parse("scan_beams", get("scan_beams")?)?,
        theta_limit: parse("theta_limit", get("theta_limit")?)?,
        edge_on_margin: parse("edge_on_margin", get("edge_on_margin")?)?,
        back_margin: parse("back_margin", get("back_margin")?)?,
        max_range: parse("max_range", get("max_range")?)?,
    };
    g.validate().map_err(|e| {
        let msg = e.to_string().replace("invalid argument: ", "");
        if line > 0 {
            ParseError::line(line, format!("the header is invalid: {msg}"))
        } else {
            ParseError::Malformed(msg)
        }
    })?;
    Ok(g)
}
