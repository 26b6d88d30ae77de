//! Basis-function interpolation surfaces over a Delaunay triangulation (paper 004 in
//! `../shared/papers`: Silva, Vidal & Cavalcante Neto, "A strategy for the interpolation of
//! surfaces through the use of basis functions", after Chaturvedi & Piegl's procedural
//! method). A study, not a codec method: `examples/basis_study.rs` compares it with Sibson's
//! interpolant and `benches/basis_study.md` has the numbers.
//!
//! The surface is `f(q) = Σ z_i B_i(q)` with `B_i = β_i / Σ_j β_j` (the paper's equations 1
//! and 2). Each `β_i` is a *swung surface*: a profile curve `z(u)`, `u ∈ [0, 1]` the distance
//! from sample `p_i` as a fraction of the distance to a *trajectory curve` around `p_i`, is
//! revolved around `p_i` and scaled by the trajectory (equations 14 and 15):
//! `β_i(q) = z(|q − p_i| / |X − p_i|)` where X is where the ray from `p_i` through q meets
//! the trajectory, and 0 outside it. The trajectory passes through the vertices of the star
//! polygon of `p_i` (the link of `p_i` in the triangulation), so the support contains the
//! star; its segments are quadratic rational Bézier curves (equation 3, end weights 1, middle
//! weight w) that may bulge outward from the star polygon's edges as far as the other
//! samples allow (no sample other than `p_i` may lie strictly inside the support, which
//! keeps `f(p_j) = z_j`).
//!
//! Three trajectories ([`Trajectory`]):
//! * `Polyhedral`: the star polygon itself and the linear profile: `β_i` is the hat function
//!   of `p_i`, so `f` is the piecewise-linear (barycentric) interpolant over the triangles.
//! * `ChaturvediPiegl`: Bézier segments through the star polygon's vertices with tangents by
//!   central differences (equation 4); the bulge of a segment is `d = min(α L, d_p)` (equations
//!   17 and 18: L the chord's length, `d_p` the distance from the chord of the nearest other
//!   sample in the region between the chord's line and the parallel through the middle
//!   control point), reached with `w = d / (h − d)`, h the middle control point's distance
//!   from the chord. `ChaturvediPieglLocal` counts only the samples of that strip that lie
//!   over the control triangle's extent along the chord.
//! * `Expanded` (the paper's contribution, section 3.5): the same segments, but only samples
//!   strictly inside the control triangle restrict the bulge, each by the weight of the conic
//!   through it, `w_P = τ1 / (2 √(τ0 τ2))` from its barycentric coordinates (equation 19);
//!   `w = min(w_α, min_P w_P)` with `w_α` the weight of the α-bulge (equation 20).
//!
//! The profile is the cubic Hermite curve biased toward the linear one by λ (equations 12 and
//! 21): `z(u) = λ (1 − u)² (1 + 2u) + (1 − λ)(1 − u)`; λ = 1 is the plain Hermite curve (zero
//! slope at both ends: a plateau at each sample), λ = 0 the straight line (slope −1). With
//! α = λ = 0 every variant is the polyhedral interpolant, as the paper says.
//!
//! # Choices where the paper's text is ambiguous (its formulas were lost in extraction)
//! * λ's direction: 0 = linear, 1 = Hermite, so that "polyhedral = α and λ equal to zero".
//! * Tangents (equation 4): `T_k = unit(V_{k+1} − V_{k−1})`. Open trajectories (p on the hull):
//!   with one triangle the end tangents make ±45° with the chord (outward); otherwise each end
//!   tangent is that of the parabola through the three end vertices (chord-length
//!   parameters). Any tangent that does not turn counter-clockwise around p (it would let a ray
//!   from p cross the trajectory twice, the paper's condition 4 and its "correction") is
//!   replaced by the direction perpendicular to `V_k − p`.
//! * Cases of a segment (figure 5), with θ0, θ1 the angles of the end tangents with the chord,
//!   positive when the curve leaves the star polygon (outward): case 1/2, both outward and
//!   θ0 + θ1 < π: one conic, middle control point where the tangent lines meet; case 3, both
//!   outward and θ0 + θ1 ≥ π: a new vertex M on the chord's perpendicular bisector at
//!   `h = min(α L, d)` outward (d: the nearest other sample over the chord; also kept inside
//!   the sector seen from p), tangent parallel to the chord, and one conic (or a straight
//!   piece when it is not case 2) on each side. Cases 4 and 5 (an inflection, or one tangent
//!   along the chord) and tangents pointing into the star polygon keep the chord straight
//!   (their equations 6–11 are lost): the support never shrinks below the star polygon.
//! * Chaturvedi–Piegl's restricting region: "the region between the chord's support line and
//!   the parallel through" the middle control point, read literally (the whole strip, however
//!   far along the chord's line) in `ChaturvediPiegl`, and limited to the control triangle's
//!   extent along the chord in `ChaturvediPieglLocal`. The other vertices of the star (the
//!   neighbours) and p itself do not count ("non-neighbouring"), for every trajectory.
//! * A weight that would be infinite (the bulge allowed reaches the control point) is capped
//!   at [`W_MAX`]: the curve is then within `h / W_MAX` of the control polygon.
//!
//! Coordinates are `f64`; the triangulation's integer sites are exact in them.
// Nothing in the codec uses it yet: only its tests and `examples/basis_study.rs` (which
// compiles this file into itself).
#![cfg_attr(not(test), allow(dead_code))]

use crate::error::{Error, Result};
use crate::geometry::triangulation::Triangulation;
use std::f64::consts::PI;

