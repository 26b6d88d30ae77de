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

/// Scratch buffers for evaluation (reuse one per thread to avoid allocation).
#[derive(Default, Clone, Debug)]
pub struct Scratch {
    /// `mark[t] == stamp` when triangle t is in the current cavity, at `slot[t]`.
    mark: Vec<u32>,
    slot: Vec<u32>,
    stamp: u32,
    cavity: Vec<u32>,
    stack: Vec<u32>,
    centres: Vec<[f64; 2]>,
    bnd: Vec<(u32, u32, u32)>,
    cycle: Vec<(u32, u32, u32)>,
    poly: Vec<[f64; 2]>,
}

/// The interpolating surface: a triangulation of the sites and their heights.
#[derive(Clone, Debug, Default)]
pub struct Surface {
    tri: Triangulation,
    heights: Vec<f64>,
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
        let id = self.tri.insert_near(p, hint)?;
        self.heights.push(h);
        Ok(id)
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

    /// Evaluate at `p` known to lie in (or on) real triangle `t` and not on a vertex.
    pub fn eval_in(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
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
        let nt = tri.num_triangle_slots();
        if s.mark.len() < nt {
            s.mark.resize(nt, 0);
            s.slot.resize(nt, 0);
        }
        let stamp = crate::geometry::triangulation::next_stamp(&mut s.stamp, &mut s.mark);
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
    /// which `want(x, y)` holds, by rasterizing each triangle once (no point location).
    /// Returns row-major values of the window (NaN where not wanted); `None` when a wanted
    /// sample lies outside the sites' hull.
    pub fn eval_window(
        &self,
        x0: i64,
        y0: i64,
        w: usize,
        h: usize,
        want: impl Fn(i64, i64) -> bool,
    ) -> Option<Vec<f64>> {
        let out = self.eval_lattice(x0, y0, w, h, 1, &want);
        for (i, v) in out.iter().enumerate() {
            let (x, y) = (x0 + (i % w) as i64, y0 + (i / w) as i64);
            if v.is_nan() && want(x, y) {
                return None;
            }
        }
        Some(out)
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
        let n = w * h;
        let mut out = vec![f64::NAN; n];
        let step = step.max(1);
        let (x1, y1) = (x0 + (w as i64 - 1) * step, y0 + (h as i64 - 1) * step);
        let idx = |x: i64, y: i64| ((y - y0) / step) as usize * w + ((x - x0) / step) as usize;
        // First lattice coordinate ≥ v on the lattice through `origin`.
        let up = |v: i64, origin: i64| origin + (v - origin + step - 1).div_euclid(step) * step;
        if !self.tri.is_2d() {
            for y in (y0..=y1).step_by(step as usize) {
                for x in (x0..=x1).step_by(step as usize) {
                    if want(x, y) {
                        out[idx(x, y)] = self.eval_collinear([x, y]).unwrap_or(f64::NAN);
                    }
                }
            }
            return out;
        }
        let mut done = vec![false; n];
        let mut s = Scratch::default();
        for t in self.tri.real_triangles() {
            let v = self.tri.tri(t).v;
            let pts = v.map(|i| self.tri.point(i));
            let ty0 = pts.iter().map(|p| p[1]).min().unwrap_or(0).max(y0);
            let ty1 = pts.iter().map(|p| p[1]).max().unwrap_or(0).min(y1);
            let mut y = up(ty0, y0);
            while y <= ty1 {
                // Intersect the three closed half-planes with row y, exactly.
                let (mut lo, mut hi) = (x0, x1);
                for k in 0..3 {
                    let a = pts[k];
                    let b = pts[(k + 1) % 3];
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let kk = dx * (y - a[1]);
                    if dy > 0 {
                        hi = hi.min(a[0] + kk.div_euclid(dy));
                    } else if dy < 0 {
                        lo = lo.max(a[0] - kk.div_euclid(-dy));
                    } else if kk < 0 {
                        hi = lo - 1;
                    }
                }
                let mut x = up(lo, x0);
                while x <= hi {
                    let i = idx(x, y);
                    if !done[i] && want(x, y) {
                        done[i] = true;
                        let p = [x, y];
                        out[i] = match v.iter().position(|&vi| self.tri.point(vi) == p) {
                            Some(k) => self.heights[v[k] as usize],
                            None => self.eval_in(p, t, &mut s),
                        };
                    }
                    x += step;
                }
                y += step;
            }
        }
        out
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
