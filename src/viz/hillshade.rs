//! Pictures of rasters for people: hillshaded, colour-tinted relief and error maps as PNG bytes.
//!
//! Everything here is a pure function from rasters to an [`RgbImage`] or to PNG bytes; no
//! file is read or written.
//!
//! * [`hillshade`]: Horn's-method hillshade blended with a hypsometric colour ramp, nodata in
//!   [`NODATA_COLOUR`], optionally with site positions drawn as red dots.
//! * [`error_map`]: `other − reference` on a diverging scale (blue negative, white zero, red
//!   positive) with a colour bar along the bottom.
//!
//! Both PNGs carry a `tEXt` chunk (keyword `Description`) that states the value range or the
//! error scale in plain words.

use crate::error::{Error, Result};
use crate::model::{Georef, Raster};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder, Rgb, RgbImage};

/// Colour of nodata samples in a hillshade (a greyed magenta that no ramp colour comes near).
pub const NODATA_COLOUR: [u8; 3] = [176, 120, 176];
/// Colour of sites drawn by [`hillshade`] when [`ShadeOptions::sites`] is set.
pub const SITE_COLOUR: [u8; 3] = [230, 0, 0];
/// Error map: samples that are nodata in both rasters.
pub const ERROR_NODATA_COLOUR: [u8; 3] = [128, 128, 128];
/// Error map: samples valid in exactly one of the two rasters (lost or invented).
pub const ERROR_MISMATCH_COLOUR: [u8; 3] = [255, 190, 0];

/// The most pixels an output picture may have.
const MAX_PIXELS: u64 = 1 << 28;

/// Metres per degree of latitude on a sphere of the Earth's mean radius (6 371 008.8 m).
const METRES_PER_DEGREE: f64 = 6_371_008.8 * std::f64::consts::PI / 180.0;

/// How [`hillshade`] lights and draws the surface.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadeOptions {
    /// Direction the light comes from, degrees clockwise from north (default 315 = north-west).
    pub azimuth: f64,
    /// Height of the light above the horizon, degrees in 0..=90 (default 45).
    pub altitude: f64,
    /// Vertical exaggeration: gradients are multiplied by this (default 1).
    pub z_factor: f64,
    /// Sample positions `(column, row)` to mark with red dots (e.g. the sites a `.vtz` kept).
    pub sites: Option<Vec<(usize, usize)>>,
    /// Integer upscale: every sample becomes a `scale × scale` block (default 1).
    pub scale: u32,
}

impl Default for ShadeOptions {
    fn default() -> Self {
        ShadeOptions {
            azimuth: 315.0,
            altitude: 45.0,
            z_factor: 1.0,
            sites: None,
            scale: 1,
        }
    }
}

/// A hillshaded, colour-tinted picture of `r` as RGB8 PNG bytes, `scale` times its size.
///
/// See [`hillshade_image`] for how it is drawn.
pub fn hillshade(r: &Raster, opts: &ShadeOptions) -> Result<Vec<u8>> {
    let img = hillshade_image(r, opts)?;
    let desc = match r.valid_range() {
        Some((lo, hi)) => format!(
            "vtz hillshade: values {lo} to {hi}; light from azimuth {} deg, altitude {} deg, z-factor {}; nodata = rgb{:?}",
            opts.azimuth, opts.altitude, opts.z_factor, NODATA_COLOUR
        ),
        None => "vtz hillshade: no valid samples".to_string(),
    };
    encode_png(&img, &[("Description", &desc)])
}

