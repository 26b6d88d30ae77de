//! One Cesium terrain tile from a geographic raster: the TMS geographic tiling scheme, edges
//! simplified the same way from both sides, interior vertices refined until every raster
//! sample in the tile is within the level's bound of the mesh Cesium will draw.
//!
//! Coordinates are global integers per zoom: `gx = x · 32767 + u`, `gy = y · 32767 + v`, so
//! the east edge of one tile and the west edge of the next are the same numbers, and every
//! longitude, latitude and height along a shared edge is computed from the same inputs in
//! both tiles (bit-identical vertices, no cracks).

use super::qmesh::{QuantizedTile, WaterMask};
use crate::error::{Error, Result};
use crate::geometry::triangulation::Triangulation;
use std::collections::HashMap;

/// Quantized coordinates per tile side.
pub const Q: u64 = 32767;

/// Cesium's geometric error of zoom level `z` in the geographic scheme
/// (`TerrainProvider.getEstimatedLevelZeroGeometricErrorForAHeightmap(WGS84, 65, 2) / 2^z`).
pub fn geometric_error(z: u8) -> f64 {
    6_378_137.0 * 2.0 * std::f64::consts::PI * 0.25 / (65.0 * 2.0) / f64::powi(2.0, z as i32)
}

/// A tile of the TMS geographic scheme: 2 × 1 tiles at zoom 0, x from the antimeridian
/// eastward, y from the south pole northward.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey {
    /// Zoom level.
    pub z: u8,
    /// Column (west → east).
    pub x: u32,
    /// Row (south → north).
    pub y: u32,
}

/// Degrees per quantized unit at zoom `z`.
fn unit(z: u8) -> f64 {
    180.0 / (f64::powi(2.0, z as i32) * Q as f64)
}

/// Longitude of global coordinate `gx` at zoom `z`.
pub fn lon(z: u8, gx: u64) -> f64 {
    -180.0 + gx as f64 * unit(z)
}

/// Latitude of global coordinate `gy` at zoom `z`.
pub fn lat(z: u8, gy: u64) -> f64 {
    -90.0 + gy as f64 * unit(z)
}

impl TileKey {
    /// West, south, east, north in degrees.
    pub fn rect(&self) -> [f64; 4] {
        let (gx, gy) = (self.x as u64 * Q, self.y as u64 * Q);
        [
            lon(self.z, gx),
            lat(self.z, gy),
            lon(self.z, gx + Q),
            lat(self.z, gy + Q),
        ]
    }
}

/// A geographic raster: sample `(col, row)` has its centre at
/// `(lon0 + col · dlon, lat0 − row · dlat)`.
pub struct GeoGrid<'a> {
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Heights, row-major from the north.
    pub data: &'a [f64],
    /// `Some(mask)`: `false` marks nodata.
    pub mask: Option<&'a [bool]>,
    /// Longitude of the centre of sample (0, 0).
    pub lon0: f64,
    /// Latitude of the centre of sample (0, 0).
    pub lat0: f64,
    /// Degrees per column (positive).
    pub dlon: f64,
    /// Degrees per row (positive; rows go south).
    pub dlat: f64,
}

impl GeoGrid<'_> {
    fn valid(&self, i: usize) -> bool {
        self.mask.is_none_or(|m| m[i])
    }

    /// Bilinear height at a point: the valid samples of its cell, their weights renormalized;
    /// within half a sample outside the centres, the border samples (their pixels' area);
    /// 0 (sea level) farther out or where all four are nodata.
    pub fn height_at(&self, lon: f64, lat: f64) -> f64 {
        if self.outside(lon, lat) {
            return 0.0;
        }
        self.height_clamped(lon, lat)
    }

    /// Bilinear height at a point with the point clamped onto the sample centres (outside
    /// them, the nearest border samples'); 0 where all four are nodata.
    fn height_clamped(&self, lon: f64, lat: f64) -> f64 {
        let fc = (lon - self.lon0) / self.dlon;
        let fr = (self.lat0 - lat) / self.dlat;
        if !(fc.is_finite() && fr.is_finite()) {
            return 0.0;
        }
        let fc = fc.clamp(0.0, (self.width - 1) as f64);
        let fr = fr.clamp(0.0, (self.height - 1) as f64);
        let c0 = (fc.max(0.0).floor() as usize).min(self.width.saturating_sub(2));
        let r0 = (fr.max(0.0).floor() as usize).min(self.height.saturating_sub(2));
        let tx = (fc - c0 as f64).clamp(0.0, 1.0);
        let ty = (fr - r0 as f64).clamp(0.0, 1.0);
        let (mut sum, mut wsum) = (0.0, 0.0);
        for (dc, dr, w) in [
            (0, 0, (1.0 - tx) * (1.0 - ty)),
            (1, 0, tx * (1.0 - ty)),
            (0, 1, (1.0 - tx) * ty),
            (1, 1, tx * ty),
        ] {
            let (c, r) = (c0 + dc, r0 + dr);
            if c >= self.width || r >= self.height || w == 0.0 {
                continue;
            }
            let i = r * self.width + c;
            if self.valid(i) {
                sum += w * self.data[i];
                wsum += w;
            }
        }
        if wsum > 0.0 { sum / wsum } else { 0.0 }
    }

    /// Whether a point is more than half a sample outside the sample centres (where
    /// [`GeoGrid::height_at`] gives 0).
    pub fn outside(&self, lon: f64, lat: f64) -> bool {
        let fc = (lon - self.lon0) / self.dlon;
        let fr = (self.lat0 - lat) / self.dlat;
        !(fc >= -0.5
            && fr >= -0.5
            && fc <= (self.width - 1) as f64 + 0.5
            && fr <= (self.height - 1) as f64 + 0.5)
    }

    fn col_lon(&self, c: usize) -> f64 {
        self.lon0 + c as f64 * self.dlon
    }

    fn row_lat(&self, r: usize) -> f64 {
        self.lat0 - r as f64 * self.dlat
    }

    /// Columns whose centres lie in `[w, e]` and rows whose centres lie in `[s, n]`
    /// (inclusive ranges; empty when the raster misses the rectangle).
    fn samples_in(&self, [w, s, e, n]: [f64; 4]) -> Option<(usize, usize, usize, usize)> {
        let eps = 1e-9;
        let c_lo = ((w - self.lon0) / self.dlon - eps).ceil().max(0.0);
        let c_hi = ((e - self.lon0) / self.dlon + eps)
            .floor()
            .min((self.width - 1) as f64);
        let r_lo = ((self.lat0 - n) / self.dlat - eps).ceil().max(0.0);
        let r_hi = ((self.lat0 - s) / self.dlat + eps)
            .floor()
            .min((self.height - 1) as f64);
        (c_lo <= c_hi && r_lo <= r_hi).then_some((
            c_lo as usize,
            c_hi as usize,
            r_lo as usize,
            r_hi as usize,
        ))
    }

    /// Longitude and latitude extent of the sample centres: west, south, east, north.
    pub fn extent(&self) -> [f64; 4] {
        [
            self.lon0,
            self.lat0 - (self.height - 1) as f64 * self.dlat,
            self.lon0 + (self.width - 1) as f64 * self.dlon,
            self.lat0,
        ]
    }

    /// Degrees per sample, the larger of the two directions.
    pub fn spacing(&self) -> f64 {
        self.dlon.max(self.dlat)
    }
}

