//! Sibson's value at one point, fast: the point's cavity (found by flooding exact circle
//! tests, or reused from the last point), its boundary laid out in the spec's order, then
//! the spec's floating-point sequence.

use super::{Circle, Scratch, Surface, cc0, sub};
use crate::geometry::triangulation::orient;

impl Surface {
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
            return self.eval_by_reference(p, t, s);
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

    /// Evaluate at `p` from the cavity structure in `s` when p lies in one of its circles:
    /// the same cavity (reused), or a new one flooded from a triangle of the old one whose
    /// circle holds p (no point location needed: p is then no site, and a hull edge through
    /// p belongs to a cavity triangle). `None` when p is in none of them (locate it then).
    /// `hint` becomes a triangle near p.
    pub(super) fn eval_near(
        &self,
        p: [i64; 2],
        hint: &mut Option<u32>,
        s: &mut Scratch,
    ) -> Option<f64> {
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
}
