//! Pictures of cells: convex polygons tinted by a value over a hillshade, with their boundaries and a colour bar.

use super::hillshade::{self, ShadeOptions, draw_text, encode_png, fmt_num, text_width};
use crate::error::{Error, Result};
use crate::model::Raster;
use image::{Rgb, RgbImage};

/// Colour of the cell boundaries.
pub const EDGE_COLOUR: [u8; 3] = [20, 20, 28];

/// The tint ramp, value 0 to the largest: pale yellow, orange, red, deep magenta.
const TINT: [(f64, [f64; 3]); 4] = [
    (0.0, [255.0, 250.0, 200.0]),
    (0.35, [253.0, 174.0, 60.0]),
    (0.7, [222.0, 45.0, 38.0]),
    (1.0, [120.0, 0.0, 110.0]),
];

/// How much of the tint covers the hillshade (the rest shows the relief).
const TINT_ALPHA: f64 = 0.55;

/// `reference`'s hillshade with each convex polygon of `polygons` (sample coordinates:
/// sample centres at integers, x to the east, y to the south) tinted by its entry of
/// `values` on a sequential ramp from 0 to the largest value, the polygon boundaries in
/// [`EDGE_COLOUR`], and a colour bar labelled 0 and the largest value below; `description`
/// goes into the PNG's `Description` text chunk.
pub fn cells_png(
    reference: &Raster,
    polygons: &[Vec<[f64; 2]>],
    values: &[f64],
    description: &str,
) -> Result<Vec<u8>> {
    if polygons.len() != values.len() {
        return Err(Error::invalid(format!(
            "{} polygons but {} values",
            polygons.len(),
            values.len()
        )));
    }
    let map = hillshade::hillshade_image(reference, &ShadeOptions::default())?;
    let (w, h) = (map.width(), map.height());
    let top = values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let div = if top > 0.0 { top } else { 1.0 };
    let labels = ["0".to_string(), fmt_num(top)];
    let glyph = if w >= 120 { 2 } else { 1 };
    let legend_h = 3 + 10 + 3 + 5 * glyph + 3;
    let mut img = RgbImage::from_pixel(w, h + legend_h, Rgb([236, 236, 236]));
    for (x, y, p) in map.enumerate_pixels() {
        img.put_pixel(x, y, *p);
    }
    // Tint: every pixel centre inside a polygon.
    for (poly, &v) in polygons.iter().zip(values) {
        if poly.len() < 3 || !v.is_finite() {
            continue;
        }
        let c = ramp(v / div);
        let (y0, y1) = span(poly.iter().map(|p| p[1]), h);
        for y in y0..y1 {
            let yc = y as f64;
            // The polygon is convex: its pixels of a row are one run [xa, xb].
            let (mut xa, mut xb) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..poly.len() {
                let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
                if (a[1] <= yc && yc <= b[1]) || (b[1] <= yc && yc <= a[1]) {
                    let x = if a[1] == b[1] {
                        xa = xa.min(a[0].min(b[0]));
                        a[0].max(b[0])
                    } else {
                        a[0] + (yc - a[1]) / (b[1] - a[1]) * (b[0] - a[0])
                    };
                    xa = xa.min(x);
                    xb = xb.max(x);
                }
            }
            if xa > xb {
                continue;
            }
            let start = xa.ceil().max(0.0) as u32;
            let end = (xb.floor() + 1.0).clamp(0.0, w as f64) as u32;
            for x in start..end {
                let p = img.get_pixel_mut(x, y);
                p.0 = [0, 1, 2].map(|k| {
                    (p.0[k] as f64 * (1.0 - TINT_ALPHA) + c[k] * TINT_ALPHA).round() as u8
                });
            }
        }
    }
    // Boundaries: each edge as a line between pixel centres.
    for poly in polygons {
        for i in 0..poly.len() {
            line(&mut img, poly[i], poly[(i + 1) % poly.len()], w, h);
        }
    }
    // The colour bar.
    let (x0, x1) = (4u32.min(w), w.saturating_sub(4));
    let bar = h + 3;
    for x in x0..x1 {
        let t = (x - x0) as f64 / (x1 - x0).max(1) as f64;
        let c = ramp(t).map(|v| v.round() as u8);
        for y in bar..bar + 10 {
            img.put_pixel(x, y, Rgb(c));
        }
    }
    let ty = bar + 10 + 3;
    draw_text(&mut img, x0, ty, &labels[0], glyph, [0, 0, 0]);
    let lw = text_width(&labels[1], glyph);
    draw_text(
        &mut img,
        x1.saturating_sub(lw),
        ty,
        &labels[1],
        glyph,
        [0, 0, 0],
    );
    encode_png(&img, &[("Description", description)])
}

/// The rows `[first, end)` of the picture whose centres a polygon's y range covers.
fn span(ys: impl Iterator<Item = f64>, h: u32) -> (u32, u32) {
    let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
        (a.min(y), b.max(y))
    });
    let first = lo.ceil().max(0.0).min(h as f64) as u32;
    let end = (hi.floor() + 1.0).clamp(0.0, h as f64) as u32;
    (first, end.max(first))
}

/// A one-pixel line from `a` to `b` (sample coordinates), clipped to the picture.
fn line(img: &mut RgbImage, a: [f64; 2], b: [f64; 2], w: u32, h: u32) {
    let steps = ((b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil() as usize).max(1);
    if steps > 1 << 24 {
        return;
    }
    for s in 0..=steps {
        let t = s as f64 / steps as f64;
        let (x, y) = (
            (a[0] + t * (b[0] - a[0])).round(),
            (a[1] + t * (b[1] - a[1])).round(),
        );
        if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
            img.put_pixel(x as u32, y as u32, Rgb(EDGE_COLOUR));
        }
    }
}

fn ramp(t: f64) -> [f64; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    for pair in TINT.windows(2) {
        let ((t0, c0), (t1, c1)) = (pair[0], pair[1]);
        if t <= t1 {
            let u = (t - t0) / (t1 - t0);
            return [0, 1, 2].map(|k| c0[k] + (c1[k] - c0[k]) * u);
        }
    }
    TINT[TINT.len() - 1].1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SampleType;

    #[test]
    fn cells_are_tinted_and_outlined() {
        let r = Raster::from_values(40, 30, vec![100.0; 1200], None, SampleType::F32).unwrap();
        let polys = vec![
            vec![[0.0, 0.0], [20.0, 0.0], [20.0, 29.0], [0.0, 29.0]],
            vec![[20.0, 0.0], [39.0, 0.0], [39.0, 29.0], [20.0, 29.0]],
        ];
        let png = cells_png(&r, &polys, &[0.0, 4.0], "test").unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.width(), 40);
        assert!(img.height() > 30);
        assert_eq!(img.get_pixel(20, 10).0, EDGE_COLOUR);
        // The high-eps cell is redder than the zero-eps one.
        let (a, b) = (img.get_pixel(10, 10).0, img.get_pixel(30, 10).0);
        assert!(b[2] < a[2] && b[1] < a[1], "{a:?} {b:?}");
        assert!(cells_png(&r, &polys, &[1.0], "x").is_err());
    }
}