/// Where the raster's surface ends at one zoom, in global quantized coordinates: the
/// outermost positions that carry the raster's border heights (`west..=east`,
/// `south..=north`); the next position outward is sea level, so the data ends in a cliff one
/// quantized unit wide. Each border position is the outermost one within half a sample of
/// the outer sample centres (the border pixels' area), or the first one beyond those centres
/// when half a sample holds no position, so every sample lies on or inside it and no sample
/// is ever measured against the cliff's slope. A function of the raster and the zoom alone,
/// so every tile agrees on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Land {
    /// Zoom.
    pub z: u8,
    /// Westernmost global `gx` with the raster's heights.
    pub west: i64,
    /// Easternmost global `gx` with the raster's heights.
    pub east: i64,
    /// Southernmost global `gy` with the raster's heights.
    pub south: i64,
    /// Northernmost global `gy` with the raster's heights.
    pub north: i64,
}

impl Land {
    /// The raster's extent at zoom `z`.
    pub fn of(grid: &GeoGrid, z: u8) -> Land {
        let u = unit(z);
        // A coordinate within a millionth of a unit of a position is that position (sample
        // centres on tile edges, e.g. whole degrees, must not fall a unit either side).
        let snap = |x: f64| {
            if (x - x.round()).abs() < 1e-6 {
                x.round()
            } else {
                x
            }
        };
        let [w, s, e, n] = grid.extent();
        let (bx, by) = (grid.dlon / 2.0 / u, grid.dlat / 2.0 / u);
        let (sw, se) = ((w + 180.0) / u, (e + 180.0) / u);
        let (ss, sn) = ((s + 90.0) / u, (n + 90.0) / u);
        Land {
            z,
            west: snap(sw - bx).ceil().min(snap(sw).floor()) as i64,
            east: snap(se + bx).floor().max(snap(se).ceil()) as i64,
            south: snap(ss - by).ceil().min(snap(ss).floor()) as i64,
            north: snap(sn + by).floor().max(snap(sn).ceil()) as i64,
        }
    }

    /// Whether global position `(gx, gy)` carries the raster's heights (else sea level).
    pub fn contains(&self, gx: i64, gy: i64) -> bool {
        (self.west..=self.east).contains(&gx) && (self.south..=self.north).contains(&gy)
    }

    /// The height of the surface the tiles approximate at global position `(gx, gy)`: the
    /// raster's bilinear height (clamped onto its border samples up to the border
    /// positions), sea level (0) beyond them.
    pub fn height(&self, grid: &GeoGrid, gx: i64, gy: i64) -> f64 {
        if !self.contains(gx, gy) {
            return 0.0;
        }
        let u = unit(self.z);
        grid.height_clamped(-180.0 + gx as f64 * u, -90.0 + gy as f64 * u)
    }
}

/// The height lattice of a pyramid: one range for every tile, so a height on a shared edge
/// gets the same code on both sides. Header heights are float32: the range is taken from
/// float32 values that contain the data.
#[derive(Clone, Copy, Debug)]
pub struct Heights {
    /// Height of code 0.
    pub min: f64,
    /// Height of code 32767.
    pub max: f64,
}

impl Heights {
    /// The lattice covering `[lo, hi]` (and 0, the height outside the raster).
    pub fn covering(lo: f64, hi: f64) -> Heights {
        let (lo, hi) = (lo.min(0.0), hi.max(0.0));
        let mut min = lo as f32;
        if min as f64 > lo {
            min = f32::from_bits(if min > 0.0 {
                min.to_bits() - 1
            } else {
                min.to_bits() + 1
            });
            if min == 0.0 {
                min = -f32::MIN_POSITIVE;
            }
        }
        let mut max = hi as f32;
        if (max as f64) < hi || max <= min {
            max = (hi.max(min as f64 + 1.0) as f32).max(min + 1.0);
            while (max as f64) < hi {
                max = f32::from_bits(max.to_bits() + 1);
            }
        }
        Heights {
            min: min as f64,
            max: max as f64,
        }
    }

    /// The height step between codes.
    pub fn step(&self) -> f64 {
        (self.max - self.min) / Q as f64
    }

