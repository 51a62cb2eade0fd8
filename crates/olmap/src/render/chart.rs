//! Bar and line charts without text (labels go in the report around them).

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{check_size, draw_error};
use crate::error::{Error, Result};
use image::RgbImage;

/// One data series of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Values, one per bin or per step (finite, and >= 0 for bar charts).
    pub values: Vec<f64>,
    /// Colour (e.g. one of [`super::PALETTE`]).
    pub colour: [u8; 3],
}

const PAD: i32 = 8;

fn check(series: &[Series], non_negative: bool) -> Result<usize> {
    let n = series.iter().map(|s| s.values.len()).max().unwrap_or(0);
    if n == 0 {
        return Err(Error::InvalidArgument(
            "a chart needs at least one value".into(),
        ));
    }
    for s in series {
        if let Some(v) = s
            .values
            .iter()
            .find(|v| !v.is_finite() || (non_negative && **v < 0.0))
        {
            return Err(Error::InvalidArgument(format!(
                "chart values must be finite{}, got {v}",
                if non_negative { " and >= 0" } else { "" }
            )));
        }
    }
    Ok(n)
}

fn axes(root: &DrawingArea<BitMapBackend<'_>, Shift>, w: i32, h: i32) -> Result<()> {
    root.fill(&WHITE).map_err(draw_error)?;
    root.draw(&PathElement::new(
        vec![(PAD, PAD), (PAD, h - PAD), (w - PAD, h - PAD)],
        BLACK.stroke_width(1),
    ))
    .map_err(draw_error)
}

/// Grouped bars: bin `i` holds one bar per series side by side, heights proportional to
/// the values (the tallest bar fills the plot), on white with a left and a bottom axis.
/// `log_y` scales heights by `ln(1 + value)` (for counts over orders of magnitude, e.g.
/// particles per search level).
///
/// ```
/// use olmap::render::{bar_chart, Series, PALETTE};
/// let img = bar_chart(&[Series { values: vec![1.0, 4.0, 2.0], colour: PALETTE[0] }],
///                     300, 200, false).unwrap();
/// assert_eq!((img.width(), img.height()), (300, 200));
/// ```
pub fn bar_chart(series: &[Series], width: u32, height: u32, log_y: bool) -> Result<RgbImage> {
    check_size(width, height)?;
    let bins = check(series, true)?;
    let scale = |v: f64| if log_y { v.ln_1p() } else { v };
    let top = series
        .iter()
        .flat_map(|s| s.values.iter())
        .map(|&v| scale(v))
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let mut image = RgbImage::new(width, height);
    {
        let (w, h) = (width as i32, height as i32);
        let root = BitMapBackend::with_buffer(&mut image, (width, height)).into_drawing_area();
        axes(&root, w, h)?;
        let plot_w = (w - 3 * PAD).max(1) as f64;
        let plot_h = (h - 3 * PAD).max(1) as f64;
        let bin_w = plot_w / bins as f64;
        let bar_w = bin_w * 0.8 / series.len().max(1) as f64;
        for (k, s) in series.iter().enumerate() {
            let [r, g, b] = s.colour;
            for (i, &v) in s.values.iter().enumerate() {
                if v <= 0.0 {
                    continue;
                }
                let x0 = PAD as f64 + 1.0 + i as f64 * bin_w + bin_w * 0.1 + k as f64 * bar_w;
                let x1 = (x0 + bar_w).max(x0 + 1.0);
                let y1 = (h - PAD - 1) as f64;
                let y0 = y1 - (scale(v) / top * plot_h).max(1.0);
                root.draw(&Rectangle::new(
                    [(x0 as i32, y0 as i32), (x1 as i32, y1 as i32)],
                    RGBColor(r, g, b).filled(),
                ))
                .map_err(draw_error)?;
            }
        }
        root.present().map_err(draw_error)?;
    }
    Ok(image)
}

/// Lines through each series' values (x: the value's index, y: the value, scaled so all
/// series fit), on white with a left and a bottom axis.
pub fn line_chart(series: &[Series], width: u32, height: u32) -> Result<RgbImage> {
    check_size(width, height)?;
    let n = check(series, false)?;
    let all = series.iter().flat_map(|s| s.values.iter().copied());
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
        (l.min(v), h.max(v))
    });
    let span = (hi - lo).max(1e-12);
    let mut image = RgbImage::new(width, height);
    {
        let (w, h) = (width as i32, height as i32);
        let root = BitMapBackend::with_buffer(&mut image, (width, height)).into_drawing_area();
        axes(&root, w, h)?;
        let plot_w = (w - 3 * PAD).max(1) as f64;
        let plot_h = (h - 3 * PAD).max(1) as f64;
        let step = plot_w / (n.max(2) - 1) as f64;
        for s in series {
            let [r, g, b] = s.colour;
            let pts: Vec<(i32, i32)> = s
                .values
                .iter()
                .enumerate()
                .map(|(i, &v)| {
                    (
                        (PAD as f64 + 1.0 + i as f64 * step) as i32,
                        ((h - PAD - 1) as f64 - (v - lo) / span * plot_h) as i32,
                    )
                })
                .collect();
            for &p in &pts {
                root.draw(&Rectangle::new(
                    [(p.0 - 1, p.1 - 1), (p.0 + 1, p.1 + 1)],
                    RGBColor(r, g, b).filled(),
                ))
                .map_err(draw_error)?;
            }
            root.draw(&PathElement::new(pts, RGBColor(r, g, b).stroke_width(2)))
                .map_err(draw_error)?;
        }
        root.present().map_err(draw_error)?;
    }
    Ok(image)
}

/// Particles per level of a global search (poses evaluated, blue, and kept for the next
/// level, red), coarsest level on the left, heights on a log scale (`ln(1 + n)`): how the
/// multi-resolution search narrows down (thesis §5.3.3).
///
/// ```
/// use olmap::align::LevelReport;
/// use olmap::render::level_chart;
/// let level = |l: usize, evaluated: usize, survivors: usize| LevelReport {
///     level: l, resolution: 0.1 * 2f64.powi(l as i32), angular_step: 0.1,
///     scan_voxels: 100, evaluated, passed: survivors, survivors, best_overlap: 50,
///     seconds: 0.0,
/// };
/// let img = level_chart(&[level(0, 500, 1), level(1, 20_000, 40)], 300, 150).unwrap();
/// assert_eq!(img.width(), 300);
/// ```
pub fn level_chart(
    levels: &[crate::align::LevelReport],
    width: u32,
    height: u32,
) -> Result<RgbImage> {
    let mut sorted: Vec<&crate::align::LevelReport> = levels.iter().collect();
    sorted.sort_by_key(|l| std::cmp::Reverse(l.level));
    bar_chart(
        &[
            Series {
                values: sorted.iter().map(|l| l.evaluated as f64).collect(),
                colour: super::PALETTE[0],
            },
            Series {
                values: sorted.iter().map(|l| l.survivors as f64).collect(),
                colour: super::PALETTE[1],
            },
        ],
        width,
        height,
        true,
    )
}
