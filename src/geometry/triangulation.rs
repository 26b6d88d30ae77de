//! Incremental Delaunay triangulation of sites on integer grid coordinates, exact predicates.
//!
//! Why not `spade`: vtz needs (1) bit-identical results in encoder and decoder, for any
//! window or thread count, (2) the Bowyer–Watson insertion cavity of a query point, which is
//! exactly what Sibson's natural-neighbour weights are made of, and (3) speed on grids.
//! Sites and samples sit on integer grid positions, so orientation and in-circle tests are
//! exact in `i64`/`i128` arithmetic, and the triangulation after inserting the same sites in
//! the same order is the same set of triangles on every platform. spade's natural-neighbour
//! interpolation depends on its locate hint (measured ~6e-13) and hides the cavity.
//!
//! Representation: triangles with counter-clockwise vertices and neighbour links; the hull is
//! closed by *ghost* triangles `(a, b, GHOST)` whose real edge a→b has the outside of the hull
//! on its left (Shewchuk's formulation), so inserting outside the hull needs no special case.

use crate::error::{Error, Result};

/// The vertex "at infinity" of ghost triangles.
pub const GHOST: u32 = u32::MAX;
const NONE: u32 = u32::MAX;

/// Largest coordinate magnitude accepted (keeps every exact predicate within i128).
pub const MAX_COORD: i64 = 1 << 24;

#[derive(Clone, Copy, Debug)]
pub struct Tri {
    /// Vertices, counter-clockwise; a ghost has `v[2] == GHOST`.
    pub v: [u32; 3],
    /// `n[k]` is the triangle across the edge opposite `v[k]` (edge `v[k+1] → v[k+2]`).
    pub n: [u32; 3],
}

impl Tri {
    #[inline]
    pub fn is_ghost(&self) -> bool {
        self.v[2] == GHOST
    }
    #[inline]
    pub fn index_of(&self, v: u32) -> usize {
        if self.v[0] == v {
            0
        } else if self.v[1] == v {
            1
        } else {
            2
        }
    }
}

