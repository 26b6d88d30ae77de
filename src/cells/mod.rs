//! Voronoi cells of scattered sites clipped to a convex hull, with the residual ε of the samples each cell holds.
//!
//! The paper's cluster hierarchy as tiles: each level's sites cut the data's convex hull into
//! convex cells (their Voronoi polygons), and each cell carries the residual of the samples
//! nearest to its site, `L_j = {(τ, f̃, ε)}`. Everything here is a pure function of points;
//! rasters and `.vtz` files are the terrain room's business (`terrain::cells`), pictures are
//! `viz::cells`.
//!
//! * [`voronoi_cells`]: the cells and their residual statistics.
//! * [`convex_hull`], [`polygon_area`]: the helpers a caller needs for the hull.
//! * [`geojson`]: a GeoJSON FeatureCollection of cells.
//! * `gpkg` (feature `gpkg`): the same features as a GeoPackage.

mod geojson;
#[cfg(feature = "gpkg")]
mod gpkg;

pub use geojson::{GeoJsonOptions, SiteInfo, geojson};
#[cfg(feature = "gpkg")]
pub use gpkg::gpkg;

use crate::error::{Error, Result};
use rayon::prelude::*;
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

/// One site's Voronoi cell clipped to the hull, and the residuals of the samples it holds.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// The clipped cell, counter-clockwise, not closed (the first vertex is not repeated).
    /// Empty for a site that repeats an earlier site's position or lies outside the hull.
    pub polygon: Vec<[f64; 2]>,
    /// Samples whose nearest site is this one (ties go to the lowest site index).
    pub samples: usize,
    /// The largest |residual| of those samples (0 when there are none).
    pub eps_max: f64,
    /// Root mean square of their residuals (0 when there are none).
    pub eps_rms: f64,
}

/// A site as spade's vertex: its position and its index in the caller's slice.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    p: [f64; 2],
    index: usize,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        Point2::new(self.p[0], self.p[1])
    }
}