    /// The nearest code.
    pub fn code(&self, h: f64) -> u16 {
        (((h - self.min) / (self.max - self.min) * Q as f64).round()).clamp(0.0, Q as f64) as u16
    }

    /// The height a decoder gives code `c` (Cesium: `lerp(min, max, c / 32767)`).
    pub fn height(&self, c: u16) -> f64 {
        self.min + (self.max - self.min) * (c as f64 / Q as f64)
    }
}

/// What a tile is asked for.
pub struct TileParams<'a> {
    /// The largest error allowed at any raster sample in the tile.
    pub target: f64,
    /// The height lattice.
    pub heights: Heights,
    /// Interior vertices to start from: raster samples (col, row), most important first.
    pub seeds: &'a [(usize, usize)],
    /// Add the oct-encoded normals extension.
    pub normals: bool,
    /// Water per sample (`true` = sea), for the water mask extension.
    pub water: Option<&'a [bool]>,
}

/// What building a tile measured.
#[derive(Clone, Debug, Default)]
pub struct TileStats {
    /// Vertices in the tile.
    pub vertices: usize,
    /// Triangles in the tile.
    pub triangles: usize,
    /// Interior vertices from the seeds.
    pub seeded: usize,
    /// Interior vertices the refinement added.
    pub added: usize,
    /// Valid raster samples in the tile (a sample on an edge counts in both tiles).
    pub samples: usize,
    /// Largest |mesh − sample| over them, with the heights Cesium decodes.
    pub max_error: f64,
    /// Sum of squared errors over them.
    pub sum_sq: f64,
    /// Samples left above the target because no vertex could be added for them (their
    /// quantized position is taken).
    pub over: usize,
}

/// A vertex of a tile under construction.
#[derive(Clone, Copy)]
struct V {
    u: u16,
    v: u16,
    h: u16,
}

/// The vertices of one tile edge: positions along it (0..=32767) and height codes, the
/// profile simplified (Douglas–Peucker) until the raster samples it crosses, and the
/// raster's border where it crosses it, are within `target`. A function of the edge alone,
/// so both tiles sharing it get the same vertices. `vertical`: an edge at fixed global
/// `gx = fixed` from `gy = start`; otherwise at fixed `gy = fixed` from `gx = start`.
#[allow(clippy::too_many_arguments)]
fn edge(
    grid: &GeoGrid,
    land: &Land,
    fixed: u64,
    start: u64,
    vertical: bool,
    target: f64,
    hs: &Heights,
) -> Vec<(u16, u16)> {
    let z = land.z;
    let at = |k: u64| -> (i64, i64) {
        if vertical {
            (fixed as i64, (start + k) as i64)
        } else {
            ((start + k) as i64, fixed as i64)
        }
    };
    let code_at = |k: u64| {
        let (gx, gy) = at(k);
        hs.code(land.height(grid, gx, gy))
    };
    // Where the edge crosses sample rows (vertical) or columns: position t in units and the
    // raster's height there, if the crossing has valid data. An edge between the outer
    // sample centres and the raster's border positions runs along the border samples.
    let mut cross: Vec<(f64, f64)> = Vec::new();
    let u = unit(z);
    let (along_lo, along_hi, on_land) = if vertical {
        (
            land.south,
            land.north,
            (land.west..=land.east).contains(&(fixed as i64)),
        )
    } else {
        (
            land.west,
            land.east,
            (land.south..=land.north).contains(&(fixed as i64)),
        )
    };
    if on_land {
        if vertical {
            let l = lon(z, fixed);
            let fc = ((l - grid.lon0) / grid.dlon).clamp(0.0, (grid.width - 1) as f64);
            let (a, b) = (lat(z, start), lat(z, start + Q));
            if let Some((_, _, r_lo, r_hi)) = grid.samples_in([grid.lon0, a, grid.lon0, b]) {
                for r in r_lo..=r_hi {
                    let la = grid.row_lat(r);
                    if has_data(grid, fc, r as f64) {
                        cross.push(((la - a) / u, grid.height_clamped(l, la)));
                    }
                }
            }
        } else {
            let la = lat(z, fixed);
            let fr = ((grid.lat0 - la) / grid.dlat).clamp(0.0, (grid.height - 1) as f64);
            let (a, b) = (lon(z, start), lon(z, start + Q));
            if let Some((c_lo, c_hi, _, _)) = grid.samples_in([a, grid.lat0, b, grid.lat0]) {
                for c in c_lo..=c_hi {
                    let lo = grid.col_lon(c);
                    if has_data(grid, c as f64, fr) {
                        cross.push(((lo - a) / u, grid.height_clamped(lo, la)));
                    }
                }
            }
        }
        // The cliff where the edge leaves the raster: its last position with the border's
        // height, and sea level one unit beyond.
        for (g, out) in [(along_lo, along_lo - 1), (along_hi, along_hi + 1)] {
            for p in [g, out] {
                let k = p - start as i64;
                if (0..=Q as i64).contains(&k) {
                    let (gx, gy) = at(k as u64);
                    cross.push((k as f64, land.height(grid, gx, gy)));
                }
            }
        }
    }
    // Beyond the raster the surface is sea level: points there, a sample apart (at most 256
    // per edge), keep the edge at 0 up to the data, so the raster's border is a cliff, not
    // a slope across the tile.
    let step = (grid.spacing() / u).max(Q as f64 / 256.0);
    let mut t = 0.0;
    while t <= Q as f64 {
        let k = t.round() as u64;
        let (gx, gy) = at(k);
        if !land.contains(gx, gy) {
            cross.push((k as f64, 0.0));
        }
        t += step;
    }
    cross.sort_by(|p, q| p.0.total_cmp(&q.0));
    let mut chosen: Vec<(u64, u16)> = vec![(0, code_at(0)), (Q, code_at(Q))];
    // Split segments until none is over the target (or too short to split).
    let mut stack = vec![(0usize, 1usize)];
    let mut out: Vec<(u64, u16)> = Vec::new();
    while let Some((i, j)) = stack.pop() {
        let (ka, ca) = chosen[i];
        let (kb, cb) = chosen[j];
        let (ha, hb) = (hs.height(ca), hs.height(cb));
        let lo = cross.partition_point(|p| p.0 <= ka as f64);
        let hi = cross.partition_point(|p| p.0 < kb as f64);
        let mut worst = (target, None);
        for &(t, h) in &cross[lo..hi] {
            let f = (t - ka as f64) / (kb - ka) as f64;
            let e = (ha + (hb - ha) * f - h).abs();
            if e > worst.0 {
                worst = (e, Some(t));
            }
        }
        match worst.1 {
            Some(t) if kb - ka >= 2 => {
                let k = (t.round() as u64).clamp(ka + 1, kb - 1);
                chosen.push((k, code_at(k)));
                let m = chosen.len() - 1;
                // Right half first on the stack so the left is handled first.
                stack.push((m, j));
                stack.push((i, m));
            }
            _ => out.push((ka, ca)),
        }
    }
    out.push((Q, chosen[1].1));
    out.sort_unstable();
    out.dedup_by_key(|p| p.0);
    out.into_iter().map(|(k, c)| (k as u16, c)).collect()
}

