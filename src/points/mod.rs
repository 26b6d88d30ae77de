//! Point sets (`.vtz` version 3): scattered points in, the Voronoi/Sibson sites of every
//! value column out, with the bound checked at every input point on what the decoder gives.
//!
//! Encoding: positions snap to a grid of the resolution (detected from the data when not
//! given: the coarsest power of ten the coordinates are multiples of, so the positions are
//! lossless), points sharing a grid position form one candidate whose target is the
//! midrange of their values (their own values are stored explicitly, within the bound), the
//! greedy selection runs on the candidates (`scattered`), and the sites and
//! positions are range coded (`payload`). The encoder then decodes its bytes
//! exactly as a decoder does, measures every point and column, and adds the violators as a
//! last level until none is left (closed loop).
// Columns index several parallel arrays (values, bounds, lattices, surfaces) at once.
#![allow(clippy::needless_range_loop)]

mod bands;
mod payload;
mod scattered;
mod verify;

pub use bands::bands_to_points;
pub use verify::verify_points;

use crate::container::VERSION_POINTS;
use crate::container::points::{
    ColumnHeader, MAX_EXTENT, POINT_SITES, POSITIONS, PointsFile, PointsHeader, write_points,
};
use crate::container::{Limits, MAGIC, SF_REQUIRED, Section};
use crate::error::{Error, Result};
use crate::model::PointSet;
use crate::quant::{ErrorBound, code_of};
use payload::{
    DecodedPointSites, Lattice, PointSites, eval_at, hilbert_index, hilbert_order, into_levels,
    read_positions, read_sites, write_positions, write_sites,
};
use scattered::{Candidates, ScatterParams, select_scattered};

/// Most closed-loop repair rounds.
const MAX_REPAIRS: usize = 16;

/// How to encode a point set.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct PointsOptions {
    /// Grid step of the positions in the CRS's units; `None`: detected (see the module).
    pub resolution: Option<f64>,
    /// The bound of every column not named in `bounds`.
    pub default_bound: ErrorBound,
    /// Bounds of named columns.
    pub bounds: Vec<(String, ErrorBound)>,
}

impl Default for PointsOptions {
    fn default() -> Self {
        PointsOptions {
            resolution: None,
            default_bound: ErrorBound::PercentOfRange(1.0),
            bounds: Vec::new(),
        }
    }
}

impl PointsOptions {
    /// Options with this bound for every column.
    pub fn new(bound: ErrorBound) -> Self {
        PointsOptions {
            default_bound: bound,
            ..Default::default()
        }
    }
    /// Set the position grid's step.
    pub fn resolution(mut self, r: f64) -> Self {
        self.resolution = Some(r);
        self
    }
    /// Set the bound of one named column.
    pub fn column_bound(mut self, name: &str, b: ErrorBound) -> Self {
        self.bounds.push((name.to_string(), b));
        self
    }
}

/// One column's result.
#[derive(Clone, Debug, serde::Serialize)]
#[non_exhaustive]
pub struct ColumnReport {
    /// The column's name.
    pub name: String,
    /// The bound held (data units).
    pub bound: f64,
    /// The largest error measured at the input points.
    pub max_error: f64,
    /// The RMSE measured at the input points.
    pub rmse: f64,
}

impl From<&ColumnHeader> for ColumnReport {
    /// What a column's stored header says of it.
    fn from(c: &ColumnHeader) -> ColumnReport {
        ColumnReport {
            name: c.name.clone(),
            bound: c.bound,
            max_error: c.max_error,
            rmse: c.rmse,
        }
    }
}

/// What encoding a point set did.
#[derive(Clone, Debug, serde::Serialize)]
#[non_exhaustive]
pub struct PointsReport {
    /// Input points.
    pub points: usize,
    /// Distinct grid positions.
    pub positions: usize,
    /// Sites kept.
    pub sites: usize,
    /// Sites per level.
    pub levels: Vec<usize>,
    /// The position grid's step.
    pub resolution: f64,
    /// Whether every input position is on the grid (positions lossless).
    pub positions_lossless: bool,
    /// Per column.
    pub columns: Vec<ColumnReport>,
    /// Bytes of the positions section.
    pub position_bytes: usize,
    /// Bytes of the sites section.
    pub site_bytes: usize,
    /// Bytes of the file.
    pub bytes: usize,
}

