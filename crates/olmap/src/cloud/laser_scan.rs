//! The [`LaserScan`] type: one sweep of a 2D laser scanner, like ROS
//! `sensor_msgs/LaserScan`, and its CSV file layout.
//!
//! ## CSV layout (version 1)
//! ```text
//! # olmap laser scan v1
//! angle_min,angle_increment,range_min,range_max,time
//! -1.5707963267948966,0.008726646259971648,0.0,8.0,12.5
//! range,intensity
//! 2.5,0.6
//! inf,0.0
//! ```
//! Line 1 is the comment `# olmap laser scan v1`; line 2 the header of the scan's
//! parameters and line 3 their values (radians, metres, seconds); line 4 is `range,intensity`
//! (or `range` for a scan without intensities); then one row per beam in angle order,
//! `inf` marking a beam with no return. Blank lines and further `#` lines are skipped.
//! Numbers are written in Rust's shortest round-trip form, so reading a written scan gives
//! it back bit for bit. Reading a malformed file gives a [`ParseError`] naming the line.
//!
//! ## JSON layout
//! ```text
//! {
//!   "angle_min": -1.5707963267948966,
//!   "angle_increment": 0.008726646259971648,
//!   "range_min": 0.0,
//!   "range_max": 8.0,
//!   "ranges": [2.5, null, 3.25],
//!   "intensities": [0.6, 0.0, 2.0],
//!   "time": 12.5
//! }
//! ```
//! One object with the field names of ROS `sensor_msgs/LaserScan`: radians, metres and
//! seconds; `null` in `ranges` for a beam with no return (written for any non-finite
//! range, read back as `f32::INFINITY`); `intensities` may be `null`, empty or absent
//! (no intensities) and `time` absent (0). Other fields (a ROS `header`, `angle_max`,
//! `scan_time`, ...) are ignored when reading. Numbers are written in their shortest
//! round-trip form, so a written scan reads back bit for bit (apart from non-finite
//! ranges, which all become infinity). Malformed JSON, and JSON that does not describe a
//! scan (a missing field, a string for a number), give a [`ParseError`] naming the line;
//! intensities of another length than the ranges give [`ParseError::Malformed`].

use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::Point3;

use super::PointCloud;
use crate::error::{ParseError, Result};
use crate::file::text::{for_each_line, json_message};

const MAGIC: &str = "# olmap laser scan v1";
const PARAMS: &str = "angle_min,angle_increment,range_min,range_max,time";
const FORMAT: &str = "olmap laser scan CSV";
const FORMAT_JSON: &str = "olmap laser scan JSON";

/// The largest laser-scan JSON read: 64 MiB (a scan of a million beams is about 20 MiB).
/// The text is read whole before it is parsed, so an endless stream stops here.
pub const MAX_JSON_BYTES: u64 = 64 << 20;

/// The error for a negative range at beam `i` (0-based).
fn negative_range(i: usize, r: f32) -> String {
    format!("the range of beam {i} is {r}: a range is a distance, >= 0 (inf or NaN for no return)")
}

/// A JSON parse error at its line, said once: serde's message ends with "at line L column
/// C", which the location already gives.
fn json_error(e: serde_json::Error) -> ParseError {
    use serde_json::error::Category;
    let message = json_message(&e);
    match e.classify() {
        Category::Eof => ParseError::Truncated(message),
        Category::Syntax => ParseError::line(
            e.line(),
            format!("column {}: invalid JSON: {message}", e.column()),
        ),
        _ => ParseError::line(
            e.line(),
            format!("column {}: not a laser scan: {message}", e.column()),
        ),
    }
}

/// The JSON layout, as written.
#[derive(serde::Serialize)]
struct JsonOut<'a> {
    angle_min: f64,
    angle_increment: f64,
    range_min: f64,
    range_max: Option<f64>,
    ranges: Vec<Option<f32>>,
    intensities: Option<&'a [f32]>,
    time: f64,
}

/// The JSON layout, as read (unknown fields ignored).
#[derive(serde::Deserialize)]
struct JsonIn {
    angle_min: f64,
    angle_increment: f64,
    range_min: f64,
    range_max: Option<f64>,
    ranges: Vec<Option<f32>>,
    #[serde(default)]
    intensities: Option<Vec<f32>>,
    #[serde(default)]
    time: f64,
}

