//! Trinary (free / occupied / unknown) maps in the ROS `map_server` file convention: an
//! 8-bit binary PGM image and a YAML file describing it.
//!
//! ```text
//! image: map.pgm
//! resolution: 0.05
//! origin: [-3.2, -1.5, 0.0]
//! negate: 0
//! occupied_thresh: 0.65
//! free_thresh: 0.196
//! mode: trinary
//! ```
//! The image is `P5`, maxval 255, one byte per cell; its **first row is the top of the
//! map** (highest y), so grid row `j` is image row `height - 1 - j`. As ROS `map_saver`
//! writes with its default thresholds, occupied cells are 0 (black), free cells 254 (white)
//! and unknown cells 205 (grey). `origin` is the world pose `[x, y, yaw]` of the lower-left
//! corner of the lower-left cell; `resolution` is metres per cell.
//!
//! Reading follows `map_server`'s trinary mode: a pixel value `v` gives the occupancy
//! `p = (255 - v) / 255` (`p = v / 255` with `negate: 1`); `p > occupied_thresh` is
//! occupied, `p < free_thresh` free, anything else unknown (205 gives 0.196078..., just
//! above 0.196: unknown). The image path is relative to the YAML file's folder unless
//! absolute. Only PGM images are read (not the PNG and other formats `map_server` also
//! takes), and only the `trinary` mode. The YAML is written and read line by line: one
//! `key: value` per line, `#` comments, blank lines; unknown keys are ignored.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::trinary::{Thresholds, Trinary, TrinaryGrid};
use crate::error::{Error, Location, ParseError, Result};
use crate::file::{read_bytes_at_most, write_atomic, OutputSet};

const YAML_FORMAT: &str = "ROS map YAML";
const PGM_FORMAT: &str = "PGM image";
/// The largest map YAML read (a real one is a few hundred bytes).
const MAX_YAML_BYTES: u64 = 1 << 20;

/// The YAML file beside a PGM image: the same path with the extension `yaml`.
pub fn yaml_path_for(pgm: &Path) -> PathBuf {
    pgm.with_extension("yaml")
}

/// Writes `map` as the PGM image `pgm_path` and the YAML file beside it (same name,
/// extension `yaml`), as one [`OutputSet`]: both appear or neither; returns the YAML path.
pub fn write_ros_map(pgm_path: impl AsRef<Path>, map: &TrinaryGrid) -> Result<PathBuf> {
    let pgm_path = pgm_path.as_ref();
    let mut set = OutputSet::new();
    declare_ros_map(&mut set, pgm_path)?;
    let yaml = write_ros_map_into(&mut set, pgm_path, map)?;
    set.commit()?;
    Ok(yaml)
}

/// Checks, before computing, that [`write_ros_map`] can write the image `pgm_path` and its
/// YAML file (folders exist and are writable, neither is a folder).
pub fn check_ros_map_output(pgm_path: &Path) -> Result<()> {
    declare_ros_map(&mut OutputSet::new(), pgm_path)
}

/// Declares the image `pgm_path` and its YAML file in `set` (checked now).
pub(crate) fn declare_ros_map(set: &mut OutputSet, pgm_path: &Path) -> Result<()> {
    set.file(pgm_path, PGM_FORMAT)?;
    set.file(&yaml_path_for(pgm_path), YAML_FORMAT)
}