type P = [f64; 2];

/// Cap on a segment's middle weight (the curve is then the control polygon, nearly).
pub const W_MAX: f64 = 1e6;
/// Angles within this of 0 or π count as 0 or π when a segment's case is chosen.
const ANGLE_EPS: f64 = 1e-9;

#[inline]
fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1]]
}
#[inline]
fn add(a: P, b: P) -> P {
    [a[0] + b[0], a[1] + b[1]]
}
#[inline]
fn mul(a: P, s: f64) -> P {
    [a[0] * s, a[1] * s]
}
#[inline]
fn dot(a: P, b: P) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
#[inline]
fn cross(a: P, b: P) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}
#[inline]
fn len(a: P) -> f64 {
    dot(a, a).sqrt()
}
#[inline]
fn unit(a: P) -> P {
    mul(a, 1.0 / len(a))
}
/// `a` turned a quarter counter-clockwise.
#[inline]
fn perp(a: P) -> P {
    [-a[1], a[0]]
}

/// How the support of a basis function is bounded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trajectory {
    /// The star polygon, with the linear profile: barycentric interpolation.
    Polyhedral,
    /// Chaturvedi & Piegl as the paper describes them: Bézier segments bounded by α and by
    /// the nearest sample in the whole strip between the chord's line and its parallel
    /// through the middle control point.
    ChaturvediPiegl,
    /// A milder reading of Chaturvedi & Piegl: only the part of that strip over the control
    /// triangle's extent along the chord restricts.
    ChaturvediPieglLocal,
    /// The paper's: Bézier segments expanded up to the samples inside their control triangle.
    Expanded,
}

/// A surface's parameters: the trajectory, the expansion fraction α (of each chord) and the
/// profile's Hermite share λ (0 linear, 1 cubic Hermite).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    pub trajectory: Trajectory,
    pub alpha: f64,
    pub lambda: f64,
}

impl Params {
    /// Piecewise-linear interpolation.
    pub fn polyhedral() -> Params {
        Params {
            trajectory: Trajectory::Polyhedral,
            alpha: 0.0,
            lambda: 0.0,
        }
    }
    /// Chaturvedi & Piegl's trajectories.
    pub fn chaturvedi_piegl(alpha: f64, lambda: f64) -> Params {
        Params {
            trajectory: Trajectory::ChaturvediPiegl,
            alpha,
            lambda,
        }
    }
    /// The paper's expanded trajectories.
    pub fn expanded(alpha: f64, lambda: f64) -> Params {
        Params {
            trajectory: Trajectory::Expanded,
            alpha,
            lambda,
        }
    }
}

/// A quadratic rational Bézier segment `q0 → q2`, middle control point `q1`, weights
/// (1, w, 1); `w = 0` is the straight segment.
#[derive(Clone, Copy, Debug)]
struct Piece {
    q0: P,
    q1: P,
    q2: P,
    w: f64,
}

impl Piece {
    fn straight(a: P, b: P) -> Piece {
        Piece {
            q0: a,
            q1: mul(add(a, b), 0.5),
            q2: b,
            w: 0.0,
        }
    }

    fn at(&self, t: f64) -> P {
        let (b0, b1, b2) = ((1.0 - t) * (1.0 - t), 2.0 * self.w * t * (1.0 - t), t * t);
        let d = b0 + b1 + b2;
        [
            (b0 * self.q0[0] + b1 * self.q1[0] + b2 * self.q2[0]) / d,
            (b0 * self.q0[1] + b1 * self.q1[1] + b2 * self.q2[1]) / d,
        ]
    }

