//! The quadtree detail selector of the height-map-to-mesh paper (papers/001, "Height map →
//! adaptive quadtree points → Delaunay mesh"): which samples of a raster become mesh
//! vertices, before [`super::triangulate`] turns them into a Delaunay mesh.
//!
//! The paper's rule: a quadrant is *detailed* when more than T % of its pixels lie outside
//! one standard deviation of its mean; a detailed quadrant is split into four, a quadrant
//! that is not detailed contributes its centre, and a detailed quadrant at the finest level
//! (where the next split would make quadrants smaller than 3×3) contributes all its
//! pixels. The image's corners, its centre and the centres of its four first quadrants are
//! always points. The threshold T is the only parameter.
//!
//! What the paper left open and what this module does (see [`select`]):
//! - **Any size.** The paper handled square images with an even side only. Here a
//!   `w × h` quadrant splits into columns `[0, w/2)`, `[w/2, w)` and rows likewise, so odd
//!   sides give children of unequal size (the second half one larger) and a side of 1 is
//!   not split (up to 4 children). A quadrant is at the finest level when a split would
//!   give a child narrower than 3 in either direction (`min(w, h) < 6`); a quadrant of one
//!   row or column is therefore always finest.
//! - **Nothing cut off.** The paper's leaves contribute only their centre, so the hull of
//!   its points could miss parts of the image (its figure 5). Here the vertices of the
//!   convex hull of the valid samples are always selected: every raster corner when the
//!   corners are valid, so the mesh covers the full rectangle.
//! - **Invalid samples** (nodata, or non-finite values) take no part in a quadrant's
//!   statistics and are never selected: a centre that is invalid is replaced by the valid
//!   sample of its quadrant nearest to it (Euclidean distance, ties to the smaller row,
//!   then column), or by nothing when the quadrant has no valid sample.
//! - **Ties.** "Outside one standard deviation" is strict (`|x − μ| > σ`, population σ,
//!   with a relative tolerance of 1e-9 on σ² so that rounding cannot turn the paper's
//!   two-value corner case, where every `|x − μ| = σ`, into outliers), and "more than T %"
//!   is strict too: T = 100 never splits, T = 0 splits every quadrant that has an outlier.
//! - **No depth limit**: the paper's `maxdepth` is not one of its user variables and is
//!   not needed to bound the work, so quadrants split down to the finest level.
//! - **Heights.** The paper gives each centre point the mean of the 3×3 pixels around
//!   it. [`select`] returns positions only; the caller takes each vertex's height from the
//!   sample itself (or from a decoded surface), so the mesh interpolates the data at its
//!   vertices instead of smoothing them.
//! - **Speed.** Each level of the tree reads each sample of its detailed quadrants three
//!   times (mean, σ, outliers): `O(n log n)` for `n` samples. The paper's `O(n⁴)`
//!   triangulation is replaced by the crate's incremental Delaunay triangulation; sites
//!   fed to it in [`insertion_order`] insert in about `O(n log n)`, while sorted sites (as
//!   [`select`] returns them) grow the hull column by column, about `O(n²)`.

use crate::error::{Error, Result};
use crate::geometry::triangulation::{Triangulation, orient};

/// The smallest side a quadrant may get by a split (the paper's 3×3 window).
const MIN_SIDE: usize = 3;

/// Relative tolerance on σ² in the outlier test (see the module docs).
const SIGMA_TOL: f64 = 1e-9;

/// A rectangle of samples: columns `x0..x0 + w`, rows `y0..y0 + h`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Quad {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
}

impl Quad {
    /// The up to four children: north-west, north-east, south-west, south-east, without
    /// the empty ones (a side of 1 is not split).
    fn children(self) -> impl Iterator<Item = Quad> {
        let halves = |a: usize, n: usize| [(a, n / 2), (a + n / 2, n - n / 2)];
        halves(self.y0, self.h)
            .into_iter()
            .flat_map(move |(y0, h)| {
                halves(self.x0, self.w)
                    .into_iter()
                    .filter(move |&(_, w)| w > 0 && h > 0)
                    .map(move |(x0, w)| Quad { x0, y0, w, h })
            })
    }

    /// Whether the next split would make a child smaller than 3 in either direction.
    fn finest(self) -> bool {
        self.w.min(self.h) < 2 * MIN_SIDE
    }

    /// The centre sample (for an even side, the first of the two middle ones).
    fn centre(self) -> (usize, usize) {
        (self.x0 + (self.w - 1) / 2, self.y0 + (self.h - 1) / 2)
    }
}

/// The raster as the selector reads it.
struct Grid<'a> {
    values: &'a [f64],
    /// Valid and finite.
    usable: Vec<bool>,
    width: usize,
    threshold: f64,
}