/// Writes the files declared by [`declare_ros_map`] where `set` stages them; returns the
/// YAML path (the final one).
pub(crate) fn write_ros_map_into(
    set: &mut OutputSet,
    pgm_path: &Path,
    map: &TrinaryGrid,
) -> Result<PathBuf> {
    if map.cells.len() != map.width * map.height {
        return Err(Error::InvalidArgument(format!(
            "trinary map of {} x {} cells holds {} cells",
            map.width,
            map.height,
            map.cells.len()
        )));
    }
    if !(map.resolution.is_finite() && map.resolution > 0.0)
        || map.origin.iter().any(|v| !v.is_finite())
    {
        return Err(Error::InvalidArgument(format!(
            "trinary map needs a resolution > 0 and a finite origin, got {} and {:?}",
            map.resolution, map.origin
        )));
    }
    let image = pgm_path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| Error::Write {
            path: pgm_path.to_path_buf(),
            format: PGM_FORMAT,
            reason: "the image needs a file name in UTF-8".into(),
        })?
        .to_string();
    write_atomic(&set.path(pgm_path)?, PGM_FORMAT, |w| {
        write!(
            w,
            "P5\n# CREATOR: olmap grid2d {:.3} m/pix\n{} {}\n255\n",
            map.resolution, map.width, map.height
        )?;
        let mut row = vec![0u8; map.width];
        for j in (0..map.height).rev() {
            for (px, t) in row
                .iter_mut()
                .zip(&map.cells[j * map.width..(j + 1) * map.width])
            {
                *px = t.pgm_value();
            }
            w.write_all(&row)?;
        }
        Ok(())
    })?;
    let yaml = yaml_path_for(pgm_path);
    write_atomic(&set.path(&yaml)?, YAML_FORMAT, |w| {
        writeln!(w, "image: {}", yaml_string(&image))?;
        writeln!(w, "resolution: {:?}", map.resolution)?;
        writeln!(
            w,
            "origin: [{:?}, {:?}, {:?}]",
            map.origin[0], map.origin[1], map.origin[2]
        )?;
        writeln!(w, "negate: 0")?;
        writeln!(w, "occupied_thresh: {:?}", map.thresholds.occupied)?;
        writeln!(w, "free_thresh: {:?}", map.thresholds.free)?;
        writeln!(w, "mode: trinary")
    })?;
    Ok(yaml)
}

/// A YAML scalar for a file name: plain when safe, else double-quoted.
fn yaml_string(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-' | '/'))
        && !s.starts_with(['-', '.']);
    if plain {
        s.to_string()
    } else {
        let mut q = String::from("\"");
        for c in s.chars() {
            match c {
                '"' => q.push_str("\\\""),
                '\\' => q.push_str("\\\\"),
                _ => q.push(c),
            }
        }
        q.push('"');
        q
    }
}

/// The YAML fields `map_server` reads.
struct Header {
    image: Option<String>,
    resolution: Option<f64>,
    origin: Option<[f64; 3]>,
    negate: bool,
    occupied: Option<f64>,
    free: Option<f64>,
}

/// Splits `key: value` and removes a trailing ` # comment` outside quotes.
fn split_yaml_line(line: &str) -> Option<(&str, &str)> {
    let (key, rest) = line.split_once(':')?;
    let rest = rest.trim();
    let value = if rest.starts_with('"') || rest.starts_with('\'') {
        rest
    } else {
        match rest.find(" #") {
            Some(k) => rest[..k].trim_end(),
            None => rest,
        }
    };
    Some((key.trim(), value))
}

fn parse_yaml_string(v: &str, line: usize) -> Result<String, ParseError> {
    let bad = || ParseError::line(line, format!("unterminated quoted string {v}"));
    if let Some(body) = v.strip_prefix('"') {
        let end = body.rfind('"').ok_or_else(bad)?;
        let mut out = String::new();
        let mut chars = body[..end].chars();
        while let Some(c) = chars.next() {
            if c == '\\' {
                out.push(chars.next().ok_or_else(bad)?);
            } else {
                out.push(c);
            }
        }
        Ok(out)
    } else if let Some(body) = v.strip_prefix('\'') {
        let end = body.rfind('\'').ok_or_else(bad)?;
        Ok(body[..end].replace("''", "'"))
    } else if v.is_empty() {
        Err(ParseError::line(line, "image: expected a file name"))
    } else {
        Ok(v.to_string())
    }
}

fn parse_number(key: &str, v: &str, line: usize) -> Result<f64, ParseError> {
    v.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| ParseError::line(line, format!("{key}: expected a number, got '{v}'")))
}