/// One sweep of a 2D laser scanner in its own plane (the sensor's xy plane; beam `i` points
/// at angle `angle_min + i angle_increment` from x toward y).
///
/// ```
/// use olmap::cloud::LaserScan;
/// let scan = LaserScan {
///     angle_min: -0.5,
///     angle_increment: 0.25,
///     range_min: 0.1,
///     range_max: 8.0,
///     ranges: vec![2.0, f32::INFINITY, 3.0],
///     intensities: Some(vec![0.5, 0.0, 2.0]),
///     time: 0.0,
/// };
/// let cloud = scan.to_cloud();
/// assert_eq!(cloud.len(), 2);
/// assert_eq!(cloud.points()[1].x, 3.0); // beam 2 points along x
/// assert_eq!(cloud.intensity().unwrap(), &[0.5, 2.0]);
/// let mut csv = Vec::new();
/// scan.write_csv(&mut csv).unwrap();
/// assert_eq!(LaserScan::read_csv(&csv[..]).unwrap(), scan);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Angle of the first beam, radians (0 along the sensor's x axis, positive toward y).
    pub angle_min: f64,
    /// Angle between consecutive beams, radians.
    pub angle_increment: f64,
    /// Shortest valid range, metres.
    pub range_min: f64,
    /// Longest valid range, metres.
    pub range_max: f64,
    /// Ranges in beam order, metres; `f32::INFINITY` (or any value outside
    /// `[range_min, range_max]`) for no valid return.
    pub ranges: Vec<f32>,
    /// Intensities, one per beam, if the scanner reports them.
    pub intensities: Option<Vec<f32>>,
    /// When the scan was taken, seconds.
    pub time: f64,
}

impl LaserScan {
    /// Angle of beam `i`, radians.
    pub fn angle(&self, i: usize) -> f64 {
        self.angle_min + i as f64 * self.angle_increment
    }

    /// Number of beams.
    pub fn len(&self) -> usize {
        self.ranges.len()
    }

    /// Whether the scan has no beams.
    pub fn is_empty(&self) -> bool {
        self.ranges.is_empty()
    }

    /// Checks the scan's parameters: `angle_min` and `time` finite, `angle_increment`
    /// finite and not zero (it may be negative: a scanner sweeping clockwise), `range_min`
    /// finite and `>= 0`, `range_max` above `range_min` (infinity allowed, NaN not), and
    /// every range a distance: `>= 0`, or `inf`/NaN for no return. The error names the
    /// field (and the beam) and the value found.
    pub fn validate(&self) -> Result<(), String> {
        self.validate_parameters()?;
        match self.ranges.iter().position(|r| *r < 0.0) {
            Some(i) => Err(negative_range(i, self.ranges[i])),
            None => Ok(()),
        }
    }

