//! Rate–distortion plots (`vtz rd --png`): bits per sample against the error, log–log,
//! one row of panels per raster (max error, RMSE), one colour and marker per method.
//!
//! Drawn with `plotters` on an RGB buffer and written as PNG with the library's encoder.
//! Text uses an embedded subset of DejaVu Sans (`src/viz/fonts/`), so no system font or
//! fontconfig is needed.

use super::hillshade::fixed_trimmed;
use crate::error::{Error, Result};
use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};
use plotters_backend::{BackendCoord, DrawingErrorKind};
use std::sync::OnceLock;

static FONT: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/src/viz/fonts/DejaVuSans-subset.ttf"
));

/// One point of a curve: bits per sample, max error and RMSE in % of the value range.
#[derive(Clone, Copy, Debug)]
pub struct Point {
    /// Bits per sample.
    pub bps: f64,
    /// Max error in % of the value range.
    pub max_pct: f64,
    /// RMSE in % of the value range.
    pub rmse_pct: f64,
}

/// The curves of one raster, one per method (in the order to draw and list them).
pub struct Raster {
    /// The raster's name (a panel title).
    pub name: String,
    /// One curve per method: its name and its points.
    pub series: Vec<(String, Vec<Point>)>,
    /// Requested bounds in % of the range, drawn as faint lines on the max-error panel.
    pub bounds_pct: Vec<f64>,
}

const PANEL_W: u32 = 600;
const PANEL_H: u32 = 420;
const TITLE_H: u32 = 44;

fn register() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    if *REGISTERED.get_or_init(|| register_font("sans-serif", FontStyle::Normal, FONT).is_ok()) {
        Ok(())
    } else {
        Err(Error::unsupported(
            "the embedded plot font is not a valid TTF",
        ))
    }
}

fn method_style(name: &str, i: usize) -> RGBColor {
    match name {
        "sibson" => RGBColor(31, 119, 180),
        "grid" => RGBColor(230, 120, 0),
        "fis" => RGBColor(44, 160, 44),
        "haar" => RGBColor(214, 39, 40),
        "best" => RGBColor(148, 103, 189),
        _ => [
            RGBColor(140, 86, 75),
            RGBColor(227, 119, 194),
            RGBColor(127, 127, 127),
        ][i % 3],
    }
}

/// A point marker: a different shape per series, drawn around one point in pixels.
struct Marker<C> {
    at: C,
    shape: usize,
    colour: RGBColor,
}

impl<'a, C: 'a> PointCollection<'a, C> for &'a Marker<C> {
    type Point = &'a C;
    type IntoIter = std::iter::Once<&'a C>;
    fn point_iter(self) -> Self::IntoIter {
        std::iter::once(&self.at)
    }
}

impl<C, DB: DrawingBackend> Drawable<DB> for Marker<C> {
    fn draw<I: Iterator<Item = BackendCoord>>(
        &self,
        mut pos: I,
        backend: &mut DB,
        _: (u32, u32),
    ) -> std::result::Result<(), DrawingErrorKind<DB::ErrorType>> {
        let Some((x, y)) = pos.next() else {
            return Ok(());
        };
        let c = self.colour;
        match self.shape % 5 {
            0 => backend.draw_circle((x, y), 4, &c.filled(), true),
            1 => backend.draw_rect((x - 4, y - 4), (x + 4, y + 4), &c.filled(), true),
            2 => backend.fill_polygon([(x, y - 6), (x - 5, y + 4), (x + 5, y + 4)], &c.filled()),
            3 => {
                let s = c.stroke_width(2);
                backend.draw_line((x - 4, y - 4), (x + 4, y + 4), &s)?;
                backend.draw_line((x - 4, y + 4), (x + 4, y - 4), &s)
            }
            _ => backend.draw_circle((x, y), 5, &c.stroke_width(2), false),
        }
    }
}

fn shape_of(name: &str, i: usize) -> usize {
    match name {
        "sibson" => 0,
        "grid" => 1,
        "fis" => 2,
        "haar" => 3,
        "best" => 4,
        _ => i,
    }
}

/// `v` with up to 3 significant digits, no trailing zeros (axis labels on a log scale).
fn sig(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return format!("{v}");
    }
    let digits = (2 - v.log10().floor() as i32).max(0) as usize;
    fixed_trimmed(v, digits)
}

/// A log axis range around `vals` (positive ones), padded by 0.15 decade.
fn log_range(vals: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, 0f64);
    for v in vals.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if hi <= 0.0 {
        return None;
    }
    let pad = 10f64.powf(0.15);
    let (mut lo, mut hi) = (lo / pad, hi * pad);
    // Keep at least one decade visible so the axis gets labels.
    if hi / lo < 10.0 {
        let mid = (lo * hi).sqrt();
        lo = mid / 10f64.sqrt();
        hi = mid * 10f64.sqrt();
    }
    Some((lo, hi))
}

