//! The Web Mercator (EPSG:3857, XYZ scheme) pyramid of a raster: the finest zoom resampled
//! from the source, each coarser zoom the 2 × 2 mean of the one below.
//!
//! Pixels are areas, as MapLibre draws them: pixel (i, j) of tile (z, x, y) with `dim`
//! pixels a side is the cell centred at the normalised Mercator point
//! `((x + (i + ½)/dim) / 2^z, (y + (j + ½)/dim) / 2^z)` (x east, y south, both in [0, 1]).
//! A parent pixel covers exactly its four children, so the levels nest.

use crate::error::{Error, Result};
use crate::formats::crs;
use crate::model::{Georef, Raster, RasterType};
use rayon::prelude::*;

/// WGS 84's semi-major axis, the sphere of Web Mercator (metres).
pub const EARTH_RADIUS: f64 = 6_378_137.0;
/// The latitude where Web Mercator's square world ends (degrees).
pub const MAX_LATITUDE: f64 = 85.051_128_779_806_59;
/// The deepest zoom `vtz web` writes (tiles of 256 pixels are then 2.4 cm at the equator).
pub const MAX_ZOOM: u8 = 24;

/// Longitude and latitude (degrees) of the normalised Mercator point (`mx`, `my`).
pub fn unproject(mx: f64, my: f64) -> (f64, f64) {
    let lon = 360.0 * mx - 180.0;
    let lat = (std::f64::consts::PI * (1.0 - 2.0 * my))
        .sinh()
        .atan()
        .to_degrees();
    (lon, lat)
}

/// The normalised Mercator point (x east, y south, in [0, 1]) of a longitude and latitude
/// (degrees; the latitude clamped to ±[`MAX_LATITUDE`]).
pub fn project(lon: f64, lat: f64) -> (f64, f64) {
    let phi = lat.clamp(-MAX_LATITUDE, MAX_LATITUDE).to_radians();
    let mx = (lon + 180.0) / 360.0;
    let my = 0.5 - (phi.tan() + 1.0 / phi.cos()).ln() / (2.0 * std::f64::consts::PI);
    (mx, my)
}

/// The ground size (metres) of one pixel at `zoom` for tiles of `dim` pixels, at latitude
/// `lat` (degrees): `2πR·cos φ / (dim·2^zoom)`.
pub fn ground_resolution(zoom: u8, dim: u32, lat: f64) -> f64 {
    2.0 * std::f64::consts::PI * EARTH_RADIUS * lat.to_radians().cos()
        / (f64::from(dim) * 2f64.powi(i32::from(zoom)))
}

/// How a longitude/latitude reaches the source raster's pixel grid.
enum Crs {
    /// A geographic CRS: pixel coordinates are affine in longitude and latitude.
    Geographic,
    /// A projected CRS, through PROJ.4 strings (`proj4rs`): from WGS 84 to the source.
    Projected {
        wgs84: Box<proj4rs::Proj>,
        src: Box<proj4rs::Proj>,
    },
}

/// The source raster, sampled at longitudes/latitudes.
pub(crate) struct Source<'a> {
    r: &'a Raster,
    g: Georef,
    crs: Crs,
    /// Added to (x − origin)/size to reach pixel-centre coordinates: −½ for areas, 0 for
    /// points (whose origin is already a centre).
    centre: f64,
    /// Longitude/latitude bounds of the data (west, south, east, north), degrees.
    pub(crate) bounds: [f64; 4],
    /// The source pixel's ground size along y (metres).
    pub(crate) pixel_metres: f64,
}

const GEOGRAPHIC: [u32; 5] = [4326, 4269, 4258, 4283, 4617];