/// The corners of the unit cell holding tile position `(su, sv)` that are interior
/// positions (1..=32766 on both axes), without repeats.
fn cell_corners(su: f64, sv: f64) -> Vec<(u16, u16)> {
    let mut out: Vec<(u16, u16)> = Vec::with_capacity(4);
    for a in [su.floor(), su.ceil()] {
        for b in [sv.floor(), sv.ceil()] {
            let inside = |k: f64| k >= 1.0 && k <= (Q - 1) as f64;
            if inside(a) && inside(b) && !out.contains(&(a as u16, b as u16)) {
                out.push((a as u16, b as u16));
            }
        }
    }
    out
}

/// Whether the bilinear cell at fractional (col, row) has a valid sample (on the grid).
fn has_data(grid: &GeoGrid, fc: f64, fr: f64) -> bool {
    let c0 = fc.max(0.0).floor() as usize;
    let r0 = fr.max(0.0).floor() as usize;
    [(0, 0), (1, 0), (0, 1), (1, 1)].iter().any(|&(dc, dr)| {
        let (c, r) = (c0 + dc, r0 + dr);
        let near = (c as f64 - fc).abs() < 1.0 && (r as f64 - fr).abs() < 1.0;
        near && c < grid.width && r < grid.height && grid.valid(r * grid.width + c)
    })
}