/// The Voronoi cells of `sites`, each clipped to the convex polygon `hull`, with the
/// residual statistics of `samples` (position, residual) assigned to their nearest site.
///
/// * `hull`: a convex polygon in either orientation, not closed (e.g. [`convex_hull`] of the
///   sample positions). The cells of distinct sites inside it tile it.
/// * A site at the position of an earlier one gets an empty cell and no samples; so does a
///   site outside the hull (its cell clipped away), though it still takes its nearest samples.
/// * `samples`: each sample goes to its nearest site (Euclidean; ties to the lowest index),
///   which is the cell containing it; only |residual| counts. Non-finite residuals or
///   positions are an error.
///
/// Cells come back in the order of `sites`. The Delaunay triangulation (spade's, with exact
/// predicates) gives each site's neighbours; a cell is the hull's bounding box cut by the
/// bisector with each neighbour, then clipped to the hull (Sutherland–Hodgman).
pub fn voronoi_cells<I>(sites: &[[f64; 2]], samples: I, hull: &[[f64; 2]]) -> Result<Vec<Cell>>
where
    I: IntoIterator<Item = ([f64; 2], f64)>,
{
    if sites.is_empty() {
        return Err(Error::invalid("Voronoi cells need at least one site"));
    }
    if let Some(p) = sites
        .iter()
        .find(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        return Err(Error::invalid(format!("site {p:?} is not a finite point")));
    }
    let hull = ccw_hull(hull)?;
    let vertices: Vec<Vertex> = sites
        .iter()
        .enumerate()
        .map(|(index, &p)| Vertex { p, index })
        .collect();
    let tri: DelaunayTriangulation<Vertex> = DelaunayTriangulation::bulk_load_stable(vertices)
        .map_err(|e| Error::invalid(format!("sites cannot be triangulated: {e:?}")))?;
    // Site index → its vertex (None for a dropped duplicate).
    let mut handle = vec![None; sites.len()];
    for v in tri.fixed_vertices() {
        handle[tri.vertex(v).data().index] = Some(v);
    }
    let (lo, hi) = bbox(&hull);
    let pad = ((hi[0] - lo[0]) + (hi[1] - lo[1])).max(1.0);
    let frame = vec![
        [lo[0] - pad, lo[1] - pad],
        [hi[0] + pad, lo[1] - pad],
        [hi[0] + pad, hi[1] + pad],
        [lo[0] - pad, hi[1] + pad],
    ];
    let mut cells: Vec<Cell> = handle
        .par_iter()
        .map(|h| {
            let Some(h) = *h else {
                return Cell::empty();
            };
            let v = tri.vertex(h);
            let p = v.data().p;
            let mut poly = frame.clone();
            for e in v.out_edges() {
                let q = e.to().data().p;
                let d = [q[0] - p[0], q[1] - p[1]];
                // Keep x with (x − p)·d ≤ |d|²/2: the side of the bisector nearer p.
                let c = d[0] * p[0] + d[1] * p[1] + 0.5 * (d[0] * d[0] + d[1] * d[1]);
                poly = clip(&poly, |x| c - (d[0] * x[0] + d[1] * x[1]));
                if poly.is_empty() {
                    break;
                }
            }
            for i in 0..hull.len() {
                let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
                poly = clip(&poly, |x| cross(a, b, x));
                if poly.is_empty() {
                    break;
                }
            }
            Cell {
                polygon: poly,
                ..Cell::empty()
            }
        })
        .collect();
    let mut sum_sq = vec![0.0f64; sites.len()];
    let mut last = None;
    for (x, r) in samples {
        if !(x[0].is_finite() && x[1].is_finite() && r.is_finite()) {
            return Err(Error::invalid(format!(
                "sample at {x:?} with residual {r} is not finite"
            )));
        }
        let i = nearest(&tri, x, &mut last);
        let c = &mut cells[i];
        c.samples += 1;
        c.eps_max = c.eps_max.max(r.abs());
        sum_sq[i] += r * r;
    }
    for (c, s) in cells.iter_mut().zip(sum_sq) {
        if c.samples > 0 {
            c.eps_rms = (s / c.samples as f64).sqrt().min(c.eps_max);
        }
    }
    Ok(cells)
}

impl Cell {
    fn empty() -> Cell {
        Cell {
            polygon: Vec::new(),
            samples: 0,
            eps_max: 0.0,
            eps_rms: 0.0,
        }
    }
}

/// The index of the site nearest `x`, ties to the lowest index. `last` is the previous
/// answer's vertex, where the walk starts (samples in scan order are found in a few steps).
fn nearest(
    tri: &DelaunayTriangulation<Vertex>,
    x: [f64; 2],
    last: &mut Option<spade::handles::FixedVertexHandle>,
) -> usize {
    let d2 = |p: [f64; 2]| (p[0] - x[0]).powi(2) + (p[1] - x[1]).powi(2);
    let v = match tri.num_vertices() {
        1 => tri.vertices().next().expect("one vertex"),
        _ => {
            let start = last.unwrap_or_else(|| tri.vertices().next().expect("a vertex").fix());
            walk(tri, start, x)
        }
    };
    *last = Some(v.fix());
    let best = d2(v.data().p);
    let mut index = v.data().index;
    // Another site at the same distance is a neighbour in the Delaunay graph (both are on
    // the empty circle around x).
    for e in v.out_edges() {
        let w = *e.to().data();
        if w.index < index && d2(w.p) == best {
            index = w.index;
        }
    }
    index
}

/// Greedy walk over Delaunay edges to the vertex nearest `x` (exact on a Delaunay graph).
fn walk<'a>(
    tri: &'a DelaunayTriangulation<Vertex>,
    start: spade::handles::FixedVertexHandle,
    x: [f64; 2],
) -> spade::handles::VertexHandle<'a, Vertex> {
    let d2 = |p: [f64; 2]| (p[0] - x[0]).powi(2) + (p[1] - x[1]).powi(2);
    let mut v = tri.vertex(start);
    let mut best = d2(v.data().p);
    loop {
        let mut next = None;
        for e in v.out_edges() {
            let w = e.to();
            let d = d2(w.data().p);
            if d < best {
                best = d;
                next = Some(w);
            }
        }
        match next {
            Some(w) => v = w,
            None => return v,
        }
    }
}

