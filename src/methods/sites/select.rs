//! Greedy Voronoi/Sibson refinement: from the hull, insert the worst-approximated sample
//! until the error bound or the site budget is met, updating only what changed.
//!
//! After inserting a site, Sibson's interpolant changes only inside the union of the
//! circumdisks of the new Delaunay triangles, so only samples there are re-evaluated. Errors
//! are kept per sample, their maxima per 8×8 block, and blocks in a max-heap with lazy
//! invalidation, so the worst sample is found in O(log n).

use crate::error::{Error, Result};
use crate::geometry::sibson::{Scratch, Surface};
use crate::geometry::triangulation::{circumcircle, incircle};
use crate::quant::{code_of, height_of};
use std::collections::BinaryHeap;
use std::str::FromStr;

const BLOCK: usize = 8;

/// Which residual norm ranks tiles for refinement: how the Sibson method picks its next
/// site.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum Norm {
    /// Insert the globally worst sample (p = ∞).
    #[default]
    Linf,
    /// Insert the worst sample of the block with the largest RMS residual (p = 2).
    L2,
}

impl FromStr for Norm {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "linf" | "max" => Ok(Norm::Linf),
            "l2" | "rms" => Ok(Norm::L2),
            o => Err(Error::invalid(format!("unknown norm '{o}' (linf, l2)"))),
        }
    }
}

/// When to stop and how to quantize heights.
#[derive(Clone, Debug)]
pub struct SelectParams {
    /// Stop once every valid sample is within this (pre-output) error.
    pub max_error: Option<f64>,
    /// Stop once the RMSE over valid samples is at most this.
    pub rmse: Option<f64>,
    /// Stop at this many sites.
    pub max_sites: Option<usize>,
    pub norm: Norm,
    /// Site heights are `offset + step · code`.
    pub step: f64,
    pub offset: f64,
}

/// Samples of a grid to approximate: values row-major with a validity mask.
pub struct Samples<'a> {
    pub width: usize,
    pub height: usize,
    pub values: &'a [f64],
    pub valid: &'a dyn Fn(usize) -> bool,
}

/// The selected sites in importance (insertion) order.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// (sample index, height code) per site, in insertion order.
    pub sites: Vec<(u32, i64)>,
    /// Number of leading sites that are the convex hull.
    pub hull: usize,
    /// Per site after the hull: the largest error of the surface of the sites before it
    /// (the error it was picked for). Read by the terrain pyramid to cut prefixes at a bound.
    pub errors: Vec<f32>,
}

/// Convex hull (counter-clockwise, no collinear points) of the valid samples' positions.
pub fn hull(s: &Samples) -> Vec<[i64; 2]> {
    // Leftmost and rightmost valid sample of each row are the only hull candidates.
    let mut cand = Vec::new();
    for y in 0..s.height {
        let row = y * s.width;
        let first = (0..s.width).find(|&x| (s.valid)(row + x));
        if let Some(x0) = first {
            let x1 = (0..s.width)
                .rev()
                .find(|&x| (s.valid)(row + x))
                .unwrap_or(x0);
            cand.push([x0 as i64, y as i64]);
            if x1 != x0 {
                cand.push([x1 as i64, y as i64]);
            }
        }
    }
    convex_hull(cand)
}

/// Convex hull (counter-clockwise from the lowest-then-leftmost corner, no collinear points)
/// of integer points; the two extreme points when they are all collinear, the points
/// themselves when fewer than three are distinct.
pub(crate) fn convex_hull(mut cand: Vec<[i64; 2]>) -> Vec<[i64; 2]> {
    cand.sort();
    cand.dedup();
    if cand.len() < 3 {
        return cand;
    }
    let cross = |o: [i64; 2], a: [i64; 2], b: [i64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    // Andrew's monotone chain: lower hull, then upper hull without popping the lower one.
    let mut h: Vec<[i64; 2]> = Vec::with_capacity(cand.len() * 2);
    for &p in &cand {
        while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0 {
            h.pop();
        }
        h.push(p);
    }
    let lower = h.len() + 1;
    for &p in cand.iter().rev().skip(1) {
        while h.len() >= lower && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0 {
            h.pop();
        }
        h.push(p);
    }
    h.pop();
    if h.len() < 3 {
        // Collinear: the two extreme points.
        return vec![cand[0], cand[cand.len() - 1]];
    }
    h
}

struct State<'a> {
    s: &'a Samples<'a>,
    surf: Surface,
    err: Vec<f64>,
    is_site: Vec<bool>,
    bw: usize,
    block_max: Vec<(f64, u32)>,
    block_ss: Vec<f64>,
    block_ver: Vec<u32>,
    heap: BinaryHeap<(u64, std::cmp::Reverse<u32>, u32)>,
    scratch: Scratch,
    sum_sq: f64,
    norm: Norm,
    /// Samples whose error is stale (inside a new circumdisk, not yet re-evaluated).
    dirty: Vec<bool>,
    /// Dirty samples per block (listed once each).
    block_dirty: Vec<Vec<u32>>,
    /// Valid samples per block.
    block_valid: Vec<u16>,
    dirty_blocks: Vec<u32>,
    evals: u64,
    scanned: u64,
    /// A triangle near each block (where its last sample was found), to start walks from.
    block_hint: Vec<u32>,
}