/// Whether `bytes` start like a point-set file (container version 3).
pub fn is_points_file(bytes: &[u8]) -> bool {
    bytes.len() >= 10
        && bytes[..8] == MAGIC
        && u16::from_le_bytes([bytes[8], bytes[9]]) == VERSION_POINTS
}

/// The grid step: the given one (checked), else the coarsest power of ten (1 down to 10⁻⁹)
/// every coordinate is a multiple of (within 10⁻⁶ of a step), else the finest that keeps
/// the extent on the grid.
/// Returns the step and whether every position is on the grid.
fn choose_resolution(p: &PointSet, given: Option<f64>) -> Result<(f64, bool)> {
    let on_grid = |r: f64| {
        p.x.iter().chain(&p.y).all(|&v| {
            let q = v / r;
            // On the grid up to float noise: a LAS reader's `X·scale + offset` is not the
            // double nearest the decimal, but within 10⁻⁶ of a step of it.
            (q - q.round()).abs() <= 1e-6
        })
    };
    let [x0, y0, x1, y1] = p.bounds().unwrap_or([0.0; 4]);
    let span = (x1 - x0).max(y1 - y0);
    let fits = |r: f64| span / r < (MAX_EXTENT - 2) as f64;
    if let Some(r) = given {
        if !(r > 0.0 && r.is_finite()) {
            return Err(Error::invalid("--xy-resolution must be a positive number"));
        }
        if !fits(r) {
            return Err(Error::invalid(format!(
                "the points span {span} units, over 2^24 steps of the resolution {r}: use a coarser --xy-resolution (at least {:.3e})",
                span / (MAX_EXTENT - 2) as f64
            )));
        }
        return Ok((r, on_grid(r)));
    }
    let mut finest_fit = None;
    for k in 0..=9 {
        let r = 10f64.powi(-k);
        if !fits(r) {
            break;
        }
        finest_fit = Some(r);
        if on_grid(r) {
            return Ok((r, true));
        }
    }
    match finest_fit {
        Some(r) => Ok((r, false)),
        None => Err(Error::invalid(format!(
            "the points span {span} units, over 2^24 metres: give --xy-resolution"
        ))),
    }
}

/// The quantized layout of a point set: distinct positions in Hilbert order, their
/// multiplicities, and the input points of each (in the order their values are coded).
struct Layout {
    resolution: f64,
    origin: [i64; 2],
    extent: [u32; 2],
    pos: Vec<[u32; 2]>,
    mult: Vec<u32>,
    /// Input point indices per position, concatenated (`mult` long each).
    members: Vec<u32>,
}