impl<'a> Source<'a> {
    /// The raster's georeferencing read as a CRS, or a clear error: a raster without one
    /// cannot be placed on the web map.
    pub(crate) fn new(r: &'a Raster) -> Result<Source<'a>> {
        let g = r.georef.clone().ok_or_else(|| {
            Error::invalid(
                "the raster has no georeferencing: a web map needs to know where it is \
                 (give a GeoTIFF, an .hgt named after its tile, or an ASCII grid with a .prj)",
            )
        })?;
        if g.pixel_size[0] <= 0.0 || g.pixel_size[1] == 0.0 {
            return Err(Error::unsupported(
                "a raster whose columns run west (negative x pixel size) cannot be tiled",
            ));
        }
        let epsg = g
            .epsg
            .or_else(|| g.wkt.as_deref().and_then(crs::epsg_of_wkt))
            .ok_or_else(|| {
                Error::invalid(
                    "the raster's CRS has no EPSG code vtz knows: reproject it first \
                     (e.g. gdalwarp -t_srs EPSG:4326)",
                )
            })?;
        let crs = if GEOGRAPHIC.contains(&epsg) {
            Crs::Geographic
        } else {
            let def = u16::try_from(epsg)
                .ok()
                .and_then(crs_definitions::from_code)
                .ok_or_else(|| {
                    Error::unsupported(format!(
                        "EPSG:{epsg} is not in vtz's CRS table: reproject the raster first \
                         (e.g. gdalwarp -t_srs EPSG:4326)"
                    ))
                })?;
            let src = proj4rs::Proj::from_proj_string(def.proj4).map_err(|e| {
                Error::unsupported(format!("EPSG:{epsg} ({}): {e}", def.proj4.trim()))
            })?;
            if src.is_latlong() {
                Crs::Geographic
            } else if src.is_geocent() {
                return Err(Error::unsupported(format!(
                    "EPSG:{epsg} is geocentric, not a map projection"
                )));
            } else {
                let wgs84 = proj4rs::Proj::from_proj_string("+proj=longlat +datum=WGS84 +no_defs")
                    .map_err(|e| Error::unsupported(format!("WGS 84: {e}")))?;
                Crs::Projected {
                    wgs84: Box::new(wgs84),
                    src: Box::new(src),
                }
            }
        };
        let centre = match g.raster_type {
            RasterType::Area => -0.5,
            RasterType::Point => 0.0,
        };
        let mut s = Source {
            r,
            g,
            crs,
            centre,
            bounds: [0.0; 4],
            pixel_metres: 0.0,
        };
        s.bounds = s.lonlat_bounds()?;
        s.pixel_metres = match s.crs {
            Crs::Geographic => s.g.pixel_size[1].abs().to_radians() * EARTH_RADIUS,
            Crs::Projected { .. } => s.g.pixel_size[1].abs(),
        };
        Ok(s)
    }

    /// Model coordinates (the source CRS) of the pixel-centre coordinates (col, row).
    fn model_of(&self, col: f64, row: f64) -> (f64, f64) {
        let [x, y] = self.g.sample_centre(col, row);
        (x, y)
    }

    /// Pixel-centre coordinates of a model point.
    fn pixel_of_model(&self, x: f64, y: f64) -> (f64, f64) {
        let g = &self.g;
        (
            (x - g.origin[0]) / g.pixel_size[0] + self.centre,
            (g.origin[1] - y) / g.pixel_size[1] + self.centre,
        )
    }

    fn to_lonlat(&self, x: f64, y: f64) -> Result<(f64, f64)> {
        match &self.crs {
            Crs::Geographic => Ok((x, y)),
            Crs::Projected { wgs84, src } => {
                let mut p = (x, y, 0.0);
                proj4rs::transform::transform(src, wgs84, &mut p)
                    .map_err(|e| Error::invalid(format!("reprojecting ({x}, {y}): {e}")))?;
                Ok((p.0.to_degrees(), p.1.to_degrees()))
            }
        }
    }

    /// Pixel-centre coordinates (col, row) of a longitude/latitude, `None` where the
    /// projection has no answer.
    pub(crate) fn pixel_of(&self, lon: f64, lat: f64) -> Option<(f64, f64)> {
        match &self.crs {
            Crs::Geographic => Some(self.pixel_of_model(lon, lat)),
            Crs::Projected { wgs84, src } => {
                let mut p = (lon.to_radians(), lat.to_radians(), 0.0);
                proj4rs::transform::transform(wgs84, src, &mut p).ok()?;
                (p.0.is_finite() && p.1.is_finite()).then(|| self.pixel_of_model(p.0, p.1))
            }
        }
    }

    /// The data's extent in longitude/latitude: its outline (pixel edges) walked in 64 steps
    /// a side, so a projected raster's curved outline is covered.
    fn lonlat_bounds(&self) -> Result<[f64; 4]> {
        let (w, h) = (self.r.width as f64, self.r.height as f64);
        let (c0, c1) = (-0.5, w - 0.5);
        let (r0, r1) = (-0.5, h - 0.5);
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        const STEPS: usize = 64;
        for k in 0..=STEPS {
            let t = k as f64 / STEPS as f64;
            for (col, row) in [
                (c0 + t * (c1 - c0), r0),
                (c0 + t * (c1 - c0), r1),
                (c0, r0 + t * (r1 - r0)),
                (c1, r0 + t * (r1 - r0)),
            ] {
                let (x, y) = self.model_of(col, row);
                let (lon, lat) = self.to_lonlat(x, y)?;
                b[0] = b[0].min(lon);
                b[1] = b[1].min(lat);
                b[2] = b[2].max(lon);
                b[3] = b[3].max(lat);
            }
        }
        if !b.iter().all(|v| v.is_finite()) || b[0] < -180.5 || b[2] > 180.5 {
            return Err(Error::invalid(format!(
                "the raster's extent ({:.4}, {:.4}) – ({:.4}, {:.4}) is not a longitude/latitude \
                 range on Earth: is its CRS right?",
                b[0], b[1], b[2], b[3]
            )));
        }
        b[0] = b[0].max(-180.0);
        b[2] = b[2].min(180.0);
        b[1] = b[1].max(-MAX_LATITUDE);
        b[3] = b[3].min(MAX_LATITUDE);
        if b[1] >= b[3] {
            return Err(Error::invalid(
                "the raster lies beyond Web Mercator's ±85.05° of latitude",
            ));
        }
        Ok(b)
    }

    /// The value at pixel-centre coordinates (col, row): bilinear between the four nearest
    /// samples, weights renormalised over the valid ones; NaN outside the raster (more than
    /// half a pixel beyond its outer centres) or where all four are nodata.
    pub(crate) fn sample(&self, col: f64, row: f64) -> f32 {
        let r = self.r;
        let (w, h) = (r.width as f64, r.height as f64);
        if !(col >= -0.5 && col <= w - 0.5 && row >= -0.5 && row <= h - 0.5) {
            return f32::NAN;
        }
        let c = col.clamp(0.0, w - 1.0);
        let rr = row.clamp(0.0, h - 1.0);
        let (c0, r0) = (c.floor() as usize, rr.floor() as usize);
        let (c1, r1) = ((c0 + 1).min(r.width - 1), (r0 + 1).min(r.height - 1));
        let (fx, fy) = (c - c0 as f64, rr - r0 as f64);
        let mut sum = 0.0;
        let mut wsum = 0.0;
        for (cc, rr, wt) in [
            (c0, r0, (1.0 - fx) * (1.0 - fy)),
            (c1, r0, fx * (1.0 - fy)),
            (c0, r1, (1.0 - fx) * fy),
            (c1, r1, fx * fy),
        ] {
            let i = rr * r.width + cc;
            if wt > 0.0 && r.is_valid(i) {
                sum += wt * r.data[i];
                wsum += wt;
            }
        }
        if wsum > 0.0 {
            (sum / wsum) as f32
        } else {
            // All weight on nodata samples: the nearest sample when it is valid.
            let i = (rr.round() as usize) * r.width + c.round() as usize;
            if r.is_valid(i) {
                r.data[i] as f32
            } else {
                f32::NAN
            }
        }
    }
}

/// One zoom of the pyramid: the tiles `tx0..tx0+ntx` × `ty0..ty0+nty` as one raster of
/// `ntx·dim × nty·dim` heights (NaN = nodata), row 0 north.
pub(crate) struct Level {
    pub(crate) zoom: u8,
    pub(crate) dim: usize,
    pub(crate) tx0: u32,
    pub(crate) ty0: u32,
    pub(crate) ntx: u32,
    pub(crate) nty: u32,
    pub(crate) data: Vec<f32>,
}

impl Level {
    fn width(&self) -> usize {
        self.ntx as usize * self.dim
    }