impl Grid<'_> {
    /// The rows of `q`: (row, values, usable), each `q.w` long.
    fn rows(&self, q: Quad) -> impl Iterator<Item = (usize, &[f64], &[bool])> {
        (q.y0..q.y0 + q.h).map(move |y| {
            let a = y * self.width + q.x0;
            (y, &self.values[a..a + q.w], &self.usable[a..a + q.w])
        })
    }

    /// Whether `q` is detailed: more than T % of its valid samples lie strictly outside one
    /// standard deviation of their mean. `None` when it has no valid sample.
    fn detailed(&self, q: Quad) -> Option<bool> {
        let (mut n, mut sum) = (0usize, 0.0f64);
        for (_, v, u) in self.rows(q) {
            for (&x, &ok) in v.iter().zip(u) {
                if ok {
                    n += 1;
                    sum += x;
                }
            }
        }
        if n == 0 {
            return None;
        }
        let mean = sum / n as f64;
        let mut ss = 0.0f64;
        for (_, v, u) in self.rows(q) {
            for (&x, &ok) in v.iter().zip(u) {
                if ok {
                    ss += (x - mean) * (x - mean);
                }
            }
        }
        let limit = ss / n as f64 * (1.0 + SIGMA_TOL);
        let mut outliers = 0usize;
        for (_, v, u) in self.rows(q) {
            for (&x, &ok) in v.iter().zip(u) {
                outliers += usize::from(ok && (x - mean) * (x - mean) > limit);
            }
        }
        Some(outliers as f64 * 100.0 > self.threshold * n as f64)
    }

    fn usable_at(&self, x: usize, y: usize) -> bool {
        self.usable[y * self.width + x]
    }

    /// The valid sample of `q` nearest to `(cx, cy)` (inside `q`): the point itself when
    /// valid, else by Euclidean distance, ties to the smaller row, then column.
    fn nearest_valid(&self, q: Quad, (cx, cy): (usize, usize)) -> Option<(usize, usize)> {
        if self.usable_at(cx, cy) {
            return Some((cx, cy));
        }
        let (x1, y1) = (q.x0 + q.w - 1, q.y0 + q.h - 1);
        let rmax = (cx - q.x0).max(x1 - cx).max(cy - q.y0).max(y1 - cy);
        let mut best: Option<(usize, usize, usize)> = None; // (d², row, col)
        let consider = |x: usize, y: usize, best: &mut Option<(usize, usize, usize)>| {
            if self.usable_at(x, y) {
                let d2 = x.abs_diff(cx).pow(2) + y.abs_diff(cy).pow(2);
                if best.is_none_or(|b| (d2, y, x) < b) {
                    *best = Some((d2, y, x));
                }
            }
        };
        for r in 1..=rmax {
            // Every sample on ring r (Chebyshev distance r) is at least r away.
            if best.is_some_and(|(d2, _, _)| d2 < r * r) {
                break;
            }
            let (ylo, yhi) = (cy.saturating_sub(r).max(q.y0), (cy + r).min(y1));
            let (xlo, xhi) = (cx.saturating_sub(r).max(q.x0), (cx + r).min(x1));
            for y in ylo..=yhi {
                if y.abs_diff(cy) == r {
                    for x in xlo..=xhi {
                        consider(x, y, &mut best);
                    }
                } else {
                    if cx >= q.x0 + r {
                        consider(cx - r, y, &mut best);
                    }
                    if cx + r <= x1 {
                        consider(cx + r, y, &mut best);
                    }
                }
            }
        }
        best.map(|(_, y, x)| (x, y))
    }

    /// The paper's `analyzeQuadrant` without its depth limit: the points of `q` into `out`.
    fn analyze(&self, q: Quad, out: &mut Vec<(usize, usize)>) {
        let Some(detailed) = self.detailed(q) else {
            return;
        };
        if !detailed {
            out.extend(self.nearest_valid(q, q.centre()));
        } else if q.finest() {
            for (y, _, u) in self.rows(q) {
                out.extend((0..q.w).filter(|&i| u[i]).map(|i| (q.x0 + i, y)));
            }
        } else {
            for c in q.children() {
                self.analyze(c, out);
            }
        }
    }

    /// The vertices of the convex hull of the valid samples (strictly convex corners only).
    fn hull_vertices(&self) -> Vec<(usize, usize)> {
        let mut ends = Vec::new();
        for (y, row) in self.usable.chunks_exact(self.width).enumerate() {
            if let Some(lo) = row.iter().position(|&u| u) {
                let hi = row.iter().rposition(|&u| u).unwrap_or(lo);
                ends.push((lo, y));
                if hi != lo {
                    ends.push((hi, y));
                }
            }
        }
        convex_hull(ends)
    }
}