    /// Where the ray from `p` in direction `d` meets the segment, for a ray between `q0` and
    /// `q2` as seen from `p` (so `cross(q0 − p, d) ≥ 0 ≥ cross(q2 − p, d)`, one crossing).
    fn ray_crossing(&self, p: P, d: P) -> P {
        // cross(C(t) − p, d) = 0 ⇔ Σ ω_j B_j(t) cross(Q_j − p, d) = 0: a quadratic in t.
        let c0 = cross(sub(self.q0, p), d);
        let c2 = cross(sub(self.q2, p), d);
        if c0 <= 0.0 {
            return self.q0;
        }
        if c2 >= 0.0 {
            return self.q2;
        }
        if self.w == 0.0 {
            // Straight: p + s d on the line q0 → q2.
            let e = sub(self.q2, self.q0);
            let den = cross(d, e);
            if den == 0.0 {
                return self.q0;
            }
            let s = cross(sub(self.q0, p), e) / den;
            return add(p, mul(d, s));
        }
        let c1 = self.w * cross(sub(self.q1, p), d);
        let g = |t: f64| (1.0 - t) * (1.0 - t) * c0 + 2.0 * t * (1.0 - t) * c1 + t * t * c2;
        let (a, b, c) = (c0 - 2.0 * c1 + c2, 2.0 * (c1 - c0), c0);
        let scale = c0.abs() + c1.abs() + c2.abs();
        let mut t = f64::NAN;
        if a.abs() <= 1e-14 * scale {
            if b != 0.0 {
                t = -c / b;
            }
        } else {
            let disc = (b * b - 4.0 * a * c).max(0.0);
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            for r in [q / a, if q != 0.0 { c / q } else { f64::NAN }] {
                if (-1e-9..=1.0 + 1e-9).contains(&r) {
                    t = r;
                    break;
                }
            }
        }
        if !t.is_finite() || !(-1e-9..=1.0 + 1e-9).contains(&t) {
            // Fallback: bisection on the sign change g(0) > 0 > g(1).
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..80 {
                let mid = 0.5 * (lo + hi);
                if g(mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            t = 0.5 * (lo + hi);
        }
        self.at(t.clamp(0.0, 1.0))
    }

    /// A box around the region between the chord and the curve: the part of the control
    /// triangle within the curve's largest distance from the chord, `h w / (1 + w)`.
    fn bbox(&self, bb: &mut [f64; 4]) {
        let mut put = |q: P| {
            bb[0] = bb[0].min(q[0]);
            bb[1] = bb[1].min(q[1]);
            bb[2] = bb[2].max(q[0]);
            bb[3] = bb[3].max(q[1]);
        };
        put(self.q0);
        put(self.q2);
        if self.w > 0.0 {
            let s = self.w / (1.0 + self.w);
            put(add(self.q0, mul(sub(self.q1, self.q0), s)));
            put(add(self.q2, mul(sub(self.q1, self.q2), s)));
        }
    }
}

/// The trajectory over one triangle of the star, (p, v0, v1): one piece, or two meeting at
/// `second.q0` (case 3).
#[derive(Clone, Copy, Debug)]
struct Sector {
    v0: P,
    v1: P,
    first: Piece,
    second: Option<Piece>,
}

#[derive(Clone, Debug)]
struct Basis {
    p: P,
    z: f64,
    /// Its sectors in `BasisSurface::sectors`, counter-clockwise.
    sectors: (u32, u32),
    bbox: [f64; 4],
}

/// Buckets of ids on a uniform grid of cells (compressed rows).
#[derive(Clone, Debug)]
struct Grid {
    x0: f64,
    y0: f64,
    inv: f64,
    nx: usize,
    ny: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Grid {
    fn new(bb: [f64; 4], cell: f64, boxes: &[[f64; 4]]) -> Grid {
        let cell = cell.max(1e-300);
        let nx = (((bb[2] - bb[0]) / cell).floor() as usize + 1).min(4096);
        let ny = (((bb[3] - bb[1]) / cell).floor() as usize + 1).min(4096);
        let mut g = Grid {
            x0: bb[0],
            y0: bb[1],
            inv: 1.0 / cell,
            nx,
            ny,
            start: vec![0; nx * ny + 1],
            items: Vec::new(),
        };
        for b in boxes {
            let (xs, ys) = g.range(b);
            for y in ys {
                for x in xs.clone() {
                    g.start[y * nx + x + 1] += 1;
                }
            }
        }
        for i in 0..nx * ny {
            g.start[i + 1] += g.start[i];
        }
        g.items = vec![0; g.start[nx * ny] as usize];
        let mut fill = g.start.clone();
        for (id, b) in boxes.iter().enumerate() {
            let (xs, ys) = g.range(b);
            for y in ys {
                for x in xs.clone() {
                    let c = y * nx + x;
                    g.items[fill[c] as usize] = id as u32;
                    fill[c] += 1;
                }
            }
        }
        g
    }

    fn ix(&self, v: f64, o: f64, n: usize) -> usize {
        let i = ((v - o) * self.inv).floor();
        if i <= 0.0 { 0 } else { (i as usize).min(n - 1) }
    }

    fn range(
        &self,
        b: &[f64; 4],
    ) -> (
        std::ops::RangeInclusive<usize>,
        std::ops::RangeInclusive<usize>,
    ) {
        (
            self.ix(b[0], self.x0, self.nx)..=self.ix(b[2], self.x0, self.nx),
            self.ix(b[1], self.y0, self.ny)..=self.ix(b[3], self.y0, self.ny),
        )
    }

    fn at(&self, q: P) -> &[u32] {
        let c = self.ix(q[1], self.y0, self.ny) * self.nx + self.ix(q[0], self.x0, self.nx);
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }
}

/// The basis-function interpolant of heights at the vertices of a Delaunay triangulation.
#[derive(Clone, Debug)]
pub struct BasisSurface {
    params: Params,
    bases: Vec<Basis>,
    sectors: Vec<Sector>,
    /// The convex hull, counter-clockwise, without collinear vertices.
    hull: Vec<P>,
    /// Candidate bases per cell (every basis whose support box meets the cell).
    grid: Grid,
}

/// What building a trajectory needs: the samples and where they are.
struct Ctx<'a> {
    params: Params,
    pts: &'a [P],
    index: &'a Grid,
}

impl Ctx<'_> {
    /// Each sample `s` (not `p` nor one of its neighbours) in the box `bb`.
    fn others(&self, bb: [f64; 4], excluded: &[u32], mut f: impl FnMut(P)) {
        let (xs, ys) = self.index.range(&bb);
        for y in ys {
            for x in xs.clone() {
                let c = y * self.index.nx + x;
                for &s in &self.index.items
                    [self.index.start[c] as usize..self.index.start[c + 1] as usize]
                {
                    if excluded.contains(&s) {
                        continue;
                    }
                    let q = self.pts[s as usize];
                    if q[0] >= bb[0] && q[0] <= bb[2] && q[1] >= bb[1] && q[1] <= bb[3] {
                        f(q);
                    }
                }
            }
        }
    }

    /// The sector over the chord `a → b` of the star of `p`, end tangents `ta`, `tb`.
    fn sector(&self, p: P, a: P, b: P, ta: P, tb: P, excluded: &[u32]) -> Sector {
        let straight = Sector {
            v0: a,
            v1: b,
            first: Piece::straight(a, b),
            second: None,
        };
        if self.params.trajectory == Trajectory::Polyhedral || self.params.alpha <= 0.0 {
            return straight;
        }
        let (th0, th1) = angles(a, b, ta, tb);
        if !(th0 > ANGLE_EPS && th1 > ANGLE_EPS) {
            // Cases 1, 4, 5 and tangents into the star: the chord stays straight.
            return straight;
        }
        if th0 + th1 < PI - ANGLE_EPS {
            // Case 2: one conic.
            return Sector {
                v0: a,
                v1: b,
                first: self.piece(a, b, ta, tb, excluded),
                second: None,
            };
        }
        // Case 3: a new vertex M over the chord's middle, tangent parallel to the chord.
        let l = len(sub(b, a));
        let c = unit(sub(b, a));
        let n = [c[1], -c[0]];
        let mid = mul(add(a, b), 0.5);
        let mut h = self.params.alpha * l;
        // The nearest other sample over the chord (a triangle a, M, b must stay empty).
        let reach = h;
        let corners = [a, b, add(a, mul(n, reach)), add(b, mul(n, reach))];
        self.others(bbox_of(&corners), excluded, |s| {
            let (x, y) = (dot(sub(s, a), c), dot(sub(s, a), n));
            if y > 0.0 && x >= 0.0 && x <= l {
                h = h.min(y);
            }
        });
        // M strictly inside the sector seen from p.
        let (ea, eb, em) = (sub(a, p), sub(b, p), sub(mid, p));
        let (ka, kb) = (cross(ea, n), cross(n, eb));
        if ka < 0.0 {
            h = h.min(0.999 * cross(ea, em) / -ka);
        }
        if kb < 0.0 {
            h = h.min(0.999 * cross(em, eb) / -kb);
        }
        if h.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return straight;
        }
        let m = add(mid, mul(n, h));
        Sector {
            v0: a,
            v1: b,
            first: self.piece(a, m, ta, c, excluded),
            second: Some(self.piece(m, b, c, tb, excluded)),
        }
    }