    /// The tile (x, y) of this level (absolute tile numbers), row-major `dim × dim`.
    pub(crate) fn tile(&self, x: u32, y: u32) -> Vec<f32> {
        let (d, w) = (self.dim, self.width());
        let (ox, oy) = ((x - self.tx0) as usize * d, (y - self.ty0) as usize * d);
        let mut out = Vec::with_capacity(d * d);
        for j in 0..d {
            let s = (oy + j) * w + ox;
            out.extend_from_slice(&self.data[s..s + d]);
        }
        out
    }

    /// Every tile of the level that holds at least one valid pixel, as (x, y).
    pub(crate) fn tiles(&self) -> Vec<(u32, u32)> {
        let (d, w) = (self.dim, self.width());
        let mut out = Vec::new();
        for ty in self.ty0..self.ty0 + self.nty {
            for tx in self.tx0..self.tx0 + self.ntx {
                let (ox, oy) = ((tx - self.tx0) as usize * d, (ty - self.ty0) as usize * d);
                let any = (0..d).any(|j| {
                    let s = (oy + j) * w + ox;
                    self.data[s..s + d].iter().any(|v| !v.is_nan())
                });
                if any {
                    out.push((tx, ty));
                }
            }
        }
        out
    }

    /// The level one zoom coarser: each pixel the mean of its valid children (NaN when none
    /// is valid).
    pub(crate) fn coarser(&self) -> Level {
        let d = self.dim;
        let tx0 = self.tx0 / 2;
        let ty0 = self.ty0 / 2;
        let ntx = (self.tx0 + self.ntx - 1) / 2 - tx0 + 1;
        let nty = (self.ty0 + self.nty - 1) / 2 - ty0 + 1;
        let w = ntx as usize * d;
        let h = nty as usize * d;
        let (sw, sh) = (self.width() as i64, (self.nty as usize * d) as i64);
        // The child level's pixel (0, 0) in the parent's doubled pixel grid.
        let ox = (self.tx0 as i64 - 2 * tx0 as i64) * d as i64;
        let oy = (self.ty0 as i64 - 2 * ty0 as i64) * d as i64;
        let mut data = vec![f32::NAN; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                let mut sum = 0.0f64;
                let mut n = 0u32;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let cx = 2 * i as i64 + dx - ox;
                    let cy = 2 * j as i64 + dy - oy;
                    if cx >= 0 && cy >= 0 && cx < sw && cy < sh {
                        let v = self.data[cy as usize * sw as usize + cx as usize];
                        if !v.is_nan() {
                            sum += f64::from(v);
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    *out = (sum / f64::from(n)) as f32;
                }
            }
        });
        Level {
            zoom: self.zoom - 1,
            dim: d,
            tx0,
            ty0,
            ntx,
            nty,
            data,
        }
    }
}