fn layout(p: &PointSet, r: f64) -> Result<Layout> {
    let n = p.len();
    let q = |v: f64| (v / r).round() as i64;
    let (mut kx0, mut ky0, mut kx1, mut ky1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
    for i in 0..n {
        let (a, b) = (q(p.x[i]), q(p.y[i]));
        kx0 = kx0.min(a);
        ky0 = ky0.min(b);
        kx1 = kx1.max(a);
        ky1 = ky1.max(b);
    }
    if n == 0 {
        (kx0, ky0, kx1, ky1) = (0, 0, 0, 0);
    }
    let extent = [(kx1 - kx0 + 1) as u64, (ky1 - ky0 + 1) as u64];
    if extent.iter().any(|&e| e > MAX_EXTENT as u64) {
        return Err(Error::invalid(
            "the points span more than 2^24 steps of the resolution",
        ));
    }
    let extent = [extent[0] as u32, extent[1] as u32];
    let order = hilbert_order(extent);
    let ij = |i: usize| [(q(p.x[i]) - kx0) as u32, (q(p.y[i]) - ky0) as u32];
    let mut idx: Vec<(u64, u32)> = (0..n)
        .map(|i| {
            let [a, b] = ij(i);
            (hilbert_index(order, a, b), i as u32)
        })
        .collect();
    idx.sort_unstable();
    let mut pos = Vec::new();
    let mut mult: Vec<u32> = Vec::new();
    let mut members = Vec::with_capacity(n);
    let mut last = None;
    for &(d, i) in &idx {
        if last == Some(d) {
            *mult.last_mut().expect("a position before") += 1;
        } else {
            pos.push(ij(i as usize));
            mult.push(1);
            last = Some(d);
        }
        members.push(i);
    }
    Ok(Layout {
        resolution: r,
        origin: [kx0, ky0],
        extent,
        pos,
        mult,
        members,
    })
}

/// Encode a point set. `progress` gets the fraction done.
pub fn encode_points(
    p: &PointSet,
    o: &PointsOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, PointsReport)> {
    p.validate()?;
    for (name, _) in &o.bounds {
        if !p.names.iter().any(|n| n == name) {
            return Err(Error::invalid(format!(
                "no value column named '{name}' (the columns: {})",
                p.names.join(", ")
            )));
        }
    }
    let t = p.columns();
    let (r, lossless) = choose_resolution(p, o.resolution)?;
    let lay = layout(p, r)?;
    // Bounds and lattices per column.
    let mut bounds = Vec::with_capacity(t);
    let mut lat = Vec::with_capacity(t);
    for c in 0..t {
        let col = &p.values[c];
        let range = col.iter().fold(None, |acc: Option<(f64, f64)>, &v| {
            Some(acc.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))))
        });
        let b = o
            .bounds
            .iter()
            .rev()
            .find(|(n, _)| *n == p.names[c])
            .map_or(o.default_bound, |x| x.1)
            .absolute(range);
        let (lo, hi) = range.unwrap_or((0.0, 0.0));
        // A constant column has range 0: any positive bound holds it exactly on the lattice.
        let b = if b > 0.0 {
            b
        } else if p.is_empty() || hi == lo {
            1.0f64.max(lo.abs() * 1e-9)
        } else {
            return Err(Error::invalid(format!(
                "column '{}': a point set needs a positive error bound (its values are not on a grid; for values with k decimals, half a unit of the last decimal keeps them exactly)",
                p.names[c]
            )));
        };
        bounds.push(b);
        lat.push(Lattice {
            step: b
                .max((hi - lo).abs() * 1e-12)
                .max(lo.abs().max(hi.abs()) * 1e-15),
            offset: lo,
        });
    }
    // Candidates: one per position, at the midrange of its points.
    let np = lay.pos.len();
    let mut cand = Candidates {
        pos: lay.pos.iter().map(|q| [q[0] as i64, q[1] as i64]).collect(),
        values: vec![Vec::with_capacity(np); t],
    };
    let mut start = Vec::with_capacity(np + 1);
    let mut at = 0usize;
    for &m in &lay.mult {
        start.push(at);
        let ids = &lay.members[at..at + m as usize];
        for c in 0..t {
            let (lo, hi) = ids
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, &i| {
                    let v = p.values[c][i as usize];
                    (a.0.min(v), a.1.max(v))
                });
            cand.values[c].push(lo + (hi - lo) / 2.0);
        }
        at += m as usize;
    }
    start.push(at);
    let sp = ScatterParams {
        bounds: bounds.clone(),
        steps: lat.iter().map(|l| l.step).collect(),
        offsets: lat.iter().map(|l| l.offset).collect(),
    };
    let sel = select_scattered(&cand, &sp, &mut |f| progress(0.95 * f))?;
    let sites: Vec<(u32, Vec<i64>)> = sel
        .sites
        .iter()
        .enumerate()
        .map(|(j, &k)| (k, (0..t).map(|c| sel.codes[c][j]).collect()))
        .collect();
    // Shared positions: every member's codes, members in code order.
    let mut shared_at = Vec::new();
    let mut shared = Vec::new();
    let mut member_order: Vec<u32> = lay.members.clone();
    for (k, &m) in lay.mult.iter().enumerate().filter(|(_, m)| **m > 1) {
        let ids = &mut member_order[start[k]..start[k] + m as usize];
        let codes_of = |i: u32| -> Vec<i64> {
            (0..t)
                .map(|c| code_of(p.values[c][i as usize], lat[c].step, lat[c].offset))
                .collect()
        };
        ids.sort_by_key(|&i| (codes_of(i), i));
        shared_at.push(k as u32);
        shared.push(ids.iter().map(|&i| codes_of(i)).collect::<Vec<_>>());
    }
    let header_of = |cols: Vec<ColumnHeader>| PointsHeader {
        points: p.len() as u64,
        positions: np as u64,
        resolution: lay.resolution,
        origin: lay.origin,
        extent: lay.extent,
        columns: cols,
        epsg: p.epsg,
        wkt: p.wkt.clone(),
    };
    let cols0: Vec<ColumnHeader> = (0..t)
        .map(|c| ColumnHeader {
            name: p.names[c].clone(),
            step: lat[c].step,
            offset: lat[c].offset,
            bound: bounds[c],
            max_error: 0.0,
            rmse: 0.0,
        })
        .collect();
    let pos_payload = write_positions(&lay.pos, &lay.mult, lay.extent);
    let hull = sel.hull;
    let mut extra_levels: Vec<Vec<(u32, Vec<i64>)>> = Vec::new();
    for round in 0..=MAX_REPAIRS {
        let mut levels = into_levels(&sites, hull);
        levels.extend(extra_levels.iter().cloned());
        let ps = PointSites {
            levels,
            shared: shared.clone(),
        };
        let site_payload = write_sites(&ps, &lay.pos, &shared_at, &lat)?;
        // Closed loop: decode as a decoder does and measure every point and column.
        let d = read_sites(&site_payload, &lay.pos, &lay.mult, &lat, None)?;
        let at_pos = eval_at(&d.surfaces, &lay.pos)?;
        let mut max = vec![0.0f64; t];
        let mut ss = vec![0.0f64; t];
        let mut bad = Vec::new();
        let mut si = 0;
        for k in 0..np {
            let m = lay.mult[k] as usize;
            for (j, &i) in member_order[start[k]..start[k] + m].iter().enumerate() {
                for c in 0..t {
                    let v = if m > 1 {
                        d.shared[si][j][c]
                    } else {
                        at_pos[c][k]
                    };
                    let e = (v - p.values[c][i as usize]).abs();
                    max[c] = max[c].max(e);
                    ss[c] += e * e;
                    if e > bounds[c] && m == 1 && !bad.iter().any(|b: &(u32, _)| b.0 == k as u32) {
                        bad.push((
                            k as u32,
                            (0..t)
                                .map(|c| {
                                    code_of(p.values[c][i as usize], lat[c].step, lat[c].offset)
                                })
                                .collect::<Vec<i64>>(),
                        ));
                    }
                }
            }
            if m > 1 {
                si += 1;
            }
        }
        let over = (0..t).any(|c| max[c] > bounds[c]);
        if !over {
            let cols: Vec<ColumnHeader> = (0..t)
                .map(|c| ColumnHeader {
                    max_error: max[c],
                    rmse: (ss[c] / p.len().max(1) as f64).sqrt(),
                    ..cols0[c].clone()
                })
                .collect();
            let report_cols = cols.iter().map(ColumnReport::from).collect();
            let sections = [
                Section {
                    kind: POSITIONS,
                    flags: SF_REQUIRED,
                    payload: pos_payload.clone(),
                },
                Section {
                    kind: POINT_SITES,
                    flags: SF_REQUIRED,
                    payload: site_payload.clone(),
                },
            ];
            let bytes = write_points(&header_of(cols), &sections)?;
            progress(1.0);
            let report = PointsReport {
                points: p.len(),
                positions: np,
                sites: d.sites.len(),
                levels: d.levels.clone(),
                resolution: lay.resolution,
                positions_lossless: lossless,
                columns: report_cols,
                position_bytes: pos_payload.len(),
                site_bytes: site_payload.len(),
                bytes: bytes.len(),
            };
            return Ok((bytes, report));
        }
        let have: std::collections::HashSet<u32> = d.sites.iter().copied().collect();
        bad.retain(|b| !have.contains(&b.0));
        if bad.is_empty() || round == MAX_REPAIRS {
            return Err(Error::unmet(
                "the point-set coder could not meet the bound (a site or shared position is off)",
            ));
        }
        bad.sort_unstable_by_key(|b| b.0);
        extra_levels.push(bad);
    }
    unreachable!("the loop returns")
}