/// Twice the signed area of (a, b, c): > 0 when counter-clockwise.
#[inline]
pub fn orient(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Positive when `d` is strictly inside the circumcircle of the counter-clockwise (a, b, c),
/// zero on it, negative outside. Exact: a floating-point evaluation decides when its error
/// bound (Shewchuk's `iccerrboundA`) allows, else exact `i128` arithmetic; use the sign only.
#[inline]
pub fn incircle(a: [i64; 2], b: [i64; 2], c: [i64; 2], d: [i64; 2]) -> i128 {
    let (adx, ady) = ((a[0] - d[0]) as f64, (a[1] - d[1]) as f64);
    let (bdx, bdy) = ((b[0] - d[0]) as f64, (b[1] - d[1]) as f64);
    let (cdx, cdy) = ((c[0] - d[0]) as f64, (c[1] - d[1]) as f64);
    let (bc, cb) = (bdx * cdy, cdx * bdy);
    let (ca, ac) = (cdx * ady, adx * cdy);
    let (ab, ba) = (adx * bdy, bdx * ady);
    let al = adx * adx + ady * ady;
    let bl = bdx * bdx + bdy * bdy;
    let cl = cdx * cdx + cdy * cdy;
    let det = al * (bc - cb) + bl * (ca - ac) + cl * (ab - ba);
    let perm = (bc.abs() + cb.abs()) * al + (ca.abs() + ac.abs()) * bl + (ab.abs() + ba.abs()) * cl;
    const EPS: f64 = f64::EPSILON / 2.0;
    let bound = (10.0 + 96.0 * EPS) * EPS * perm;
    if det > bound {
        1
    } else if -det > bound {
        -1
    } else {
        incircle_exact(a, b, c, d)
    }
}

/// [`incircle`] in exact integer arithmetic.
pub fn incircle_exact(a: [i64; 2], b: [i64; 2], c: [i64; 2], d: [i64; 2]) -> i128 {
    let (adx, ady) = ((a[0] - d[0]) as i128, (a[1] - d[1]) as i128);
    let (bdx, bdy) = ((b[0] - d[0]) as i128, (b[1] - d[1]) as i128);
    let (cdx, cdy) = ((c[0] - d[0]) as i128, (c[1] - d[1]) as i128);
    let al = adx * adx + ady * ady;
    let bl = bdx * bdx + bdy * bdy;
    let cl = cdx * cdx + cdy * cdy;
    al * (bdx * cdy - bdy * cdx) + bl * (cdx * ady - cdy * adx) + cl * (adx * bdy - ady * bdx)
}

/// Advance a visit stamp for `marks` (entries equal to the returned stamp are "visited");
/// on wrap-around every mark is cleared so no stale entry can match.
pub(crate) fn next_stamp(stamp: &mut u32, marks: &mut [u32]) -> u32 {
    *stamp = stamp.wrapping_add(1);
    if *stamp == 0 {
        marks.iter_mut().for_each(|m| *m = 0);
        *stamp = 1;
    }
    *stamp
}

/// An incremental Delaunay triangulation. Vertex ids are insertion indices.
#[derive(Clone, Debug, Default)]
pub struct Triangulation {
    pts: Vec<[i64; 2]>,
    tris: Vec<Tri>,
    alive: Vec<bool>,
    free: Vec<u32>,
    /// Points waiting until three non-collinear ones exist.
    pending: Vec<u32>,
    /// A live triangle to start walks from.
    last: u32,
    // Scratch buffers reused by insertions.
    cavity: Vec<u32>,
    stack: Vec<u32>,
    mark: Vec<u32>,
    stamp: u32,
    boundary: Vec<(u32, u32, u32)>,
    made: Vec<(u32, u32, u32)>,
    /// Triangles created by the last insertion.
    created: Vec<u32>,
}

/// Where a point is relative to the triangulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// On an existing vertex.
    Vertex(u32),
    /// Inside or on the boundary of this real triangle.
    Triangle(u32),
    /// Outside the convex hull (or no triangle exists yet).
    Outside,
}

impl Triangulation {
    #[cfg(test)]
    pub fn new() -> Self {
        Self::default()
    }

