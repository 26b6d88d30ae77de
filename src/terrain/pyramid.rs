//! Cesium terrain pyramids (`vtz tiles`): a geographic raster as quantized-mesh-1.0 tiles
//! in the TMS geographic scheme with `layer.json`. One greedy Sibson selection at the
//! finest bound orders the sites; each zoom starts from the prefix of sites whose surface met
//! that zoom's bound (the progressive levels are the levels of detail), then each tile is
//! refined until every raster sample in it is within the bound of the mesh Cesium draws.

use crate::error::{Error, Result};
use crate::mesh::terrain::{self, GeoGrid, Heights, TileKey, TileParams, TileStats};
use crate::methods::sites::{Norm, Samples, SelectParams, select_sites};
use crate::model::Raster;
use crate::quant::ErrorBound;
use rayon::prelude::*;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Deepest zoom `vtz tiles` writes (tiles of 0.00004°, about 5 m).
pub const MAX_ZOOM: u8 = 22;

/// What `vtz tiles` asks for.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct TerrainRequest {
    /// The bound at the finest zoom (default 1 % of the value range); coarser zooms use
    /// Cesium's geometric error of the level when it is larger.
    pub max_error: Option<ErrorBound>,
    /// The finest zoom (default: the first whose tiles span at most 256 samples).
    pub max_zoom: Option<u8>,
    /// Add the oct-encoded vertex normals extension.
    pub normals: bool,
    /// Add the water mask extension (flat regions at or below sea level).
    pub water_mask: bool,
    /// Gzip each tile (the server must then send `Content-Encoding: gzip`).
    pub gzip: bool,
    /// Beside each tile, `{z}/{x}/{y}.json` with the vertices (u, v, height codes) and
    /// triangles it holds, in file order: for checking the tiles with another decoder.
    pub expected_json: bool,
}

impl Default for TerrainRequest {
    fn default() -> Self {
        TerrainRequest {
            max_error: None,
            max_zoom: None,
            normals: true,
            water_mask: true,
            gzip: false,
            expected_json: false,
        }
    }
}

/// One zoom level of a written pyramid.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct TerrainLevel {
    /// Zoom.
    pub zoom: u8,
    /// Tiles written.
    pub tiles: usize,
    /// Cesium's geometric error of the level (metres).
    pub geometric_error: f64,
    /// The bound every raster sample meets at this level (checked: a level that misses it
    /// fails the whole pyramid).
    pub target: f64,
    /// Greedy sites in the level's prefix.
    pub sites: usize,
    /// Vertices over all tiles (edge vertices once per tile).
    pub vertices: usize,
    /// Triangles over all tiles.
    pub triangles: usize,
    /// Vertices the per-tile refinement added to the prefix and edges.
    pub added: usize,
    /// Valid samples measured (a sample on a tile edge counts in each tile).
    pub samples: usize,
    /// Largest |mesh − sample| over every valid sample in the level's tiles, measured on the
    /// mesh a decoder reconstructs (quantized positions and height codes, edges included).
    pub max_error: f64,
    /// Root mean square error.
    pub rmse: f64,
    /// Samples farther than the target from the decoded mesh: always 0 in a written pyramid
    /// ([`write_terrain`] fails with [`Error::Unmet`] instead).
    pub over: usize,
    /// Bytes of the level's tiles.
    pub bytes: u64,
}

/// What `vtz tiles` wrote.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct TerrainReport {
    /// The finest bound in data units.
    pub bound: f64,
    /// Height of one quantized-mesh height code (the lattice shared by every tile).
    pub height_step: f64,
    /// Extent of the sample centres: west, south, east, north (degrees).
    pub bounds: [f64; 4],
    /// Greedy sites selected at the finest bound.
    pub sites: usize,
    /// Per zoom, coarse to fine.
    pub levels: Vec<TerrainLevel>,
}

impl TerrainReport {
    /// Tiles written.
    pub fn tiles(&self) -> usize {
        self.levels.iter().map(|l| l.tiles).sum()
    }

    /// Bytes of all tiles.
    pub fn bytes(&self) -> u64 {
        self.levels.iter().map(|l| l.bytes).sum()
    }
}

