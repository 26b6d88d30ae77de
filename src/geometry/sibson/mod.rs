//! Sibson's natural-neighbour interpolant over the sites, evaluated canonically.
//!
//! The weight of a natural neighbour v of p is the area p's Voronoi cell would steal from v's
//! if p were inserted. That cell comes from the Bowyer–Watson cavity of p (the triangles whose
//! circumcircle strictly contains p): for each cavity-boundary vertex v_i (counter-clockwise
//! v_0 … v_{k−1}) the stolen region is the convex polygon
//! `[cc(p, v_i, v_{i+1}), C(t_1), …, C(t_m), cc(p, v_{i−1}, v_i)]` where t_1 … t_m are the
//! cavity triangles around v_i and C their circumcentres (Watson's construction).
//!
//! Determinism: the cavity is a set defined by exact integer predicates, the boundary cycle
//! starts at its lowest vertex id, and every float operation runs in a fixed order on values
//! derived only from the sites' integer positions and heights, so the result is a pure
//! function of (sites, p): the same bits for any locate hint, window or thread.
//! Samples on a hull edge take the linear interpolant along that edge (Sibson's limit there);
//! when every site is collinear the surface is piecewise linear along the line.
//!
//! Rooms: this file holds the surface (insertion, per-triangle data, compaction) and the
//! walks over grids, windows and lattices; `cavity` evaluates one point fast (its cavity
//! found or reused, then the spec's floating-point sequence); `reference` is the spec's
//! operation order with nothing reused, the yardstick of the tests and the fallback.

use crate::geometry::triangulation::{Location, Triangulation, orient};

/// Scratch buffers for evaluation (reuse one per thread to avoid allocation). Besides
/// buffers it holds the last cavity's structure, reused while the next query point has the
/// same cavity (checked exactly, see [`Surface::eval_in`]).
#[derive(Default, Clone, Debug)]
pub struct Scratch {
    /// `mark[t] == stamp` when triangle t is in the current cavity, at `slot[t]`.
    mark: Vec<u32>,
    slot: Vec<u32>,
    /// `seen[t] == stamp` when triangle t was tested and found outside the cavity.
    seen: Vec<u32>,
    stamp: u32,
    cavity: Vec<u32>,
    stack: Vec<u32>,
    centres: Vec<[f64; 2]>,
    bnd: Vec<(u32, u32, u32)>,
    cycle: Vec<(u32, u32, u32)>,
    poly: Vec<[f64; 2]>,
    /// The boundary walk: (vertex, its fan's range in `walk_fan`) in walk order.
    walk: Vec<(u32, u32, u32)>,
    walk_fan: Vec<u32>,
    // The reusable structure of the last cavity, in the spec's order: the exact circle tests
    // of its triangles and of the real triangles next to it, each cavity triangle's first
    // vertex and circumcentre offset, the cycle's vertices and heights from the lowest site
    // id, and per vertex its fan (cavity slots) from the outgoing edge's triangle.
    cav_circles: Vec<Circle>,
    out_circles: Vec<Circle>,
    cav_ao: Vec<([i64; 2], [f64; 2])>,
    /// Hull edges of the cavity's triangles (a sample on one takes the edge's interpolant).
    hull_edges: Vec<(u32, u32)>,
    vpos: Vec<[i64; 2]>,
    vh: Vec<f64>,
    fan_start: Vec<u32>,
    fan: Vec<u32>,
    pv: Vec<[f64; 2]>,
    /// The surface generation the structure belongs to (0: none).
    generation: u64,
}

/// One triangle's exact circumcircle test (see [`TriInfo`]); `d == 0`: use the general
/// predicate on triangle `t`.
#[derive(Clone, Copy, Debug, Default)]
struct Circle {
    a: [i64; 2],
    n: [i64; 2],
    d: i64,
    t: u32,
}

impl Scratch {
    /// Size the per-triangle marks for `nt` slots and start a new visit stamp (clearing
    /// every mark when it wraps); forgets the reusable structure.
    fn next_stamp(&mut self, nt: usize) -> u32 {
        if self.mark.len() < nt {
            self.mark.resize(nt, 0);
            self.slot.resize(nt, 0);
            self.seen.resize(nt, 0);
        }
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.mark.iter_mut().for_each(|m| *m = 0);
            self.seen.iter_mut().for_each(|m| *m = 0);
            self.stamp = 1;
        }
        self.generation = 0;
        self.stamp
    }
}