/// Sutherland–Hodgman against one half-plane: keep the part of the convex polygon `poly`
/// where `side(x) ≥ 0`.
fn clip(poly: &[[f64; 2]], side: impl Fn([f64; 2]) -> f64) -> Vec<[f64; 2]> {
    let s: Vec<f64> = poly.iter().map(|&p| side(p)).collect();
    if s.iter().all(|&v| v >= 0.0) {
        return poly.to_vec();
    }
    let mut out = Vec::with_capacity(poly.len() + 1);
    for i in 0..poly.len() {
        let j = (i + 1) % poly.len();
        let (a, b, sa, sb) = (poly[i], poly[j], s[i], s[j]);
        if sa >= 0.0 {
            out.push(a);
        }
        if (sa >= 0.0) != (sb >= 0.0) {
            let t = sa / (sa - sb);
            out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
        }
    }
    // A polygon reduced to a segment or a point has no area: no cell.
    if out.len() < 3 || polygon_area(&out) <= 0.0 {
        out.clear();
    }
    out
}

/// (b − a) × (x − a): positive when x is left of the directed line a → b.
fn cross(a: [f64; 2], b: [f64; 2], x: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (x[1] - a[1]) - (b[1] - a[1]) * (x[0] - a[0])
}

fn bbox(p: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for q in p {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    (lo, hi)
}

/// `hull` checked (at least 3 finite vertices, convex, some area) and made counter-clockwise.
fn ccw_hull(hull: &[[f64; 2]]) -> Result<Vec<[f64; 2]>> {
    let mut h: Vec<[f64; 2]> = hull.to_vec();
    if h.len() > 1 && h.first() == h.last() {
        h.pop();
    }
    if h.iter().any(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(Error::invalid("the hull has a vertex that is not finite"));
    }
    let area = polygon_area(&h);
    if h.len() < 3 || area == 0.0 {
        return Err(Error::invalid(
            "the hull needs at least 3 vertices enclosing some area",
        ));
    }
    if area < 0.0 {
        h.reverse();
    }
    let n = h.len();
    let scale = bbox(&h);
    let eps = 1e-9 * ((scale.1[0] - scale.0[0]) + (scale.1[1] - scale.0[1])).powi(2);
    for i in 0..n {
        if cross(h[i], h[(i + 1) % n], h[(i + 2) % n]) < -eps {
            return Err(Error::invalid("the hull is not convex"));
        }
    }
    Ok(h)
}

/// Signed area of a polygon (positive when counter-clockwise), not closed.
pub fn polygon_area(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    if n < 3 {
        return 0.0;
    }
    // Relative to the first vertex, for precision far from the origin.
    let o = p[0];
    let mut a = 0.0;
    for i in 1..n - 1 {
        a += cross(o, p[i], p[i + 1]);
    }
    0.5 * a
}

/// The convex hull of `points`, counter-clockwise, without collinear vertices (Andrew's
/// monotone chain). Fewer than 3 vertices when the points are collinear; non-finite points
/// are skipped.
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points
        .iter()
        .copied()
        .filter(|q| q[0].is_finite() && q[1].is_finite())
        .collect();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = h.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(s: f64) -> Vec<[f64; 2]> {
        vec![[0.0, 0.0], [s, 0.0], [s, s], [0.0, s]]
    }

    fn inside(poly: &[[f64; 2]], x: [f64; 2]) -> bool {
        (0..poly.len()).all(|i| cross(poly[i], poly[(i + 1) % poly.len()], x) >= -1e-9)
    }

    #[test]
    fn two_sites_halve_a_square() {
        let cells = voronoi_cells(
            &[[1.0, 1.0], [3.0, 1.0]],
            [([0.5, 0.5], 1.0), ([3.5, 1.0], -2.0), ([3.9, 3.9], 1.0)],
            &square(4.0),
        )
        .unwrap();
        assert!((polygon_area(&cells[0].polygon) - 8.0).abs() < 1e-12);
        assert!((polygon_area(&cells[1].polygon) - 8.0).abs() < 1e-12);
        assert_eq!((cells[0].samples, cells[1].samples), (1, 2));
        assert_eq!(cells[1].eps_max, 2.0);
        assert!((cells[1].eps_rms - 2.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn random_sites_tile_the_hull() {
        let mut rng = crate::testutil::Rng(7);
        let pts: Vec<[f64; 2]> = (0..300)
            .map(|_| [1000.0 + 50.0 * rng.unit(), 2000.0 + 30.0 * rng.unit()])
            .collect();
        let hull = convex_hull(&pts);
        let samples: Vec<([f64; 2], f64)> = pts.iter().map(|&p| (p, 1.0)).collect();
        let sites = &pts[..40];
        let cells = voronoi_cells(sites, samples, &hull).unwrap();
        let total: f64 = cells.iter().map(|c| polygon_area(&c.polygon)).sum();
        let ha = polygon_area(&hull);
        assert!((total - ha).abs() < 1e-9 * ha, "{total} vs {ha}");
        for (s, c) in sites.iter().zip(&cells) {
            assert!(inside(&c.polygon, *s));
            assert!(c.samples >= 1);
        }
        assert_eq!(cells.iter().map(|c| c.samples).sum::<usize>(), 300);
    }

    #[test]
    fn duplicates_collinear_and_single_sites() {
        let hull = square(2.0);
        let cells = voronoi_cells(&[[1.0, 1.0]], [([0.0, 0.0], 0.5)], &hull).unwrap();
        assert_eq!(polygon_area(&cells[0].polygon), 4.0);
        let cells = voronoi_cells(
            &[[0.5, 0.5], [1.0, 1.0], [0.5, 0.5], [1.5, 1.5]],
            [([0.4, 0.4], 0.5)],
            &hull,
        )
        .unwrap();
        assert!(cells[2].polygon.is_empty());
        assert_eq!(cells[0].samples, 1);
        let total: f64 = cells.iter().map(|c| polygon_area(&c.polygon)).sum();
        assert!((total - 4.0).abs() < 1e-12);
        // A tie between two sites goes to the lower index.
        let cells = voronoi_cells(&[[1.5, 1.0], [0.5, 1.0]], [([1.0, 1.0], 1.0)], &hull).unwrap();
        assert_eq!((cells[0].samples, cells[1].samples), (1, 0));
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(voronoi_cells(&[], [], &square(1.0)).is_err());
        assert!(voronoi_cells(&[[0.5, 0.5]], [], &[[0.0, 0.0], [1.0, 1.0]]).is_err());
        assert!(voronoi_cells(&[[f64::NAN, 0.5]], [], &square(1.0)).is_err());
        assert!(voronoi_cells(&[[0.5, 0.5]], [([0.1, 0.1], f64::NAN)], &square(1.0)).is_err());
        let dent = [[0.0, 0.0], [2.0, 0.0], [1.0, 0.2], [2.0, 2.0], [0.0, 2.0]];
        assert!(voronoi_cells(&[[0.5, 0.5]], [], &dent).is_err());
    }

    #[test]
    fn hull_is_ccw_and_minimal() {
        let pts = [
            [0.0, 0.0],
            [1.0, 0.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [1.0, 1.0],
            [0.0, 2.0],
        ];
        let h = convex_hull(&pts);
        assert_eq!(h.len(), 4);
        assert_eq!(polygon_area(&h), 4.0);
        assert_eq!(convex_hull(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]).len(), 2);
    }
}