/// Build tile `key`: edges, seeds inside it, then refinement until every valid raster sample
/// in the tile is within `p.target` of the mesh (decoded heights), or no vertex can be added.
pub fn build_tile(
    grid: &GeoGrid,
    key: TileKey,
    p: &TileParams,
) -> Result<(QuantizedTile, TileStats)> {
    let z = key.z;
    let (gx0, gy0) = (key.x as u64 * Q, key.y as u64 * Q);
    let hs = &p.heights;
    let land = Land::of(grid, z);
    let mut verts: Vec<V> = Vec::new();
    let mut at: HashMap<(u16, u16), u32> = HashMap::new();
    let mut add = |verts: &mut Vec<V>, v: V| -> bool {
        if at.contains_key(&(v.u, v.v)) {
            return false;
        }
        at.insert((v.u, v.v), verts.len() as u32);
        verts.push(v);
        true
    };
    for (k, h) in edge(grid, &land, gx0, gy0, true, p.target, hs) {
        add(&mut verts, V { u: 0, v: k, h });
    }
    for (k, h) in edge(grid, &land, gx0 + Q, gy0, true, p.target, hs) {
        add(
            &mut verts,
            V {
                u: Q as u16,
                v: k,
                h,
            },
        );
    }
    for (k, h) in edge(grid, &land, gy0, gx0, false, p.target, hs) {
        add(&mut verts, V { u: k, v: 0, h });
    }
    for (k, h) in edge(grid, &land, gy0 + Q, gx0, false, p.target, hs) {
        add(
            &mut verts,
            V {
                u: k,
                v: Q as u16,
                h,
            },
        );
    }
    let mut stats = TileStats::default();
    let rect = key.rect();
    let u = unit(z);
    // Position of a sample in tile units (fractional).
    let pos = |c: usize, r: usize| -> (f64, f64) {
        (
            (grid.col_lon(c) - rect[0]) / u,
            (grid.row_lat(r) - rect[1]) / u,
        )
    };
    let interior = |x: f64| -> Option<u16> {
        let k = x.round();
        (k >= 1.0 && k <= (Q - 1) as f64).then_some(k as u16)
    };
    for &(c, r) in p.seeds {
        let (su, sv) = pos(c, r);
        if let (Some(a), Some(b)) = (interior(su), interior(sv)) {
            let h = hs.code(grid.data[r * grid.width + c]);
            if add(&mut verts, V { u: a, v: b, h }) {
                stats.seeded += 1;
            }
        }
    }
    // The raster's border inside the tile: its last positions with the border samples'
    // heights and, one unit beyond, sea level, a sample apart (at most 256 per tile side):
    // the data ends in a cliff one unit wide that no sample lies on.
    {
        let step = (grid.spacing() / u).max(Q as f64 / 256.0);
        let (x0, y0) = (gx0 as i64, gy0 as i64);
        let interior = |g: i64, o: i64| (1..Q as i64).contains(&(g - o));
        // Global positions lo..=hi along a side, clipped to the tile's interior, a step
        // apart, both ends included.
        let span = |lo: i64, hi: i64, o: i64| -> Vec<i64> {
            let (a, b) = (lo.max(o + 1), hi.min(o + Q as i64 - 1));
            let mut out = Vec::new();
            let mut t = a as f64;
            while t < b as f64 {
                out.push(t.round() as i64);
                t += step;
            }
            if a <= b {
                out.push(b);
            }
            out
        };
        let mut ring: Vec<(i64, i64, bool)> = Vec::new();
        for (d, sea) in [(0i64, false), (1, true)] {
            let (w, e) = (land.west - d, land.east + d);
            let (s, n) = (land.south - d, land.north + d);
            for gx in [w, e] {
                if interior(gx, x0) {
                    ring.extend(span(s, n, y0).into_iter().map(|gy| (gx, gy, sea)));
                }
            }
            for gy in [s, n] {
                if interior(gy, y0) {
                    ring.extend(span(w, e, x0).into_iter().map(|gx| (gx, gy, sea)));
                }
            }
        }
        for (gx, gy, sea) in ring {
            let h = if sea { 0.0 } else { land.height(grid, gx, gy) };
            add(
                &mut verts,
                V {
                    u: (gx - x0) as u16,
                    v: (gy - y0) as u16,
                    h: hs.code(h),
                },
            );
        }
    }
    let range = grid.samples_in(rect);
    let cells: Vec<(usize, usize)> = verts.iter().map(|v| (v.u as usize, v.v as usize)).collect();
    let (mut tri, first) = super::delaunay(&cells)?;
    // The triangulation numbers vertices in insertion order: keep a map back.
    let mut id_of: Vec<u32> = first.iter().map(|&i| i as u32).collect();
    const MAX_ROUNDS: usize = 200;
    for round in 0.. {
        let Some((c_lo, c_hi, r_lo, r_hi)) = range else {
            break;
        };
        let worst = scan(
            grid,
            &tri,
            &id_of,
            &verts,
            hs,
            rect,
            u,
            (c_lo, c_hi, r_lo, r_hi),
            p.target,
        );
        let mut inserted = 0;
        let mut over = 0;
        for (e, c, r) in worst.into_iter().flatten() {
            if e <= p.target {
                continue;
            }
            let (su, sv) = pos(c, r);
            let a = (su.round().clamp(1.0, (Q - 1) as f64)) as u16;
            let b = (sv.round().clamp(1.0, (Q - 1) as f64)) as u16;
            let value = hs.code(grid.data[r * grid.width + c]);
            // A vertex at (a, b) with the sample's value, where that position is free.
            let mut place = |a: u16, b: u16| -> Result<bool> {
                if !add(
                    &mut verts,
                    V {
                        u: a,
                        v: b,
                        h: value,
                    },
                ) {
                    return Ok(false);
                }
                tri.insert_near([a as i64, b as i64], None)?;
                id_of.push((verts.len() - 1) as u32);
                inserted += 1;
                stats.added += 1;
                Ok(true)
            };
            if place(a, b)? {
                continue;
            }
            // Its position is taken: the mesh there is off by the rounding of its position
            // (a peak, a pit or a cliff beside it). The free interior corners of the unit
            // cell around it get its value, so the mesh is flat at its value around it (no
            // other sample lies in that cell unless the zoom's quantized positions are
            // coarser than the raster's posts).
            let mut pinned = false;
            for (a, b) in cell_corners(su, sv) {
                pinned |= place(a, b)?;
            }
            if !pinned {
                over += 1;
            }
        }
        if inserted == 0 || round >= MAX_ROUNDS {
            if std::env::var_os("VTZ_DEBUG_TERRAIN").is_some() && over > 0 {
                eprintln!(
                    "tile {z}/{}/{}: round {round}, inserted {inserted}, over {over}",
                    key.x, key.y
                );
            }
            stats.over = over;
            break;
        }
    }
    // Final measurement: each sample once, every valid sample of the tile.
    if let Some(rg) = range {
        let (n, max, ss, over) = measure(grid, &tri, &id_of, &verts, hs, rect, u, rg, p.target);
        let (c_lo, c_hi, r_lo, r_hi) = rg;
        let valid = (r_lo..=r_hi)
            .map(|r| {
                (c_lo..=c_hi)
                    .filter(|&c| grid.valid(r * grid.width + c))
                    .count()
            })
            .sum::<usize>();
        if n != valid {
            return Err(Error::unmet(format!(
                "terrain tile {z}/{}/{}: {} of its {valid} samples lie in no triangle",
                key.x,
                key.y,
                valid - n
            )));
        }
        stats.samples = n;
        stats.max_error = max;
        stats.sum_sq = ss;
        stats.over = over;
    }
    // Triangles in file order, vertices renumbered by first use (the order high-water-mark
    // coding needs), so the written tile lists them exactly as `QuantizedTile` does.
    let mut tris: Vec<[u32; 3]> = tri
        .real_triangles()
        .map(|t| tri.tri(t).v.map(|k| id_of[k as usize]))
        .collect();
    tris.sort_unstable();
    let mut order = vec![u32::MAX; verts.len()];
    let mut new_verts: Vec<V> = Vec::with_capacity(verts.len());
    for t in tris.iter_mut() {
        for i in t.iter_mut() {
            if order[*i as usize] == u32::MAX {
                order[*i as usize] = new_verts.len() as u32;
                new_verts.push(verts[*i as usize]);
            }
            *i = order[*i as usize];
        }
    }
    if new_verts.len() != verts.len() {
        return Err(Error::invalid("a terrain tile vertex lies in no triangle"));
    }
    stats.vertices = new_verts.len();
    stats.triangles = tris.len();
    let normals = p.normals.then(|| {
        new_verts
            .iter()
            .map(|v| normal(grid, z, gx0 + v.u as u64, gy0 + v.v as u64))
            .collect()
    });
    let water = p.water.map(|w| water_mask(grid, w, rect));
    Ok((
        QuantizedTile {
            rect,
            min_height: hs.min,
            max_height: hs.max,
            vertices: new_verts.iter().map(|v| [v.u, v.v, v.h]).collect(),
            triangles: tris,
            normals,
            water,
        },
        stats,
    ))
}