/// The interpolating surface: a triangulation of the sites and their heights.
#[derive(Clone, Debug, Default)]
pub struct Surface {
    tri: Triangulation,
    heights: Vec<f64>,
    info: Vec<TriInfo>,
    /// Changes on every insertion (unique across surfaces), so a [`Scratch`] never reuses a
    /// structure from another surface or an older state of this one.
    generation: u64,
}

/// A fresh surface generation.
fn next_generation() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

#[inline]
fn sub(a: [i64; 2], b: [i64; 2]) -> [f64; 2] {
    [(a[0] - b[0]) as f64, (a[1] - b[1]) as f64]
}

/// Circumcentre of (0, a, b), `a` and `b` given relative to the origin.
#[inline]
fn cc0(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    let d = 2.0 * (a[0] * b[1] - a[1] * b[0]);
    let la = a[0] * a[0] + a[1] * a[1];
    let lb = b[0] * b[0] + b[1] * b[1];
    [(b[1] * la - a[1] * lb) / d, (a[0] * lb - b[0] * la) / d]
}

/// What the evaluator keeps per triangle slot that does not depend on the query point: the
/// canonical first vertex, the circumcentre's offset from it (the spec's `cc(b − a, c − a)`,
/// so `C(t)` relative to p is one addition per coordinate), and an exact integer form of the
/// circumcircle test. Kept in step with the triangulation by [`Surface::insert_near`].
#[derive(Clone, Copy, Debug, Default)]
struct TriInfo {
    a: [i64; 2],
    o: [f64; 2],
    /// p is strictly inside the circumcircle iff `d·|p − a|² < 2 (p − a)·n` (exact in
    /// i128 while the triangle spans under 2^19). `d == 0`: fall back to [`incircle`].
    n: [i64; 2],
    d: i64,
}

/// Triangles spanning less than this use the precomputed integer circle test.
const EXACT_SPAN: i64 = 1 << 19;

impl TriInfo {
    fn of(tri: &Triangulation, t: u32) -> TriInfo {
        let v = tri.tri(t).v;
        if tri.tri(t).is_ghost() {
            return TriInfo::default();
        }
        let r0 = if v[0] < v[1] && v[0] < v[2] {
            0
        } else if v[1] < v[2] {
            1
        } else {
            2
        };
        let a = tri.point(v[r0]);
        let b = tri.point(v[(r0 + 1) % 3]);
        let c = tri.point(v[(r0 + 2) % 3]);
        let (u, w) = ([b[0] - a[0], b[1] - a[1]], [c[0] - a[0], c[1] - a[1]]);
        // Exactly the reference's float operations: (b − p) − (a − p) is b − a exactly.
        let o = cc0([u[0] as f64, u[1] as f64], [w[0] as f64, w[1] as f64]);
        let span = u.iter().chain(&w).map(|x| x.abs()).max().unwrap_or(0);
        let (n, d) = if span < EXACT_SPAN {
            let (lu, lw) = (u[0] * u[0] + u[1] * u[1], w[0] * w[0] + w[1] * w[1]);
            (
                [w[1] * lu - u[1] * lw, u[0] * lw - w[0] * lu],
                2 * (u[0] * w[1] - u[1] * w[0]),
            )
        } else {
            ([0, 0], 0)
        };
        TriInfo { a, o, n, d }
    }
}

impl Surface {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn triangulation(&self) -> &Triangulation {
        &self.tri
    }

    /// Add a site at integer position `p` with height `h`; returns its id.
    pub fn insert(&mut self, p: [i64; 2], h: f64) -> crate::error::Result<u32> {
        self.insert_near(p, h, None)
    }