/// The raster's grid in longitude/latitude, or a clear error when it is not geographic.
fn geo_grid(r: &Raster) -> Result<GeoGrid<'_>> {
    let g = r.georef.as_ref().ok_or_else(|| {
        Error::unsupported(
            "terrain tiles need a georeferenced raster in geographic coordinates (EPSG:4326); \
             this one has no georeferencing",
        )
    })?;
    if g.epsg != Some(4326) {
        let crs = g
            .epsg
            .map_or_else(|| "an unknown CRS".to_string(), |e| format!("EPSG:{e}"));
        return Err(Error::unsupported(format!(
            "terrain tiles need geographic coordinates (EPSG:4326); this raster is in {crs} \
             (reproject it first, e.g. gdalwarp -t_srs EPSG:4326)"
        )));
    }
    if !(g.pixel_size[0] > 0.0 && g.pixel_size[1] > 0.0) {
        return Err(Error::unsupported(
            "terrain tiles need a north-up raster (positive pixel sizes)",
        ));
    }
    if r.width < 2 || r.height < 2 {
        return Err(Error::invalid("terrain tiles need at least 2 × 2 samples"));
    }
    let [lon0, lat0] = g.sample_centre(0.0, 0.0);
    let grid = GeoGrid {
        width: r.width,
        height: r.height,
        data: &r.data,
        mask: r.mask.as_deref(),
        lon0,
        lat0,
        dlon: g.pixel_size[0],
        dlat: g.pixel_size[1],
    };
    let [w, s, e, n] = grid.extent();
    if !(w >= -180.0 - 1e-9 && e <= 180.0 + 1e-9 && s >= -90.0 - 1e-9 && n <= 90.0 + 1e-9) {
        return Err(Error::unsupported(format!(
            "sample centres span longitude {w}..{e}, latitude {s}..{n}: outside -180..180, -90..90"
        )));
    }
    Ok(grid)
}

/// A tile ready to write: its key, bytes, expected-values JSON and statistics.
type Built = (TileKey, Vec<u8>, Option<String>, TileStats);

/// The tiles of zoom `z` the extent meets (both tiles at zoom 0, which Cesium always needs).
fn tiles_of(z: u8, [w, s, e, n]: [f64; 4]) -> Vec<TileKey> {
    let tw = 180.0 / f64::powi(2.0, z as i32);
    let (nx, ny) = (2u64 << z, 1u64 << z);
    let idx = |v: f64, origin: f64, count: u64| {
        (((v - origin) / tw).floor().max(0.0) as u64).min(count - 1)
    };
    let (x0, x1, y0, y1) = if z == 0 {
        (0, 1, 0, 0)
    } else {
        (
            idx(w, -180.0, nx),
            idx(e, -180.0, nx),
            idx(s, -90.0, ny),
            idx(n, -90.0, ny),
        )
    };
    let mut out = Vec::new();
    for y in y0..=y1 {
        for x in x0..=x1 {
            out.push(TileKey {
                z,
                x: x as u32,
                y: y as u32,
            });
        }
    }
    out
}

/// The default finest zoom: the first whose tiles span at most 256 samples.
pub fn default_max_zoom(r: &Raster) -> Result<u8> {
    let g = geo_grid(r)?;
    let mut z = 0u8;
    while z < MAX_ZOOM && 180.0 / f64::powi(2.0, z as i32) / g.spacing() > 256.0 {
        z += 1;
    }
    Ok(z)
}