    #[cfg(test)]
    pub fn num_vertices(&self) -> usize {
        self.pts.len()
    }
    pub fn point(&self, v: u32) -> [i64; 2] {
        self.pts[v as usize]
    }
    pub fn points(&self) -> &[[i64; 2]] {
        &self.pts
    }
    pub fn tri(&self, t: u32) -> &Tri {
        &self.tris[t as usize]
    }
    /// Number of triangle slots (live or free); triangle ids are below this.
    pub fn num_triangle_slots(&self) -> usize {
        self.tris.len()
    }
    /// Whether any real triangle exists (three non-collinear sites were inserted).
    pub fn is_2d(&self) -> bool {
        !self.tris.is_empty()
    }
    /// Ids of the live real (non-ghost) triangles, in storage order.
    pub fn real_triangles(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.tris.len() as u32)
            .filter(|&t| self.alive[t as usize] && !self.tris[t as usize].is_ghost())
    }
    /// Triangles created by the most recent insertion (real and ghost).
    pub fn created(&self) -> &[u32] {
        &self.created
    }

    fn alloc(&mut self, t: Tri) -> u32 {
        if let Some(i) = self.free.pop() {
            self.tris[i as usize] = t;
            self.alive[i as usize] = true;
            i
        } else {
            self.tris.push(t);
            self.alive.push(true);
            self.mark.push(0);
            (self.tris.len() - 1) as u32
        }
    }

    /// Renumber the live triangles so that triangles near each other in the plane are near
    /// each other in memory (strips of 16 rows, then by column; ghosts last), dropping free
    /// slots. Changes no vertex id and no triangle, only their storage order, so every
    /// evaluation gives the same bits; walks and cavities then touch fewer cache lines.
    pub fn compact_spatially(&mut self) {
        let live: Vec<u32> = (0..self.tris.len() as u32)
            .filter(|&t| self.alive[t as usize])
            .collect();
        // Sort key: ghosts last, then strips of 16 rows, then column (all coordinates are
        // within ±MAX_COORD = ±2^24, so each part fits its bits after an offset).
        let key = |t: u32| -> u64 {
            let tr = &self.tris[t as usize];
            let (mut sx, mut sy, mut n) = (0i64, 0i64, 0i64);
            for &v in tr.v.iter().filter(|&&v| v != GHOST) {
                let p = self.pts[v as usize];
                (sx, sy, n) = (sx + p[0], sy + p[1], n + 1);
            }
            let n = n.max(1);
            let strip = ((sy / n).div_euclid(16) + (1 << 21)) as u64;
            let col = (sx / n + (1 << 25)) as u64;
            (u64::from(tr.is_ghost()) << 62) | (strip << 32) | col
        };
        let mut order: Vec<(u64, u32)> = live.iter().map(|&t| (key(t), t)).collect();
        drop(live);
        order.sort_unstable();
        let mut new_id = vec![NONE; self.tris.len()];
        for (i, &(_, t)) in order.iter().enumerate() {
            new_id[t as usize] = i as u32;
        }
        let tris: Vec<Tri> = order
            .iter()
            .map(|&(_, t)| {
                let tr = self.tris[t as usize];
                Tri {
                    v: tr.v,
                    n: tr.n.map(|x| new_id[x as usize]),
                }
            })
            .collect();
        self.last = new_id[self.last as usize];
        self.alive = vec![true; tris.len()];
        self.mark = vec![0; tris.len()];
        self.stamp = 0;
        self.tris = tris;
        self.free.clear();
        self.created.clear();
    }

    /// Whether `p` is in the (generalised) circumcircle of triangle `t`: strictly inside for
    /// real triangles; for ghosts, strictly outside the hull edge or on its open segment.
    #[inline]
    pub fn in_circle(&self, t: u32, p: [i64; 2]) -> bool {
        let tr = &self.tris[t as usize];
        let a = self.pts[tr.v[0] as usize];
        let b = self.pts[tr.v[1] as usize];
        if tr.is_ghost() {
            let o = orient(a, b, p);
            if o != 0 {
                return o > 0;
            }
            // Collinear: on the open segment between a and b.
            let d = (p[0] - a[0]) * (b[0] - a[0]) + (p[1] - a[1]) * (b[1] - a[1]);
            let l = (b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]);
            return d > 0 && d < l;
        }
        let c = self.pts[tr.v[2] as usize];
        incircle(a, b, c, p) > 0
    }

    /// Walk from `start` (or the last triangle) to the triangle containing `p`.
    pub fn locate(&self, p: [i64; 2], start: Option<u32>) -> Location {
        if self.tris.is_empty() {
            return Location::Outside;
        }
        let mut t = match start {
            Some(s) if (s as usize) < self.tris.len() && self.alive[s as usize] => s,
            _ => self.last,
        };
        if self.tris[t as usize].is_ghost() {
            t = self.tris[t as usize].n[2];
        }
        // A visibility walk terminates on Delaunay triangulations; the cap is a safety net.
        let cap = 4 * self.tris.len() + 64;
        let mut rot = 0usize;
        for _ in 0..cap {
            let tr = self.tris[t as usize];
            let mut moved = false;
            for k0 in 0..3 {
                let k = (k0 + rot) % 3;
                let a = self.pts[tr.v[(k + 1) % 3] as usize];
                let b = self.pts[tr.v[(k + 2) % 3] as usize];
                if orient(a, b, p) < 0 {
                    let nb = tr.n[k];
                    if self.tris[nb as usize].is_ghost() {
                        return Location::Outside;
                    }
                    t = nb;
                    moved = true;
                    rot += 1;
                    break;
                }
            }
            if !moved {
                for &v in &tr.v {
                    if self.pts[v as usize] == p {
                        return Location::Vertex(v);
                    }
                }
                return Location::Triangle(t);
            }
        }
        self.locate_scan(p)
    }

    fn locate_scan(&self, p: [i64; 2]) -> Location {
        for t in self.real_triangles() {
            let tr = &self.tris[t as usize];
            let [a, b, c] = tr.v.map(|v| self.pts[v as usize]);
            if orient(a, b, p) >= 0 && orient(b, c, p) >= 0 && orient(c, a, p) >= 0 {
                for &v in &tr.v {
                    if self.pts[v as usize] == p {
                        return Location::Vertex(v);
                    }
                }
                return Location::Triangle(t);
            }
        }
        Location::Outside
    }

    /// Insert a site; returns its vertex id. Duplicate positions are an error.
    #[cfg(test)]
    pub fn insert(&mut self, p: [i64; 2]) -> Result<u32> {
        self.insert_near(p, None)
    }

    /// [`insert`](Self::insert), starting the point location at triangle `hint`.
    pub fn insert_near(&mut self, p: [i64; 2], hint: Option<u32>) -> Result<u32> {
        if p[0].abs() > MAX_COORD || p[1].abs() > MAX_COORD {
            return Err(Error::limit(format!(
                "site coordinate {p:?} beyond ±{MAX_COORD}"
            )));
        }
        let id = self.pts.len() as u32;
        self.created.clear();
        if self.tris.is_empty() {
            if self.pts.contains(&p) {
                return Err(Error::invalid(format!("duplicate site {p:?}")));
            }
            self.pts.push(p);
            self.pending.push(id);
            self.try_start();
            return Ok(id);
        }
        let start = match self.locate(p, hint) {
            Location::Vertex(_) => return Err(Error::invalid(format!("duplicate site {p:?}"))),
            Location::Triangle(t) => t,
            Location::Outside => self.find_ghost_seeing(p),
        };
        self.pts.push(p);
        self.insert_from(id, start);
        Ok(id)
    }

    /// A ghost triangle whose circumcircle contains the outside point `p`.
    fn find_ghost_seeing(&self, p: [i64; 2]) -> u32 {
        (0..self.tris.len() as u32)
            .find(|&t| {
                self.alive[t as usize] && self.tris[t as usize].is_ghost() && self.in_circle(t, p)
            })
            .expect("a point outside the hull sees a hull edge")
    }

    /// Once three non-collinear points exist, build the first triangle and add the rest.
    fn try_start(&mut self) {
        let n = self.pending.len();
        if n < 3 {
            return;
        }
        let a = self.pending[0];
        let b = self.pending[1];
        let Some(ci) = (2..n).find(|&i| {
            orient(
                self.pts[a as usize],
                self.pts[b as usize],
                self.pts[self.pending[i] as usize],
            ) != 0
        }) else {
            return;
        };
        let c = self.pending[ci];
        let (b, c) = if orient(
            self.pts[a as usize],
            self.pts[b as usize],
            self.pts[c as usize],
        ) > 0
        {
            (b, c)
        } else {
            (c, b)
        };
        // Real triangle 0 and its three ghosts 1..3, allocated in that order (neighbours
        // linked below).
        let [t0, g_ab, g_bc, g_ca] = [[a, b, c], [b, a, GHOST], [c, b, GHOST], [a, c, GHOST]]
            .map(|v| self.alloc(Tri { v, n: [NONE; 3] }));
        self.tris[t0 as usize].n = [g_bc, g_ca, g_ab];
        // Ghost (b, a, G): n[2] across edge b→a is t0; n[0] across (a, G); n[1] across (G, b).
        self.tris[g_ab as usize].n = [g_ca, g_bc, t0];
        self.tris[g_bc as usize].n = [g_ab, g_ca, t0];
        self.tris[g_ca as usize].n = [g_bc, g_ab, t0];
        self.last = t0;
        let rest: Vec<u32> = self
            .pending
            .iter()
            .copied()
            .filter(|&v| v != a && v != b && v != c)
            .collect();
        self.pending.clear();
        for v in rest {
            let p = self.pts[v as usize];
            let start = match self.locate(p, None) {
                Location::Triangle(t) => t,
                Location::Outside => self.find_ghost_seeing(p),
                Location::Vertex(_) => unreachable!("duplicates were rejected"),
            };
            self.insert_from(v, start);
        }
    }

    /// Bowyer–Watson: remove every triangle whose circumcircle contains vertex `id`, and
    /// connect `id` to the boundary of that cavity.
    fn insert_from(&mut self, id: u32, start: u32) {
        let p = self.pts[id as usize];
        let stamp = next_stamp(&mut self.stamp, &mut self.mark);
        self.cavity.clear();
        self.stack.clear();
        self.boundary.clear();
        self.stack.push(start);
        self.mark[start as usize] = stamp;
        while let Some(t) = self.stack.pop() {
            self.cavity.push(t);
            let tr = self.tris[t as usize];
            for k in 0..3 {
                let nb = tr.n[k];
                let (a, b) = (tr.v[(k + 1) % 3], tr.v[(k + 2) % 3]);
                if self.mark[nb as usize] == stamp {
                    continue;
                }
                if self.in_circle(nb, p) {
                    self.mark[nb as usize] = stamp;
                    self.stack.push(nb);
                } else {
                    self.boundary.push((a, b, nb));
                }
            }
        }
        // Edges of the cavity that are in the cavity on both sides are gone; boundary
        // edges whose outer triangle joined the cavity later are interior too.
        let mut boundary = std::mem::take(&mut self.boundary);
        boundary.retain(|&(_, _, nb)| self.mark[nb as usize] != stamp);
        for &t in &self.cavity {
            self.alive[t as usize] = false;
            self.free.push(t);
        }
        // New triangles (a, b, p), normalised so a ghost vertex is last.
        let mut made = std::mem::take(&mut self.made);
        made.clear();
        for &(a, b, outer) in &boundary {
            let v = if a == GHOST {
                [b, id, GHOST]
            } else if b == GHOST {
                [id, a, GHOST]
            } else {
                [a, b, id]
            };
            let t = self.alloc(Tri { v, n: [NONE; 3] });
            // Link across the boundary edge a→b.
            let k = 3 - self.tris[t as usize].index_of(a) - self.tris[t as usize].index_of(b);
            self.tris[t as usize].n[k] = outer;
            let o = &mut self.tris[outer as usize];
            let ko = 3 - o.index_of(a) - o.index_of(b);
            o.n[ko] = t;
            made.push((a, b, t));
            self.created.push(t);
        }
        // Link new triangles to each other: (a, b, p) and (b, c, p) share edge b–p.
        for i in 0..made.len() {
            let (a, b, t) = made[i];
            let next = made
                .iter()
                .find(|&&(a2, _, _)| a2 == b)
                .expect("cavity boundary is a closed cycle")
                .2;
            let prev = made
                .iter()
                .find(|&&(_, b2, _)| b2 == a)
                .expect("cavity boundary is a closed cycle")
                .2;
            let tr = self.tris[t as usize];
            // Edge b–p is opposite a; edge p–a is opposite b.
            self.tris[t as usize].n[tr.index_of(a)] = next;
            self.tris[t as usize].n[tr.index_of(b)] = prev;
            if !tr.is_ghost() {
                self.last = t;
            }
        }
        self.boundary = boundary;
        self.made = made;
    }
}