    /// [`insert`](Self::insert) with a triangle near `p` to start the location walk from.
    pub fn insert_near(
        &mut self,
        p: [i64; 2],
        h: f64,
        hint: Option<u32>,
    ) -> crate::error::Result<u32> {
        let was_2d = self.tri.is_2d();
        let id = self.tri.insert_near(p, hint)?;
        self.heights.push(h);
        self.generation = next_generation();
        let slots = self.tri.num_triangle_slots();
        if self.info.len() < slots {
            self.info.resize(slots, TriInfo::default());
        }
        if was_2d {
            for &t in self.tri.created() {
                self.info[t as usize] = TriInfo::of(&self.tri, t);
            }
        } else if self.tri.is_2d() {
            for t in 0..slots as u32 {
                self.info[t as usize] = TriInfo::of(&self.tri, t);
            }
        }
        Ok(id)
    }

    /// Store the triangles in spatial order (see [`Triangulation::compact_spatially`]): the
    /// same surface, faster to evaluate over a grid. Call it once the sites are all in.
    pub fn compact(&mut self) {
        if !self.tri.is_2d() {
            return;
        }
        // Free the old per-triangle data first: on dense site sets it is the largest part of
        // the surface.
        self.info = Vec::new();
        self.tri.compact_spatially();
        let slots = self.tri.num_triangle_slots();
        self.info = (0..slots as u32)
            .map(|t| TriInfo::of(&self.tri, t))
            .collect();
        self.generation = next_generation();
    }

    /// The surface's value at `p`, or `None` outside the sites' convex hull.
    /// `hint` is a triangle to start the walk from; it is updated to where `p` was found.
    pub fn eval(&self, p: [i64; 2], hint: &mut u32, s: &mut Scratch) -> Option<f64> {
        if !self.tri.is_2d() {
            return self.eval_collinear(p);
        }
        match self.tri.locate(p, Some(*hint)) {
            Location::Vertex(v) => Some(self.heights[v as usize]),
            Location::Outside => None,
            Location::Triangle(t) => {
                *hint = t;
                Some(self.eval_in(p, t, s))
            }
        }
    }

    /// The surface's value at `p` (`None` outside the hull), for a sequence of nearby points
    /// on one scratch: from the last point's cavity when p lies in one of its circles (see
    /// `eval_near`), else by a walk from `hint`. `hint` becomes a triangle near p.
    pub fn eval_seq(&self, p: [i64; 2], hint: &mut Option<u32>, s: &mut Scratch) -> Option<f64> {
        if !self.tri.is_2d() {
            return self.eval_collinear(p);
        }
        if let Some(v) = self.eval_near(p, hint, s) {
            return Some(v);
        }
        match self.tri.locate(p, *hint) {
            Location::Vertex(v) => Some(self.heights[v as usize]),
            Location::Triangle(t) => {
                *hint = Some(t);
                Some(self.eval_in(p, t, s))
            }
            Location::Outside => None,
        }
    }

    /// Evaluate every sample of the window `[x0, x0+w) × [y0, y0+h)` of the integer grid for
    /// which `want(x, y)` holds. Returns row-major values of the window (NaN where not
    /// wanted); `None` when a wanted sample lies outside the sites' hull.
    pub fn eval_window(
        &self,
        x0: i64,
        y0: i64,
        w: usize,
        h: usize,
        want: impl Fn(i64, i64) -> bool,
    ) -> Option<Vec<f64>> {
        let mut out = vec![f64::NAN; w * h];
        self.eval_window_into(x0, y0, w, h, want, &mut out)
            .then_some(out)
    }

    /// [`eval_window`](Self::eval_window) into `out` (`w·h` values, left NaN where not
    /// wanted); `false` when a wanted sample lies outside the sites' hull.
    pub fn eval_window_into(
        &self,
        x0: i64,
        y0: i64,
        w: usize,
        h: usize,
        want: impl Fn(i64, i64) -> bool,
        out: &mut [f64],
    ) -> bool {
        self.eval_lattice_into(x0, y0, w, h, 1, &want, out);
        for (i, v) in out.iter().enumerate() {
            let (x, y) = (x0 + (i % w) as i64, y0 + (i / w) as i64);
            if v.is_nan() && want(x, y) {
                return false;
            }
        }
        true
    }