/// The picture [`hillshade`] encodes.
///
/// * Shading: Horn's 3×3 gradient, lit from `azimuth`/`altitude`, gradients times
///   `z_factor`. Missing neighbours (outside the raster or nodata) take the centre value.
/// * Sample spacing: the georef pixel size when there is one, else 1 (so rasters without a
///   georef look steep unless their values are in pixel units; use `z_factor`). A
///   *geographic* georef (EPSG 4326 or 4269; or, with no EPSG code, pixel sizes under 0.1
///   with an origin inside ±360, ±90) has its degrees turned into metres on a sphere, the
///   east–west spacing shrunk by cos(latitude) of each row. Rasters are taken as north-up.
/// * Colour: a hypsometric ramp over the valid value range (green → tan → brown → white).
///   When the range reaches 0 or below, values ≤ 0 are water, deep blue to light blue at 0.
///   The ramp colour is multiplied by the shade, normalised so that flat ground keeps it.
/// * Nodata samples are [`NODATA_COLOUR`], unshaded. Sites are [`SITE_COLOUR`] dots.
pub fn hillshade_image(r: &Raster, opts: &ShadeOptions) -> Result<RgbImage> {
    r.validate()?;
    check_shade_options(opts)?;
    let (w, h) = (r.width, r.height);
    let s = opts.scale as usize;
    let mut img = new_image(w, h, s, 0)?;
    let shade = shade_values(r, opts);
    let ramp = Ramp::new(r.valid_range());
    let flat = opts.altitude.to_radians().sin().max(0.05);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let c = if r.is_valid(i) {
                blend(ramp.colour(r.data[i]), shade[i], flat)
            } else {
                NODATA_COLOUR
            };
            fill_block(&mut img, x * s, y * s, s, c);
        }
    }
    if let Some(sites) = &opts.sites {
        let mut pts = Vec::with_capacity(sites.len());
        for &(x, y) in sites {
            if x >= w || y >= h {
                return Err(Error::invalid(format!(
                    "site ({x}, {y}) is outside the {w}x{h} raster"
                )));
            }
            pts.push((x * s + s / 2, y * s + s / 2));
        }
        overlay_points(&mut img, &pts, SITE_COLOUR, (opts.scale / 3).max(1));
    }
    Ok(img)
}

/// Draw a dot of `radius` pixels (1 = a plus of 5 pixels) in `colour` at each image position
/// `(x, y)`; dots are clipped at the image edges.
pub fn overlay_points(img: &mut RgbImage, points: &[(usize, usize)], colour: [u8; 3], radius: u32) {
    let (iw, ih) = (img.width() as i64, img.height() as i64);
    let r = radius as i64;
    for &(px, py) in points {
        let (Ok(px), Ok(py)) = (i64::try_from(px), i64::try_from(py)) else {
            continue;
        };
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (px + dx, py + dy);
                if dx * dx + dy * dy <= r * r && (0..iw).contains(&x) && (0..ih).contains(&y) {
                    img.put_pixel(x as u32, y as u32, Rgb(colour));
                }
            }
        }
    }
}

/// An error map of `other` against `reference` (same size) as RGB8 PNG bytes.
///
/// Each sample valid in both shows `other − reference` on a diverging scale: white at 0,
/// red for positive, blue for negative, full colour at ±`max` (default: the largest absolute
/// difference) and beyond. Samples nodata in both are [`ERROR_NODATA_COLOUR`]; samples valid
/// in only one are [`ERROR_MISMATCH_COLOUR`]. Below the map is a colour bar from −max to
/// +max, labelled with the numbers when the picture is wide enough; the `Description` text
/// chunk states the scale in any case.
pub fn error_map(reference: &Raster, other: &Raster, max: Option<f64>) -> Result<Vec<u8>> {
    reference.validate()?;
    other.validate()?;
    if reference.width != other.width || reference.height != other.height {
        return Err(Error::invalid(format!(
            "sizes differ: {}x{} and {}x{}",
            reference.width, reference.height, other.width, other.height
        )));
    }
    let scale = match max {
        Some(m) if !(m.is_finite() && m > 0.0) => {
            return Err(Error::invalid(format!(
                "error map scale {m} must be a positive number"
            )));
        }
        Some(m) => m,
        None => (0..reference.len())
            .filter(|&i| reference.is_valid(i) && other.is_valid(i))
            .map(|i| (other.data[i] - reference.data[i]).abs())
            .fold(0.0, f64::max),
    };
    let (w, h) = (reference.width, reference.height);
    let labels = [
        format!("-{}", fmt_num(scale)),
        "0".to_string(),
        format!("+{}", fmt_num(scale)),
    ];
    let legend = Legend::fit(w, &labels);
    let mut img = new_image(w, h, 1, legend.height())?;
    let div = if scale > 0.0 { scale } else { 1.0 };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let c = match (reference.is_valid(i), other.is_valid(i)) {
                (true, true) => diverging((other.data[i] - reference.data[i]) / div),
                (false, false) => ERROR_NODATA_COLOUR,
                _ => ERROR_MISMATCH_COLOUR,
            };
            img.put_pixel(x as u32, y as u32, Rgb(c));
        }
    }
    legend.draw(&mut img, h as u32, &labels);
    let desc = format!(
        "vtz error map: other - reference; white = 0, blue = -{scale} or less, red = +{scale} or more (data units); grey = nodata in both, amber = nodata in one only"
    );
    encode_png(&img, &[("Description", &desc)])
}