/// A triangle's plane over tile units: height = a·u + b·v + c, and its vertices.
struct Plane {
    p: [[f64; 2]; 3],
    a: f64,
    b: f64,
    c: f64,
}

fn planes(tri: &Triangulation, id_of: &[u32], verts: &[V], hs: &Heights) -> Vec<Plane> {
    tri.real_triangles()
        .map(|t| {
            let ids = tri.tri(t).v.map(|k| id_of[k as usize] as usize);
            let p = ids.map(|i| [verts[i].u as f64, verts[i].v as f64]);
            let h = ids.map(|i| hs.height(verts[i].h));
            let (x1, y1) = (p[1][0] - p[0][0], p[1][1] - p[0][1]);
            let (x2, y2) = (p[2][0] - p[0][0], p[2][1] - p[0][1]);
            let (z1, z2) = (h[1] - h[0], h[2] - h[0]);
            let det = x1 * y2 - x2 * y1;
            let a = (z1 * y2 - z2 * y1) / det;
            let b = (x1 * z2 - x2 * z1) / det;
            Plane {
                p,
                a,
                b,
                c: h[0] - a * p[0][0] - b * p[0][1],
            }
        })
        .collect()
}

/// Call `f(plane index, col, row, error)` for every valid sample of `rows × cols` inside
/// each triangle (a sample on a shared edge may be visited twice).
#[allow(clippy::too_many_arguments)]
fn each_sample(
    grid: &GeoGrid,
    planes: &[Plane],
    rect: [f64; 4],
    u: f64,
    (c_lo, c_hi, r_lo, r_hi): (usize, usize, usize, usize),
    mut f: impl FnMut(usize, usize, usize, f64),
) {
    let eps = 1e-7;
    for (k, pl) in planes.iter().enumerate() {
        let vmin = pl.p.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min);
        let vmax = pl.p.iter().map(|q| q[1]).fold(f64::NEG_INFINITY, f64::max);
        // Rows whose centre latitude is within [vmin, vmax] (tile units).
        let lat_of = |v: f64| rect[1] + v * u;
        let row_hi = ((grid.lat0 - lat_of(vmin)) / grid.dlat + eps).floor();
        let row_lo = ((grid.lat0 - lat_of(vmax)) / grid.dlat - eps).ceil();
        let row_lo = row_lo.max(r_lo as f64);
        let row_hi = row_hi.min(r_hi as f64);
        if row_lo > row_hi {
            continue;
        }
        for r in row_lo as usize..=row_hi as usize {
            let sv = (grid.row_lat(r) - rect[1]) / u;
            // The triangle's extent along this row.
            let (mut umin, mut umax) = (f64::INFINITY, f64::NEG_INFINITY);
            for e in 0..3 {
                let (p, q) = (pl.p[e], pl.p[(e + 1) % 3]);
                let (lo, hi) = if p[1] <= q[1] { (p, q) } else { (q, p) };
                if sv < lo[1] - eps || sv > hi[1] + eps {
                    continue;
                }
                if (hi[1] - lo[1]).abs() < 1e-12 {
                    umin = umin.min(lo[0].min(hi[0]));
                    umax = umax.max(lo[0].max(hi[0]));
                } else {
                    let t = ((sv - lo[1]) / (hi[1] - lo[1])).clamp(0.0, 1.0);
                    let x = lo[0] + t * (hi[0] - lo[0]);
                    umin = umin.min(x);
                    umax = umax.max(x);
                }
            }
            if umin > umax {
                continue;
            }
            let lon_of = |x: f64| rect[0] + x * u;
            let c0 = (((lon_of(umin) - grid.lon0) / grid.dlon) - eps)
                .ceil()
                .max(c_lo as f64);
            let c1 = (((lon_of(umax) - grid.lon0) / grid.dlon) + eps)
                .floor()
                .min(c_hi as f64);
            if c0 > c1 {
                continue;
            }
            for c in c0 as usize..=c1 as usize {
                let i = r * grid.width + c;
                if !grid.valid(i) {
                    continue;
                }
                let su = (grid.col_lon(c) - rect[0]) / u;
                let e = (pl.a * su + pl.b * sv + pl.c - grid.data[i]).abs();
                f(k, c, r, e);
            }
        }
    }
}

/// Per triangle, its worst sample over `target` (error, col, row).
#[allow(clippy::too_many_arguments)]
fn scan(
    grid: &GeoGrid,
    tri: &Triangulation,
    id_of: &[u32],
    verts: &[V],
    hs: &Heights,
    rect: [f64; 4],
    u: f64,
    range: (usize, usize, usize, usize),
    target: f64,
) -> Vec<Option<(f64, usize, usize)>> {
    let pl = planes(tri, id_of, verts, hs);
    let mut worst: Vec<Option<(f64, usize, usize)>> = vec![None; pl.len()];
    each_sample(grid, &pl, rect, u, range, |k, c, r, e| {
        if e > target && worst[k].is_none_or(|w| e > w.0) {
            worst[k] = Some((e, c, r));
        }
    });
    worst
}