    /// One conic `a → b` with end tangents `ta`, `tb` when both leave the chord outward and
    /// their lines meet (case 2), else the straight chord.
    fn piece(&self, a: P, b: P, ta: P, tb: P, excluded: &[u32]) -> Piece {
        let (th0, th1) = angles(a, b, ta, tb);
        if !(th0 > ANGLE_EPS && th1 > ANGLE_EPS && th0 + th1 < PI - ANGLE_EPS) {
            return Piece::straight(a, b);
        }
        let l = len(sub(b, a));
        let c = unit(sub(b, a));
        let n = [c[1], -c[0]];
        let s = (th0 + th1).sin();
        let r0 = l * th1.sin() / s;
        let q1 = add(a, add(mul(c, r0 * th0.cos()), mul(n, r0 * th0.sin())));
        let h = dot(sub(q1, a), n);
        let d_alpha = self.params.alpha * l;
        let w = match self.params.trajectory {
            Trajectory::Polyhedral => 0.0,
            Trajectory::ChaturvediPiegl | Trajectory::ChaturvediPieglLocal => {
                // The strip between the chord's line and the parallel through q1: all of it,
                // or the part over the control triangle's extent along the chord.
                let xq = dot(sub(q1, a), c);
                let (x0, x1, bb) = if self.params.trajectory == Trajectory::ChaturvediPiegl {
                    (f64::MIN, f64::MAX, [f64::MIN, f64::MIN, f64::MAX, f64::MAX])
                } else {
                    let (x0, x1) = (xq.min(0.0), xq.max(l));
                    let (e0, e1) = (add(a, mul(c, x0)), add(a, mul(c, x1)));
                    let bb = bbox_of(&[e0, e1, add(e0, mul(n, h)), add(e1, mul(n, h))]);
                    (x0, x1, bb)
                };
                let mut d = d_alpha;
                self.others(bb, excluded, |s| {
                    let (x, y) = (dot(sub(s, a), c), dot(sub(s, a), n));
                    if y > 0.0 && y < h && x >= x0 && x <= x1 {
                        d = d.min(y);
                    }
                });
                weight_for_bulge(d, h)
            }
            Trajectory::Expanded => {
                let mut w = weight_for_bulge(d_alpha, h);
                let area = cross(sub(q1, a), sub(b, a));
                self.others(bbox_of(&[a, q1, b]), excluded, |s| {
                    // Barycentric coordinates in (a, q1, b).
                    let t0 = cross(sub(q1, s), sub(b, s)) / area;
                    let t1 = cross(sub(b, s), sub(a, s)) / area;
                    let t2 = 1.0 - t0 - t1;
                    if t0 > 0.0 && t1 > 0.0 && t2 > 0.0 {
                        w = w.min(t1 / (2.0 * (t0 * t2).sqrt()));
                    }
                });
                w
            }
        };
        Piece {
            q0: a,
            q1,
            q2: b,
            w,
        }
    }
}

/// The weight for which the conic's largest distance from the chord, `h w / (1 + w)`, is
/// `d` (equation 18), capped at [`W_MAX`].
fn weight_for_bulge(d: f64, h: f64) -> f64 {
    if d <= 0.0 {
        0.0
    } else if d >= h {
        W_MAX
    } else {
        (d / (h - d)).min(W_MAX)
    }
}

/// The angles of the end tangents with the chord `a → b`, positive when the curve leaves the
/// star polygon (to the chord's right, away from p): at a of `ta`, at b of `−tb` with `b → a`.
fn angles(a: P, b: P, ta: P, tb: P) -> (f64, f64) {
    let c = unit(sub(b, a));
    let n = [c[1], -c[0]];
    (
        dot(ta, n).atan2(dot(ta, c)),
        (-dot(tb, n)).atan2(dot(tb, c)),
    )
}

