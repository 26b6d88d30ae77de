//! The spec's evaluation of Sibson's interpolant, operation by operation and nothing reused:
//! what every fast path must match bit for bit (and their fallback). Its cavity flood and
//! boundary cycle repeat `cavity`'s work in the spec's plainest form on purpose: sharing
//! the fast code would make the tests compare it with itself.

use super::{Scratch, Surface, cc0, sub};
use crate::geometry::triangulation::orient;

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
    /// The reference evaluation (always compiled for the fallback of [`eval_in`]).
    pub(super) fn eval_by_reference(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
        s.generation = 0;
        self.reference(p, t, s)
    }

    /// The spec's evaluation, operation by operation, with nothing reused between calls: the
    /// reference that [`eval_in`](Self::eval_in) must match bit for bit (tests compare them).
    #[cfg(test)]
    pub fn eval_in_reference(&self, p: [i64; 2], t: u32, s: &mut Scratch) -> f64 {
        self.eval_by_reference(p, t, s)
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
}
