//! Greedy Voronoi/Sibson refinement on scattered points: the raster selector's algorithm
//! (`methods::sites`' greedy selection on a grid) with buckets of nearby points in place of 8×8 blocks, and t value columns.
//!
//! Candidates are distinct integer positions (points on the resolution grid; points sharing
//! a position are one candidate, see [`Candidates`]). From the convex hull, the candidate
//! with the largest normalised error `max_c |S_c(p) − v_c| / E_c` becomes a site until every
//! candidate is within its bounds. After an insertion only candidates inside the closed
//! circumdisks of the new Delaunay triangles can change (Sibson's interpolant is local), so
//! only they are marked stale; buckets keep their maxima in a max-heap with lazy
//! invalidation, and stale errors are recomputed when their bucket reaches the top.
// Columns index several parallel arrays (values, bounds, lattices, surfaces) at once.
#![allow(clippy::needless_range_loop)]

use crate::error::{Error, Result};
use crate::geometry::sibson::{Scratch, Surface};
use crate::geometry::triangulation::{MAX_COORD, circumcircle, incircle};
use crate::methods::sites::convex_hull;
use crate::quant::{code_of, height_of};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Candidates per bucket on average.
const PER_BUCKET: usize = 8;

/// Distinct positions with one target value per column.
#[derive(Clone, Debug, Default)]
pub struct Candidates {
    /// Integer positions in `[0, MAX_COORD]²`, all distinct.
    pub pos: Vec<[i64; 2]>,
    /// `values[c][k]`: the value column c should take at candidate k.
    pub values: Vec<Vec<f64>>,
}

/// The bounds and height lattices of the columns.
#[derive(Clone, Debug)]
pub struct ScatterParams {
    /// Per column: stop once every candidate is within this error.
    pub bounds: Vec<f64>,
    /// Per column: site values are `offset + step · code`.
    pub steps: Vec<f64>,
    /// Per column: the lattice's offset.
    pub offsets: Vec<f64>,
}

/// The selected sites in importance (insertion) order.
#[derive(Clone, Debug, Default)]
pub struct ScatterSelection {
    /// Candidate index per site, in insertion order.
    pub sites: Vec<u32>,
    /// `codes[c][j]`: column c's height code of site j.
    pub codes: Vec<Vec<i64>>,
    /// Number of leading sites that are the convex hull.
    pub hull: usize,
}

/// Buckets: a uniform grid over the candidates' bounding box, about [`PER_BUCKET`]
/// candidates per bucket, with the candidates of each bucket listed together.
struct Buckets {
    x0: i64,
    y0: i64,
    side: i64,
    bw: usize,
    bh: usize,
    /// Candidates of bucket b: `order[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    order: Vec<u32>,
}