/// Encode an RGB image as PNG bytes, adding a `tEXt` chunk for each (keyword, text) pair
/// (keywords 1–79 Latin-1 characters; non-Latin-1 text characters become `?`).
pub fn encode_png(img: &RgbImage, text: &[(&str, &str)]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Default, FilterType::Adaptive)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            ExtendedColorType::Rgb8,
        )
        .map_err(|e| Error::invalid(format!("PNG encoding failed: {e}")))?;
    // Signature (8 bytes), then IHDR: length 4, type 4, data 13, CRC 4.
    const AFTER_IHDR: usize = 8 + 4 + 4 + 13 + 4;
    if out.get(12..16) != Some(b"IHDR".as_slice()) {
        return Err(Error::invalid("PNG encoder wrote no IHDR chunk first"));
    }
    let mut chunks = Vec::new();
    for (key, value) in text {
        if key.is_empty() || key.len() > 79 || !key.bytes().all(|b| (32..=126).contains(&b)) {
            return Err(Error::invalid(format!(
                "PNG text keyword '{key}' is not valid"
            )));
        }
        let mut data = key.as_bytes().to_vec();
        data.push(0);
        data.extend(value.chars().map(|c| match u8::try_from(c) {
            Ok(b) if b >= 32 || b == b'\n' => b,
            _ => b'?',
        }));
        let len =
            u32::try_from(data.len()).map_err(|_| Error::invalid("PNG text chunk too long"))?;
        let mut typed = b"tEXt".to_vec();
        typed.extend_from_slice(&data);
        chunks.extend_from_slice(&len.to_be_bytes());
        chunks.extend_from_slice(&typed);
        chunks.extend_from_slice(&crc32fast::hash(&typed).to_be_bytes());
    }
    out.splice(AFTER_IHDR..AFTER_IHDR, chunks);
    Ok(out)
}

fn check_shade_options(o: &ShadeOptions) -> Result<()> {
    if !o.azimuth.is_finite() {
        return Err(Error::invalid(format!(
            "azimuth {} is not a number",
            o.azimuth
        )));
    }
    if !(0.0..=90.0).contains(&o.altitude) {
        return Err(Error::invalid(format!(
            "altitude {} is not between 0 and 90 degrees",
            o.altitude
        )));
    }
    if !o.z_factor.is_finite() {
        return Err(Error::invalid(format!(
            "z-factor {} is not a number",
            o.z_factor
        )));
    }
    if o.scale == 0 {
        return Err(Error::invalid("scale must be at least 1"));
    }
    Ok(())
}

/// A black image of `w·s × (h·s + extra)` pixels, refusing sizes over [`MAX_PIXELS`].
fn new_image(w: usize, h: usize, s: usize, extra: u32) -> Result<RgbImage> {
    let too_big = || {
        Error::limit(format!(
            "a {w}x{h} picture at scale {s} is over the limit of {MAX_PIXELS} pixels"
        ))
    };
    let iw = w.checked_mul(s).and_then(|v| u32::try_from(v).ok());
    let ih = h
        .checked_mul(s)
        .and_then(|v| u32::try_from(v).ok())
        .and_then(|v| v.checked_add(extra));
    let (Some(iw), Some(ih)) = (iw, ih) else {
        return Err(too_big());
    };
    if iw as u64 * ih as u64 > MAX_PIXELS {
        return Err(too_big());
    }
    Ok(RgbImage::new(iw, ih))
}

fn fill_block(img: &mut RgbImage, x0: usize, y0: usize, s: usize, c: [u8; 3]) {
    for y in y0..y0 + s {
        for x in x0..x0 + s {
            img.put_pixel(x as u32, y as u32, Rgb(c));
        }
    }
}