fn bbox_of(pts: &[P]) -> [f64; 4] {
    let mut bb = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
    for q in pts {
        bb[0] = bb[0].min(q[0]);
        bb[1] = bb[1].min(q[1]);
        bb[2] = bb[2].max(q[0]);
        bb[3] = bb[3].max(q[1]);
    }
    bb
}

/// The tangent at `v[0]` of the parabola through `v[0], v[1], v[2]` (chord-length
/// parameters).
fn parabola_start_tangent(v: [P; 3]) -> P {
    let t1 = len(sub(v[1], v[0]));
    let t2 = t1 + len(sub(v[2], v[1]));
    let l0 = -(t1 + t2) / (t1 * t2);
    let l1 = t2 / (t1 * (t2 - t1));
    let l2 = -t1 / (t2 * (t2 - t1));
    unit(add(add(mul(v[0], l0), mul(v[1], l1)), mul(v[2], l2)))
}

/// Tangents of the trajectory at the star polygon's vertices `link` around `p` (closed: the
/// polygon wraps around; open: `p` on the hull, `link` from one hull neighbour to the other).
fn tangents(p: P, link: &[P], closed: bool) -> Vec<P> {
    let n = link.len();
    let mut t: Vec<P> = Vec::with_capacity(n);
    for k in 0..n {
        let tk = if closed {
            unit(sub(link[(k + 1) % n], link[(k + n - 1) % n]))
        } else if k > 0 && k + 1 < n {
            unit(sub(link[k + 1], link[k - 1]))
        } else if n == 2 {
            // One triangle: ±45° with the chord, outward.
            let c = unit(sub(link[1], link[0]));
            let o = [c[1], -c[0]];
            let (cs, sn) = (
                std::f64::consts::FRAC_1_SQRT_2,
                std::f64::consts::FRAC_1_SQRT_2,
            );
            if k == 0 {
                add(mul(c, cs), mul(o, sn))
            } else {
                sub(mul(c, cs), mul(o, sn))
            }
        } else if k == 0 {
            parabola_start_tangent([link[0], link[1], link[2]])
        } else {
            mul(
                parabola_start_tangent([link[n - 1], link[n - 2], link[n - 3]]),
                -1.0,
            )
        };
        // A ray from p may meet the trajectory once only: the tangent must turn
        // counter-clockwise around p.
        let r = sub(link[k], p);
        t.push(if cross(r, tk) > 1e-12 * len(r) {
            tk
        } else {
            unit(perp(r))
        });
    }
    t
}

/// `z(u)`: the cubic Hermite profile biased toward the linear one by `1 − λ`.
#[inline]
pub fn profile(u: f64, lambda: f64) -> f64 {
    if u >= 1.0 {
        return 0.0;
    }
    let u = u.max(0.0);
    let v = 1.0 - u;
    lambda * v * v * (1.0 + 2.0 * u) + (1.0 - lambda) * v
}

impl BasisSurface {
    /// The surface over `tri` (which must be two-dimensional) with `heights[v]` at vertex v.
    pub fn new(tri: &Triangulation, heights: &[f64], params: Params) -> Result<BasisSurface> {
        if !tri.is_2d() {
            return Err(Error::invalid(
                "basis surfaces need three non-collinear sites",
            ));
        }
        let pts: Vec<P> = tri
            .points()
            .iter()
            .map(|q| [q[0] as f64, q[1] as f64])
            .collect();
        if heights.len() != pts.len() {
            return Err(Error::invalid(format!(
                "{} heights for {} sites",
                heights.len(),
                pts.len()
            )));
        }
        let nv = pts.len();
        // The link of each vertex as directed edges (counter-clockwise around it).
        let mut edges: Vec<Vec<(u32, u32)>> = vec![Vec::new(); nv];
        for t in tri.real_triangles() {
            let v = tri.tri(t).v;
            for k in 0..3 {
                edges[v[k] as usize].push((v[(k + 1) % 3], v[(k + 2) % 3]));
            }
        }
        let all = bbox_of(&pts);
        let cell = ((all[2] - all[0]) * (all[3] - all[1]) / nv as f64)
            .sqrt()
            .max(1e-9);
        let point_boxes: Vec<[f64; 4]> = pts.iter().map(|q| [q[0], q[1], q[0], q[1]]).collect();
        let index = Grid::new(all, cell, &point_boxes);
        let ctx = Ctx {
            params,
            pts: &pts,
            index: &index,
        };
        let mut bases = Vec::with_capacity(nv);
        let mut sectors = Vec::new();
        let mut hull_next: Vec<Option<u32>> = vec![None; nv];
        for (i, es) in edges.iter().enumerate() {
            if es.is_empty() {
                return Err(Error::invalid(format!("site {i} is in no triangle")));
            }
            // Chain the link: open when some edge's start is no edge's end.
            let start = es
                .iter()
                .position(|&(a, _)| !es.iter().any(|&(_, b)| b == a));
            let closed = start.is_none();
            let mut ids = vec![es[start.unwrap_or(0)].0];
            while ids.len() <= es.len() {
                let last = *ids.last().expect("nonempty");
                match es.iter().find(|&&(a, _)| a == last) {
                    Some(&(_, b)) if !(closed && b == ids[0]) => ids.push(b),
                    _ => break,
                }
            }
            if !closed {
                hull_next[i] = Some(ids[0]);
            }
            let p = pts[i];
            let link: Vec<P> = ids.iter().map(|&v| pts[v as usize]).collect();
            let tan = tangents(p, &link, closed);
            let mut excluded = ids.clone();
            excluded.push(i as u32);
            let first = sectors.len() as u32;
            let mut bb = bbox_of(&link);
            bb = bbox_of(&[p, [bb[0], bb[1]], [bb[2], bb[3]]]);
            let chords = if closed { link.len() } else { link.len() - 1 };
            for k in 0..chords {
                let k1 = (k + 1) % link.len();
                let s = ctx.sector(p, link[k], link[k1], tan[k], tan[k1], &excluded);
                s.first.bbox(&mut bb);
                if let Some(sec) = &s.second {
                    sec.bbox(&mut bb);
                }
                sectors.push(s);
            }
            bases.push(Basis {
                p,
                z: heights[i],
                sectors: (first, sectors.len() as u32),
                bbox: bb,
            });
        }
        // The hull, counter-clockwise, from the first hull vertex; collinear vertices dropped.
        let h0 = hull_next.iter().position(|n| n.is_some()).expect("a hull");
        let mut ring = vec![h0 as u32];
        loop {
            let nx = hull_next[*ring.last().expect("nonempty") as usize].expect("hull cycle");
            if nx as usize == h0 || ring.len() > nv {
                break;
            }
            ring.push(nx);
        }
        let rp: Vec<P> = ring.iter().map(|&v| pts[v as usize]).collect();
        let m = rp.len();
        let hull: Vec<P> = (0..m)
            .filter(|&k| cross(sub(rp[k], rp[(k + m - 1) % m]), sub(rp[(k + 1) % m], rp[k])) != 0.0)
            .map(|k| rp[k])
            .collect();
        let boxes: Vec<[f64; 4]> = bases.iter().map(|b| b.bbox).collect();
        let grid = Grid::new(all, cell, &boxes);
        Ok(BasisSurface {
            params,
            bases,
            sectors,
            hull,
            grid,
        })
    }