/// How to decode a point set.
#[derive(Clone, Debug, Default)]
#[non_exhaustive]
pub struct DecodePoints {
    /// Only the kept sites (importance order), with their stored values.
    pub sites_only: bool,
    /// Only the first `level` levels of sites (a coarser surface, evaluated at every point).
    pub level: Option<usize>,
    /// Limits on what the file may make the decoder allocate.
    pub limits: Limits,
}

impl DecodePoints {
    /// Decode every point (the default).
    pub fn new() -> Self {
        Self::default()
    }
    /// Only the kept sites.
    pub fn sites_only(mut self, yes: bool) -> Self {
        self.sites_only = yes;
        self
    }
    /// A prefix of the levels.
    pub fn level(mut self, l: Option<usize>) -> Self {
        self.level = l;
        self
    }
}

/// A point-set file's summary.
#[derive(Clone, Debug, serde::Serialize)]
#[non_exhaustive]
pub struct PointsInfo {
    /// Points.
    pub points: u64,
    /// Distinct positions.
    pub positions: u64,
    /// Sites.
    pub sites: usize,
    /// Sites per level.
    pub levels: Vec<usize>,
    /// Position grid step.
    pub resolution: f64,
    /// Bounding box `[xmin, ymin, xmax, ymax]` of the grid.
    pub bounds: [f64; 4],
    /// Per column: name, bound, max error, RMSE as the encoder measured them.
    pub columns: Vec<ColumnReport>,
    /// EPSG code, when known.
    pub epsg: Option<u32>,
    /// Whether the file carries a WKT.
    pub has_wkt: bool,
    /// Sections: (name, bytes).
    pub sections: Vec<(String, u64)>,
    /// Bytes of the file.
    pub bytes: usize,
}