/// Whether a georef's coordinates are longitude/latitude degrees.
fn is_geographic(g: &Georef) -> bool {
    match g.epsg {
        Some(4326 | 4269) => true,
        Some(_) => false,
        None => {
            g.pixel_size.iter().all(|p| p.abs() < 0.1)
                && g.origin[0].abs() <= 360.0
                && g.origin[1].abs() <= 90.0
        }
    }
}

/// Ground spacing (east–west, north–south) between neighbouring samples of each row.
fn row_spacing(r: &Raster) -> Vec<(f64, f64)> {
    let usable = |p: f64| {
        if p.is_finite() && p != 0.0 {
            p.abs()
        } else {
            1.0
        }
    };
    let Some(g) = &r.georef else {
        return vec![(1.0, 1.0); r.height];
    };
    let (px, py) = (usable(g.pixel_size[0]), usable(g.pixel_size[1]));
    if !is_geographic(g) {
        return vec![(px, py); r.height];
    }
    (0..r.height)
        .map(|y| {
            let lat = g.sample_centre(0.0, y as f64)[1];
            let c = lat.to_radians().cos().clamp(0.01, 1.0);
            (px * METRES_PER_DEGREE * c, py * METRES_PER_DEGREE)
        })
        .collect()
}

/// Illumination in 0..=1 of every sample (0 for nodata), by Horn's method.
fn shade_values(r: &Raster, o: &ShadeOptions) -> Vec<f64> {
    let (w, h) = (r.width, r.height);
    let spacing = row_spacing(r);
    let (az, alt) = (o.azimuth.to_radians(), o.altitude.to_radians());
    // Unit vector towards the light: x east, y north, z up.
    let light = [az.sin() * alt.cos(), az.cos() * alt.cos(), alt.sin()];
    let mut out = vec![0.0; w * h];
    for (y, &(dx, dy)) in spacing.iter().enumerate().take(h) {
        for x in 0..w {
            let i = y * w + x;
            if !r.is_valid(i) {
                continue;
            }
            let c = r.data[i];
            let z = |ox: isize, oy: isize| -> f64 {
                let (nx, ny) = (x as isize + ox, y as isize + oy);
                if nx < 0 || ny < 0 || nx as usize >= w || ny as usize >= h {
                    return c;
                }
                let j = ny as usize * w + nx as usize;
                if r.is_valid(j) { r.data[j] } else { c }
            };
            let east =
                (z(1, -1) + 2.0 * z(1, 0) + z(1, 1)) - (z(-1, -1) + 2.0 * z(-1, 0) + z(-1, 1));
            let south =
                (z(-1, 1) + 2.0 * z(0, 1) + z(1, 1)) - (z(-1, -1) + 2.0 * z(0, -1) + z(1, -1));
            // Slopes dz/d(east) and dz/d(north); the surface normal is (-p, -q, 1).
            let p = o.z_factor * east / (8.0 * dx);
            let q = -o.z_factor * south / (8.0 * dy);
            let lit = (-p * light[0] - q * light[1] + light[2]) / (1.0 + p * p + q * q).sqrt();
            out[i] = if lit.is_finite() { lit.max(0.0) } else { 0.0 };
        }
    }
    out
}

/// Multiply a ramp colour by the shade, normalised so flat ground (`shade == flat`) keeps
/// its colour; lit slopes brighten towards white, slopes facing away darken.
fn blend(c: [f64; 3], shade: f64, flat: f64) -> [u8; 3] {
    let f = 0.25 + 0.75 * (shade / flat);
    c.map(|v| {
        let out = if f <= 1.0 {
            v * f
        } else {
            // Beyond flat: move towards white rather than clipping channels unevenly.
            let k = ((f - 1.0) / (1.0 / flat - 1.0).max(1e-9)).min(1.0) * 0.6;
            v + (255.0 - v) * k
        };
        out.round().clamp(0.0, 255.0) as u8
    })
}

const LAND: [(f64, [f64; 3]); 5] = [
    (0.0, [56.0, 128.0, 64.0]),
    (0.3, [150.0, 186.0, 96.0]),
    (0.55, [224.0, 206.0, 138.0]),
    (0.8, [158.0, 114.0, 76.0]),
    (1.0, [250.0, 250.0, 250.0]),
];
const WATER: [(f64, [f64; 3]); 2] = [(0.0, [24.0, 56.0, 140.0]), (1.0, [150.0, 196.0, 236.0])];

