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

fn polygon_area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    let mut s = 0.0;
    for i in 0..n {
        let a = poly[i];
        let b = poly[(i + 1) % n];
        s += a[0] * b[1] - a[1] * b[0];
    }
    (0.5 * s).abs()
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

    /// The exact circumcircle test of real triangle `t`, ready to copy where a loop wants it.
    #[inline]
    fn circle(&self, t: u32) -> Circle {
        let f = &self.info[t as usize];
        Circle {
            a: f.a,
            n: f.n,
            d: f.d,
            t,
        }
    }

    /// Whether `p` is strictly inside circle `c` (exact).
    #[inline]
    fn inside(&self, c: &Circle, p: [i64; 2]) -> bool {
        if c.d == 0 {
            return self.tri.in_circle(c.t, p);
        }
        let (x, y) = (p[0] - c.a[0], p[1] - c.a[1]);
        let pp = x * x + y * y;
        // A float evaluation decides unless the two sides are within its rounding error
        // (a few ulps of the largest term; 2^-40 of their sum is far beyond it), then the
        // exact i128 one.
        let (tx, ty) = (x as f64 * c.n[0] as f64, y as f64 * c.n[1] as f64);
        let l = c.d as f64 * pp as f64;
        let r = 2.0 * (tx + ty);
        let tol = (l.abs() + 2.0 * (tx.abs() + ty.abs())) * (1.0 / (1u64 << 40) as f64);
        if l < r - tol {
            return true;
        }
        if l > r + tol {
            return false;
        }
        (c.d as i128) * (pp as i128)
            < 2 * ((x as i128) * (c.n[0] as i128) + (y as i128) * (c.n[1] as i128))
    }

    /// Evaluate at `p` known to lie in (or on) real triangle `t` and not on a vertex.
    ///
    /// The same value, bit for bit, as the spec's operation order
    /// ([`eval_in_reference`](Self::eval_in_reference)), faster: circumcircle tests and
    /// circumcentre offsets are precomputed per triangle, the boundary cycle is walked
    /// instead of sorted, and when `p` has the cavity of the previous call on this scratch
    /// (every cavity triangle still contains p and no triangle next to it does, so by the
    /// cavity's connectedness it is the same set) its cycle and fans are reused; only the
    /// floating-point operations, which depend on p, run again.
    pub fn eval_in(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
        let tri = &self.tri;
        let tr = *tri.tri(t);
        // On a hull edge: linear along the edge.
        for k in 0..3 {
            if tri.tri(tr.n[k]).is_ghost() {
                let a = tr.v[(k + 1) % 3];
                let b = tr.v[(k + 2) % 3];
                if orient(tri.point(a), tri.point(b), p) == 0 {
                    return self.lerp_edge(a, b, p);
                }
            }
        }
        let same = s.generation == self.generation
            && s.cav_circles.iter().all(|c| self.inside(c, p))
            && !s.out_circles.iter().any(|c| self.inside(c, p));
        if !same && !self.build_cavity(p, t, s) {
            return self.eval_in_reference_free(p, t, s);
        }
        self.weights(p, s)
    }

    /// Sibson's value at `p` from the cavity structure in `s` (the floating-point part).
    #[inline(never)]
    fn weights(&self, p: [i64; 2], s: &mut Scratch) -> f64 {
        // Circumcentres of the cavity triangles relative to p (the spec's a + cc(b−a, c−a)),
        // and the cycle's vertices relative to p (the first repeated at the end).
        s.centres.clear();
        s.centres.extend(s.cav_ao.iter().map(|(a, o)| {
            let d = sub(*a, p);
            [d[0] + o[0], d[1] + o[1]]
        }));
        s.pv.clear();
        s.pv.extend(s.vpos.iter().map(|&v| sub(v, p)));
        let k = s.vpos.len();
        s.pv.push(s.pv[0]);
        let mut num = 0.0;
        let mut den = 0.0;
        let mut g_prev = cc0(s.pv[k - 1], s.pv[k]);
        for i in 0..k {
            let g_next = cc0(s.pv[i], s.pv[i + 1]);
            // Shoelace over [g_next, C(t₁), …, C(t_m), g_prev], term by term in the
            // reference's order.
            let mut acc = 0.0;
            let mut prev = g_next;
            for &c in &s.fan[s.fan_start[i] as usize..s.fan_start[i + 1] as usize] {
                let q = s.centres[c as usize];
                acc += prev[0] * q[1] - prev[1] * q[0];
                prev = q;
            }
            acc += prev[0] * g_prev[1] - prev[1] * g_prev[0];
            acc += g_prev[0] * g_next[1] - g_prev[1] * g_next[0];
            let w = (0.5 * acc).abs();
            num += w * s.vh[i];
            den += w;
            g_prev = g_next;
        }
        num / den
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

    /// Evaluate at `p` from the cavity structure in `s` when p lies in one of its circles:
    /// the same cavity (reused), or a new one flooded from a triangle of the old one whose
    /// circle holds p (no point location needed: p is then no site, and a hull edge through
    /// p belongs to a cavity triangle). `None` when p is in none of them (locate it then).
    /// `hint` becomes a triangle near p.
    fn eval_near(&self, p: [i64; 2], hint: &mut Option<u32>, s: &mut Scratch) -> Option<f64> {
        if s.generation != self.generation {
            return None;
        }
        let mut seed = None;
        let mut all = true;
        for c in &s.cav_circles {
            if self.inside(c, p) {
                seed.get_or_insert(c.t);
            } else {
                all = false;
            }
        }
        let seed = seed?;
        let same = all && !s.out_circles.iter().any(|c| self.inside(c, p));
        if !same && !self.build_cavity(p, seed, s) {
            return None;
        }
        *hint = Some(seed);
        for &(a, b) in &s.hull_edges {
            if orient(self.tri.point(a), self.tri.point(b), p) == 0 {
                // On the line of a chord of a circle strictly holding p: on the open edge.
                return Some(self.lerp_edge(a, b, p));
            }
        }
        Some(self.weights(p, s))
    }

    /// Find the cavity of `p` (flood fill from `t`), walk its boundary and lay out the cycle
    /// in the spec's order (from the lowest site id, each vertex's cavity fan from the
    /// triangle holding its outgoing edge); `false` if the walk did not close (never on a
    /// valid triangulation; the caller then evaluates by the reference).
    #[inline(never)]
    fn build_cavity(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> bool {
        let tri = &self.tri;
        let stamp = s.next_stamp(tri.num_triangle_slots());
        s.cavity.clear();
        s.out_circles.clear();
        s.hull_edges.clear();
        s.stack.clear();
        s.mark[t as usize] = stamp;
        s.slot[t as usize] = 0;
        s.cavity.push(t);
        s.stack.push(t);
        // A boundary edge to start the walk from: (triangle, index of the opposite vertex).
        let mut edge = None;
        while let Some(c) = s.stack.pop() {
            let n = tri.tri(c).n;
            for (k, nb) in n.into_iter().enumerate() {
                let nbu = nb as usize;
                if s.mark[nbu] == stamp {
                    continue;
                }
                if tri.tri(nb).is_ghost() {
                    let v = tri.tri(c).v;
                    s.hull_edges.push((v[(k + 1) % 3], v[(k + 2) % 3]));
                }
                if s.seen[nbu] != stamp {
                    if !tri.tri(nb).is_ghost() {
                        let circle = self.circle(nb);
                        if self.inside(&circle, p) {
                            s.mark[nbu] = stamp;
                            s.slot[nbu] = s.cavity.len() as u32;
                            s.cavity.push(nb);
                            s.stack.push(nb);
                            continue;
                        }
                        s.out_circles.push(circle);
                    }
                    s.seen[nbu] = stamp;
                }
                edge.get_or_insert((c, k));
            }
        }
        let Some((mut c, k)) = edge else {
            return false;
        };
        // Walk the boundary counter-clockwise: at each vertex b (entered through triangle c),
        // turn around b through the cavity until the outgoing edge b→x leaves it. Fans are
        // collected from the incoming edge's triangle to the outgoing one's.
        s.walk.clear();
        s.walk_fan.clear();
        let start = tri.tri(c).v[(k + 2) % 3];
        let mut b = start;
        let cap = 3 * s.cavity.len() + 3;
        loop {
            let from = s.walk_fan.len() as u32;
            let next;
            loop {
                if s.walk_fan.len() > cap {
                    return false;
                }
                s.walk_fan.push(s.slot[c as usize]);
                let tr = tri.tri(c);
                let kb = tr.index_of(b);
                let nb = tr.n[(kb + 2) % 3];
                if s.mark[nb as usize] == stamp {
                    c = nb;
                } else {
                    next = tr.v[(kb + 1) % 3];
                    break;
                }
            }
            s.walk.push((b, from, s.walk_fan.len() as u32));
            if next == start {
                break;
            }
            if s.walk.len() > cap {
                return false;
            }
            b = next;
        }
        // The spec's order: from the lowest site id; each fan reversed.
        let kk = s.walk.len();
        let first = (0..kk).min_by_key(|&i| s.walk[i].0).unwrap_or(0);
        s.vpos.clear();
        s.vh.clear();
        s.fan.clear();
        s.fan_start.clear();
        for i in (first..kk).chain(0..first) {
            let (v, from, to) = s.walk[i];
            s.vpos.push(tri.point(v));
            s.vh.push(self.heights[v as usize]);
            s.fan_start.push(s.fan.len() as u32);
            s.fan
                .extend(s.walk_fan[from as usize..to as usize].iter().rev().copied());
        }
        s.fan_start.push(s.fan.len() as u32);
        s.cav_circles.clear();
        s.cav_ao.clear();
        for &c in &s.cavity {
            s.cav_circles.push(self.circle(c));
            let f = &self.info[c as usize];
            s.cav_ao.push((f.a, f.o));
        }
        s.generation = self.generation;
        true
    }

    /// The reference evaluation (always compiled for the fallback of [`eval_in`]).
    fn eval_in_reference_free(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
        s.generation = 0;
        self.reference(p, t, s)
    }

    /// The spec's evaluation, operation by operation, with nothing reused between calls: the
    /// reference that [`eval_in`](Self::eval_in) must match bit for bit (tests compare them).
    #[cfg(test)]
    pub fn eval_in_reference(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
        self.eval_in_reference_free(p, t, s)
    }

    fn reference(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
        let tri = &self.tri;
        let tr = *tri.tri(t);
        // On a hull edge: linear along the edge.
        for k in 0..3 {
            let a = tr.v[(k + 1) % 3];
            let b = tr.v[(k + 2) % 3];
            if tri.tri(tr.n[k]).is_ghost() && orient(tri.point(a), tri.point(b), p) == 0 {
                return self.lerp_edge(a, b, p);
            }
        }
        // Cavity: real triangles whose circumcircle strictly contains p.
        let stamp = s.next_stamp(tri.num_triangle_slots());
        s.cavity.clear();
        s.stack.clear();
        s.mark[t as usize] = stamp;
        s.slot[t as usize] = 0;
        s.cavity.push(t);
        s.stack.push(t);
        while let Some(c) = s.stack.pop() {
            let n = tri.tri(c).n;
            for nb in n {
                if s.mark[nb as usize] == stamp || tri.tri(nb).is_ghost() {
                    continue;
                }
                if tri.in_circle(nb, p) {
                    s.mark[nb as usize] = stamp;
                    s.slot[nb as usize] = s.cavity.len() as u32;
                    s.cavity.push(nb);
                    s.stack.push(nb);
                }
            }
        }
        let in_cavity = |s: &Scratch, t: u32| s.mark[t as usize] == stamp;
        // Circumcentres of cavity triangles, relative to p; boundary edges.
        s.centres.clear();
        s.bnd.clear();
        for ci in 0..s.cavity.len() {
            let c = s.cavity[ci];
            let v = tri.tri(c).v;
            // Canonical rotation: start at the lowest site id (counter-clockwise order kept).
            let r0 = if v[0] < v[1] && v[0] < v[2] {
                0
            } else if v[1] < v[2] {
                1
            } else {
                2
            };
            let a = sub(tri.point(v[r0]), p);
            let b = sub(tri.point(v[(r0 + 1) % 3]), p);
            let d = sub(tri.point(v[(r0 + 2) % 3]), p);
            let o = cc0([b[0] - a[0], b[1] - a[1]], [d[0] - a[0], d[1] - a[1]]);
            s.centres.push([a[0] + o[0], a[1] + o[1]]);
            let n = tri.tri(c).n;
            for k in 0..3 {
                if !in_cavity(s, n[k]) {
                    s.bnd.push((v[(k + 1) % 3], v[(k + 2) % 3], ci as u32));
                }
            }
        }
        // Boundary cycle from its lowest vertex id, counter-clockwise around p. Each vertex
        // starts exactly one boundary edge, so sorting by it gives a lookup table.
        s.bnd.sort_unstable_by_key(|e| e.0);
        let find = |bnd: &[(u32, u32, u32)], a: u32| {
            bnd.binary_search_by_key(&a, |e| e.0)
                .map(|i| bnd[i])
                .expect("cavity boundary is a cycle")
        };
        let start = s.bnd[0].0;
        s.cycle.clear();
        let mut cur = start;
        loop {
            let (a, b, ci) = find(&s.bnd, cur);
            s.cycle.push((a, b, ci));
            cur = b;
            if cur == start || s.cycle.len() > s.bnd.len() {
                break;
            }
        }
        let k = s.cycle.len();
        let mut num = 0.0;
        let mut den = 0.0;
        let mut g_prev = {
            let (a, b, _) = s.cycle[k - 1];
            cc0(sub(tri.point(a), p), sub(tri.point(b), p))
        };
        for i in 0..k {
            let (vi, vn, ci0) = s.cycle[i];
            let g_next = cc0(sub(tri.point(vi), p), sub(tri.point(vn), p));
            s.poly.clear();
            s.poly.push(g_next);
            // Cavity triangles around vi, from the one holding edge vi→vn, counter-clockwise.
            let mut ct = s.cavity[ci0 as usize];
            for _ in 0..s.cavity.len() {
                s.poly.push(s.centres[s.slot[ct as usize] as usize]);
                let tr = tri.tri(ct);
                let kv =
                    tr.v.iter()
                        .position(|&v| v == vi)
                        .expect("vertex of triangle");
                let nb = tr.n[(kv + 1) % 3];
                if !in_cavity(s, nb) {
                    break;
                }
                ct = nb;
            }
            s.poly.push(g_prev);
            let w = polygon_area(&s.poly);
            num += w * self.heights[vi as usize];
            den += w;
            g_prev = g_next;
        }
        num / den
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
    /// `want` holds, by rasterizing each triangle once. Points outside the sites' hull (and
    /// unwanted ones) are NaN. Each value is the same as [`eval`](Self::eval) gives.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::triangulation::Location;
    use crate::testutil::Rng;

    fn surface(pts: &[[i64; 2]], mut f: impl FnMut([i64; 2]) -> f64) -> Surface {
        let mut s = Surface::new();
        for &p in pts {
            s.insert(p, f(p)).unwrap();
        }
        s
    }

    fn random_sites(n: usize, w: i64, h: i64, seed: u64) -> Vec<[i64; 2]> {
        let mut rng = Rng(seed);
        let mut pts = vec![[0, 0], [w, 0], [w, h], [0, h]];
        while pts.len() < n {
            let p = [
                rng.below(w as u64 + 1) as i64,
                rng.below(h as u64 + 1) as i64,
            ];
            if !pts.contains(&p) {
                pts.push(p);
            }
        }
        pts
    }

    #[test]
    fn reproduces_linear_functions() {
        let f = |p: [i64; 2]| 3.0 + 0.75 * p[0] as f64 - 1.25 * p[1] as f64;
        for seed in 1..6 {
            let pts = random_sites(60, 50, 40, seed);
            let s = surface(&pts, f);
            let mut sc = Scratch::default();
            let mut hint = 0;
            for y in 0..=40 {
                for x in 0..=50 {
                    let v = s.eval([x, y], &mut hint, &mut sc).unwrap();
                    assert!(
                        (v - f([x, y])).abs() < 1e-9,
                        "({x},{y}): {v} vs {}",
                        f([x, y])
                    );
                }
            }
        }
    }

    #[test]
    fn interpolates_sites_and_stays_within_their_range() {
        let pts = random_sites(80, 30, 30, 7);
        let mut rng = Rng(99);
        let hs: Vec<f64> = (0..pts.len()).map(|_| rng.below(1000) as f64).collect();
        let mut s = Surface::new();
        for (p, h) in pts.iter().zip(&hs) {
            s.insert(*p, *h).unwrap();
        }
        let mut sc = Scratch::default();
        let mut hint = 0;
        for (p, h) in pts.iter().zip(&hs) {
            assert_eq!(s.eval(*p, &mut hint, &mut sc), Some(*h));
        }
        for y in 0..=30 {
            for x in 0..=30 {
                let v = s.eval([x, y], &mut hint, &mut sc).unwrap();
                assert!((0.0..=999.0).contains(&v), "{v}");
            }
        }
    }

    #[test]
    fn result_does_not_depend_on_the_hint() {
        let pts = random_sites(100, 40, 40, 3);
        let mut rng = Rng(5);
        let s = surface(&pts, |_| rng.below(500) as f64 * 0.37);
        let tris: Vec<u32> = s.triangulation().real_triangles().collect();
        let mut sc = Scratch::default();
        for y in 0..=40 {
            for x in 0..=40 {
                let mut h0 = tris[0];
                let v0 = s.eval([x, y], &mut h0, &mut sc).unwrap();
                for &t in tris.iter().step_by(7) {
                    let mut h = t;
                    let v = s.eval([x, y], &mut h, &mut sc).unwrap();
                    assert_eq!(v.to_bits(), v0.to_bits(), "({x},{y})");
                }
            }
        }
    }

    #[test]
    fn matches_spade_natural_neighbour() {
        use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation as _};
        struct Ph(Point2<f64>, f64);
        impl HasPosition for Ph {
            type Scalar = f64;
            fn position(&self) -> Point2<f64> {
                self.0
            }
        }
        let pts = random_sites(150, 64, 48, 11);
        let mut rng = Rng(17);
        let hs: Vec<f64> = (0..pts.len())
            .map(|_| rng.below(3000) as f64 * 0.1)
            .collect();
        let mut ours = Surface::new();
        let mut theirs: DelaunayTriangulation<Ph> = DelaunayTriangulation::new();
        for (p, h) in pts.iter().zip(&hs) {
            ours.insert(*p, *h).unwrap();
            theirs
                .insert(Ph(Point2::new(p[0] as f64, p[1] as f64), *h))
                .unwrap();
        }
        let nn = theirs.natural_neighbor();
        let mut sc = Scratch::default();
        let mut hint = 0;
        let mut worst: f64 = 0.0;
        for y in 0..=48 {
            for x in 0..=64 {
                let v = ours.eval([x, y], &mut hint, &mut sc).unwrap();
                if let Some(r) = nn.interpolate(|v| v.data().1, Point2::new(x as f64, y as f64)) {
                    worst = worst.max((v - r).abs());
                }
            }
        }
        assert!(worst < 1e-6, "largest difference from spade: {worst}");
    }

    #[test]
    fn window_evaluation_matches_pointwise_bit_for_bit() {
        let pts = random_sites(120, 45, 33, 23);
        let mut rng = Rng(8);
        let s = surface(&pts, |_| rng.below(900) as f64 * 1.3);
        let full = s.eval_window(0, 0, 46, 34, |_, _| true).unwrap();
        let mut sc = Scratch::default();
        let mut hint = 0;
        for y in 0..34 {
            for x in 0..46 {
                let v = s.eval([x, y], &mut hint, &mut sc).unwrap();
                assert_eq!(
                    v.to_bits(),
                    full[(y * 46 + x) as usize].to_bits(),
                    "({x},{y})"
                );
            }
        }
        let win = s
            .eval_window(7, 5, 20, 11, |x, y| (x + y) % 5 != 0)
            .unwrap();
        for y in 0..11 {
            for x in 0..20 {
                let v = win[y * 20 + x];
                let (gx, gy) = (x as i64 + 7, y as i64 + 5);
                if (gx + gy) % 5 != 0 {
                    assert_eq!(v.to_bits(), full[(gy * 46 + gx) as usize].to_bits());
                } else {
                    assert!(v.is_nan());
                }
            }
        }
        assert!(
            s.eval_window(0, 0, 47, 34, |_, _| true).is_none(),
            "outside the hull"
        );
    }

    /// Every sample of `[0, w] × [0, h]` by the fast evaluator (in scanline order, reusing
    /// cavities, and in a scrambled order) against the reference, bit for bit.
    fn check_fast_matches_reference(s: &Surface, w: i64, h: i64, seed: u64) {
        let mut fast = Scratch::default();
        let mut refs = Scratch::default();
        let mut pts: Vec<[i64; 2]> = (0..=h).flat_map(|y| (0..=w).map(move |x| [x, y])).collect();
        for pass in 0..2 {
            if pass == 1 {
                let mut rng = Rng(seed);
                for i in (1..pts.len()).rev() {
                    pts.swap(i, rng.below(i as u64 + 1) as usize);
                }
            }
            for &p in &pts {
                let Location::Triangle(t) = s.tri.locate(p, None) else {
                    continue;
                };
                let a = s.eval_in(p, t, &mut fast);
                let b = s.eval_in_reference(p, t, &mut refs);
                assert_eq!(a.to_bits(), b.to_bits(), "{p:?}: {a} vs {b}");
            }
        }
        // The grid evaluators (row order, cavities reused and flooded from the last one):
        // whole grid, windows and lattices of several steps, each point against the
        // reference (or the site's height, or the hull edge's interpolant).
        let reference = |p: [i64; 2], refs: &mut Scratch| match s.tri.locate(p, None) {
            Location::Triangle(t) => Some(s.eval_in_reference(p, t, refs)),
            Location::Vertex(v) => Some(s.heights[v as usize]),
            Location::Outside => None,
        };
        for (x0, y0, step) in [(0, 0, 1), (3, 2, 1), (0, 0, 2), (1, 1, 3)] {
            let (lw, lh) = (
                ((w - x0) / step + 1) as usize,
                ((h - y0) / step + 1) as usize,
            );
            let out = s.eval_lattice(x0, y0, lw, lh, step, &|x, y| (x * 7 + y) % 11 != 0);
            for j in 0..lh {
                for i in 0..lw {
                    let p = [x0 + i as i64 * step, y0 + j as i64 * step];
                    let v = out[j * lw + i];
                    if (p[0] * 7 + p[1]) % 11 == 0 {
                        assert!(v.is_nan());
                        continue;
                    }
                    let r = reference(p, &mut refs).unwrap_or(f64::NAN);
                    assert_eq!(v.to_bits(), r.to_bits(), "{p:?} step {step}: {v} vs {r}");
                }
            }
        }
    }

    #[test]
    fn fast_evaluation_matches_the_reference_bit_for_bit() {
        for seed in 1..8 {
            let pts = random_sites(40 + 30 * seed as usize, 60, 45, seed);
            let mut rng = Rng(seed + 100);
            let s = surface(&pts, |_| rng.below(5000) as f64 * 0.37);
            check_fast_matches_reference(&s, 60, 45, seed);
        }
        // Co-circular sites on a lattice (the degenerate case of gridded data), and long thin
        // triangles (a few sites far apart, as over flat regions).
        let lattice: Vec<[i64; 2]> = (0..=8)
            .flat_map(|y| (0..=8).map(move |x| [x * 6, y * 5]))
            .collect();
        let s = surface(&lattice, |p| (p[0] * 7 + p[1] * p[1]) as f64);
        check_fast_matches_reference(&s, 48, 40, 9);
        let thin = [
            [0, 0],
            [300, 0],
            [300, 7],
            [0, 7],
            [150, 3],
            [40, 1],
            [260, 6],
        ];
        let s = surface(&thin, |p| (p[0] + 11 * p[1]) as f64 * 0.5);
        check_fast_matches_reference(&s, 300, 7, 10);
    }

    #[test]
    fn collinear_sites_interpolate_linearly() {
        let s = surface(&[[0, 0], [10, 0], [4, 0]], |p| p[0] as f64 * 2.0);
        let mut sc = Scratch::default();
        let mut hint = 0;
        assert_eq!(s.eval([7, 0], &mut hint, &mut sc), Some(14.0));
        assert_eq!(s.eval([7, 1], &mut hint, &mut sc), None);
        assert_eq!(s.eval([11, 0], &mut hint, &mut sc), None);
    }
}