struct Opened {
    header: PointsHeader,
    pos: Vec<[u32; 2]>,
    mult: Vec<u32>,
    sites: DecodedPointSites,
}

fn open(bytes: &[u8], limits: Limits, max_levels: Option<usize>) -> Result<Opened> {
    let f = PointsFile::read(bytes, limits)?;
    let h = f.header.clone();
    let (pos, mult) = read_positions(f.required(POSITIONS)?, h.positions, h.points, h.extent)?;
    let lat: Vec<Lattice> = h
        .columns
        .iter()
        .map(|c| Lattice {
            step: c.step,
            offset: c.offset,
        })
        .collect();
    let sites = read_sites(f.required(POINT_SITES)?, &pos, &mult, &lat, max_levels)?;
    Ok(Opened {
        header: h,
        pos,
        mult,
        sites,
    })
}

fn coord(h: &PointsHeader, q: [u32; 2]) -> (f64, f64) {
    (
        grid_coord(h.origin[0] + q[0] as i64, h.resolution),
        grid_coord(h.origin[1] + q[1] as i64, h.resolution),
    )
}

/// The coordinate of grid step `k` (spec/FORMAT.md): `k / N` when the resolution is `1/N`
/// for an integer N (so decimal resolutions give the double nearest the decimal, as a text
/// reader does), else `k · r`.
fn grid_coord(k: i64, r: f64) -> f64 {
    let n = (1.0 / r).round();
    if r < 1.0 && n <= 1e15 && (n * r - 1.0).abs() <= 1e-12 {
        k as f64 / n
    } else {
        k as f64 * r
    }
}

/// Decode a point-set file: every point (the surface at its position, or its stored value
/// where points share a position), in the file's spatial order; or only the sites.
pub fn decode_points(bytes: &[u8], o: &DecodePoints) -> Result<PointSet> {
    if o.level == Some(0) {
        return Err(Error::invalid("--level counts from 1"));
    }
    let op = open(bytes, o.limits, o.level)?;
    let h = &op.header;
    let t = h.columns.len();
    let mut out = PointSet {
        names: h.columns.iter().map(|c| c.name.clone()).collect(),
        values: vec![Vec::new(); t],
        epsg: h.epsg,
        wkt: h.wkt.clone(),
        ..Default::default()
    };
    if o.sites_only {
        for (j, &k) in op.sites.sites.iter().enumerate() {
            let (x, y) = coord(h, op.pos[k as usize]);
            out.x.push(x);
            out.y.push(y);
            for c in 0..t {
                out.values[c].push(op.sites.values[c][j]);
            }
        }
        return Ok(out);
    }
    let at = eval_at(&op.sites.surfaces, &op.pos)?;
    let n = h.points as usize;
    out.x.reserve(n);
    out.y.reserve(n);
    let mut si = 0;
    for (k, &q) in op.pos.iter().enumerate() {
        let (x, y) = coord(h, q);
        let m = op.mult[k] as usize;
        for j in 0..m {
            out.x.push(x);
            out.y.push(y);
            for c in 0..t {
                let v = match op.sites.shared.get(si) {
                    Some(s) if m > 1 => s[j][c],
                    _ => at[c][k],
                };
                out.values[c].push(v);
            }
        }
        if m > 1 {
            si += 1;
        }
    }
    Ok(out)
}