/// The hypsometric colour ramp over a value range.
struct Ramp {
    lo: f64,
    hi: f64,
}

impl Ramp {
    fn new(range: Option<(f64, f64)>) -> Ramp {
        let (lo, hi) = range.unwrap_or((0.0, 1.0));
        Ramp { lo, hi }
    }

    fn colour(&self, v: f64) -> [f64; 3] {
        let (lo, hi) = (self.lo, self.hi);
        if lo <= 0.0 && v <= 0.0 {
            // Water: from the deepest value to 0 (or to the top of an all-negative range).
            let top = hi.min(0.0);
            let t = if top > lo { (v - lo) / (top - lo) } else { 1.0 };
            return ramp(&WATER, t);
        }
        let bottom = lo.max(0.0);
        let t = if hi > bottom {
            (v - bottom) / (hi - bottom)
        } else {
            0.5
        };
        ramp(&LAND, t)
    }
}

fn ramp(stops: &[(f64, [f64; 3])], t: f64) -> [f64; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    for pair in stops.windows(2) {
        let ((t0, c0), (t1, c1)) = (pair[0], pair[1]);
        if t <= t1 {
            let u = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
            return [0, 1, 2].map(|k| c0[k] + (c1[k] - c0[k]) * u);
        }
    }
    stops[stops.len() - 1].1
}

/// Error colour for `t` = difference / scale: blue (−1) – white (0) – red (+1), clamped.
fn diverging(t: f64) -> [u8; 3] {
    const RED: [f64; 3] = [200.0, 16.0, 16.0];
    const BLUE: [f64; 3] = [24.0, 64.0, 200.0];
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let end = if t >= 0.0 { RED } else { BLUE };
    let u = t.abs();
    end.map(|c| (255.0 + (c - 255.0) * u).round() as u8)
}

/// A short label for a number: up to 4 significant digits, scientific when tiny or huge.
pub(super) fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:.2e}");
    }
    let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
    fixed_trimmed(v, decimals)
}