    /// Whether `q` is inside the sites' convex hull or on its boundary.
    pub fn in_hull(&self, q: P) -> bool {
        let n = self.hull.len();
        (0..n).all(|k| {
            let (a, b) = (self.hull[k], self.hull[(k + 1) % n]);
            let (e, r) = (sub(b, a), sub(q, a));
            cross(e, r) >= -1e-12 * len(e) * len(r)
        })
    }

    /// The unnormalised basis function `β_i(q)` of vertex `i`.
    pub fn beta(&self, i: u32, q: P) -> f64 {
        let b = &self.bases[i as usize];
        let d = sub(q, b.p);
        if d == [0.0, 0.0] {
            return 1.0;
        }
        for s in &self.sectors[b.sectors.0 as usize..b.sectors.1 as usize] {
            if cross(sub(s.v0, b.p), d) >= 0.0 && cross(sub(s.v1, b.p), d) <= 0.0 {
                let piece = match &s.second {
                    Some(sec) if cross(sub(sec.q0, b.p), d) >= 0.0 => sec,
                    _ => &s.first,
                };
                let x = sub(piece.ray_crossing(b.p, d), b.p);
                let u = dot(d, x) / dot(x, x);
                return profile(u, self.params.lambda);
            }
        }
        0.0
    }

    /// The normalised basis functions `(i, B_i(q))` that are not zero at `q` into `out`;
    /// false (and `out` empty) outside the hull.
    pub fn basis_at(&self, q: P, out: &mut Vec<(u32, f64)>) -> bool {
        out.clear();
        if !self.in_hull(q) {
            return false;
        }
        let mut sum = 0.0;
        for &i in self.grid.at(q) {
            let bb = &self.bases[i as usize].bbox;
            if q[0] < bb[0] || q[0] > bb[2] || q[1] < bb[1] || q[1] > bb[3] {
                continue;
            }
            if self.bases[i as usize].p == q {
                out.clear();
                out.push((i, 1.0));
                return true;
            }
            let v = self.beta(i, q);
            if v > 0.0 {
                out.push((i, v));
                sum += v;
            }
        }
        if sum <= 0.0 {
            out.clear();
            return false;
        }
        for o in out.iter_mut() {
            o.1 /= sum;
        }
        true
    }

    /// `f(q) = Σ z_i B_i(q)`, or `None` outside the sites' convex hull.
    pub fn eval(&self, q: P) -> Option<f64> {
        if !self.in_hull(q) {
            return None;
        }
        let (mut num, mut den) = (0.0, 0.0);
        for &i in self.grid.at(q) {
            let b = &self.bases[i as usize];
            let bb = &b.bbox;
            if q[0] < bb[0] || q[0] > bb[2] || q[1] < bb[1] || q[1] > bb[3] {
                continue;
            }
            if b.p == q {
                return Some(b.z);
            }
            let v = self.beta(i, q);
            if v > 0.0 {
                num += v * b.z;
                den += v;
            }
        }
        (den > 0.0).then(|| num / den)
    }

    /// How the chords were bounded: (straight, one conic, split in two by a new vertex).
    pub fn chord_cases(&self) -> [usize; 3] {
        let mut n = [0; 3];
        for s in &self.sectors {
            n[match (s.first.w > 0.0, &s.second) {
                (_, Some(_)) => 2,
                (true, None) => 1,
                (false, None) => 0,
            }] += 1;
        }
        n
    }