fn parse_header(text: &str) -> Result<Header, ParseError> {
    let mut h = Header {
        image: None,
        resolution: None,
        origin: None,
        negate: false,
        occupied: None,
        free: None,
    };
    let mut seen: Vec<String> = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let l = raw.trim_end_matches('\r');
        let t = l.trim();
        if t.is_empty() || t.starts_with('#') || t == "---" {
            continue;
        }
        let (key, v) = split_yaml_line(l)
            .ok_or_else(|| ParseError::line(line, format!("expected 'key: value', got '{t}'")))?;
        if seen.iter().any(|s| s == key) {
            return Err(ParseError::line(line, format!("key '{key}' given twice")));
        }
        seen.push(key.to_string());
        match key {
            "image" => h.image = Some(parse_yaml_string(v, line)?),
            "resolution" => {
                let r = parse_number(key, v, line)?;
                if r <= 0.0 {
                    return Err(ParseError::line(
                        line,
                        format!("resolution must be > 0, got {r}"),
                    ));
                }
                h.resolution = Some(r);
            }
            "origin" => {
                let inner = v
                    .strip_prefix('[')
                    .and_then(|s| s.strip_suffix(']'))
                    .ok_or_else(|| {
                        ParseError::line(line, format!("origin: expected [x, y, yaw], got '{v}'"))
                    })?;
                let nums = inner
                    .split(',')
                    .map(|s| parse_number(key, s.trim(), line))
                    .collect::<Result<Vec<_>, _>>()?;
                let o: [f64; 3] = nums.try_into().map_err(|n: Vec<f64>| {
                    ParseError::line(
                        line,
                        format!("origin: expected 3 numbers [x, y, yaw], got {}", n.len()),
                    )
                })?;
                h.origin = Some(o);
            }
            "negate" => {
                h.negate = match v {
                    "0" | "false" => false,
                    "1" | "true" => true,
                    _ => {
                        return Err(ParseError::line(
                            line,
                            format!("negate: expected 0 or 1, got '{v}'"),
                        ))
                    }
                }
            }
            "occupied_thresh" | "free_thresh" => {
                let p = parse_number(key, v, line)?;
                if !(0.0..=1.0).contains(&p) {
                    return Err(ParseError::line(
                        line,
                        format!("{key} must be within [0, 1], got {p}"),
                    ));
                }
                if key == "free_thresh" {
                    h.free = Some(p);
                } else {
                    h.occupied = Some(p);
                }
            }
            "mode" if v != "trinary" => {
                return Err(ParseError::Unsupported(format!(
                    "line {line}: mode '{v}' (only 'trinary' maps are read)"
                )));
            }
            _ => {}
        }
    }
    Ok(h)
}

/// Reads a ROS map (the YAML file and the PGM image it names) into a trinary grid.
/// Errors name the file (YAML or image) and the line or byte at fault.
pub fn read_ros_map(yaml_path: impl AsRef<Path>) -> Result<TrinaryGrid> {
    let yaml_path = yaml_path.as_ref();
    let yaml_err = |source: ParseError| Error::Read {
        path: yaml_path.to_path_buf(),
        format: YAML_FORMAT,
        source,
    };
    let bytes = read_bytes_at_most(yaml_path, MAX_YAML_BYTES, YAML_FORMAT)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| yaml_err(ParseError::Malformed(format!("not UTF-8 text: {e}"))))?;
    let h = parse_header(text).map_err(yaml_err)?;
    let missing = |key: &str| yaml_err(ParseError::Malformed(format!("missing key '{key}'")));
    let image = h.image.ok_or_else(|| missing("image"))?;
    let resolution = h.resolution.ok_or_else(|| missing("resolution"))?;
    let origin = h.origin.ok_or_else(|| missing("origin"))?;
    let occupied = h.occupied.ok_or_else(|| missing("occupied_thresh"))?;
    let free = h.free.ok_or_else(|| missing("free_thresh"))?;
    if free > occupied {
        return Err(yaml_err(ParseError::Malformed(format!(
            "free_thresh {free} is above occupied_thresh {occupied}"
        ))));
    }
    let thresholds = Thresholds { occupied, free };
    let image_path = match yaml_path.parent() {
        Some(dir) if Path::new(&image).is_relative() => dir.join(&image),
        _ => PathBuf::from(&image),
    };
    // The largest image read: MAX_CELLS pixels and a generous header.
    let max_image = super::grid::MAX_CELLS as u64 + MAX_YAML_BYTES;
    let data = read_bytes_at_most(&image_path, max_image, PGM_FORMAT)?;
    let pgm = parse_pgm(&data).map_err(|source| Error::Read {
        path: image_path.clone(),
        format: PGM_FORMAT,
        source,
    })?;
    let maxval = pgm.maxval as f64;
    let (w, hgt) = (pgm.width, pgm.height);
    let mut cells = vec![Trinary::Unknown; w * hgt];
    for r in 0..hgt {
        let j = hgt - 1 - r;
        for i in 0..w {
            let v = pgm.pixels[r * w + i] as f64;
            let p = if h.negate {
                v / maxval
            } else {
                (maxval - v) / maxval
            };
            cells[j * w + i] = thresholds.classify(p);
        }
    }
    Ok(TrinaryGrid {
        resolution,
        origin,
        width: w,
        height: hgt,
        cells,
        thresholds,
    })
}