impl State<'_> {
    fn block_of(&self, i: usize) -> usize {
        let (x, y) = (i % self.s.width, i / self.s.width);
        (y / BLOCK) * self.bw + x / BLOCK
    }

    fn rescan_block(&mut self, b: usize) {
        let (bx, by) = (b % self.bw, b / self.bw);
        let (w, h) = (self.s.width, self.s.height);
        let mut best = (-1.0f64, u32::MAX);
        let mut ss = 0.0;
        for y in by * BLOCK..((by + 1) * BLOCK).min(h) {
            for x in bx * BLOCK..((bx + 1) * BLOCK).min(w) {
                let i = y * w + x;
                let e = self.err[i];
                if e > best.0 {
                    best = (e, i as u32);
                }
                ss += e * e;
            }
        }
        self.block_max[b] = best;
        self.block_ss[b] = ss;
        self.block_ver[b] = self.block_ver[b].wrapping_add(1);
        if best.1 != u32::MAX {
            let key = match self.norm {
                Norm::Linf => best.0,
                Norm::L2 => ss,
            };
            self.heap.push((
                key.to_bits(),
                std::cmp::Reverse(b as u32),
                self.block_ver[b],
            ));
        }
    }

    /// Mark the samples inside the closed circumdisks of the last insertion's triangles as
    /// stale: their error is recomputed when their block reaches the top of the heap or
    /// before a stopping decision (lazy evaluation; most are re-dirtied before they matter).
    fn update_after_insert(&mut self) {
        let (w, h) = (self.s.width as i64, self.s.height as i64);
        let created: Vec<u32> = self.surf.triangulation().created().to_vec();
        for t in created {
            let tri = *self.surf.triangulation().tri(t);
            if tri.is_ghost() {
                continue;
            }
            let [a, b_, c] = tri.v.map(|v| self.surf.triangulation().point(v));
            // The circumcircle, in floating point (only to bound the samples to test).
            let ([ox, oy], r2) = circumcircle(a, b_, c);
            let r = r2.sqrt();
            // The circle's chord on row y, padded by one sample for rounding (the exact test
            // below decides which samples are in the closed disk).
            let chord = |y: i64| -> (i64, i64) {
                let dy = (y as f64 - oy).abs() - 1.0;
                let half = if dy <= 0.0 { r } else { (r2 - dy * dy).max(0.0).sqrt() };
                (
                    ((ox - half).floor() as i64 - 1).max(0),
                    ((ox + half).ceil() as i64 + 1).min(w - 1),
                )
            };
            let y0 = ((oy - r).floor() as i64 - 1).max(0);
            let y1 = ((oy + r).ceil() as i64 + 1).min(h - 1);
            if y0 > y1 {
                continue;
            }
            // Block by block: a block without valid samples, or whose valid samples are all
            // stale already, is skipped whole (large circles over flat regions and nodata
            // would otherwise be scanned sample by sample after every insertion).
            let b = BLOCK as i64;
            for by in y0 / b..=y1 / b {
                let (ry0, ry1) = ((by * b).max(y0), (by * b + b - 1).min(y1));
                // The widest chord in this band of rows: at the row nearest the centre.
                let yc = (oy.round() as i64).clamp(ry0, ry1);
                let (cx0, cx1) = chord(yc);
                if cx0 > cx1 {
                    continue;
                }
                for bx in cx0 / b..=cx1 / b {
                    let bl = by as usize * self.bw + bx as usize;
                    if self.block_dirty[bl].len() >= self.block_valid[bl] as usize {
                        continue;
                    }
                    for y in ry0..=ry1 {
                        let (x0, x1) = chord(y);
                        for x in x0.max(bx * b)..=x1.min(bx * b + b - 1) {
                            let i = (y * w + x) as usize;
                            self.scanned += 1;
                            // Marked already (by this insertion or an earlier one): stale.
                            if self.dirty[i] || !(self.s.valid)(i) {
                                continue;
                            }
                            if incircle(a, b_, c, [x, y]) < 0 {
                                continue;
                            }
                            self.dirty[i] = true;
                            if self.block_dirty[bl].is_empty() {
                                self.dirty_blocks.push(bl as u32);
                            }
                            self.block_dirty[bl].push(i as u32);
                        }
                    }
                }
            }
        }
    }

    /// Recompute the stale errors of block `b` and requeue it.
    fn clean_block(&mut self, b: usize) {
        let list = std::mem::take(&mut self.block_dirty[b]);
        if list.is_empty() {
            return;
        }
        let w = self.s.width;
        let mut list = list;
        // Row order: neighbours share cavities (`Surface::eval_seq`).
        list.sort_unstable();
        let mut hint = Some(self.block_hint[b]).filter(|&h| h != u32::MAX);
        for &i in &list {
            let i = i as usize;
            self.dirty[i] = false;
            let v = self
                .surf
                .eval_seq([(i % w) as i64, (i / w) as i64], &mut hint, &mut self.scratch)
                .expect("valid samples lie in the hull");
            self.evals += 1;
            let e = (v - self.s.values[i]).abs();
            self.sum_sq += e * e - self.err[i] * self.err[i];
            self.err[i] = e;
        }
        self.block_hint[b] = hint.unwrap_or(u32::MAX);
        self.block_dirty[b] = list;
        self.block_dirty[b].clear();
        self.rescan_block(b);
    }

    /// Bring every stale error up to date.
    fn flush(&mut self) {
        let blocks = std::mem::take(&mut self.dirty_blocks);
        for b in blocks {
            self.clean_block(b as usize);
        }
    }

    /// The current worst block (dropping stale heap entries, cleaning dirty blocks on the
    /// way) and its worst sample.
    fn worst(&mut self) -> Option<(f64, usize)> {
        while let Some(&(_, std::cmp::Reverse(b), ver)) = self.heap.peek() {
            if self.block_ver[b as usize] != ver {
                self.heap.pop();
                continue;
            }
            if !self.block_dirty[b as usize].is_empty() {
                self.heap.pop();
                self.clean_block(b as usize);
                continue;
            }
            let (e, i) = self.block_max[b as usize];
            return Some((e, i as usize));
        }
        None
    }

    fn global_max(&self) -> f64 {
        self.err.iter().copied().fold(0.0, f64::max)
    }
}