/// The strictly convex vertices of the hull of `pts` (Andrew's monotone chain), counter-
/// clockwise in (col, row) coordinates from the smallest point; one or two points for a
/// degenerate set.
fn convex_hull(mut pts: Vec<(usize, usize)>) -> Vec<(usize, usize)> {
    pts.sort_unstable();
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let p = |a: (usize, usize)| [a.0 as i64, a.1 as i64];
    let mut hull: Vec<(usize, usize)> = Vec::with_capacity(pts.len() + 1);
    for pass in 0..2 {
        let start = hull.len();
        let it: Box<dyn Iterator<Item = &(usize, usize)>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &q in it {
            while hull.len() >= start + 2
                && orient(p(hull[hull.len() - 2]), p(hull[hull.len() - 1]), p(q)) <= 0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    if hull.len() < 3 {
        // All collinear: the two ends.
        return vec![pts[0], pts[pts.len() - 1]];
    }
    hull
}

/// The paper's selector: sample positions `(col, row)` of a `width × height` raster
/// (`values` row-major, row 0 north), sorted (by column, then row), distinct, all valid.
///
/// A sample takes part when `valid(i)` holds and `values[i]` is finite. Always selected:
/// the vertices of the convex hull of the valid samples (the four raster corners when they
/// are valid, so a mesh of the points covers the whole rectangle), the raster's centre and
/// the centres of its (up to) four first quadrants, each moved to the nearest valid sample
/// of its quadrant when it is invalid. Then each first quadrant is analysed as the paper
/// does: split while more than `threshold_pct` % of its valid samples lie outside one
/// standard deviation of their mean; a leaf contributes its centre (or the nearest valid
/// sample of it), a detailed quadrant at the finest level (`min(w, h) < 6`) all its valid
/// samples. See the module docs for how the paper's open points are settled.
///
/// Heights: the paper gives a leaf's point the mean of the 3×3 pixels around its centre.
/// This function returns positions only; use each position's own sample height (or a
/// decoded surface's value there), so that the mesh interpolates the data at its vertices.
///
/// Errors: `threshold_pct` outside `0..=100` (or NaN), or `values.len() != width × height`,
/// is [`Error::InvalidArgument`]. An empty raster gives no points.
pub fn select(
    values: &[f64],
    valid: &dyn Fn(usize) -> bool,
    width: usize,
    height: usize,
    threshold_pct: f64,
) -> Result<Vec<(usize, usize)>> {
    if !(0.0..=100.0).contains(&threshold_pct) {
        return Err(Error::invalid(format!(
            "quadtree threshold {threshold_pct} % must be between 0 and 100"
        )));
    }
    if width.checked_mul(height) != Some(values.len()) {
        return Err(Error::invalid(format!(
            "{} values for a {width}x{height} raster",
            values.len()
        )));
    }
    if values.is_empty() {
        return Ok(Vec::new());
    }
    let grid = Grid {
        values,
        usable: (0..values.len())
            .map(|i| valid(i) && values[i].is_finite())
            .collect(),
        width,
        threshold: threshold_pct,
    };
    let mut out = grid.hull_vertices();
    let root = Quad {
        x0: 0,
        y0: 0,
        w: width,
        h: height,
    };
    out.extend(grid.nearest_valid(root, root.centre()));
    for q in root.children() {
        out.extend(grid.nearest_valid(q, q.centre()));
        grid.analyze(q, &mut out);
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

/// Indices into `sites` in an order that the crate's incremental Delaunay triangulation
/// (and so [`super::triangulate`], which inserts in the order given) handles in
/// `O(n log n)`: the vertices of the sites' convex hull first (every later site then falls
/// inside the hull, so no insertion searches the hull from outside), then the rest along a
/// Hilbert curve (each insertion's point location starts next to the previous one).
/// Sorted input, such as [`select`]'s, instead grows the hull one column at a time.
pub fn insertion_order(sites: &[(usize, usize)]) -> Vec<usize> {
    let hull = convex_hull(sites.to_vec());
    let mut first: Vec<usize> = Vec::with_capacity(hull.len());
    let mut is_hull = vec![false; sites.len()];
    if !hull.is_empty() {
        let mut idx: std::collections::HashMap<(usize, usize), usize> =
            std::collections::HashMap::with_capacity(hull.len());
        for &h in &hull {
            idx.insert(h, usize::MAX);
        }
        for (i, s) in sites.iter().enumerate() {
            if let Some(slot) = idx.get_mut(s)
                && *slot == usize::MAX
            {
                *slot = i;
            }
        }
        for h in &hull {
            let i = idx[h];
            is_hull[i] = true;
            first.push(i);
        }
    }
    let side = sites
        .iter()
        .map(|&(x, y)| x.max(y))
        .max()
        .unwrap_or(0)
        .saturating_add(1)
        .next_power_of_two();
    let mut rest: Vec<(u64, usize)> = sites
        .iter()
        .enumerate()
        .filter(|&(i, _)| !is_hull[i])
        .map(|(i, &(x, y))| (hilbert(side as u64, x as u64, y as u64), i))
        .collect();
    rest.sort_unstable();
    first.extend(rest.into_iter().map(|(_, i)| i));
    first
}

/// The distance of `(x, y)` along the Hilbert curve filling a `side × side` square (`side` a
/// power of two).
fn hilbert(side: u64, mut x: u64, mut y: u64) -> u64 {
    let mut d = 0u64;
    let mut s = side / 2;
    while s > 0 {
        let rx = u64::from(x & s != 0);
        let ry = u64::from(y & s != 0);
        d += s * s * ((3 * rx) ^ ry);
        if ry == 0 {
            if rx == 1 {
                x = side - 1 - x;
                y = side - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        s /= 2;
    }
    d
}

/// Max error and RMSE, over the valid samples of a `width × height` raster, of the linear
/// (piecewise-planar) interpolant over the Delaunay triangulation of `sites`, each site at
/// its own sample's height: what a mesh of those vertices shows. A sample counts when
/// `valid(i)` holds and its value is finite (as in [`select`]). A valid sample outside the
/// triangulation (outside the sites' hull) makes both `f64::INFINITY`. Sites that are all
/// collinear are interpolated along their line. Triangles are those of the crate's exact
/// Delaunay triangulation with the sites inserted in [`insertion_order`] (among co-circular
/// sites, which triangulation wins depends on that order).
///
/// # Panics
///
/// When `values.len() != width × height`, or a site lies outside the raster, is not a
/// valid sample or repeats another.
// Used by the tests and examples/quadtree_vs_greedy.rs (which includes this file).
#[allow(dead_code)]
pub fn linear_errors(
    values: &[f64],
    valid: &dyn Fn(usize) -> bool,
    width: usize,
    height: usize,
    sites: &[(usize, usize)],
) -> (f64, f64) {
    assert_eq!(
        values.len(),
        width * height,
        "values for a {width}x{height} raster"
    );
    let usable: Vec<bool> = (0..values.len())
        .map(|i| valid(i) && values[i].is_finite())
        .collect();
    let (est, _) = linear_surface(values, &usable, (width, height), sites, false);
    let (mut max, mut ss, mut n) = (0.0f64, 0.0f64, 0usize);
    for (i, &e) in est.iter().enumerate() {
        if !usable[i] {
            continue;
        }
        if e.is_nan() {
            return (f64::INFINITY, f64::INFINITY);
        }
        let d = (e - values[i]).abs();
        max = max.max(d);
        ss += d * d;
        n += 1;
    }
    (max, if n == 0 { 0.0 } else { (ss / n as f64).sqrt() })
}

/// The linear interpolant of [`linear_errors`] at every usable sample (NaN elsewhere and
/// outside the triangulation), and with `keep_triangles` the triangles (none when the
/// sites are collinear).
#[allow(clippy::type_complexity)]
fn linear_surface(
    values: &[f64],
    usable: &[bool],
    (width, height): (usize, usize),
    sites: &[(usize, usize)],
    keep_triangles: bool,
) -> (Vec<f64>, Vec<[(usize, usize); 3]>) {
    for &(x, y) in sites {
        assert!(
            x < width && y < height,
            "site ({x}, {y}) outside the raster"
        );
        assert!(
            usable[y * width + x],
            "site ({x}, {y}) is not a valid sample"
        );
    }
    let z = |(x, y): (usize, usize)| values[y * width + x];
    let mut est = vec![f64::NAN; values.len()];
    let order = insertion_order(sites);
    let mut tri = Triangulation::default();
    for &i in &order {
        let (x, y) = sites[i];
        tri.insert_near([x as i64, y as i64], None)
            .expect("distinct sites inside the coordinate limit");
    }
    let mut triangles = Vec::new();
    if tri.is_2d() {
        // Vertex ids are insertion indices.
        let site_of = |v: u32| sites[order[v as usize]];
        for t in tri.real_triangles() {
            let corners = tri.tri(t).v.map(site_of);
            fill_triangle(corners.map(|s| (s, z(s))), width, height, usable, &mut est);
            if keep_triangles {
                triangles.push(corners);
            }
        }
    } else {
        fill_collinear(sites, &z, width, usable, &mut est);
    }
    (est, triangles)
}

/// Write the plane through a triangle's three (site, height) corners into `est` at every
/// valid sample inside it or on its boundary (rows scanned exactly, no bounding box).
fn fill_triangle(
    corners: [((usize, usize), f64); 3],
    width: usize,
    height: usize,
    usable: &[bool],
    est: &mut [f64],
) {
    let p = corners.map(|((x, y), _)| [x as i64, y as i64]);
    let h = corners.map(|(_, z)| z);
    let (p, h) = if orient(p[0], p[1], p[2]) < 0 {
        ([p[0], p[2], p[1]], [h[0], h[2], h[1]])
    } else {
        (p, h)
    };
    let det = orient(p[0], p[1], p[2]);
    if det == 0 {
        return;
    }
    let ymin = p.iter().map(|q| q[1]).min().unwrap_or(0).max(0);
    let ymax = p
        .iter()
        .map(|q| q[1])
        .max()
        .unwrap_or(0)
        .min(height as i64 - 1);
    for y in ymin..=ymax {
        // Inside ⇔ orient(p_k, p_k+1, s) ≥ 0 for each edge: dy·(x − px) ≤ dx·(y − py).
        let (mut xlo, mut xhi) = (0i64, width as i64 - 1);
        for k in 0..3 {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let rhs = dx * (y - a[1]);
            match dy.signum() {
                1 => xhi = xhi.min(a[0] + rhs.div_euclid(dy)),
                -1 => xlo = xlo.max(a[0] - rhs.div_euclid(-dy)),
                _ if rhs < 0 => xhi = -1,
                _ => {}
            }
        }
        for x in xlo..=xhi {
            let i = y as usize * width + x as usize;
            if !usable[i] {
                continue;
            }
            let s = [x, y];
            let w0 = orient(p[1], p[2], s) as f64;
            let w1 = orient(p[2], p[0], s) as f64;
            let w2 = orient(p[0], p[1], s) as f64;
            est[i] = (w0 * h[0] + w1 * h[1] + w2 * h[2]) / det as f64;
        }
    }
}

/// Fewer than three non-collinear sites: interpolate linearly along their line.
fn fill_collinear(
    sites: &[(usize, usize)],
    z: &dyn Fn((usize, usize)) -> f64,
    width: usize,
    usable: &[bool],
    est: &mut [f64],
) {
    let Some(&s0) = sites.first() else { return };
    let p = |(x, y): (usize, usize)| [x as i64, y as i64];
    let far = sites.iter().copied().find(|&s| s != s0);
    let dir = far.map_or([1, 0], |s1| [p(s1)[0] - p(s0)[0], p(s1)[1] - p(s0)[1]]);
    let param = |q: [i64; 2]| (q[0] - p(s0)[0]) * dir[0] + (q[1] - p(s0)[1]) * dir[1];
    let mut along: Vec<(i64, f64)> = sites.iter().map(|&s| (param(p(s)), z(s))).collect();
    along.sort_unstable_by_key(|a| a.0);
    for (i, e) in est.iter_mut().enumerate() {
        if !usable[i] {
            continue;
        }
        let q = [(i % width) as i64, (i / width) as i64];
        let on_line = match far {
            Some(s1) => orient(p(s0), p(s1), q) == 0,
            None => q == p(s0),
        };
        if !on_line {
            continue;
        }
        let t = param(q);
        let k = along.partition_point(|a| a.0 < t);
        if k < along.len() && along[k].0 == t {
            *e = along[k].1;
        } else if k > 0 && k < along.len() {
            let ((t0, z0), (t1, z1)) = (along[k - 1], along[k]);
            *e = z0 + (z1 - z0) * (t - t0) as f64 / (t1 - t0) as f64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::Rng;

    fn all(_: usize) -> bool {
        true
    }

    fn noise(w: usize, h: usize, seed: u64) -> Vec<f64> {
        let mut rng = Rng(seed);
        (0..w * h).map(|_| rng.unit() * 1000.0).collect()
    }

    /// Every valid position of the raster, sorted like [`select`]'s output.
    fn every_valid(w: usize, h: usize, ok: &dyn Fn(usize) -> bool) -> Vec<(usize, usize)> {
        let mut v: Vec<(usize, usize)> = (0..w * h)
            .filter(|&i| ok(i))
            .map(|i| (i % w, i / w))
            .collect();
        v.sort_unstable();
        v
    }

    /// Twice the area of the convex hull of `pts`.
    fn hull_area2(pts: &[(usize, usize)]) -> i64 {
        let h = convex_hull(pts.to_vec());
        (0..h.len())
            .map(|k| {
                let (a, b) = (h[k], h[(k + 1) % h.len()]);
                a.0 as i64 * b.1 as i64 - b.0 as i64 * a.1 as i64
            })
            .sum::<i64>()
            .abs()
    }

    fn check_output(pts: &[(usize, usize)], w: usize, h: usize, ok: &dyn Fn(usize) -> bool) {
        assert!(pts.windows(2).all(|p| p[0] < p[1]), "sorted and distinct");
        for &(x, y) in pts {
            assert!(x < w && y < h, "({x}, {y}) outside {w}x{h}");
            assert!(ok(y * w + x), "({x}, {y}) is invalid");
        }
    }

    #[test]
    fn children_partition_their_quadrant() {
        for (w, h) in [
            (1, 1),
            (1, 2),
            (2, 1),
            (3, 3),
            (7, 4),
            (6, 6),
            (11, 13),
            (2, 9),
        ] {
            let q = Quad { x0: 5, y0: 3, w, h };
            let kids: Vec<Quad> = q.children().collect();
            assert!((1..=4).contains(&kids.len()));
            let mut seen = vec![0; w * h];
            for c in &kids {
                assert!(c.w > 0 && c.h > 0);
                for y in c.y0..c.y0 + c.h {
                    for x in c.x0..c.x0 + c.w {
                        seen[(y - 3) * w + x - 5] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&s| s == 1), "{w}x{h}: {kids:?}");
            if !q.finest() {
                assert!(kids.iter().all(|c| c.w >= 3 && c.h >= 3));
            }
        }
        assert!(
            Quad {
                x0: 0,
                y0: 0,
                w: 1,
                h: 500
            }
            .finest()
        );
        assert!(
            !Quad {
                x0: 0,
                y0: 0,
                w: 6,
                h: 6
            }
            .finest()
        );
    }

    #[test]
    fn threshold_zero_selects_every_valid_sample_of_noise() {
        let (w, h) = (64, 48);
        let v = noise(w, h, 1);
        assert_eq!(
            select(&v, &all, w, h, 0.0).unwrap(),
            every_valid(w, h, &all)
        );
        // With about 10 % nodata (and NaNs marked valid, which count as invalid).
        let (w, h) = (37, 29);
        let mut rng = Rng(2);
        let mut v = noise(w, h, 3);
        let holes: Vec<bool> = (0..w * h).map(|_| rng.unit() < 0.1).collect();
        v[5 * w + 7] = f64::NAN;
        let ok = |i: usize| !holes[i];
        let usable = |i: usize| ok(i) && v[i].is_finite();
        let got = select(&v, &ok, w, h, 0.0).unwrap();
        check_output(&got, w, h, &usable);
        assert_eq!(got, every_valid(w, h, &usable));
    }

    #[test]
    fn threshold_hundred_selects_only_the_roots_corners_and_centres() {
        let (w, h) = (50, 40);
        let v = noise(w, h, 4);
        let got = select(&v, &all, w, h, 100.0).unwrap();
        let mut want = vec![
            (0, 0),
            (49, 0),
            (0, 39),
            (49, 39),
            (24, 19),
            (12, 9),
            (37, 9),
            (12, 29),
            (37, 29),
        ];
        want.sort_unstable();
        assert_eq!(got, want);
    }

    /// The paper's figure 2: pixels of two extreme values in equal numbers all lie exactly
    /// one standard deviation from the mean, so no quadrant is detailed, whatever T.
    #[test]
    fn two_values_in_equal_numbers_are_never_detailed() {
        let (w, h) = (16, 16);
        let v: Vec<f64> = (0..w * h)
            .map(|i| if (i % w + i / w) % 2 == 0 { 0.0 } else { 255.0 })
            .collect();
        assert_eq!(select(&v, &all, w, h, 0.0).unwrap().len(), 9);
    }

    #[test]
    fn odd_and_thin_sizes_cover_the_full_rectangle() {
        let sizes = [
            (1, 1),
            (1, 2),
            (2, 1),
            (1, 7),
            (7, 1),
            (2, 3),
            (3, 2),
            (5, 5),
            (6, 7),
            (37, 23),
            (101, 3),
            (3, 101),
            (257, 129),
        ];
        for (k, &(w, h)) in sizes.iter().enumerate() {
            // A smooth surface with a bump, so some quadrants split and some do not.
            let mut v: Vec<f64> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    (x / 9.0).sin() * 30.0 + y * 0.5 + (-(x - 20.0).powi(2) / 8.0).exp() * 50.0
                })
                .collect();
            if k % 2 == 1 {
                v = noise(w, h, k as u64);
            }
            for t in [0.0, 30.0, 45.0, 100.0] {
                let got = select(&v, &all, w, h, t).unwrap();
                check_output(&got, w, h, &all);
                for c in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
                    assert!(got.binary_search(&c).is_ok(), "{w}x{h} T={t}: corner {c:?}");
                }
                assert_eq!(
                    hull_area2(&got),
                    2 * (w as i64 - 1) * (h as i64 - 1),
                    "{w}x{h} T={t}"
                );
                let (max, _) = linear_errors(&v, &all, w, h, &got);
                assert!(max.is_finite(), "{w}x{h} T={t}: a sample outside the mesh");
            }
        }
    }

    #[test]
    fn invalid_samples_are_never_selected_and_nothing_valid_is_cut_off() {
        let (w, h) = (61, 47);
        let mut rng = Rng(9);
        let v = noise(w, h, 10);
        // Half the samples missing, plus every sample near the north-west corner and a
        // whole quadrant of the root.
        let holes: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                rng.unit() < 0.5 || x + y < 9 || (x >= 30 && y >= 23)
            })
            .collect();
        let ok = |i: usize| !holes[i];
        for t in [0.0, 20.0, 35.0, 45.0, 100.0] {
            let got = select(&v, &ok, w, h, t).unwrap();
            check_output(&got, w, h, &ok);
            let (max, rmse) = linear_errors(&v, &ok, w, h, &got);
            assert!(
                max.is_finite() && rmse.is_finite(),
                "T={t}: a valid sample cut off"
            );
        }
        let none = select(&v, &|_| false, w, h, 10.0).unwrap();
        assert!(none.is_empty());
    }

    #[test]
    fn an_invalid_centre_moves_to_the_nearest_valid_sample_of_its_quadrant() {
        // Constant: no quadrant is detailed, so the points are the corners and centres.
        let (w, h) = (10, 10);
        let v = vec![7.0; w * h];
        let base = select(&v, &all, w, h, 50.0).unwrap();
        assert!(base.binary_search(&(7, 7)).is_ok());
        let ok = |i: usize| i != 7 * w + 7;
        let got = select(&v, &ok, w, h, 50.0).unwrap();
        // Four samples at distance 1; ties go to the smaller row: (col 7, row 6).
        assert!(got.binary_search(&(7, 7)).is_err());
        assert!(got.binary_search(&(7, 6)).is_ok(), "{got:?}");
        assert_eq!(got.len(), base.len());
        // A quadrant without valid samples adds nothing.
        let ok = |i: usize| !(i % w >= 5 && i / w >= 5);
        let got = select(&v, &ok, w, h, 50.0).unwrap();
        check_output(&got, w, h, &ok);
        assert!(got.iter().all(|&(x, y)| x < 5 || y < 5));
    }

    #[test]
    fn bad_arguments_are_refused() {
        let v = vec![0.0; 12];
        for t in [-0.1, 100.5, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                select(&v, &all, 4, 3, t),
                Err(Error::InvalidArgument { .. })
            ));
        }
        assert!(select(&v, &all, 5, 3, 10.0).is_err());
        assert!(select(&[], &all, 0, 0, 10.0).unwrap().is_empty());
        // Constant: nothing is detailed. Corners, the centre (1, 1), the quadrants'
        // centres (0, 0), (2, 0), (0, 1), (2, 1) (quadrants of 2|2 columns, 1|2 rows).
        let got = select(&v, &all, 4, 3, 0.0).unwrap();
        assert_eq!(
            got,
            vec![
                (0, 0),
                (0, 1),
                (0, 2),
                (1, 1),
                (2, 0),
                (2, 1),
                (3, 0),
                (3, 2)
            ]
        );
    }

    #[test]
    fn linear_errors_of_planes_vanish_and_bumps_show() {
        // A plane is reproduced exactly by any triangulation of its corners.
        let (w, h) = (23, 17);
        let plane: Vec<f64> = (0..w * h)
            .map(|i| 2.0 * (i % w) as f64 - 3.0 * (i / w) as f64 + 1.0)
            .collect();
        let corners = [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1), (5, 9)];
        let (max, rmse) = linear_errors(&plane, &all, w, h, &corners);
        assert!(max < 1e-9 && rmse < 1e-9, "{max} {rmse}");
        // Every sample a site: exact.
        let v = noise(w, h, 5);
        assert_eq!(
            linear_errors(&v, &all, w, h, &every_valid(w, h, &all)),
            (0.0, 0.0)
        );
        // A 3×3 bump of 4 at the centre, corners at 0: the centre is off by 4.
        let mut b = vec![0.0; 9];
        b[4] = 4.0;
        let (max, rmse) = linear_errors(&b, &all, 3, 3, &[(0, 0), (2, 0), (0, 2), (2, 2)]);
        assert_eq!(max, 4.0);
        assert!((rmse - 4.0 / 3.0).abs() < 1e-12);
        // A valid sample outside the sites' hull.
        assert_eq!(
            linear_errors(&b, &all, 3, 3, &[(0, 0), (2, 0), (0, 2)]).0,
            f64::INFINITY
        );
        // ... unless the samples outside (x + y > 2) are invalid.
        let ok = |i: usize| i % 3 + i / 3 <= 2;
        assert_eq!(
            linear_errors(&b, &ok, 3, 3, &[(0, 0), (2, 0), (0, 2)]).0,
            4.0
        );
        // Collinear sites: linear along their line.
        let row: Vec<f64> = (0..9).map(|x| (x * x) as f64).collect();
        let (max, _) = linear_errors(&row, &all, 9, 1, &[(0, 0), (4, 0), (8, 0)]);
        // Between 0 and 4 the chord of x² is 4x: largest gap 4 at x = 2.
        assert_eq!(max, 4.0);
    }

    /// The row scan of each triangle reaches exactly the samples inside it or on its
    /// boundary: against a brute-force search over all triangles, on random sites.
    #[test]
    fn the_linear_surface_matches_a_brute_force_evaluation() {
        let (w, h) = (53, 41);
        let v = noise(w, h, 12);
        let mut rng = Rng(13);
        let usable: Vec<bool> = (0..w * h).map(|_| rng.unit() < 0.9).collect();
        for keep in [0.02, 0.2] {
            let sites: Vec<(usize, usize)> = (0..w * h)
                .filter(|&i| usable[i] && rng.unit() < keep)
                .map(|i| (i % w, i / w))
                .collect();
            let (est, tris) = linear_surface(&v, &usable, (w, h), &sites, true);
            assert!(!tris.is_empty());
            let p = |(x, y): (usize, usize)| [x as i64, y as i64];
            let mut inside = 0;
            for i in (0..w * h).filter(|&i| usable[i]) {
                let s = [(i % w) as i64, (i / w) as i64];
                let hit = tris.iter().find_map(|t| {
                    let [a, b, c] = t.map(p);
                    let d = orient(a, b, c) as f64;
                    let ws = [orient(b, c, s), orient(c, a, s), orient(a, b, s)];
                    (ws.iter().all(|&x| x >= 0) || ws.iter().all(|&x| x <= 0)).then(|| {
                        let z = t.map(|(x, y)| v[y * w + x]);
                        (ws[0] as f64 * z[0] + ws[1] as f64 * z[1] + ws[2] as f64 * z[2]) / d
                    })
                });
                match hit {
                    Some(z) => {
                        inside += 1;
                        assert!((z - est[i]).abs() < 1e-9, "{s:?}: {z} vs {}", est[i]);
                    }
                    None => assert!(est[i].is_nan(), "{s:?} is outside every triangle"),
                }
            }
            assert!(inside > w * h / 2);
        }
    }

    #[test]
    fn insertion_order_is_a_permutation_with_the_hull_first() {
        let v = noise(40, 30, 6);
        let sites = select(&v, &all, 40, 30, 40.0).unwrap();
        let order = insertion_order(&sites);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..sites.len()).collect::<Vec<_>>());
        let mut first: Vec<(usize, usize)> = order[..4].iter().map(|&i| sites[i]).collect();
        first.sort_unstable();
        assert_eq!(first, vec![(0, 0), (0, 29), (39, 0), (39, 29)]);
    }

    /// A 2000×1500 raster (3 M samples): selection at three thresholds and the triangulation
    /// of millions of points finish with the expected counts. Their times are printed, not
    /// checked (speed is measured in the benches).
    #[test]
    fn millions_of_samples_select_and_mesh() {
        let (w, h) = (2000, 1500);
        let mut rng = Rng(11);
        let v: Vec<f64> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let hill = 300.0 * (x / 170.0).sin() * (y / 230.0).cos();
                let flat = if x < 700.0 { 0.0 } else { hill };
                flat + rng.unit() * if y < 500.0 { 0.0 } else { 3.0 }
            })
            .collect();
        let t0 = std::time::Instant::now();
        let mut counts = Vec::new();
        for t in [0.0, 35.0, 100.0] {
            let pts = select(&v, &all, w, h, t).unwrap();
            counts.push(pts.len());
        }
        let took = t0.elapsed();
        eprintln!("3 selections of {w}x{h}: {took:?}, {counts:?} points");
        assert_eq!(counts[2], 9);
        assert!(counts[0] > 1_000_000, "{counts:?}");
        // Meshing: 2.65 M points in release builds, 0.49 M in debug builds.
        let t = if cfg!(debug_assertions) { 35.0 } else { 0.0 };
        let pts = select(&v, &all, w, h, t).unwrap();
        let t1 = std::time::Instant::now();
        let (max, _) = linear_errors(&v, &all, w, h, &pts);
        let took = t1.elapsed();
        eprintln!("linear_errors of {} points: {took:?}", pts.len());
        assert!(max.is_finite());
    }
}