/// `v` with `decimals` decimals, then without trailing zeros (and a bare decimal point).
pub(super) fn fixed_trimmed(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The characters [`glyph`] draws, and at the same index their 3×5 glyphs: one octal digit
/// per row, top row first, a digit's bits the row's pixels left to right (`0o75557` is "0":
/// 111, 101, 101, 101, 111).
const GLYPH_CHARS: &str = "0123456789.-+e";
const GLYPH_ROWS: [u16; 14] = [
    0o75557, 0o26227, 0o71747, 0o71717, 0o55711, 0o74717, 0o74757, 0o71111, 0o75757, 0o75717,
    0o00002, 0o00700, 0o02720, 0o74747,
];

/// 3×5 glyphs, one row of 3 bits per entry, top row first; `E` is drawn as `e`, any
/// character without a glyph as a blank.
fn glyph(c: char) -> [u8; 5] {
    match GLYPH_CHARS.find(c.to_ascii_lowercase()) {
        Some(i) => [4, 3, 2, 1, 0].map(|row| ((GLYPH_ROWS[i] >> (3 * row)) & 0o7) as u8),
        None => [0; 5],
    }
}

/// Width in pixels of `text` drawn at glyph scale `g` (glyphs 3 wide, 1 apart).
pub(super) fn text_width(text: &str, g: u32) -> u32 {
    let n = text.chars().count() as u32;
    (n * 4).saturating_sub(1) * g
}

pub(super) fn draw_text(img: &mut RgbImage, x0: u32, y0: u32, text: &str, g: u32, colour: [u8; 3]) {
    for (k, ch) in text.chars().enumerate() {
        let gx = x0 + k as u32 * 4 * g;
        for (row, bits) in glyph(ch).iter().enumerate() {
            for col in 0..3u32 {
                if bits & (0b100 >> col) == 0 {
                    continue;
                }
                for dy in 0..g {
                    for dx in 0..g {
                        let (x, y) = (gx + col * g + dx, y0 + row as u32 * g + dy);
                        if x < img.width() && y < img.height() {
                            img.put_pixel(x, y, Rgb(colour));
                        }
                    }
                }
            }
        }
    }
}

/// Layout of the colour bar under an error map.
struct Legend {
    /// Side margin of the bar.
    margin: u32,
    /// Glyph scale of the labels, 0 = no labels.
    glyph: u32,
}

const LEGEND_GAP: u32 = 3;
const LEGEND_BAR: u32 = 8;
const LEGEND_BG: [u8; 3] = [236, 236, 236];

impl Legend {
    fn fit(width: usize, labels: &[String; 3]) -> Legend {
        let w = u32::try_from(width).unwrap_or(u32::MAX);
        let margin = if w >= 24 { 4 } else { 0 };
        let glyph = [2, 1]
            .into_iter()
            .find(|&g| {
                let need: u32 = labels.iter().map(|l| text_width(l, g)).sum::<u32>() + 4 * 4 * g;
                need + 2 * margin <= w
            })
            .unwrap_or(0);
        Legend { margin, glyph }
    }

    fn height(&self) -> u32 {
        let text = if self.glyph > 0 {
            5 * self.glyph + LEGEND_GAP
        } else {
            0
        };
        LEGEND_GAP + LEGEND_BAR + text + LEGEND_GAP
    }

    fn draw(&self, img: &mut RgbImage, top: u32, labels: &[String; 3]) {
        let w = img.width();
        for y in top..img.height() {
            for x in 0..w {
                img.put_pixel(x, y, Rgb(LEGEND_BG));
            }
        }
        let (x0, x1) = (self.margin, w - self.margin);
        let span = (x1 - x0).max(1) as f64;
        let bar = top + LEGEND_GAP;
        for x in x0..x1 {
            // Pixel centre mapped to −1..1, so a bar of odd width has white in the middle.
            let t = ((x - x0) as f64 + 0.5) / span * 2.0 - 1.0;
            let c = diverging(t);
            for y in bar..bar + LEGEND_BAR {
                img.put_pixel(x, y, Rgb(c));
            }
        }
        if self.glyph == 0 {
            return;
        }
        let g = self.glyph;
        let ty = bar + LEGEND_BAR + LEGEND_GAP;
        let ink = [0, 0, 0];
        draw_text(img, x0, ty, &labels[0], g, ink);
        let mid = (x0 + x1) / 2;
        draw_text(
            img,
            mid.saturating_sub(text_width(&labels[1], g) / 2),
            ty,
            &labels[1],
            g,
            ink,
        );
        draw_text(
            img,
            x1.saturating_sub(text_width(&labels[2], g)),
            ty,
            &labels[2],
            g,
            ink,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{RasterType, SampleType};

    fn raster(w: usize, h: usize, f: impl Fn(usize, usize) -> f64) -> Raster {
        let data = (0..w * h).map(|i| f(i % w, i / w)).collect();
        Raster::from_values(w, h, data, None, SampleType::F32).unwrap()
    }

    fn decode(png: &[u8]) -> RgbImage {
        image::load_from_memory(png).expect("valid PNG").to_rgb8()
    }

    fn brightness(p: &Rgb<u8>) -> u32 {
        p.0.iter().map(|&c| c as u32).sum()
    }

    #[test]
    fn hillshade_has_the_raster_size_and_scales() {
        let r = raster(7, 5, |x, y| (x * y) as f64);
        let img = decode(&hillshade(&r, &ShadeOptions::default()).unwrap());
        assert_eq!(img.dimensions(), (7, 5));
        let opts = ShadeOptions {
            scale: 3,
            ..Default::default()
        };
        let img = decode(&hillshade(&r, &opts).unwrap());
        assert_eq!(img.dimensions(), (21, 15));
    }

    #[test]
    fn slope_facing_the_sun_is_brighter() {
        let n = 9;
        // Rising to the south-east: faces the north-west sun. And its mirror image.
        let toward = raster(n, n, |x, y| 100.0 + (x + y) as f64);
        let away = raster(n, n, |x, y| 100.0 + (2 * (n - 1) - x - y) as f64);
        let flat = raster(n, n, |_, _| 100.0);
        let o = ShadeOptions::default();
        let a = decode(&hillshade(&toward, &o).unwrap());
        let b = decode(&hillshade(&away, &o).unwrap());
        let c = decode(&hillshade(&flat, &o).unwrap());
        let (ba, bb, bc) = (
            brightness(a.get_pixel(4, 4)),
            brightness(b.get_pixel(4, 4)),
            brightness(c.get_pixel(4, 4)),
        );
        assert!(ba > bc && bc > bb, "toward {ba}, flat {bc}, away {bb}");
        // The same with the sun in the south-east.
        let o = ShadeOptions {
            azimuth: 135.0,
            ..Default::default()
        };
        let a = decode(&hillshade(&toward, &o).unwrap());
        let b = decode(&hillshade(&away, &o).unwrap());
        assert!(brightness(b.get_pixel(4, 4)) > brightness(a.get_pixel(4, 4)));
    }

    #[test]
    fn nodata_gets_the_nodata_colour() {
        let r = raster(4, 3, |x, y| {
            if (x, y) == (1, 1) {
                f64::NAN
            } else {
                (x + 10 * y) as f64
            }
        });
        let opts = ShadeOptions {
            scale: 2,
            ..Default::default()
        };
        let img = decode(&hillshade(&r, &opts).unwrap());
        for (x, y) in [(2, 2), (3, 2), (2, 3), (3, 3)] {
            assert_eq!(img.get_pixel(x, y).0, NODATA_COLOUR);
        }
        assert_ne!(img.get_pixel(0, 0).0, NODATA_COLOUR);
        let all = raster(2, 2, |_, _| f64::NAN);
        let img = decode(&hillshade(&all, &ShadeOptions::default()).unwrap());
        assert!(img.pixels().all(|p| p.0 == NODATA_COLOUR));
    }

    #[test]
    fn sites_are_drawn_and_checked() {
        let r = raster(10, 10, |x, _| x as f64);
        let opts = ShadeOptions {
            sites: Some(vec![(0, 0), (5, 5), (9, 9)]),
            ..Default::default()
        };
        let img = decode(&hillshade(&r, &opts).unwrap());
        for (x, y) in [(0, 0), (5, 5), (9, 9), (6, 5), (5, 4)] {
            assert_eq!(img.get_pixel(x, y).0, SITE_COLOUR);
        }
        assert_ne!(img.get_pixel(6, 6).0, SITE_COLOUR);
        let bad = ShadeOptions {
            sites: Some(vec![(10, 0)]),
            ..Default::default()
        };
        assert!(hillshade(&r, &bad).is_err());
    }

    #[test]
    fn water_is_blue_and_land_is_not() {
        let r = raster(4, 1, |x, _| [-20.0, 0.0, 250.0, 500.0][x]);
        let img = decode(&hillshade(&r, &ShadeOptions::default()).unwrap());
        for x in 0..2 {
            let [r, g, b] = img.get_pixel(x, 0).0;
            assert!(b > r && b > g, "pixel {x} is {r},{g},{b}");
        }
        let [r, _, b] = img.get_pixel(2, 0).0;
        assert!(r > b);
    }

    #[test]
    fn geographic_spacing_shrinks_with_latitude() {
        let mut r = raster(3, 3, |_, _| 0.0);
        r.georef = Some(Georef {
            origin: [10.0, 60.0],
            pixel_size: [1.0 / 1200.0, 1.0 / 1200.0],
            raster_type: RasterType::Point,
            epsg: None,
            wkt: None,
            geokeys: None,
        });
        let s = row_spacing(&r);
        assert!((s[0].1 - 92.66).abs() < 0.1, "{:?}", s[0]);
        assert!((s[0].0 / s[0].1 - 0.5).abs() < 1e-9);
        // A projected CRS keeps its pixel size.
        r.georef.as_mut().unwrap().epsg = Some(32633);
        assert_eq!(row_spacing(&r)[0], (1.0 / 1200.0, 1.0 / 1200.0));
    }

    #[test]
    fn identical_rasters_give_a_white_error_map() {
        let r = raster(40, 30, |x, y| (x * y) as f64);
        let img = decode(&error_map(&r, &r, None).unwrap());
        assert_eq!(img.width(), 40);
        assert!(img.height() > 30);
        for y in 0..30 {
            for x in 0..40 {
                assert_eq!(img.get_pixel(x, y).0, [255, 255, 255]);
            }
        }
    }

    #[test]
    fn error_map_signs_scale_and_nodata() {
        let a = raster(3, 2, |x, y| if (x, y) == (2, 1) { f64::NAN } else { 10.0 });
        let b = raster(3, 2, |x, y| match (x, y) {
            (0, 0) => 12.0,
            (1, 0) => 8.0,
            (2, 0) => 11.0,
            (0, 1) => f64::NAN,
            (2, 1) => f64::NAN,
            _ => 10.0,
        });
        let img = decode(&error_map(&a, &b, None).unwrap());
        assert_eq!(img.get_pixel(0, 0).0, diverging(1.0));
        assert_eq!(img.get_pixel(1, 0).0, diverging(-1.0));
        let [r, g, bl] = img.get_pixel(2, 0).0;
        assert!(r > g && r > bl && g < 255, "{r},{g},{bl}");
        assert_eq!(img.get_pixel(0, 1).0, ERROR_MISMATCH_COLOUR);
        assert_eq!(img.get_pixel(1, 1).0, [255, 255, 255]);
        assert_eq!(img.get_pixel(2, 1).0, ERROR_NODATA_COLOUR);
        // A fixed scale of 4: +2 is half-saturated.
        let img = decode(&error_map(&a, &b, Some(4.0)).unwrap());
        assert_eq!(img.get_pixel(0, 0).0, diverging(0.5));
        assert!(error_map(&a, &b, Some(0.0)).is_err());
        assert!(error_map(&a, &raster(2, 2, |_, _| 0.0), None).is_err());
    }

    #[test]
    fn one_by_one_rasters_do_not_panic() {
        let r = raster(1, 1, |_, _| 5.0);
        let nd = raster(1, 1, |_, _| f64::NAN);
        for ras in [&r, &nd] {
            let img = decode(&hillshade(ras, &ShadeOptions::default()).unwrap());
            assert_eq!(img.dimensions(), (1, 1));
            let opts = ShadeOptions {
                sites: ras.is_valid(0).then(|| vec![(0, 0)]),
                scale: 5,
                ..Default::default()
            };
            assert_eq!(decode(&hillshade(ras, &opts).unwrap()).dimensions(), (5, 5));
            let img = decode(&error_map(ras, ras, None).unwrap());
            assert_eq!(img.width(), 1);
            let img = decode(&error_map(&r, &raster(1, 1, |_, _| 6.0), Some(0.5)).unwrap());
            assert_eq!(img.get_pixel(0, 0).0, diverging(1.0));
        }
    }

    #[test]
    fn bad_options_are_rejected() {
        let r = raster(2, 2, |x, _| x as f64);
        for o in [
            ShadeOptions {
                scale: 0,
                ..Default::default()
            },
            ShadeOptions {
                altitude: 91.0,
                ..Default::default()
            },
            ShadeOptions {
                azimuth: f64::NAN,
                ..Default::default()
            },
            ShadeOptions {
                z_factor: f64::INFINITY,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                hillshade(&r, &o),
                Err(Error::InvalidArgument { .. })
            ));
        }
        let o = ShadeOptions {
            scale: 1 << 20,
            ..Default::default()
        };
        assert!(matches!(
            hillshade(&r, &o),
            Err(Error::LimitExceeded { .. })
        ));
    }

    #[test]
    fn text_chunk_is_written() {
        let r = raster(30, 4, |x, _| x as f64);
        let png = error_map(&r, &raster(30, 4, |_, _| 0.0), None).unwrap();
        let text = String::from_utf8_lossy(&png);
        assert!(
            text.contains("tEXtDescription\0vtz error map"),
            "no tEXt chunk"
        );
        assert!(text.contains("+29 or more"));
    }

    #[test]
    fn labels_are_short() {
        assert_eq!(fmt_num(3.52), "3.52");
        assert_eq!(fmt_num(47.25), "47.25");
        assert_eq!(fmt_num(1234.5678), "1235");
        assert_eq!(fmt_num(0.5), "0.5");
        assert_eq!(fmt_num(2.0), "2");
        assert_eq!(fmt_num(1e-5), "1.00e-5");
    }

    #[test]
    fn glyphs_unpack_top_row_first() {
        assert_eq!(glyph('0'), [0b111, 0b101, 0b101, 0b101, 0b111]);
        assert_eq!(glyph('4'), [0b101, 0b101, 0b111, 0b001, 0b001]);
        assert_eq!(glyph('+'), [0b000, 0b010, 0b111, 0b010, 0b000]);
        assert_eq!(glyph('E'), glyph('e'));
        assert_eq!(glyph('x'), [0; 5]);
    }
}
