use plotters::style::RGBColor;

/// Viridis, sampled at 9 evenly spaced points (0 dark purple, 1 yellow).
const VIRIDIS: [(u8, u8, u8); 9] = [
    (0x44, 0x01, 0x54),
    (0x47, 0x2c, 0x7a),
    (0x3b, 0x52, 0x8b),
    (0x2c, 0x72, 0x8e),
    (0x21, 0x91, 0x8c),
    (0x28, 0xae, 0x80),
    (0x5e, 0xc9, 0x62),
    (0xad, 0xdc, 0x30),
    (0xfd, 0xe7, 0x25),
];

/// Blue (-1, clockwise) to near white (0) to red (+1, counter-clockwise): ColorBrewer RdBu.
const DIVERGING: [(u8, u8, u8); 9] = [
    (0x21, 0x66, 0xac),
    (0x43, 0x93, 0xc3),
    (0x92, 0xc5, 0xde),
    (0xd1, 0xe5, 0xf0),
    (0xf7, 0xf7, 0xf7),
    (0xfd, 0xdb, 0xc7),
    (0xf4, 0xa5, 0x82),
    (0xd6, 0x60, 0x4d),
    (0xb2, 0x18, 0x2b),
];

/// Number of colour levels of the sequential map (S).
pub(crate) const SEQUENTIAL_LEVELS: i32 = 32;

/// Number of colour levels on each side of zero of the diverging map (R+ / R-).
pub(crate) const DIVERGING_LEVELS: i32 = 16;

fn interpolate(table: &[(u8, u8, u8)], t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (table.len() - 1) as f64;
    let k = (x.floor() as usize).min(table.len() - 2);
    let f = x - k as f64;
    let lerp = |a: u8, b: u8| (f64::from(a) + (f64::from(b) - f64::from(a)) * f).round() as u8;
    let (a, b) = (table[k], table[k + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// The sequential level (0 ..= `SEQUENTIAL_LEVELS - 1`) of `t` in [0, 1].
pub(crate) fn sequential_level(t: f64) -> i32 {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((t * f64::from(SEQUENTIAL_LEVELS)) as i32).min(SEQUENTIAL_LEVELS - 1)
}

/// Colour of a sequential level (its centre on the viridis map).
pub(crate) fn sequential_colour(level: i32) -> RGBColor {
    interpolate(
        &VIRIDIS,
        (f64::from(level) + 0.5) / f64::from(SEQUENTIAL_LEVELS),
    )
}

/// Colour of `t` in [-1, 1] on the diverging map, quantised to `2 * DIVERGING_LEVELS + 1`
/// levels so neighbouring cells of one level share a colour.
pub(crate) fn diverging_colour(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let level = (t * f64::from(DIVERGING_LEVELS)).round() / f64::from(DIVERGING_LEVELS);
    interpolate(&DIVERGING, 0.5 * (level + 1.0))
}