    /// How far the trajectories reach beyond the star polygons: the mean over chords of the
    /// largest distance of the trajectory from the chord, as a fraction of the chord's length.
    pub fn mean_bulge(&self) -> f64 {
        let mut sum = 0.0;
        for s in &self.sectors {
            let l = len(sub(s.v1, s.v0));
            let n = {
                let c = unit(sub(s.v1, s.v0));
                [c[1], -c[0]]
            };
            let mut h: f64 = 0.0;
            for piece in std::iter::once(&s.first).chain(s.second.as_ref()) {
                let hq = dot(sub(piece.q1, s.v0), n);
                let hm = dot(sub(piece.q0, s.v0), n).max(dot(sub(piece.q2, s.v0), n));
                h = h.max(hm).max(hm + (hq - hm) * piece.w / (1.0 + piece.w));
            }
            sum += h / l;
        }
        sum / self.sectors.len().max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::triangulation::Location;
    use crate::testutil::Rng;

    fn random_tri(n: usize, size: i64, seed: u64) -> (Triangulation, Vec<f64>) {
        let mut rng = Rng(seed);
        let mut tri = Triangulation::default();
        let mut hs = Vec::new();
        while hs.len() < n {
            let p = [
                rng.below(size as u64 + 1) as i64,
                rng.below(size as u64 + 1) as i64,
            ];
            if tri.insert_near(p, None).is_ok() {
                hs.push(rng.unit());
            }
        }
        (tri, hs)
    }

    fn all_params() -> Vec<Params> {
        let mut v = vec![Params::polyhedral()];
        for (a, l) in [(0.25, 0.25), (0.5, 0.5), (1.0, 1.0), (1.0, 0.0)] {
            v.push(Params::chaturvedi_piegl(a, l));
            v.push(Params {
                trajectory: Trajectory::ChaturvediPieglLocal,
                alpha: a,
                lambda: l,
            });
            v.push(Params::expanded(a, l));
        }
        v
    }

    /// Random points strictly inside the hull.
    fn inner_points(s: &BasisSurface, size: i64, n: usize, seed: u64) -> Vec<P> {
        let mut rng = Rng(seed);
        let mut out = Vec::new();
        while out.len() < n {
            let q = [rng.unit() * size as f64, rng.unit() * size as f64];
            if s.in_hull(q) {
                out.push(q);
            }
        }
        out
    }

    #[test]
    fn partition_of_unity_inside_the_hull() {
        for seed in 1..4 {
            let (tri, hs) = random_tri(150, 1000, seed);
            for params in all_params() {
                let s = BasisSurface::new(&tri, &hs, params).unwrap();
                let mut b = Vec::new();
                for q in inner_points(&s, 1000, 2000, seed + 10) {
                    assert!(s.basis_at(q, &mut b), "{params:?} {q:?}");
                    let sum: f64 = b.iter().map(|x| x.1).sum();
                    assert!((sum - 1.0).abs() < 1e-12, "{params:?} {q:?}: {sum}");
                    assert!(b.iter().all(|x| x.1 > 0.0 && x.1 <= 1.0 + 1e-12));
                }
                // Outside the hull: nothing.
                assert!(s.eval([-1.0, -1.0]).is_none());
            }
        }
    }

    #[test]
    fn interpolates_the_samples() {
        for seed in 1..4 {
            let (tri, hs) = random_tri(200, 1000, seed);
            for params in all_params() {
                let s = BasisSurface::new(&tri, &hs, params).unwrap();
                for (i, q) in tri.points().iter().enumerate() {
                    let p = [q[0] as f64, q[1] as f64];
                    assert_eq!(s.eval(p), Some(hs[i]), "{params:?} site {i}");
                    // Every other basis function vanishes there: no sample is strictly
                    // inside another's support.
                    for j in 0..hs.len() as u32 {
                        if j as usize != i {
                            let b = s.beta(j, p);
                            assert!(b < 1e-9, "{params:?} β_{j} at site {i}: {b}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn polyhedral_is_barycentric_interpolation() {
        for seed in 1..4 {
            let (tri, hs) = random_tri(120, 1000, seed);
            let surfaces = [
                BasisSurface::new(&tri, &hs, Params::polyhedral()).unwrap(),
                // α = λ = 0 is the polyhedral surface for both Bézier trajectories too.
                BasisSurface::new(&tri, &hs, Params::chaturvedi_piegl(0.0, 0.0)).unwrap(),
                BasisSurface::new(&tri, &hs, Params::expanded(0.0, 0.0)).unwrap(),
            ];
            let mut checked = 0;
            for y in (0..=1000).step_by(7) {
                for x in (0..=1000).step_by(7) {
                    let Location::Triangle(t) = tri.locate([x, y], None) else {
                        continue;
                    };
                    let v = tri.tri(t).v;
                    let [a, b, c] = v.map(|k| tri.point(k)).map(|q| [q[0] as f64, q[1] as f64]);
                    let q = [x as f64, y as f64];
                    let area = cross(sub(b, a), sub(c, a));
                    let la = cross(sub(b, q), sub(c, q)) / area;
                    let lb = cross(sub(c, q), sub(a, q)) / area;
                    let lc = 1.0 - la - lb;
                    let want =
                        la * hs[v[0] as usize] + lb * hs[v[1] as usize] + lc * hs[v[2] as usize];
                    for s in &surfaces {
                        let got = s.eval(q).unwrap();
                        assert!((got - want).abs() < 1e-12, "{q:?}: {got} vs {want}");
                    }
                    checked += 1;
                }
            }
            assert!(checked > 10_000);
        }
    }

    #[test]
    fn continuous_across_triangle_edges() {
        for seed in 1..4 {
            let (tri, hs) = random_tri(150, 1000, seed);
            // Interior edges: those of two real triangles.
            let mut edges = std::collections::HashMap::new();
            for t in tri.real_triangles() {
                let v = tri.tri(t).v;
                for k in 0..3 {
                    let (a, b) = (v[k], v[(k + 1) % 3]);
                    *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                }
            }
            let interior: Vec<(u32, u32)> = edges
                .into_iter()
                .filter(|&(_, n)| n == 2)
                .map(|(e, _)| e)
                .collect();
            assert!(interior.len() > 300);
            for params in all_params() {
                let s = BasisSurface::new(&tri, &hs, params).unwrap();
                let mut worst: f64 = 0.0;
                for &(a, b) in &interior {
                    let (pa, pb) = (tri.point(a), tri.point(b));
                    let (pa, pb) = ([pa[0] as f64, pa[1] as f64], [pb[0] as f64, pb[1] as f64]);
                    let n = perp(unit(sub(pb, pa)));
                    for t in [0.013, 0.25, 0.5, 0.77, 0.991] {
                        let q = add(pa, mul(sub(pb, pa), t));
                        let delta = 1e-10;
                        let l = s.eval(add(q, mul(n, delta))).unwrap();
                        let r = s.eval(sub(q, mul(n, delta))).unwrap();
                        worst = worst.max((l - r).abs());
                    }
                }
                // Heights in [0, 1] over 1000 units: a jump would be ≫ 1e-9.
                assert!(worst < 1e-9, "{params:?}: {worst}");
            }
        }
    }

    #[test]
    fn expanded_reaches_at_least_as_far_as_chaturvedi_piegl() {
        let (tri, hs) = random_tri(300, 1000, 5);
        for alpha in [0.25, 0.5, 1.0] {
            // Each is at least as wide as the one before, chord by chord.
            let chain = [
                Trajectory::ChaturvediPiegl,
                Trajectory::ChaturvediPieglLocal,
                Trajectory::Expanded,
            ]
            .map(|trajectory| {
                let p = Params {
                    trajectory,
                    alpha,
                    lambda: 1.0,
                };
                BasisSurface::new(&tri, &hs, p).unwrap()
            });
            let [straight, conic, _] = chain[2].chord_cases();
            assert!(conic > straight / 4, "{straight} {conic}");
            for pair in chain.windows(2) {
                let (bc, be) = (pair[0].mean_bulge(), pair[1].mean_bulge());
                assert!(be >= bc && bc > 0.0, "α {alpha}: {bc} vs {be}");
                for (a, b) in pair[0].sectors.iter().zip(&pair[1].sectors) {
                    for (pa, pb) in [(a.first, b.first)]
                        .into_iter()
                        .chain(a.second.zip(b.second))
                    {
                        assert!(pb.w >= pa.w - 1e-12, "{pa:?} {pb:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn case_3_splits_the_chord_at_a_new_vertex() {
        // Chord a → b with p above it; both end tangents leave it outward (below) at 106.7°:
        // their lines do not meet beyond the chord.
        let (p, a, b) = ([5.0, 5.0], [0.0, 0.0], [10.0, 0.0]);
        let far = [5.0, -3.0];
        let pts = vec![p, a, b, far];
        let boxes: Vec<[f64; 4]> = pts.iter().map(|q| [q[0], q[1], q[0], q[1]]).collect();
        let index = Grid::new([0.0, -3.0, 10.0, 5.0], 2.0, &boxes);
        let (ta, tb) = (unit([-0.3, -1.0]), unit([-0.3, 1.0]));
        for (alpha, h) in [(0.1, 1.0), (1.0, 3.0)] {
            let ctx = Ctx {
                params: Params::expanded(alpha, 1.0),
                pts: &pts,
                index: &index,
            };
            let s = ctx.sector(p, a, b, ta, tb, &[0, 1, 2]);
            let second = s.second.expect("split");
            // M over the middle, at min(α L, the sample at depth 3) below the chord.
            assert!((second.q0[0] - 5.0).abs() < 1e-12);
            assert!((second.q0[1] + h).abs() < 1e-12, "{:?}", second.q0);
            assert!(s.first.w > 0.0 && second.w > 0.0);
            // The boundary seen from p is one continuous, star-shaped curve.
            let mut last = a;
            for k in 1..200 {
                let x = k as f64 / 200.0 * 10.0;
                let d = sub([x, 0.0], p);
                let piece = if cross(sub(second.q0, p), d) >= 0.0 {
                    &second
                } else {
                    &s.first
                };
                let c = piece.ray_crossing(p, d);
                assert!(cross(sub(c, p), d).abs() < 1e-9 * len(d) * len(sub(c, p)));
                assert!(len(sub(c, last)) < 0.5, "{k}: {c:?} after {last:?}");
                assert!(c[1] <= 1e-12 && c[1] >= -h - 1e-12);
                last = c;
            }
        }
    }

    #[test]
    fn profile_ends() {
        for l in [0.0, 0.3, 1.0] {
            assert_eq!(profile(0.0, l), 1.0);
            assert_eq!(profile(1.0, l), 0.0);
            // Slope at both ends: λ − 1 (zero for the Hermite curve).
            let e = 1e-6;
            assert!(((profile(e, l) - 1.0) / e - (l - 1.0)).abs() < 1e-4);
            assert!(((0.0 - profile(1.0 - e, l)) / e - (l - 1.0)).abs() < 1e-4);
        }
    }
}