impl Buckets {
    fn new(pos: &[[i64; 2]]) -> Buckets {
        let (mut x0, mut y0, mut x1, mut y1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
        for p in pos {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        let (w, h) = ((x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64);
        let target = (pos.len() / PER_BUCKET).max(1) as f64;
        let mut side = ((w * h / target).sqrt().ceil() as i64).max(1);
        // Thin extents: keep the bucket count near the target.
        while ((w / side as f64).ceil() * (h / side as f64).ceil()) > 4.0 * target + 16.0 {
            side *= 2;
        }
        let bw = ((x1 - x0) / side + 1) as usize;
        let bh = ((y1 - y0) / side + 1) as usize;
        let mut b = Buckets {
            x0,
            y0,
            side,
            bw,
            bh,
            start: vec![0; bw * bh + 1],
            order: vec![0; pos.len()],
        };
        for p in pos {
            let i = b.of(*p) + 1;
            b.start[i] += 1;
        }
        for i in 0..bw * bh {
            b.start[i + 1] += b.start[i];
        }
        let mut fill = b.start.clone();
        for (k, p) in pos.iter().enumerate() {
            let bi = b.of(*p);
            b.order[fill[bi] as usize] = k as u32;
            fill[bi] += 1;
        }
        b
    }

    fn of(&self, p: [i64; 2]) -> usize {
        ((p[1] - self.y0) / self.side) as usize * self.bw + ((p[0] - self.x0) / self.side) as usize
    }

    fn members(&self, b: usize) -> &[u32] {
        &self.order[self.start[b] as usize..self.start[b + 1] as usize]
    }
}

struct State<'a> {
    c: &'a Candidates,
    bounds: &'a [f64],
    surfs: Vec<Surface>,
    b: Buckets,
    err: Vec<f64>,
    is_site: Vec<bool>,
    dirty: Vec<bool>,
    bucket_max: Vec<(f64, u32)>,
    bucket_ver: Vec<u32>,
    bucket_dirty: Vec<Vec<u32>>,
    dirty_buckets: Vec<u32>,
    /// Per bucket and column: a triangle near the bucket's last evaluated candidate.
    hints: Vec<u32>,
    heap: BinaryHeap<(u64, Reverse<u32>, u32)>,
    scratch: Scratch,
}

impl State<'_> {
    fn cols(&self) -> usize {
        self.surfs.len()
    }

    /// The normalised error of candidate k on the current surfaces.
    fn eval(&mut self, k: usize, hints: &mut [Option<u32>]) -> Result<f64> {
        let p = self.c.pos[k];
        let mut e: f64 = 0.0;
        for c in 0..self.cols() {
            let v = self.surfs[c]
                .eval_seq(p, &mut hints[c], &mut self.scratch)
                .ok_or_else(|| Error::invalid("a point lies outside the sites' hull"))?;
            e = e.max((v - self.c.values[c][k]).abs() / self.bounds[c]);
        }
        Ok(e)
    }

    fn rescan(&mut self, b: usize) {
        let mut best = (-1.0f64, u32::MAX);
        for &k in self.b.members(b) {
            let e = self.err[k as usize];
            if e > best.0 {
                best = (e, k);
            }
        }
        self.bucket_max[b] = best;
        self.bucket_ver[b] = self.bucket_ver[b].wrapping_add(1);
        if best.1 != u32::MAX {
            self.heap
                .push((best.0.to_bits(), Reverse(b as u32), self.bucket_ver[b]));
        }
    }

    fn mark(&mut self, k: usize) {
        if self.dirty[k] {
            return;
        }
        self.dirty[k] = true;
        let b = self.b.of(self.c.pos[k]);
        if self.bucket_dirty[b].is_empty() {
            self.dirty_buckets.push(b as u32);
        }
        self.bucket_dirty[b].push(k as u32);
    }

    /// Mark the candidates inside the closed circumdisks of the last insertion's triangles
    /// (every candidate while the sites are still collinear).
    fn update_after_insert(&mut self) {
        let tri = self.surfs[0].triangulation();
        if !tri.is_2d() {
            for k in 0..self.c.pos.len() {
                self.mark(k);
            }
            return;
        }
        let created: Vec<[[i64; 2]; 3]> = tri
            .created()
            .iter()
            .map(|&t| *tri.tri(t))
            .filter(|t| !t.is_ghost())
            .map(|t| t.v.map(|v| tri.point(v)))
            .collect();
        for [a, b_, c] in created {
            // The circumcircle in floating point, only to bound the buckets to visit.
            let ([ox, oy], r2) = circumcircle(a, b_, c);
            let r = r2.sqrt() + 2.0;
            let s = &self.b;
            let bx0 = (((ox - r).floor() as i64 - s.x0).max(0) / s.side) as usize;
            let by0 = (((oy - r).floor() as i64 - s.y0).max(0) / s.side) as usize;
            let bx1 = ((((ox + r).ceil() as i64 - s.x0).max(0) / s.side) as usize).min(s.bw - 1);
            let by1 = ((((oy + r).ceil() as i64 - s.y0).max(0) / s.side) as usize).min(s.bh - 1);
            for byi in by0..=by1 {
                for bxi in bx0..=bx1 {
                    let bl = byi * self.b.bw + bxi;
                    let (lo, hi) = (self.b.start[bl] as usize, self.b.start[bl + 1] as usize);
                    for j in lo..hi {
                        let k = self.b.order[j] as usize;
                        if self.dirty[k] || incircle(a, b_, c, self.c.pos[k]) < 0 {
                            continue;
                        }
                        self.mark(k);
                    }
                }
            }
        }
    }

    fn clean(&mut self, b: usize) -> Result<()> {
        let mut list = std::mem::take(&mut self.bucket_dirty[b]);
        if list.is_empty() {
            return Ok(());
        }
        // Spatial order within the bucket: neighbours share cavities.
        list.sort_unstable_by_key(|&k| {
            let p = self.c.pos[k as usize];
            (p[1], p[0])
        });
        let t = self.cols();
        let mut hints: Vec<Option<u32>> = self.hints[b * t..(b + 1) * t]
            .iter()
            .map(|&h| Some(h).filter(|&h| h != u32::MAX))
            .collect();
        for &k in &list {
            let k = k as usize;
            self.dirty[k] = false;
            self.err[k] = self.eval(k, &mut hints)?;
        }
        for (c, h) in hints.into_iter().enumerate() {
            self.hints[b * t + c] = h.unwrap_or(u32::MAX);
        }
        list.clear();
        self.bucket_dirty[b] = list;
        self.rescan(b);
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        for b in std::mem::take(&mut self.dirty_buckets) {
            self.clean(b as usize)?;
        }
        Ok(())
    }

    /// The worst candidate (fresh), cleaning stale buckets on the way.
    fn worst(&mut self) -> Result<Option<(f64, usize)>> {
        while let Some(&(_, Reverse(b), ver)) = self.heap.peek() {
            let b = b as usize;
            if self.bucket_ver[b] != ver {
                self.heap.pop();
                continue;
            }
            if !self.bucket_dirty[b].is_empty() {
                self.heap.pop();
                self.clean(b)?;
                continue;
            }
            let (e, k) = self.bucket_max[b];
            return Ok(Some((e, k as usize)));
        }
        Ok(None)
    }

    fn insert(&mut self, k: usize, codes: &mut [Vec<i64>], p: &ScatterParams) -> Result<()> {
        let b = self.b.of(self.c.pos[k]);
        let t = self.cols();
        for c in 0..t {
            let code = code_of(self.c.values[c][k], p.steps[c], p.offsets[c]);
            let hint = Some(self.hints[b * t + c]).filter(|&h| h != u32::MAX);
            self.surfs[c].insert_near(
                self.c.pos[k],
                height_of(code, p.steps[c], p.offsets[c]),
                hint,
            )?;
            codes[c].push(code);
        }
        self.is_site[k] = true;
        Ok(())
    }
}

/// Run the greedy refinement until every candidate is within its bounds. `progress` gets the
/// fraction done (by error, on a log scale).
pub fn select_scattered(
    c: &Candidates,
    p: &ScatterParams,
    progress: &mut dyn FnMut(f64),
) -> Result<ScatterSelection> {
    let t = c.values.len();
    if t == 0 || p.bounds.len() != t || p.steps.len() != t || p.offsets.len() != t {
        return Err(Error::invalid("one bound and one lattice per value column"));
    }
    for col in 0..t {
        if !(p.bounds[col] > 0.0 && p.bounds[col].is_finite()) {
            return Err(Error::invalid(
                "a point set's error bounds must be positive",
            ));
        }
        if !(p.steps[col] > 0.0 && p.steps[col].is_finite() && p.offsets[col].is_finite()) {
            return Err(Error::invalid("height step must be a positive number"));
        }
    }
    let n = c.pos.len();
    let mut sel = ScatterSelection {
        codes: vec![Vec::new(); t],
        ..Default::default()
    };
    if n == 0 {
        return Ok(sel);
    }
    if c.pos
        .iter()
        .any(|q| q[0] < 0 || q[1] < 0 || q[0] > MAX_COORD || q[1] > MAX_COORD)
    {
        return Err(Error::limit("point positions outside the coder's grid"));
    }
    let b = Buckets::new(&c.pos);
    let nb = b.bw * b.bh;
    let mut st = State {
        c,
        bounds: &p.bounds,
        surfs: vec![Surface::new(); t],
        err: vec![0.0; n],
        is_site: vec![false; n],
        dirty: vec![false; n],
        bucket_max: vec![(-1.0, u32::MAX); nb],
        bucket_ver: vec![0; nb],
        bucket_dirty: vec![Vec::new(); nb],
        dirty_buckets: Vec::new(),
        hints: vec![u32::MAX; nb * t],
        heap: BinaryHeap::new(),
        scratch: Scratch::default(),
        b,
    };
    // The hull first, in its counter-clockwise order.
    let order = convex_hull(c.pos.clone());
    let at: std::collections::HashMap<[i64; 2], usize> =
        order.iter().enumerate().map(|(i, &q)| (q, i)).collect();
    let mut hull: Vec<(usize, u32)> = (0..n as u32)
        .filter_map(|k| at.get(&c.pos[k as usize]).map(|&i| (i, k)))
        .collect();
    hull.sort_unstable();
    let hull: Vec<u32> = hull.into_iter().map(|(_, k)| k).collect();
    for &k in &hull {
        st.insert(k as usize, &mut sel.codes, p)?;
        sel.sites.push(k);
    }
    sel.hull = hull.len();
    for k in 0..n {
        st.mark(k);
    }
    st.flush()?;
    let first = st.worst()?.map_or(1.0, |w| w.0).max(1.0 + 1e-9);
    let mut last_report = 0;
    while let Some((e, k)) = st.worst()? {
        if e <= 1.0 {
            st.flush()?;
            match st.worst()? {
                Some((e, _)) if e > 1.0 => continue,
                _ => break,
            }
        }
        if st.is_site[k] {
            return Err(Error::unmet(
                "a site itself is off its bound: the height step is too coarse",
            ));
        }
        st.insert(k, &mut sel.codes, p)?;
        sel.sites.push(k as u32);
        st.update_after_insert();
        let bl = st.b.of(c.pos[k]);
        st.clean(bl)?;
        if sel.sites.len() - last_report >= 1024 {
            last_report = sel.sites.len();
            progress(((first / e).ln() / first.ln()).clamp(0.0, 1.0));
        }
    }
    Ok(sel)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(pos: Vec<[i64; 2]>, z: Vec<f64>, bound: f64) -> (ScatterSelection, Vec<Surface>) {
        let c = Candidates {
            pos,
            values: vec![z],
        };
        let p = ScatterParams {
            bounds: vec![bound],
            steps: vec![bound],
            offsets: vec![0.0],
        };
        let sel = select_scattered(&c, &p, &mut |_| {}).unwrap();
        let mut s = Surface::new();
        for (j, &k) in sel.sites.iter().enumerate() {
            s.insert(c.pos[k as usize], height_of(sel.codes[0][j], bound, 0.0))
                .unwrap();
        }
        // Every candidate within the bound.
        let mut sc = Scratch::default();
        let mut hint = None;
        for (k, &q) in c.pos.iter().enumerate() {
            let v = s.eval_seq(q, &mut hint, &mut sc).unwrap();
            assert!(
                (v - c.values[0][k]).abs() <= bound * (1.0 + 1e-12),
                "{q:?}: {v} vs {}",
                c.values[0][k]
            );
        }
        (sel, vec![s])
    }

    #[test]
    fn random_points_meet_the_bound() {
        let mut rng = crate::testutil::Rng(12345);
        let mut rnd = || (rng.next() >> 33) as i64;
        let mut pos = std::collections::BTreeSet::new();
        while pos.len() < 3000 {
            pos.insert([rnd() % 5000, rnd() % 3000]);
        }
        let pos: Vec<[i64; 2]> = pos.into_iter().collect();
        let z = pos
            .iter()
            .map(|q| 100.0 * ((q[0] as f64) / 700.0).sin() + (q[1] as f64) / 50.0)
            .collect();
        let (sel, _) = run(pos, z, 0.5);
        assert!(sel.sites.len() < 3000, "{} sites", sel.sites.len());
    }

    #[test]
    fn collinear_and_tiny_sets() {
        let pos: Vec<[i64; 2]> = (0..50).map(|i| [i * 3, i * 2]).collect();
        let z = (0..50).map(|i| ((i * i) % 17) as f64).collect();
        run(pos, z, 0.25);
        run(vec![[5, 5]], vec![3.0], 0.1);
        run(vec![[0, 0], [10, 0]], vec![1.0, 2.0], 0.1);
        run(vec![[0, 0], [10, 0], [3, 7]], vec![1.0, 2.0, -4.0], 0.1);
    }

    #[test]
    fn co_circular_points() {
        // A regular 8×8 grid plus points on one circle: many co-circular quadruples.
        let mut pos = Vec::new();
        for i in 0..8 {
            for j in 0..8 {
                pos.push([i * 100, j * 100]);
            }
        }
        for q in [[350, 850], [850, 350], [-150, 350], [350, -150]] {
            pos.push([q[0] + 200, q[1] + 200]);
        }
        let z = pos
            .iter()
            .map(|q| ((q[0] * 7 + q[1] * 3) % 11) as f64)
            .collect();
        run(pos, z, 0.05);
    }
}