/// A decoded 8-bit greyscale image, rows from the top.
struct Pgm<'a> {
    width: usize,
    height: usize,
    maxval: u32,
    pixels: &'a [u8],
}

/// Parses a binary (`P5`) 8-bit PGM image.
fn parse_pgm(data: &[u8]) -> Result<Pgm<'_>, ParseError> {
    if data.is_empty() {
        return Err(ParseError::Empty);
    }
    if data.starts_with(b"P2") {
        return Err(ParseError::Unsupported(
            "ASCII PGM (P2); only binary P5 images are read".into(),
        ));
    }
    if !data.starts_with(b"P5") {
        return Err(ParseError::at(
            Location::Byte(0),
            "expected the PGM magic number 'P5'",
        ));
    }
    let mut pos = 2usize;
    let mut fields = [0u64; 3];
    for (k, name) in ["width", "height", "maxval"].iter().enumerate() {
        // Whitespace and comments before the field.
        loop {
            match data.get(pos) {
                Some(c) if c.is_ascii_whitespace() => pos += 1,
                Some(b'#') => {
                    while data.get(pos).is_some_and(|&c| c != b'\n') {
                        pos += 1;
                    }
                }
                Some(_) => break,
                None => {
                    return Err(ParseError::Truncated(format!(
                        "the header ends before the {name}"
                    )))
                }
            }
        }
        let start = pos;
        while data.get(pos).is_some_and(u8::is_ascii_digit) {
            pos += 1;
        }
        let text = std::str::from_utf8(&data[start..pos]).unwrap_or("");
        fields[k] = text.parse().map_err(|_| {
            ParseError::at(
                Location::Byte(start as u64),
                format!("expected the {name} (a decimal number)"),
            )
        })?;
    }
    let [width, height, maxval] = fields;
    if maxval == 0 || maxval > 255 {
        return Err(if maxval > 255 {
            ParseError::Unsupported(format!("16-bit PGM (maxval {maxval}); only 8-bit is read"))
        } else {
            ParseError::at(Location::Byte(pos as u64), "maxval must be 1..=255")
        });
    }
    if !data.get(pos).is_some_and(u8::is_ascii_whitespace) {
        return Err(ParseError::at(
            Location::Byte(pos as u64),
            "expected one whitespace byte after maxval",
        ));
    }
    pos += 1;
    let n = width
        .checked_mul(height)
        .filter(|&n| n <= super::grid::MAX_CELLS as u64)
        .ok_or_else(|| ParseError::Malformed(format!("a {width} x {height} image is too large")))?
        as usize;
    let pixels = data.get(pos..pos + n).ok_or_else(|| {
        ParseError::Truncated(format!(
            "{width} x {height} pixels need {n} bytes after the header, found {}",
            data.len() - pos
        ))
    })?;
    Ok(Pgm {
        width: width as usize,
        height: height as usize,
        maxval: maxval as u32,
        pixels,
    })
}