/// The first site count at which [`select_capped`] asks whether to give up.
pub const GIVE_UP_FROM: usize = 512;

/// Run the greedy refinement. `progress` gets the fraction done (by error or site budget).
pub fn select(s: &Samples, p: &SelectParams, progress: &mut dyn FnMut(f64)) -> Result<Selection> {
    Ok(select_capped(s, p, progress, &mut |_| false)?.expect("never gives up"))
}

/// [`select`], asking `give_up` whether to stop at [`GIVE_UP_FROM`] sites and then each
/// time the count has grown by a quarter: then it returns `Ok(None)` (`best` stops the
/// sites encoder once its payload passes the smallest candidate's).
pub fn select_capped(
    s: &Samples,
    p: &SelectParams,
    progress: &mut dyn FnMut(f64),
    give_up: &mut dyn FnMut(&Selection) -> bool,
) -> Result<Option<Selection>> {
    if !(p.step > 0.0 && p.step.is_finite() && p.offset.is_finite()) {
        return Err(Error::invalid("height step must be a positive number"));
    }
    let n = s.width * s.height;
    let valid_count = (0..n).filter(|&i| (s.valid)(i)).count();
    let mut sel = Selection::default();
    if valid_count == 0 {
        return Ok(Some(sel));
    }
    let hull = hull(s);
    let mut surf = Surface::new();
    let mut is_site = vec![false; n];
    for &q in &hull {
        let i = q[1] as usize * s.width + q[0] as usize;
        let code = code_of(s.values[i], p.step, p.offset);
        surf.insert(q, height_of(code, p.step, p.offset))?;
        is_site[i] = true;
        sel.sites.push((i as u32, code));
    }
    sel.hull = sel.sites.len();
    let bw = s.width.div_ceil(BLOCK);
    let bh = s.height.div_ceil(BLOCK);
    let mut st = State {
        s,
        surf,
        err: vec![0.0; n],
        is_site,
        bw,
        block_max: vec![(-1.0, u32::MAX); bw * bh],
        block_ss: vec![0.0; bw * bh],
        block_ver: vec![0; bw * bh],
        heap: BinaryHeap::new(),
        scratch: Scratch::default(),
        sum_sq: 0.0,
        norm: p.norm,
        dirty: vec![false; n],
        block_dirty: vec![Vec::new(); bw * bh],
        block_valid: {
            let mut v = vec![0u16; bw * bh];
            for i in (0..n).filter(|&i| (s.valid)(i)) {
                v[(i / s.width / BLOCK) * bw + (i % s.width) / BLOCK] += 1;
            }
            v
        },
        dirty_blocks: Vec::new(),
        evals: 0,
        scanned: 0,
        block_hint: vec![u32::MAX; bw * bh],
    };
    // Initial errors: evaluate the hull surface everywhere.
    let vals = st
        .surf
        .eval_window(0, 0, s.width, s.height, |x, y| {
            (s.valid)(y as usize * s.width + x as usize)
        })
        .ok_or_else(|| Error::invalid("valid samples outside their own hull"))?;
    for (i, &v) in vals.iter().enumerate() {
        if (s.valid)(i) {
            st.err[i] = (v - s.values[i]).abs();
            st.sum_sq += st.err[i] * st.err[i];
        }
    }
    drop(vals);
    for b in 0..bw * bh {
        st.rescan_block(b);
    }
    let first_max = st.global_max().max(f64::MIN_POSITIVE);
    let debug = std::env::var_os("VTZ_DEBUG_SELECT").is_some();
    let target_sites = p.max_sites.unwrap_or(usize::MAX).min(valid_count);
    let mut last_report = 0usize;
    let mut next_check = GIVE_UP_FROM;
    loop {
        if sel.sites.len() >= target_sites {
            break;
        }
        let Some((mut e, mut i)) = st.worst() else {
            break;
        };
        // Stopping decisions are made on fresh errors only.
        let stop = |st: &mut State| -> bool {
            if let Some(me) = p.max_error {
                let m = match p.norm {
                    Norm::Linf => st.worst().map_or(0.0, |w| w.0),
                    Norm::L2 => st.global_max(),
                };
                if m > me {
                    return false;
                }
            }
            if let Some(r) = p.rmse {
                if (st.sum_sq.max(0.0) / valid_count as f64).sqrt() > r {
                    return false;
                }
            }
            p.max_error.is_some() || p.rmse.is_some()
        };
        let maybe_done = match p.norm {
            Norm::Linf => p.max_error.is_some_and(|me| e <= me),
            Norm::L2 => sel.sites.len() % 64 == 0,
        } || p
            .rmse
            .is_some_and(|r| (st.sum_sq.max(0.0) / valid_count as f64).sqrt() <= r);
        if maybe_done {
            st.flush();
            if stop(&mut st) {
                break;
            }
            match st.worst() {
                Some(w) => (e, i) = w,
                None => break,
            }
        }
        if st.is_site[i] || e <= 0.0 {
            // Every remaining error is at a site (quantization) or zero: nothing to gain.
            break;
        }
        let q = [(i % s.width) as i64, (i / s.width) as i64];
        let code = code_of(s.values[i], p.step, p.offset);
        let hint = st.block_hint[st.block_of(i)];
        st.surf
            .insert_near(q, height_of(code, p.step, p.offset), Some(hint))?;
        st.is_site[i] = true;
        sel.sites.push((i as u32, code));
        sel.errors.push(e as f32);
        if sel.sites.len() >= next_check {
            // Every quarter more sites: the encoder stops within 1.25× the sites at which
            // it passes the cap (each check writes the payload so far: about 5 writes in all).
            next_check = sel.sites.len() + sel.sites.len() / 4;
            if give_up(&sel) {
                return Ok(None);
            }
        }
        if debug && sel.sites.len().is_power_of_two() {
            eprintln!("select: {} sites, {} evaluations", sel.sites.len(), st.evals);
        }
        st.update_after_insert();
        // The new site's own block first: it holds the largest changes.
        let bl = st.block_of(i);
        st.clean_block(bl);
        if sel.sites.len() - last_report >= 256 {
            last_report = sel.sites.len();
            let f = match (p.max_error, p.max_sites) {
                (_, Some(ms)) => sel.sites.len() as f64 / ms as f64,
                (Some(me), None) => {
                    ((first_max / e.max(me)).ln() / (first_max / me).ln().max(1e-9)).clamp(0.0, 1.0)
                }
                _ => 0.0,
            };
            progress(f);
        }
    }
    if std::env::var_os("VTZ_DEBUG_SELECT").is_some() {
        eprintln!(
            "select: {} sites, {} samples visited to mark stale ones, {} evaluations ({:.1} per sample)",
            sel.sites.len(),
            st.scanned,
            st.evals,
            st.evals as f64 / valid_count as f64
        );
    }
    Ok(Some(sel))
}