/// The tiles of `zoom` (x0, y0, x1, y1 inclusive) that the bounds touch.
fn tile_range(b: [f64; 4], zoom: u8) -> (u32, u32, u32, u32) {
    let n = 1u64 << zoom;
    let (mx0, my0) = project(b[0], b[3]);
    let (mx1, my1) = project(b[2], b[1]);
    let t = |m: f64| ((m * n as f64).floor().max(0.0) as u64).min(n - 1) as u32;
    (t(mx0), t(my0), t(mx1), t(my1))
}

/// Pixels of the finest level whose longitude/latitude are interpolated (projected sources
/// only): the source CRS is evaluated exactly every `STRIDE` pixels, linearly between. Over
/// 16 pixels of a 512-pixel tile at zoom 0 (the largest step in degrees) the error of a
/// transverse Mercator is far below a source pixel.
const STRIDE: usize = 16;

/// The finest level, resampled from the source (bilinear; nodata kept), `progress` called
/// with the fraction of rows done.
pub(crate) fn finest_level(
    src: &Source,
    zoom: u8,
    dim: u32,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Level> {
    let (x0, y0, x1, y1) = tile_range(src.bounds, zoom);
    let (ntx, nty) = (x1 - x0 + 1, y1 - y0 + 1);
    let d = dim as usize;
    let w = ntx as usize * d;
    let h = nty as usize * d;
    let samples = (w as u64) * (h as u64);
    // The level and the tiles' bytes stay in memory: refuse what would not fit comfortably.
    const MAX_SAMPLES: u64 = 1 << 31;
    if samples > MAX_SAMPLES {
        return Err(Error::limit(format!(
            "zoom {zoom} would be {w} x {h} pixels ({} GB in memory): give a smaller --max-zoom",
            samples * 4 / 1_000_000_000
        )));
    }
    let scale = (1u64 << zoom) as f64 * f64::from(dim);
    let px = |i: usize| (f64::from(x0) * f64::from(dim) + i as f64 + 0.5) / scale;
    let py = |j: usize| (f64::from(y0) * f64::from(dim) + j as f64 + 0.5) / scale;
    let mut data = vec![f32::NAN; w * h];
    let done = std::sync::atomic::AtomicUsize::new(0);
    match src.crs {
        Crs::Geographic => {
            // Separable: a column's longitude and a row's latitude give its pixel coordinate.
            let cols: Vec<f64> = (0..w)
                .map(|i| src.pixel_of_model(unproject(px(i), 0.5).0, 0.0).0)
                .collect();
            data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
                let lat = unproject(0.5, py(j)).1;
                let r = src.pixel_of_model(0.0, lat).1;
                for (out, &c) in row.iter_mut().zip(&cols) {
                    *out = src.sample(c, r);
                }
                let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if n % 256 == 0 {
                    progress(n as f64 / h as f64);
                }
            });
        }
        Crs::Projected { .. } => {
            // Exact pixel coordinates on a grid every STRIDE pixels (and the last pixel).
            let gx: Vec<usize> = (0..w).step_by(STRIDE).chain([w - 1]).collect();
            let gy: Vec<usize> = (0..h).step_by(STRIDE).chain([h - 1]).collect();
            let grid: Vec<Vec<Option<(f64, f64)>>> = gy
                .par_iter()
                .map(|&j| {
                    gx.iter()
                        .map(|&i| {
                            let (lon, lat) = unproject(px(i), py(j));
                            src.pixel_of(lon, lat)
                        })
                        .collect()
                })
                .collect();
            data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
                let gj = (j / STRIDE).min(gy.len() - 2);
                let (ja, jb) = (gy[gj], gy[gj + 1]);
                let ty = if jb > ja {
                    (j - ja) as f64 / (jb - ja) as f64
                } else {
                    0.0
                };
                for (i, out) in row.iter_mut().enumerate() {
                    let gi = (i / STRIDE).min(gx.len() - 2);
                    let (ia, ib) = (gx[gi], gx[gi + 1]);
                    let tx = if ib > ia {
                        (i - ia) as f64 / (ib - ia) as f64
                    } else {
                        0.0
                    };
                    let corners = [
                        grid[gj][gi],
                        grid[gj][gi + 1],
                        grid[gj + 1][gi],
                        grid[gj + 1][gi + 1],
                    ];
                    let p = match corners {
                        [Some(a), Some(b), Some(c), Some(e)] => {
                            let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
                            Some((
                                lerp(lerp(a.0, b.0, tx), lerp(c.0, e.0, tx), ty),
                                lerp(lerp(a.1, b.1, tx), lerp(c.1, e.1, tx), ty),
                            ))
                        }
                        _ => {
                            let (lon, lat) = unproject(px(i), py(j));
                            src.pixel_of(lon, lat)
                        }
                    };
                    if let Some((c, r)) = p {
                        *out = src.sample(c, r);
                    }
                }
                let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if n % 256 == 0 {
                    progress(n as f64 / h as f64);
                }
            });
        }
    }
    Ok(Level {
        zoom,
        dim: d,
        tx0: x0,
        ty0: y0,
        ntx,
        nty,
        data,
    })
}