/// Samples measured once each: count, max error, sum of squares, count over `target`.
#[allow(clippy::too_many_arguments)]
fn measure(
    grid: &GeoGrid,
    tri: &Triangulation,
    id_of: &[u32],
    verts: &[V],
    hs: &Heights,
    rect: [f64; 4],
    u: f64,
    range: (usize, usize, usize, usize),
    target: f64,
) -> (usize, f64, f64, usize) {
    let (c_lo, c_hi, r_lo, _) = range;
    let w = c_hi - c_lo + 1;
    let mut err = vec![f64::NAN; w * (range.3 - r_lo + 1)];
    let pl = planes(tri, id_of, verts, hs);
    each_sample(grid, &pl, rect, u, range, |_, c, r, e| {
        let i = (r - r_lo) * w + c - c_lo;
        // On a shared edge both triangles give the same value up to rounding: keep the worse.
        if err[i].is_nan() || e > err[i] {
            err[i] = e;
        }
    });
    let mut n = 0;
    let mut max = 0.0f64;
    let mut ss = 0.0;
    let mut over = 0;
    for (i, &e) in err.iter().enumerate().filter(|e| !e.1.is_nan()) {
        if e > target && std::env::var_os("VTZ_DEBUG_TERRAIN").is_some() {
            let (c, r) = (c_lo + i % w, r_lo + i / w);
            eprintln!("over: sample ({c}, {r}) error {e}");
        }
        n += 1;
        max = max.max(e);
        ss += e * e;
        over += (e > target) as usize;
    }
    (n, max, ss, over)
}

/// The unit normal (ECEF) at a global point: the raster's slope over a step that grows with
/// the tile (coarse levels shade their own relief, not the finest detail). A function of the
/// point and the zoom, so a vertex on a shared edge gets the same normal in both tiles.
fn normal(grid: &GeoGrid, z: u8, gx: u64, gy: u64) -> [f64; 3] {
    let (lo, la) = (lon(z, gx), lat(z, gy));
    let step = (unit(z) * Q as f64 / 64.0).max(grid.spacing());
    let dzdx = (grid.height_at(lo + step, la) - grid.height_at(lo - step, la))
        / (2.0 * step * 111_319.49 * la.to_radians().cos().max(1e-6));
    let dzdy =
        (grid.height_at(lo, la + step) - grid.height_at(lo, la - step)) / (2.0 * step * 110_574.0);
    let (e, n, up) = (-dzdx, -dzdy, 1.0);
    let l = (e * e + n * n + up * up).sqrt();
    let (e, n, up) = (e / l, n / l, up / l);
    let (sl, cl) = la.to_radians().sin_cos();
    let (so, co) = lo.to_radians().sin_cos();
    [
        -so * e - sl * co * n + cl * co * up,
        co * e - sl * so * n + cl * so * up,
        cl * n + sl * up,
    ]
}

/// The 256 × 256 water mask of a tile (north row first): a cell is water when the sample
/// nearest its centre is.
fn water_mask(grid: &GeoGrid, water: &[bool], [w, s, e, n]: [f64; 4]) -> WaterMask {
    let mut g = vec![0u8; 256 * 256];
    for i in 0..256 {
        let la = n - (i as f64 + 0.5) / 256.0 * (n - s);
        let fr = ((grid.lat0 - la) / grid.dlat).round();
        if fr < 0.0 || fr > (grid.height - 1) as f64 {
            continue;
        }
        for j in 0..256 {
            let lo = w + (j as f64 + 0.5) / 256.0 * (e - w);
            let fc = ((lo - grid.lon0) / grid.dlon).round();
            if fc < 0.0 || fc > (grid.width - 1) as f64 {
                continue;
            }
            if water[fr as usize * grid.width + fc as usize] {
                g[i * 256 + j] = 255;
            }
        }
    }
    if g.iter().all(|&b| b == g[0]) {
        WaterMask::Uniform(g[0])
    } else {
        WaterMask::Grid(g)
    }
}