/// Labelled ticks (1-2-5 style, at most 7) and light grid lines (every 1..9 × 10ⁿ) for a
/// log axis over `lo..hi`.
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let at = |mantissas: &[f64]| -> Vec<f64> {
        let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (d0..=d1)
            .flat_map(|d| mantissas.iter().map(move |m| m * 10f64.powi(d)))
            .filter(|v| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9))
            .collect()
    };
    let sets: [&[f64]; 5] = [
        &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0],
        &[1.0, 2.0, 3.0, 5.0],
        &[1.0, 2.0, 5.0],
        &[1.0, 3.0],
        &[1.0],
    ];
    let bold = sets
        .iter()
        .map(|m| at(m))
        .find(|t| t.len() <= 7)
        .unwrap_or_else(|| at(&[1.0]));
    let light = at(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
        .into_iter()
        .filter(|v| !bold.iter().any(|b| (b - v).abs() <= 1e-9 * v))
        .collect();
    (bold, light)
}

fn draw_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> Error {
    Error::unsupported(format!("drawing the plot: {e}"))
}

/// Draw the rasters' curves (one row of two panels each) and return PNG bytes.
pub fn rd_png(rasters: &[Raster], title: &str) -> Result<Vec<u8>> {
    register()?;
    let rows = rasters.len().max(1) as u32;
    let (w, h) = (2 * PANEL_W, TITLE_H + rows * PANEL_H);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let (top, body) = root.split_vertically(TITLE_H);
        top.draw(&Text::new(
            title.to_string(),
            (16, 12),
            ("sans-serif", 22).into_font().color(&BLACK),
        ))
        .map_err(draw_err)?;
        let areas = body.split_evenly((rows as usize, 2));
        for (r, raster) in rasters.iter().enumerate() {
            for (panel, area) in areas[2 * r..2 * r + 2].iter().enumerate() {
                draw_panel(area, raster, panel == 1)?;
            }
        }
        root.present().map_err(draw_err)?;
    }
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| Error::unsupported("plot buffer has the wrong size"))?;
    crate::viz::hillshade::encode_png(&img, &[("Description", title)])
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    r: &Raster,
    rmse: bool,
) -> Result<()> {
    let y_of = |p: &Point| if rmse { p.rmse_pct } else { p.max_pct };
    let ok = |p: &Point| p.bps > 0.0 && p.bps.is_finite() && y_of(p) > 0.0 && y_of(p).is_finite();
    let pts = || {
        r.series
            .iter()
            .flat_map(|(_, v)| v.iter())
            .filter(|p| ok(p))
    };
    let what = if rmse { "RMSE" } else { "max error" };
    let caption = format!("{} — {what}", r.name);
    let ranges = log_range(pts().map(|p| p.bps)).zip(log_range(
        pts()
            .map(y_of)
            .chain(r.bounds_pct.iter().copied().filter(|_| !rmse)),
    ));
    let Some(((x0, x1), (y0, y1))) = ranges else {
        // Nothing to draw (every run failed, or all were lossless): say so in the panel.
        area.titled(&caption, ("sans-serif", 18))
            .and_then(|a| {
                a.draw(&Text::new(
                    "no lossy results to plot".to_string(),
                    (40, 60),
                    ("sans-serif", 16)
                        .into_font()
                        .color(&RGBColor(120, 120, 120)),
                ))
            })
            .map_err(draw_err)?;
        return Ok(());
    };
    let ((xb, xl), (yb, yl)) = (log_ticks(x0, x1), log_ticks(y0, y1));
    let mut chart = ChartBuilder::on(area)
        .caption(&caption, ("sans-serif", 18))
        .margin(12)
        .margin_right(20)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(
            (x0..x1)
                .log_scale()
                .with_key_points(xb)
                .with_light_points(xl),
            (y0..y1)
                .log_scale()
                .with_key_points(yb)
                .with_light_points(yl),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc("bits per sample")
        .y_desc(format!("{what}, % of range"))
        .x_label_formatter(&|v| sig(*v))
        .y_label_formatter(&|v| sig(*v))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(RGBColor(242, 242, 242))
        .bold_line_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(draw_err)?;
    if !rmse {
        let grey = RGBColor(150, 150, 150);
        for &b in r.bounds_pct.iter().filter(|&&b| b > y0 && b < y1) {
            chart
                .draw_series(DashedLineSeries::new(
                    [(x0, b), (x1, b)],
                    4,
                    4,
                    grey.stroke_width(1),
                ))
                .map_err(draw_err)?;
        }
    }
    let mut any = false;
    for (i, (name, v)) in r.series.iter().enumerate() {
        let mut v: Vec<(f64, f64)> = v
            .iter()
            .filter(|p| ok(p))
            .map(|p| (p.bps, y_of(p)))
            .collect();
        if v.is_empty() {
            continue;
        }
        any = true;
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let c = method_style(name, i);
        let shape = shape_of(name, i);
        chart
            .draw_series(LineSeries::new(v.iter().copied(), c.stroke_width(2)))
            .map_err(draw_err)?
            .label(name.clone())
            .legend(move |(x, y)| {
                EmptyElement::at((x, y))
                    + PathElement::new(vec![(0, 0), (24, 0)], c.stroke_width(2))
                    + Marker {
                        at: (12, 0),
                        shape,
                        colour: c,
                    }
            });
        chart
            .draw_series(v.iter().map(|&p| Marker {
                at: p,
                shape,
                colour: c,
            }))
            .map_err(draw_err)?;
    }
    if any {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(draw_err)?;
    }
    Ok(())
}
