//! The cells of a `.vtz` file's sites (`vtz cells`): one level's Voronoi tiles over the raster, each with the residual of the level's surface against a reference.
//!
//! The level-K surface is Sibson's interpolant through the sites of levels 0..=K (the
//! progressive decode of the sites section); the reference is the file's full decode or
//! the original raster. The geometry is `cells::voronoi_cells`; this file only turns a
//! raster into its inputs and the result into GeoJSON or a picture.

use crate::cells::{self, Cell, GeoJsonOptions, SiteInfo};
use crate::codec::{DecodeOptions, Decoder, SectionChoice};
use crate::container::Limits;
use crate::error::{Error, Result};
use crate::methods::{Method, Site, StatValue};
use crate::model::{Georef, Raster};
use serde_json::{Map, json};
use std::io::{Read, Seek};

/// What [`file_cells`] measures.
#[derive(Clone, Debug, Default)]
pub struct CellsRequest<'a> {
    /// The level K: the cells of the sites of levels 0..=K (default: the last level).
    pub level: Option<usize>,
    /// The original samples to measure against (same size as the file); default: the
    /// file's full decode.
    pub source: Option<&'a Raster>,
    /// Limits on what the file may allocate.
    pub limits: Limits,
}

/// One level's cells of a `.vtz` file, with what they were measured against.
#[derive(Clone, Debug)]
pub struct FileCells {
    /// One cell per site of the level, in rank order; coordinates in CRS units relative to
    /// sample (0, 0)'s centre ([`FileCells::geojson`] writes them in CRS units).
    pub cells: Vec<Cell>,
    /// The level's sites (levels 0..=K), in rank order.
    pub sites: Vec<Site>,
    /// The level K.
    pub level: usize,
    /// Levels in the file.
    pub levels: usize,
    /// Sites in the file (all levels).
    pub total_sites: usize,
    /// The file's stored max error (its primary section's), when it keeps one.
    pub bound: Option<f64>,
    /// The reference samples: the full decode, or the source.
    pub reference: Raster,
    /// Whether `reference` is the source (true) or the file's full decode.
    pub from_source: bool,
    /// The file's georeferencing.
    pub georef: Option<Georef>,
    /// Valid samples measured (valid in the reference and the level's surface).
    pub valid: usize,
}

/// The cells of the sites of levels 0..=K of the `.vtz` in `reader` (untiled, with a sites
/// section), with ε = |surface_K − reference| over the valid samples of each cell.
pub fn file_cells<R: Read + Seek + Send + 'static>(
    reader: R,
    req: &CellsRequest,
) -> Result<FileCells> {
    let mut d = Decoder::with_limits(reader, req.limits)?;
    let info = d.info().clone();
    let all = d.sites()?;
    let levels = all.iter().map(|s| s.level + 1).max().unwrap_or(0);
    let level = match req.level {
        None => levels.saturating_sub(1),
        Some(k) if k < levels => k,
        Some(k) => {
            return Err(Error::invalid(format!(
                "--level {k}: the file has levels 0 to {}",
                levels.saturating_sub(1)
            )));
        }
    };
    let primary = info.sections.get(info.primary).and_then(|s| s.method);
    let bound = d
        .stats()?
        .into_iter()
        .find(|s| Some(s.method) == primary)
        .and_then(|s| match s.get("max_error") {
            Some(StatValue::Number(v)) => Some(*v),
            _ => None,
        });
    let surface = d
        .options(DecodeOptions {
            limits: req.limits,
            section: SectionChoice::Method(Method::SIBSON),
            levels: Some(level + 1),
            ..Default::default()
        })
        .decode()?;
    let reference = match req.source {
        Some(r) => {
            if (r.width, r.height) != (surface.width, surface.height) {
                return Err(Error::invalid(format!(
                    "the source is {}x{} but the file is {}x{}",
                    r.width, r.height, surface.width, surface.height
                )));
            }
            r.clone()
        }
        None => d
            .options(DecodeOptions {
                limits: req.limits,
                ..Default::default()
            })
            .decode()?,
    };
    let total_sites = all.len();
    let sites: Vec<Site> = all.into_iter().take_while(|s| s.level <= level).collect();
    let frame = Frame::new(info.georef.as_ref());
    let (w, h) = (surface.width, surface.height);
    let valid = |i: usize| surface.is_valid(i) && reference.is_valid(i);
    // The hull of the valid samples: the first and last valid sample of every row suffice.
    let mut ends = Vec::with_capacity(2 * h);
    for y in 0..h {
        let row = y * w..(y + 1) * w;
        if let Some(x) = row.clone().find(|&i| valid(i)) {
            ends.push(frame.local((x - y * w) as f64, y as f64));
        }
        if let Some(x) = row.rev().find(|&i| valid(i)) {
            ends.push(frame.local((x - y * w) as f64, y as f64));
        }
    }
    let hull = cells::convex_hull(&ends);
    if hull.len() < 3 {
        return Err(Error::invalid(
            "the valid samples lie on a line: their hull has no area, so there are no cells",
        ));
    }
    let positions: Vec<[f64; 2]> = sites
        .iter()
        .map(|s| frame.local(s.col as f64, s.row as f64))
        .collect();
    let samples = (0..w * h).filter(|&i| valid(i)).map(|i| {
        (
            frame.local((i % w) as f64, (i / w) as f64),
            surface.data[i] - reference.data[i],
        )
    });
    let cells = cells::voronoi_cells(&positions, samples, &hull)?;
    let valid_count = (0..w * h).filter(|&i| valid(i)).count();
    Ok(FileCells {
        cells,
        total_sites,
        sites,
        level,
        levels,
        bound,
        reference,
        from_source: req.source.is_some(),
        georef: info.georef,
        valid: valid_count,
    })
}