    /// Evaluate the lattice points `(x0 + i·step, y0 + j·step)`, `i < w`, `j < h`, for which
    /// `want` holds, row by row ([`eval_seq`](Self::eval_seq)). Points outside the sites'
    /// hull (and unwanted ones) are NaN. Each value is the same as [`eval`](Self::eval) gives.
    pub fn eval_lattice(
        &self,
        x0: i64,
        y0: i64,
        w: usize,
        h: usize,
        step: i64,
        want: &dyn Fn(i64, i64) -> bool,
    ) -> Vec<f64> {
        let mut out = vec![f64::NAN; w * h];
        self.eval_lattice_into(x0, y0, w, h, step, want, &mut out);
        out
    }

    /// [`eval_lattice`](Self::eval_lattice) into `out` (`w·h` values, NaN on entry).
    #[allow(clippy::too_many_arguments)]
    fn eval_lattice_into(
        &self,
        x0: i64,
        y0: i64,
        w: usize,
        h: usize,
        step: i64,
        want: &dyn Fn(i64, i64) -> bool,
        out: &mut [f64],
    ) {
        let step = step.max(1);
        let (x1, y1) = (x0 + (w as i64 - 1) * step, y0 + (h as i64 - 1) * step);
        let idx = |x: i64, y: i64| ((y - y0) / step) as usize * w + ((x - x0) / step) as usize;
        // First lattice coordinate ≥ v on the lattice through `origin`.
        if !self.tri.is_2d() {
            for y in (y0..=y1).step_by(step as usize) {
                for x in (x0..=x1).step_by(step as usize) {
                    if want(x, y) {
                        out[idx(x, y)] = self.eval_collinear([x, y]).unwrap_or(f64::NAN);
                    }
                }
            }
            return;
        }
        // Row by row: the next sample is found by a short walk from the last one's triangle,
        // and neighbouring samples often share their cavity (see `eval_in`).
        let mut s = Scratch::default();
        let mut row_hint: Option<u32> = None;
        for j in 0..h {
            let y = y0 + j as i64 * step;
            let mut hint = row_hint;
            let mut first: Option<u32> = None;
            let row = &mut out[j * w..(j + 1) * w];
            for (i, o) in row.iter_mut().enumerate() {
                let x = x0 + i as i64 * step;
                if !want(x, y) {
                    continue;
                }
                if let Some(v) = self.eval_seq([x, y], &mut hint, &mut s) {
                    *o = v;
                }
                first = first.or(hint);
            }
            row_hint = first.or(row_hint);
        }
    }

    fn lerp_edge(&self, a: u32, b: u32, p: [i64; 2]) -> f64 {
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        let pa = self.tri.point(a);
        let pb = self.tri.point(b);
        let l2 = ((pb[0] - pa[0]) * (pb[0] - pa[0]) + (pb[1] - pa[1]) * (pb[1] - pa[1])) as f64;
        let t = ((p[0] - pa[0]) * (pb[0] - pa[0]) + (p[1] - pa[1]) * (pb[1] - pa[1])) as f64 / l2;
        let ha = self.heights[a as usize];
        let hb = self.heights[b as usize];
        ha + (hb - ha) * t
    }

    /// Fewer than three non-collinear sites: piecewise linear along their line.
    fn eval_collinear(&self, p: [i64; 2]) -> Option<f64> {
        let pts = self.tri.points();
        if let Some(i) = pts.iter().position(|&q| q == p) {
            return Some(self.heights[i]);
        }
        if pts.len() < 2 || orient(pts[0], pts[1], p) != 0 {
            return None;
        }
        let dir = [pts[1][0] - pts[0][0], pts[1][1] - pts[0][1]];
        let param = |q: [i64; 2]| (q[0] - pts[0][0]) * dir[0] + (q[1] - pts[0][1]) * dir[1];
        let tp = param(p);
        // Nearest site on each side of p (ties cannot happen: positions are distinct).
        let mut lo: Option<(i64, usize)> = None;
        let mut hi: Option<(i64, usize)> = None;
        for (i, &q) in pts.iter().enumerate() {
            let t = param(q);
            if t < tp && lo.is_none_or(|(b, _)| t > b) {
                lo = Some((t, i));
            }
            if t > tp && hi.is_none_or(|(b, _)| t < b) {
                hi = Some((t, i));
            }
        }
        let ((_, a), (_, b)) = (lo?, hi?);
        Some(self.lerp_edge(a as u32, b as u32, p))
    }
}

mod cavity;
mod reference;
#[cfg(test)]
mod tests;