    /// [`LaserScan::validate`] without the ranges.
    fn validate_parameters(&self) -> Result<(), String> {
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("{name} must be a finite number, found {v}"))
            }
        };
        finite("angle_min", self.angle_min)?;
        finite("angle_increment", self.angle_increment)?;
        if self.angle_increment == 0.0 {
            return Err(
                "angle_increment must not be 0: every beam would point the same way".into(),
            );
        }
        finite("range_min", self.range_min)?;
        if self.range_min < 0.0 {
            return Err(format!("range_min must be >= 0, found {}", self.range_min));
        }
        if self.range_max.is_nan() || self.range_max <= self.range_min {
            return Err(format!(
                "range_max must be above range_min ({}), found {}",
                self.range_min, self.range_max
            ));
        }
        finite("time", self.time)
    }

    /// Whether beam `i` has a valid return (finite, within `[range_min, range_max]`).
    pub fn is_valid(&self, i: usize) -> bool {
        let r = self.ranges[i] as f64;
        r.is_finite() && r >= self.range_min && r <= self.range_max
    }

    /// The valid returns as points in the sensor plane (`z = 0`), with their intensities
    /// when the scan has them; the cloud's origin is the sensor.
    pub fn to_cloud(&self) -> PointCloud {
        let mut pts = Vec::new();
        let mut ints = Vec::new();
        for i in 0..self.len() {
            if !self.is_valid(i) {
                continue;
            }
            let r = self.ranges[i] as f64;
            let (s, c) = self.angle(i).sin_cos();
            pts.push(Point3::new((r * c) as f32, (r * s) as f32, 0.0));
            if let Some(v) = &self.intensities {
                ints.push(v[i]);
            }
        }
        let mut cloud = PointCloud::from_points(pts);
        if self.intensities.is_some() {
            cloud
                .set_intensity(Some(ints))
                .expect("one intensity per point");
        }
        cloud
    }

    /// Writes the scan as CSV (see the module documentation).
    pub fn write_csv<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        writeln!(w, "{MAGIC}")?;
        writeln!(w, "{PARAMS}")?;
        writeln!(
            w,
            "{:?},{:?},{:?},{:?},{:?}",
            self.angle_min, self.angle_increment, self.range_min, self.range_max, self.time
        )?;
        match &self.intensities {
            Some(ints) => {
                if ints.len() != self.ranges.len() {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::InvalidInput,
                        format!(
                            "laser scan has {} ranges but {} intensities",
                            self.ranges.len(),
                            ints.len()
                        ),
                    ));
                }
                writeln!(w, "range,intensity")?;
                for (r, v) in self.ranges.iter().zip(ints) {
                    writeln!(w, "{r:?},{v:?}")?;
                }
            }
            None => {
                writeln!(w, "range")?;
                for r in &self.ranges {
                    writeln!(w, "{r:?}")?;
                }
            }
        }
        Ok(())
    }

    /// Reads a scan from CSV (see the module documentation).
    pub fn read_csv<R: BufRead>(reader: R) -> Result<Self, ParseError> {
        // Stage: 0 magic, 1 parameter header, 2 parameter values, 3 column header, 4 rows.
        let mut stage = 0;
        let mut params = [0.0f64; 5];
        let mut with_int = false;
        let mut ranges = Vec::new();
        let mut ints = Vec::new();
        for_each_line(reader, |n, line| {
            let t = line.trim();
            if stage == 0 {
                if t != MAGIC {
                    return Err(ParseError::line(
                        n,
                        format!("expected the first line '{MAGIC}', found '{t}'"),
                    ));
                }
                stage = 1;
                return Ok(());
            }
            if t.is_empty() || t.starts_with('#') {
                return Ok(());
            }
            let fields: Vec<&str> = t.split(',').map(str::trim).collect();
            match stage {
                1 => {
                    if t.replace(' ', "") != PARAMS {
                        return Err(ParseError::line(n, format!("expected '{PARAMS}'")));
                    }
                }
                2 => {
                    if fields.len() != 5 {
                        return Err(ParseError::line(
                            n,
                            format!("expected 5 values ({PARAMS}), found {}", fields.len()),
                        ));
                    }
                    for (k, f) in fields.iter().enumerate() {
                        params[k] = f.parse::<f64>().map_err(|_| {
                            ParseError::line(n, format!("value {} is not a number: '{f}'", k + 1))
                        })?;
                    }
                    LaserScan::from_params(params)
                        .validate_parameters()
                        .map_err(|reason| ParseError::line(n, reason))?;
                }
                3 => {
                    with_int = match fields.as_slice() {
                        ["range", "intensity"] => true,
                        ["range"] => false,
                        _ => {
                            return Err(ParseError::line(
                                n,
                                "expected the column header 'range,intensity' or 'range'",
                            ))
                        }
                    };
                }
                _ => {
                    let want = if with_int { 2 } else { 1 };
                    if fields.len() != want {
                        return Err(ParseError::line(
                            n,
                            format!("expected {want} values, found {}", fields.len()),
                        ));
                    }
                    let parse = |f: &str| {
                        f.parse::<f32>()
                            .map_err(|_| ParseError::line(n, format!("not a number: '{f}'")))
                    };
                    let range = parse(fields[0])?;
                    if range < 0.0 {
                        return Err(ParseError::line(n, negative_range(ranges.len(), range)));
                    }
                    ranges.push(range);
                    if with_int {
                        ints.push(parse(fields[1])?);
                    }
                    return Ok(());
                }
            }
            stage += 1;
            Ok(())
        })?;
        match stage {
            0 => return Err(ParseError::Empty),
            1..=3 => {
                return Err(ParseError::Truncated(
                    "the scan's parameter or column header lines are missing".into(),
                ))
            }
            _ => {}
        }
        Ok(LaserScan {
            ranges,
            intensities: with_int.then_some(ints),
            ..LaserScan::from_params(params)
        })
    }

    /// A scan without beams from the CSV parameter values
    /// `angle_min, angle_increment, range_min, range_max, time`.
    fn from_params(params: [f64; 5]) -> LaserScan {
        LaserScan {
            angle_min: params[0],
            angle_increment: params[1],
            range_min: params[2],
            range_max: params[3],
            time: params[4],
            ranges: Vec::new(),
            intensities: None,
        }
    }

    /// Writes the scan as JSON (see the module documentation).
    ///
    /// ```
    /// use olmap::cloud::LaserScan;
    /// let scan = LaserScan {
    ///     angle_min: -0.5,
    ///     angle_increment: 0.25,
    ///     range_min: 0.1,
    ///     range_max: 8.0,
    ///     ranges: vec![2.0, f32::INFINITY, 3.0],
    ///     intensities: None,
    ///     time: 1.5,
    /// };
    /// let mut json = Vec::new();
    /// scan.write_json(&mut json).unwrap();
    /// assert!(String::from_utf8_lossy(&json).contains("null"));
    /// assert_eq!(LaserScan::read_json(&json[..]).unwrap(), scan);
    /// ```
    pub fn write_json<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        if let Some(ints) = &self.intensities {
            if ints.len() != self.ranges.len() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "laser scan has {} ranges but {} intensities",
                        self.ranges.len(),
                        ints.len()
                    ),
                ));
            }
        }
        let out = JsonOut {
            angle_min: self.angle_min,
            angle_increment: self.angle_increment,
            range_min: self.range_min,
            range_max: self.range_max.is_finite().then_some(self.range_max),
            ranges: self
                .ranges
                .iter()
                .map(|r| r.is_finite().then_some(*r))
                .collect(),
            intensities: self.intensities.as_deref(),
            time: self.time,
        };
        serde_json::to_writer_pretty(&mut w, &out).map_err(std::io::Error::other)?;
        writeln!(w)
    }

    /// Reads a scan from JSON (see the module documentation); a `null` `range_max` reads
    /// as infinity.
    pub fn read_json<R: std::io::Read>(reader: R) -> Result<Self, ParseError> {
        let mut text = String::new();
        use std::io::Read as _;
        reader.take(MAX_JSON_BYTES + 1).read_to_string(&mut text)?;
        if text.len() as u64 > MAX_JSON_BYTES {
            return Err(ParseError::TooLarge {
                what: format!("a laser scan JSON of more than {MAX_JSON_BYTES} bytes"),
                limit: format!("{} MiB", MAX_JSON_BYTES >> 20),
            });
        }
        if text.trim().is_empty() {
            return Err(ParseError::Empty);
        }
        let parsed: JsonIn = serde_json::from_str(&text).map_err(json_error)?;
        let intensities = parsed
            .intensities
            .filter(|v| !v.is_empty() || parsed.ranges.is_empty());
        if let Some(ints) = &intensities {
            if ints.len() != parsed.ranges.len() {
                return Err(ParseError::Malformed(format!(
                    "{} ranges but {} intensities",
                    parsed.ranges.len(),
                    ints.len()
                )));
            }
        }
        let scan = LaserScan {
            angle_min: parsed.angle_min,
            angle_increment: parsed.angle_increment,
            range_min: parsed.range_min,
            range_max: parsed.range_max.unwrap_or(f64::INFINITY),
            ranges: parsed
                .ranges
                .into_iter()
                .map(|r| r.unwrap_or(f32::INFINITY))
                .collect(),
            intensities,
            time: parsed.time,
        };
        scan.validate().map_err(ParseError::Malformed)?;
        Ok(scan)
    }

    /// Writes the scan as JSON to a file atomically.
    pub fn write_json_path(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), FORMAT_JSON, |w| self.write_json(w))
    }

    /// Reads a scan from a JSON file; errors name the file and, for malformed JSON, the
    /// line.
    pub fn read_json_path(path: impl AsRef<Path>) -> Result<Self> {
        crate::file::parse_file(path.as_ref(), FORMAT_JSON, Self::read_json)
    }

    /// Reads a scan from a `.json` file as JSON, anything else as CSV.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let json = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("json"));
        if json {
            Self::read_json_path(path)
        } else {
            Self::read_csv_path(path)
        }
    }

    /// Writes the scan as CSV to a file atomically.
    pub fn write_csv_path(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::file::write_atomic(path.as_ref(), FORMAT, |w| self.write_csv(w))
    }

    /// Reads a scan from a CSV file; errors name the file and the line.
    pub fn read_csv_path(path: impl AsRef<Path>) -> Result<Self> {
        crate::file::parse_file(path.as_ref(), FORMAT, Self::read_csv)
    }
}