/// The default finest zoom: the first whose pixels are no larger than the source's (at the
/// data's centre latitude).
pub(crate) fn default_max_zoom(src: &Source, dim: u32) -> u8 {
    let lat = 0.5 * (src.bounds[1] + src.bounds[3]);
    let ratio = ground_resolution(0, dim, lat) / src.pixel_metres.max(1e-9);
    (ratio.log2().ceil().max(0.0) as u8).min(MAX_ZOOM)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mercator_round_trip_and_known_points() {
        for &(lon, lat) in &[(0.0, 0.0), (-159.5, 22.1), (13.5, 45.5), (179.9, -60.0)] {
            let (mx, my) = project(lon, lat);
            let (lo, la) = unproject(mx, my);
            assert!(
                (lo - lon).abs() < 1e-9 && (la - lat).abs() < 1e-9,
                "{lon},{lat}"
            );
        }
        assert_eq!(project(0.0, 0.0), (0.5, 0.5));
        let (_, top) = project(0.0, MAX_LATITUDE);
        assert!(top.abs() < 1e-9, "{top}");
        // 156543.03 m per pixel at zoom 0 for 256-pixel tiles at the equator.
        assert!((ground_resolution(0, 256, 0.0) - 156_543.033_928).abs() < 1e-3);
        assert!((ground_resolution(1, 512, 60.0) - 156_543.033_928 / 4.0 * 0.5).abs() < 1e-3);
    }

    #[test]
    fn coarser_level_is_the_mean_of_valid_children() {
        // Two tiles of 2 pixels at zoom 3 starting at odd x: the parent range covers both.
        let l = Level {
            zoom: 3,
            dim: 2,
            tx0: 1,
            ty0: 2,
            ntx: 2,
            nty: 1,
            data: vec![1.0, 3.0, 5.0, f32::NAN, 2.0, 4.0, 6.0, 8.0],
        };
        let c = l.coarser();
        assert_eq!((c.zoom, c.tx0, c.ty0, c.ntx, c.nty), (2, 0, 1, 2, 1));
        // Parent tile 0 holds child tile 1 (x = 1) in its right half: pixels (1,0),(1,1).
        let t0 = c.tile(0, 1);
        assert!(t0[0].is_nan() && t0[2].is_nan());
        assert_eq!(t0[1], (1.0 + 3.0 + 2.0 + 4.0) / 4.0);
        assert!(t0[3].is_nan());
        let t1 = c.tile(1, 1);
        assert_eq!(t1[0], (5.0 + 6.0 + 8.0) / 3.0);
        assert!(t1[1].is_nan() && t1[2].is_nan() && t1[3].is_nan());
    }
}