/// The sites of a point-set file with their levels, for the cluster hierarchy: positions,
/// values per column, the level each entered (0-based), and every point's residual against
/// the level-`level` surface (column 0) — see `vtz cells`.
pub struct PointHierarchy {
    /// Site positions (CRS units).
    pub sites: Vec<[f64; 2]>,
    /// Level (0-based) per site.
    pub site_level: Vec<usize>,
    /// Column 0's value per site.
    pub site_value: Vec<f64>,
    /// Every point's position and |surface_level − decoded value| in column 0.
    pub samples: Vec<([f64; 2], f64)>,
    /// EPSG code, when known.
    pub epsg: Option<u32>,
    /// The CRS's WKT, when the file carries one.
    pub wkt: Option<String>,
    /// Levels in the file.
    pub levels: usize,
}

/// The level-`level` (1-based; `None`: all) sites of a point set and the residuals of the
/// full decode against their surface.
pub fn point_hierarchy(
    bytes: &[u8],
    level: Option<usize>,
    limits: Limits,
) -> Result<PointHierarchy> {
    let full = decode_points(
        bytes,
        &DecodePoints {
            limits,
            ..Default::default()
        },
    )?;
    let op = open(bytes, limits, level)?;
    let h = &op.header;
    let at = eval_at(&op.sites.surfaces[..1], &op.pos)?;
    let mut samples = Vec::with_capacity(full.len());
    let mut i = 0;
    for (k, &m) in op.mult.iter().enumerate() {
        for _ in 0..m {
            samples.push(([full.x[i], full.y[i]], (at[0][k] - full.values[0][i]).abs()));
            i += 1;
        }
    }
    let mut site_level = Vec::with_capacity(op.sites.sites.len());
    for (l, &n) in op.sites.levels.iter().enumerate() {
        site_level.extend(std::iter::repeat_n(l, n));
    }
    let levels = count_levels(bytes, limits)?;
    Ok(PointHierarchy {
        sites: op
            .sites
            .sites
            .iter()
            .map(|&k| {
                let (x, y) = coord(h, op.pos[k as usize]);
                [x, y]
            })
            .collect(),
        site_level,
        site_value: op.sites.values[0].clone(),
        samples,
        epsg: h.epsg,
        wkt: h.wkt.clone(),
        levels,
    })
}

fn count_levels(bytes: &[u8], limits: Limits) -> Result<usize> {
    let f = PointsFile::read(bytes, limits)?;
    let s = f.required(POINT_SITES)?;
    if s.len() < 8 {
        return Err(Error::corrupt("point-sites section is truncated"));
    }
    Ok(u32::from_le_bytes([s[4], s[5], s[6], s[7]]) as usize)
}

/// Summarise a point-set file (decoding its sites).
pub fn points_info(bytes: &[u8], limits: Limits) -> Result<PointsInfo> {
    let f = PointsFile::read(bytes, limits)?;
    let sections = f
        .entries
        .iter()
        .map(|e| (e.name.clone(), e.length))
        .collect();
    let op = open(bytes, limits, None)?;
    let h = &op.header;
    let (x0, y0) = coord(h, [0, 0]);
    let (x1, y1) = coord(h, [h.extent[0] - 1, h.extent[1] - 1]);
    Ok(PointsInfo {
        points: h.points,
        positions: h.positions,
        sites: op.sites.sites.len(),
        levels: op.sites.levels.clone(),
        resolution: h.resolution,
        bounds: [x0, y0, x1, y1],
        columns: h.columns.iter().map(ColumnReport::from).collect(),
        epsg: h.epsg,
        has_wkt: h.wkt.is_some(),
        sections,
        bytes: bytes.len(),
    })
}

