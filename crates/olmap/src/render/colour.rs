//! Colour maps.

use image::Rgb;

/// Distinct colours for series and robots, in order.
pub const PALETTE: [[u8; 3]; 6] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [23, 190, 207],
];

fn ramp(t: f64, stops: &[[u8; 3]]) -> Rgb<u8> {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (stops.len() - 1) as f64;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f64;
    let (a, b) = (stops[i], stops[i + 1]);
    Rgb(std::array::from_fn(|c| {
        (a[c] as f64 + f * (b[c] as f64 - a[c] as f64)).round() as u8
    }))
}

/// The colour of a height, `t` in `[0, 1]` from the lowest to the highest (clamped): dark
/// blue, cyan, green, yellow, red. Never white, the background of top views.
///
/// ```
/// use olmap::render::height_colour;
/// assert_eq!(height_colour(0.0).0, [48, 18, 120]);
/// assert_eq!(height_colour(1.0).0, [200, 20, 20]);
/// ```
pub fn height_colour(t: f64) -> Rgb<u8> {
    ramp(
        t,
        &[
            [48, 18, 120],
            [30, 160, 220],
            [40, 180, 80],
            [240, 200, 30],
            [200, 20, 20],
        ],
    )
}

/// The colour of a heat-map value, `t` in `[0, 1]` (clamped): black, red, yellow, white.
pub fn heat_colour(t: f64) -> Rgb<u8> {
    ramp(
        t,
        &[[0, 0, 0], [180, 20, 10], [250, 200, 30], [255, 255, 255]],
    )
}