/// The cells' frame: `local` = (col·px, −row·py) for a georeferenced file, else
/// (col, −row); CRS = the centre of sample (0, 0) + local.
#[derive(Clone, Copy, Debug)]
struct Frame {
    step: [f64; 2],
    origin: Option<[f64; 2]>,
}

impl Frame {
    fn new(g: Option<&Georef>) -> Frame {
        match g {
            Some(g) => Frame {
                step: g.pixel_size,
                origin: Some(g.sample_centre(0.0, 0.0)),
            },
            None => Frame {
                step: [1.0, 1.0],
                origin: None,
            },
        }
    }

    fn local(&self, col: f64, row: f64) -> [f64; 2] {
        [col * self.step[0], -row * self.step[1]]
    }

    /// Output coordinates: CRS with a georef; (col, row) without one (as `vtz sites`).
    fn out(&self, p: [f64; 2]) -> [f64; 2] {
        match self.origin {
            Some(o) => [o[0] + p[0], o[1] + p[1]],
            None => [p[0], -p[1]],
        }
    }

    /// Picture coordinates: sample (col, row), sample centres at integers.
    fn pixel(&self, p: [f64; 2]) -> [f64; 2] {
        [p[0] / self.step[0], -p[1] / self.step[1]]
    }
}

impl FileCells {
    /// Each cell's polygon in the output coordinates (CRS; (col, row) without a georef).
    pub fn polygons(&self) -> Vec<Vec<[f64; 2]>> {
        let f = Frame::new(self.georef.as_ref());
        self.cells
            .iter()
            .map(|c| c.polygon.iter().map(|&p| f.out(p)).collect())
            .collect()
    }

    /// The GeoJSON FeatureCollection: one Polygon per cell (properties rank, level, value,
    /// samples, eps_max, eps_rms), the `"crs"` member when the EPSG code is known, and a
    /// `"vtz"` member saying what ε was measured against.
    pub fn geojson(&self, source_name: Option<&str>) -> Result<Vec<u8>> {
        let (cells, sites, opts) = self.features(source_name);
        cells::geojson(&cells, &sites, &opts)
    }

    /// The same features as [`FileCells::geojson`] as a GeoPackage (one polygon table
    /// `cells`; the `"vtz"` member becomes the table's description).
    #[cfg(feature = "gpkg")]
    pub fn gpkg(&self, source_name: Option<&str>) -> Result<Vec<u8>> {
        let (cells, sites, opts) = self.features(source_name);
        let wkt = self.georef.as_ref().and_then(|g| g.wkt.as_deref());
        cells::gpkg(&cells, &sites, &opts, wkt)
    }

    /// The cells in output coordinates, their sites' descriptions, and the collection's
    /// properties.
    fn features(&self, source_name: Option<&str>) -> (Vec<Cell>, Vec<SiteInfo>, GeoJsonOptions) {
        let polys = self.polygons();
        let cells: Vec<Cell> = self
            .cells
            .iter()
            .zip(polys)
            .map(|(c, p)| Cell {
                polygon: p,
                ..c.clone()
            })
            .collect();
        let sites: Vec<SiteInfo> = self
            .sites
            .iter()
            .map(|s| SiteInfo {
                rank: s.rank,
                level: s.level,
                value: s.height,
            })
            .collect();
        let mut about = Map::new();
        about.insert("level".into(), json!(self.level));
        about.insert("levels".into(), json!(self.levels));
        about.insert("sites".into(), json!(self.sites.len()));
        about.insert("samples".into(), json!(self.valid));
        about.insert("file_max_error".into(), json!(self.bound));
        about.insert(
            "coordinates".into(),
            json!(match self.georef {
                Some(_) => "CRS coordinates; sample centres",
                None => "sample column and row (no georeferencing)",
            }),
        );
        if self.from_source {
            about.insert("reference".into(), json!("source"));
            if let Some(n) = source_name {
                about.insert("source".into(), json!(n));
            }
            about.insert(
                "eps".into(),
                json!("eps = |level surface - source| over the valid samples of the tile"),
            );
        } else {
            about.insert("reference".into(), json!("decode"));
            about.insert(
                "eps".into(),
                json!("eps = |level surface - the file's full decode| over the valid samples of the tile; the error to the original is at most eps + file_max_error"),
            );
        }
        let opts = GeoJsonOptions {
            epsg: self.georef.as_ref().and_then(|g| g.epsg),
            about,
        };
        (cells, sites, opts)
    }

    /// A picture: the reference's hillshade, each cell tinted by its eps_max, the cell
    /// boundaries drawn over it, and a colour bar (0 to the largest eps_max) below.
    pub fn png(&self) -> Result<Vec<u8>> {
        let f = Frame::new(self.georef.as_ref());
        let polys: Vec<Vec<[f64; 2]>> = self
            .cells
            .iter()
            .map(|c| c.polygon.iter().map(|&p| f.pixel(p)).collect())
            .collect();
        let eps: Vec<f64> = self.cells.iter().map(|c| c.eps_max).collect();
        let what = if self.from_source { "source" } else { "decode" };
        let desc = format!(
            "vtz cells: level {} ({} sites) over a hillshade of the {what}; cells tinted by eps_max (max |level surface - {what}|), file max error {}",
            self.level,
            self.sites.len(),
            self.bound
                .map_or("unknown".to_string(), |b| crate::metrics::num(b)
                    .to_string())
        );
        crate::viz::cells::cells_png(&self.reference, &polys, &eps, &desc)
    }
}