/// Write the pyramid of `raster` into `dir` (`layer.json`, `{z}/{x}/{y}.terrain`): built in a
/// temporary directory beside it, renamed at the end. An existing `dir` is replaced only
/// with `force` and only when it holds a `layer.json` (a previous pyramid).
///
/// Every valid sample of every zoom is measured against the mesh a decoder reconstructs
/// (quantized positions and heights, tile edges and the raster's border included); a zoom
/// where one is farther than its bound fails with [`Error::Unmet`] and nothing is written.
pub fn write_terrain(
    raster: &Raster,
    req: &TerrainRequest,
    dir: &Path,
    force: bool,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<TerrainReport> {
    let grid = geo_grid(raster)?;
    if dir.exists() {
        if !force {
            return Err(Error::invalid(format!(
                "{} exists (use --force to replace it)",
                dir.display()
            )));
        }
        if !dir.join("layer.json").is_file() {
            return Err(Error::invalid(format!(
                "{} exists and is not a terrain pyramid (no layer.json): not replacing it",
                dir.display()
            )));
        }
    }
    let max_zoom = match req.max_zoom {
        Some(z) if z > MAX_ZOOM => {
            return Err(Error::invalid(format!(
                "--max-zoom {z} is deeper than {MAX_ZOOM}"
            )));
        }
        Some(z) => z,
        None => default_max_zoom(raster)?,
    };
    let range = raster
        .valid_range()
        .ok_or_else(|| Error::invalid("the raster has no valid sample"))?;
    let requested = req.max_error.unwrap_or(ErrorBound::PercentOfRange(1.0));
    let mut bound = requested.absolute(Some(range));
    let heights = Heights::covering(range.0, range.1);
    if range.0 == range.1 {
        // One height everywhere: any bound is met by a flat tile (within half a height
        // step of the one value), whatever a percent of the range 0 makes of the request.
        bound = bound.max(heights.step());
    }
    if !(bound.is_finite() && bound >= heights.step()) {
        let what = match req.max_error {
            Some(_) => format!("--max-error {bound}"),
            None => format!("the default bound (1 % of the range: {bound})"),
        };
        return Err(Error::invalid(format!(
            "{what} is finer than a quantized-mesh height step ({:.4}: the height \
             range {}..{} in 32767 steps)",
            heights.step(),
            heights.min,
            heights.max
        )));
    }
    // The sites in importance order, each with the error it was picked for.
    let valid = |i: usize| raster.is_valid(i);
    let samples = Samples {
        width: raster.width,
        height: raster.height,
        values: &raster.data,
        valid: &valid,
    };
    let sp = SelectParams {
        max_error: Some(bound),
        rmse: None,
        max_sites: None,
        norm: Norm::Linf,
        step: (bound / 8.0).max((range.1 - range.0) * 1e-9),
        offset: 0.0,
    };
    let sel = select_sites(&samples, &sp, &mut |f| progress(0.4 * f))?;
    // suffix[i]: the largest error among sites hull+i.. (non-increasing).
    let mut suffix = vec![0f32; sel.errors.len()];
    let mut m = 0f32;
    for i in (0..sel.errors.len()).rev() {
        m = m.max(sel.errors[i]);
        suffix[i] = m;
    }
    let sites: Vec<(usize, usize)> = sel
        .sites
        .iter()
        .map(|&(i, _)| (i as usize % raster.width, i as usize / raster.width))
        .collect();
    let water = req.water_mask.then(|| terrain::water(&grid));
    let extent = grid.extent();
    let zooms: Vec<(u8, Vec<TileKey>)> = (0..=max_zoom).map(|z| (z, tiles_of(z, extent))).collect();
    let total: usize = zooms.iter().map(|z| z.1.len()).sum();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let tmp = temp_dir(dir)?;
    let result = (|| -> Result<TerrainReport> {
        let mut report = TerrainReport {
            bound,
            height_step: heights.step(),
            bounds: extent,
            sites: sel.sites.len(),
            levels: Vec::new(),
        };
        for (z, keys) in &zooms {
            let z = *z;
            let ge = terrain::geometric_error(z);
            let target = if z == max_zoom { bound } else { ge.max(bound) };
            let k = sel.hull + suffix.partition_point(|&e| e as f64 > target);
            // Seeds bucketed by tile.
            let tw = 180.0 / f64::powi(2.0, z as i32);
            let mut buckets: HashMap<(u32, u32), Vec<(usize, usize)>> = HashMap::new();
            for &(c, r) in &sites[..k] {
                let lo = grid.lon0 + c as f64 * grid.dlon;
                let la = grid.lat0 - r as f64 * grid.dlat;
                let x = ((lo + 180.0) / tw).floor() as u32;
                let y = ((la + 90.0) / tw).floor() as u32;
                buckets.entry((x, y)).or_default().push((c, r));
            }
            let built: Vec<Result<Built>> = keys
                .par_iter()
                .map(|&key| {
                    let seeds = buckets.get(&(key.x, key.y)).map_or(&[][..], |v| &v[..]);
                    let p = TileParams {
                        target,
                        heights,
                        seeds,
                        normals: req.normals,
                        water: water.as_deref(),
                    };
                    let (tile, stats) = terrain::build_tile(&grid, key, &p)?;
                    let mut bytes = tile.encode()?;
                    if req.gzip {
                        let mut gz = flate2::write::GzEncoder::new(
                            Vec::new(),
                            flate2::Compression::default(),
                        );
                        gz.write_all(&bytes)
                            .and_then(|_| gz.finish())
                            .map(|b| bytes = b)
                            .map_err(|e| Error::io("gzip", e))?;
                    }
                    let json = req.expected_json.then(|| {
                        serde_json::json!({
                            "vertices": tile.vertices,
                            "triangles": tile.triangles,
                            "west": tile.rect[0], "south": tile.rect[1],
                            "east": tile.rect[2], "north": tile.rect[3],
                            "min_height": tile.min_height, "max_height": tile.max_height,
                        })
                        .to_string()
                    });
                    let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                    progress(0.4 + 0.6 * d as f64 / total as f64);
                    Ok((key, bytes, json, stats))
                })
                .collect();
            let mut level = TerrainLevel {
                zoom: z,
                tiles: keys.len(),
                geometric_error: ge,
                target,
                sites: k,
                ..Default::default()
            };
            let mut ss = 0.0;
            for b in built {
                let (key, bytes, json, s) = b?;
                let d = tmp.join(key.z.to_string()).join(key.x.to_string());
                std::fs::create_dir_all(&d).map_err(|e| Error::io(d.display().to_string(), e))?;
                let f = d.join(format!("{}.terrain", key.y));
                std::fs::write(&f, &bytes).map_err(|e| Error::io(f.display().to_string(), e))?;
                if let Some(j) = json {
                    let f = d.join(format!("{}.json", key.y));
                    std::fs::write(&f, j).map_err(|e| Error::io(f.display().to_string(), e))?;
                }
                level.bytes += bytes.len() as u64;
                level.vertices += s.vertices;
                level.triangles += s.triangles;
                level.added += s.added;
                level.samples += s.samples;
                level.max_error = level.max_error.max(s.max_error);
                level.over += s.over;
                ss += s.sum_sq;
            }
            level.rmse = if level.samples > 0 {
                (ss / level.samples as f64).sqrt()
            } else {
                0.0
            };
            if level.over > 0 || level.max_error > target {
                // Measured on the decoded tiles: never write a pyramid that breaks its bound.
                return Err(Error::unmet(format!(
                    "zoom {z}: {} of {} samples are farther than the bound {target} from the \
                     decoded mesh (max error {:.3}); its quantized positions are too coarse for \
                     this raster: use a larger --max-error or a deeper --max-zoom",
                    level.over, level.samples, level.max_error
                )));
            }
            report.levels.push(level);
        }
        let layer = layer_json(dir, &report, &zooms, req);
        let f = tmp.join("layer.json");
        std::fs::write(&f, layer).map_err(|e| Error::io(f.display().to_string(), e))?;
        Ok(report)
    })();
    let result = result.and_then(|report| {
        if dir.exists() {
            std::fs::remove_dir_all(dir).map_err(|e| Error::io(dir.display().to_string(), e))?;
        }
        std::fs::rename(&tmp, dir).map_err(|e| Error::io(dir.display().to_string(), e))?;
        Ok(report)
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    crate::formats::untrack(&tmp);
    result
}

/// A new empty directory beside `dir` to build in.
fn temp_dir(dir: &Path) -> Result<PathBuf> {
    let name = dir
        .file_name()
        .ok_or_else(|| Error::invalid(format!("{}: not a directory name", dir.display())))?;
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    for k in 0..1000 {
        let t = parent.join(format!(
            ".{}.vtz-tmp-{}-{k}",
            name.to_string_lossy(),
            std::process::id()
        ));
        match std::fs::create_dir(&t) {
            Ok(()) => {
                crate::formats::track(&t);
                return Ok(t);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(Error::io(parent.display().to_string(), e)),
        }
    }
    Err(Error::invalid("could not create a temporary directory"))
}

/// Cesium's `layer.json` (TileJSON 2.1.0 with quantized-mesh fields).
fn layer_json(
    dir: &Path,
    report: &TerrainReport,
    zooms: &[(u8, Vec<TileKey>)],
    req: &TerrainRequest,
) -> String {
    let available: Vec<serde_json::Value> = zooms
        .iter()
        .map(|(_, keys)| {
            let x0 = keys.iter().map(|k| k.x).min().unwrap_or(0);
            let x1 = keys.iter().map(|k| k.x).max().unwrap_or(0);
            let y0 = keys.iter().map(|k| k.y).min().unwrap_or(0);
            let y1 = keys.iter().map(|k| k.y).max().unwrap_or(0);
            serde_json::json!([{"startX": x0, "startY": y0, "endX": x1, "endY": y1}])
        })
        .collect();
    let mut ext = Vec::new();
    if req.normals {
        ext.push("octvertexnormals");
    }
    if req.water_mask {
        ext.push("watermask");
    }
    let name = dir
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let j = serde_json::json!({
        "tilejson": "2.1.0",
        "name": name,
        "description": "Cesium quantized-mesh-1.0 terrain written by vtz",
        "version": "1.0.0",
        "format": "quantized-mesh-1.0",
        "attribution": "",
        "scheme": "tms",
        "tiles": ["{z}/{x}/{y}.terrain?v={version}"],
        "projection": "EPSG:4326",
        "bounds": report.bounds,
        "minzoom": 0,
        "maxzoom": zooms.len() - 1,
        "available": available,
        "extensions": ext,
        "vtz": {
            "max_error": report.bound,
            "height_step": report.height_step,
            "levels": report.levels.iter().map(|l| serde_json::json!({
                "zoom": l.zoom, "target": l.target, "geometric_error": l.geometric_error,
                "max_error": l.max_error, "rmse": l.rmse, "vertices": l.vertices,
                "samples": l.samples, "over": l.over,
            })).collect::<Vec<_>>(),
        },
    });
    serde_json::to_string_pretty(&j).unwrap_or_default()
}