/// How to rasterize a point set's surface ([`rasterize_points`]).
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct RasterizePoints {
    /// Cell size in the CRS's units: a multiple of the file's position resolution.
    pub cell: f64,
    /// The value column (default: the first).
    pub column: Option<String>,
    /// Only cells whose centre is a stored position are valid (a point set made from a
    /// grid of this cell size decodes back to its grid); otherwise every cell inside the
    /// convex hull of the points is.
    pub only_positions: bool,
    /// Limits on what the file may make the decoder allocate.
    pub limits: Limits,
}

impl RasterizePoints {
    /// Cells of this size, the first column, the whole hull.
    pub fn new(cell: f64) -> Self {
        RasterizePoints {
            cell,
            column: None,
            only_positions: false,
            limits: Limits::default(),
        }
    }
    /// Choose the value column by name.
    pub fn column(mut self, name: Option<String>) -> Self {
        self.column = name;
        self
    }
    /// Valid cells only at stored positions.
    pub fn only_positions(mut self, yes: bool) -> Self {
        self.only_positions = yes;
        self
    }
}

/// Sibson's surface of a point-set file on a north-up grid of `cell`-sized pixels covering
/// the points (pixel centres on the position grid; outside the convex hull: nodata), with
/// the file's CRS. Values are f32.
pub fn rasterize_points(bytes: &[u8], o: &RasterizePoints) -> Result<crate::model::Raster> {
    use crate::model::{Georef, Raster, RasterType, SampleType};
    let op = open(bytes, o.limits, None)?;
    let h = &op.header;
    let c = match &o.column {
        None => 0,
        Some(n) => h.columns.iter().position(|c| &c.name == n).ok_or_else(|| {
            Error::invalid(format!(
                "no column '{n}' (the columns: {})",
                h.columns
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?,
    };
    let r = h.resolution;
    let k = (o.cell / r).round();
    if !(o.cell > 0.0 && o.cell.is_finite()) || k < 1.0 || ((k * r - o.cell).abs() > 1e-9 * o.cell)
    {
        return Err(Error::invalid(format!(
            "--cell {} must be a positive multiple of the file's position resolution {r}",
            o.cell
        )));
    }
    if op.pos.is_empty() {
        return Err(Error::invalid(
            "the point set is empty: nothing to rasterize",
        ));
    }
    let step = k as i64;
    let [ex, ey] = [h.extent[0] as i64, h.extent[1] as i64];
    // Pixel centres at grid steps 0, step, 2·step … from the lowest stored position.
    let (w, hh) = ((ex - 1) / step + 1, (ey - 1) / step + 1);
    let n = (w as u64) * (hh as u64);
    if n > o.limits.max_samples {
        return Err(Error::limit(format!(
            "a {w}x{hh} raster is over the limit of {} samples: use a larger --cell",
            o.limits.max_samples
        )));
    }
    let (w, hh) = (w as usize, hh as usize);
    let at: std::collections::HashSet<[u32; 2]> = if o.only_positions {
        op.pos.iter().copied().collect()
    } else {
        Default::default()
    };
    let want = |x: i64, y: i64| !o.only_positions || at.contains(&[x as u32, y as u32]);
    let surf = &op.sites.surfaces[c];
    let south_up = surf.eval_lattice(0, 0, w, hh, step, &want);
    let mut data = vec![f64::NAN; w * hh];
    for row in 0..hh {
        let src = &south_up[(hh - 1 - row) * w..(hh - row) * w];
        for (d, &v) in data[row * w..(row + 1) * w].iter_mut().zip(src) {
            *d = if v.is_nan() { v } else { v as f32 as f64 };
        }
    }
    let mut raster = Raster::from_values(w, hh, data, None, SampleType::F32)?;
    let (x0, _) = coord(h, [0, 0]);
    let (_, ytop) = coord(h, [0, ((hh - 1) as i64 * step) as u32]);
    raster.georef = Some(Georef {
        origin: [x0 - o.cell / 2.0, ytop + o.cell / 2.0],
        pixel_size: [o.cell, o.cell],
        raster_type: RasterType::Area,
        epsg: h.epsg,
        wkt: h.wkt.clone(),
        geokeys: None,
    });
    Ok(raster)
}