/// The circumcircle of the triangle `a, b, c` in floating point: its centre and its squared
/// radius. Only for bounding a search (which samples or buckets a new triangle's circle may
/// reach); the exact in-circle test is [`Triangulation`]'s.
pub fn circumcircle(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> ([f64; 2], f64) {
    let (ax, ay) = (a[0] as f64, a[1] as f64);
    let (bx, by) = ((b[0] - a[0]) as f64, (b[1] - a[1]) as f64);
    let (cx, cy) = ((c[0] - a[0]) as f64, (c[1] - a[1]) as f64);
    let d = 2.0 * (bx * cy - by * cx);
    let lb = bx * bx + by * by;
    let lc = cx * cx + cy * cy;
    let ux = (cy * lb - by * lc) / d;
    let uy = (bx * lc - cx * lb) / d;
    ([ax + ux, ay + uy], ux * ux + uy * uy)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn check_delaunay(tr: &Triangulation) {
        let mut real = 0;
        for t in 0..tr.tris.len() as u32 {
            if !tr.alive[t as usize] {
                continue;
            }
            let x = tr.tris[t as usize];
            for k in 0..3 {
                let nb = x.n[k];
                assert!(tr.alive[nb as usize], "dead neighbour");
                let y = tr.tris[nb as usize];
                assert!(y.n.contains(&t), "neighbour link not mutual");
            }
            if x.is_ghost() {
                continue;
            }
            real += 1;
            let [a, b, c] = x.v.map(|v| tr.pts[v as usize]);
            assert!(orient(a, b, c) > 0, "triangle not CCW");
            for (i, &p) in tr.pts.iter().enumerate() {
                if x.v.contains(&(i as u32)) {
                    continue;
                }
                assert!(incircle(a, b, c, p) <= 0, "not Delaunay");
            }
        }
        assert!(real > 0);
    }

    #[test]
    fn grid_points_with_cocircular_squares() {
        let mut tr = Triangulation::new();
        for (x, y) in [(0, 0), (10, 0), (10, 10), (0, 10)] {
            tr.insert([x, y]).unwrap();
        }
        for y in 0..=10 {
            for x in 0..=10 {
                if (x + y) % 3 == 0 && !([0, 10].contains(&x) && [0, 10].contains(&y)) {
                    tr.insert([x, y]).unwrap();
                }
            }
        }
        check_delaunay(&tr);
        assert!(tr.insert([5, 5]).is_ok() || tr.insert([5, 5]).is_err());
        assert!(tr.insert([0, 0]).is_err());
    }

    #[test]
    fn collinear_start_waits_for_a_third_point() {
        let mut tr = Triangulation::new();
        for x in 0..5 {
            tr.insert([x, 0]).unwrap();
        }
        assert!(!tr.is_2d());
        tr.insert([2, 3]).unwrap();
        assert!(tr.is_2d());
        check_delaunay(&tr);
        assert_eq!(tr.num_vertices(), 6);
        assert_eq!(tr.real_triangles().count(), 4);
    }

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(2000))]
        #[test]
        fn filtered_incircle_has_the_exact_sign(
            a in (-300i64..300, -300i64..300), b in (-300i64..300, -300i64..300),
            c in (-300i64..300, -300i64..300), d in (-300i64..300, -300i64..300),
            big in proptest::bool::ANY,
        ) {
            let s = if big { 1 << 20 } else { 1 };
            let p = |q: (i64, i64)| [q.0 * s + q.1, q.1 * s - q.0];
            let (a, b, c, d) = (p(a), p(b), p(c), p(d));
            prop_assert_eq!(incircle(a, b, c, d).signum(), incircle_exact(a, b, c, d).signum());
        }
    }

    #[test]
    fn cocircular_grid_points_are_exactly_on_the_circle() {
        // The four corners of a square are co-circular: the filter must defer to exact math.
        for s in [1i64, 7, 1 << 12, 1 << 22] {
            assert_eq!(incircle([0, 0], [s, 0], [s, s], [0, s]), 0);
            if s > 2 {
                assert!(incircle([0, 0], [s, 0], [s, s], [1, 1]) > 0);
            }
        }
    }

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(48))]
        #[test]
        fn random_insertions_stay_delaunay(pts in proptest::collection::vec((0i64..40, 0i64..40), 3..120)) {
            let mut tr = Triangulation::new();
            for (x, y) in pts {
                let _ = tr.insert([x, y]);
            }
            if tr.is_2d() {
                check_delaunay(&tr);
                for (i, &p) in tr.pts.iter().enumerate() {
                    prop_assert_eq!(tr.locate(p, None), Location::Vertex(i as u32));
                }
            }
        }
    }
}