/// Water per sample: the flat regions at or below sea level, read as sea: a valid sample
/// at most 0 whose eight neighbours (inside the raster) are valid and equal to it. Dry land
/// below sea level is rarely perfectly flat; SRTM and most DEMs set the sea to one value.
pub fn water(grid: &GeoGrid) -> Vec<bool> {
    let (w, h) = (grid.width, grid.height);
    let mut out = vec![false; w * h];
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            if !grid.valid(i) || grid.data[i] > 0.0 {
                continue;
            }
            let v = grid.data[i];
            let mut flat = true;
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                    if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                        continue;
                    }
                    let j = rr as usize * w + cc as usize;
                    if !grid.valid(j) || grid.data[j] != v {
                        flat = false;
                    }
                }
            }
            out[i] = flat;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(data: &[f64], w: usize, h: usize) -> GeoGrid<'_> {
        GeoGrid {
            width: w,
            height: h,
            data,
            mask: None,
            lon0: 10.0,
            lat0: 1.0,
            dlon: 1.0 / (w - 1) as f64,
            dlat: 1.0 / (h - 1) as f64,
        }
    }

    fn bumpy(w: usize, h: usize) -> Vec<f64> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                200.0 * (x / 7.0).sin() * (y / 5.0).cos() + 3.0 * x
            })
            .collect()
    }

    #[test]
    fn geometric_error_is_cesiums() {
        // Cesium's level-0 error for the geographic scheme, 77 067.34 m, halves per level.
        assert!((geometric_error(0) - 77_067.34).abs() < 0.01);
        assert!((geometric_error(3) * 8.0 - geometric_error(0)).abs() < 1e-9);
    }

    #[test]
    fn shared_edges_are_identical_and_every_sample_is_within_the_target() {
        let (w, h) = (121, 121);
        let data = bumpy(w, h);
        let g = grid(&data, w, h);
        let hs = Heights::covering(-300.0, 600.0);
        let z = 8; // tiles of 0.703°: the 1° raster meets a 3 × 3 block of them
        let target = 5.0;
        let p = TileParams {
            target,
            heights: hs,
            seeds: &[],
            normals: true,
            water: None,
        };
        let x0 = ((10.0 + 180.0) / (180.0 / 256.0)) as u32;
        let y0 = ((0.0 + 90.0) / (180.0 / 256.0)) as u32;
        let a = build_tile(&g, TileKey { z, x: x0, y: y0 }, &p).unwrap();
        let b = build_tile(
            &g,
            TileKey {
                z,
                x: x0 + 1,
                y: y0,
            },
            &p,
        )
        .unwrap();
        let c = build_tile(
            &g,
            TileKey {
                z,
                x: x0,
                y: y0 + 1,
            },
            &p,
        )
        .unwrap();
        for (t, s) in [&a, &b, &c] {
            assert!(s.samples > 0);
            assert!(
                s.max_error <= target,
                "max error {} > {target}",
                s.max_error
            );
            assert_eq!(s.over, 0);
            assert!(t.vertices.len() < 5000);
        }
        let edge = |t: &QuantizedTile, f: &dyn Fn(&[u16; 3]) -> bool, along: usize| {
            let mut e: Vec<(u16, u16)> = t
                .vertices
                .iter()
                .filter(|v| f(v))
                .map(|v| (v[along], v[2]))
                .collect();
            e.sort_unstable();
            e
        };
        let ae = edge(&a.0, &|v| v[0] == 32767, 1);
        assert!(ae.len() > 2);
        assert_eq!(ae, edge(&b.0, &|v| v[0] == 0, 1));
        assert_eq!(
            edge(&a.0, &|v| v[1] == 32767, 0),
            edge(&c.0, &|v| v[1] == 0, 0)
        );
        // Normals on the shared edge agree too.
        let na: Vec<_> =
            a.0.vertices
                .iter()
                .zip(a.0.normals.as_ref().unwrap())
                .filter(|(v, _)| v[0] == 32767)
                .map(|(v, n)| (v[1], n.map(f64::to_bits)))
                .collect();
        let mut na = na;
        na.sort_unstable();
        let mut nb: Vec<_> =
            b.0.vertices
                .iter()
                .zip(b.0.normals.as_ref().unwrap())
                .filter(|(v, _)| v[0] == 0)
                .map(|(v, n)| (v[1], n.map(f64::to_bits)))
                .collect();
        nb.sort_unstable();
        assert_eq!(na, nb);
        // And the tile encodes.
        assert!(a.0.encode().unwrap().len() > 88);
    }

    #[test]
    fn the_bound_holds_at_a_raster_border_far_from_sea_level() {
        // 3″ posts (155 quantized units at zoom 10) 4000 m above or below the sea level
        // outside the raster: its border is a 4 km cliff beside the outer posts. Borders
        // inside the tile, a row 0.3 units inside the tile's south edge, a column on the
        // tile's west edge, a column 0.4 units inside it.
        let (w, h) = (121, 121);
        let key = TileKey {
            z: 10,
            x: 1200,
            y: 600,
        };
        let rect = key.rect();
        let u = unit(key.z);
        let d = 1.0 / 1200.0;
        for offset in [4000.0, -4000.0] {
            let data: Vec<f64> = bumpy(w, h).iter().map(|v| 0.5 * v + offset).collect();
            let lo = data.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = data.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            for (lon0, south) in [
                (rect[0] + 10.37 * d, rect[1] + 0.3 * u),
                (rect[0], rect[1] + 7.61 * d),
                (rect[0] + 0.4 * u, rect[1] + 5.0 * d + 0.6 * u),
            ] {
                let g = GeoGrid {
                    width: w,
                    height: h,
                    data: &data,
                    mask: None,
                    lon0,
                    lat0: south + (h - 1) as f64 * d,
                    dlon: d,
                    dlat: d,
                };
                let p = TileParams {
                    target: 1.0,
                    heights: Heights::covering(lo, hi),
                    seeds: &[],
                    normals: false,
                    water: None,
                };
                let (_, s) = build_tile(&g, key, &p).unwrap();
                assert_eq!(s.samples, w * h, "every post lies in the tile");
                assert!(
                    s.max_error <= 1.0 && s.over == 0,
                    "offset {offset}, west {lon0}, south {south}: {s:?}"
                );
            }
        }
    }

    #[test]
    fn a_looser_target_needs_fewer_vertices() {
        let (w, h) = (121, 121);
        let data = bumpy(w, h);
        let g = grid(&data, w, h);
        let key = TileKey {
            z: 7,
            x: 135,
            y: 64,
        };
        let n = |target| {
            let p = TileParams {
                target,
                heights: Heights::covering(-300.0, 600.0),
                seeds: &[],
                normals: false,
                water: None,
            };
            let (_, s) = build_tile(&g, key, &p).unwrap();
            assert!(s.max_error <= target, "{s:?}");
            s.vertices
        };
        assert!(n(50.0) < n(5.0));
    }

    #[test]
    fn the_height_lattice_holds_its_range_in_float32() {
        let hs = Heights::covering(-34.0, 1579.0);
        assert!(hs.min <= -34.0 && hs.max >= 1579.0);
        assert_eq!(hs.min, hs.min as f32 as f64);
        assert_eq!(hs.max, hs.max as f32 as f64);
        assert_eq!(hs.code(hs.min), 0);
        assert_eq!(hs.code(hs.max), 32767);
        let hs = Heights::covering(5.0, 5.0);
        assert!(hs.max > hs.min && hs.min <= 0.0 && hs.max >= 5.0);
    }

    #[test]
    fn flat_sea_is_water_and_land_is_not() {
        let (w, h) = (10, 10);
        let data: Vec<f64> = (0..100)
            .map(|i| if i % 10 < 5 { 0.0 } else { 50.0 + i as f64 })
            .collect();
        let g = grid(&data, w, h);
        let wt = water(&g);
        assert!(wt[2 * 10 + 2]);
        assert!(!wt[2 * 10 + 4]); // next to land
        assert!(!wt[2 * 10 + 7]);
    }
}
