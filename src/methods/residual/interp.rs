//! Multilevel interpolation (as SZ3 predicts): an anchor grid of stride 2^L coded with MED,
//! then levels coarse to fine, each a vertical pass (odd rows of the level, even columns)
//! and a horizontal pass (every row of the level, odd columns), predicting each sample by
//! cubic interpolation (−1, 9, 9, −1)/16 of its known neighbours along the pass, corrected
//! on the finest levels by a least-squares 2-D stencil the encoder fits and sends.

use super::coder::{BinCoder, Ctx, LEVELS, round_div};
use crate::predict::med::anchor_med;
use super::ls::{self, Normal};
use super::plane::{FIXED, Plane, SKIPPED, State, quarter_bins};
use crate::error::Result;

/// Points of the least-squares stencil, (dy, dx) in units of the level's step s, per pass;
/// all known when the pass reaches a sample (vertical pass first).
const STENCIL: [[(isize, isize); NF]; 2] = [
    [(-1, 0), (1, 0), (-3, 0), (3, 0), (0, -2), (-1, -2), (1, -2), (-1, 2), (1, 2), (-2, 0)],
    [(0, -1), (0, 1), (0, -3), (0, 3), (-1, 0), (-1, -1), (-1, 1), (1, -1), (1, 1), (-2, 0)],
];
/// Stencil points.
pub const NF: usize = 10;
/// The causal neighbours (dx, dy in units of s) whose residuals set a sample's contexts.
const CTX_NB: [(isize, isize); 10] = [
    (-1, 0),
    (1, 0),
    (0, -1),
    (0, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
    (1, 1),
    (-2, 0),
    (0, -2),
];

/// The interpolation predictor's settings, as stored in the section.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// Anchor stride 2^levels (1..=12).
    pub levels: u32,
    /// Levels (finest first) with a least-squares correction (0..=levels, ≤ 4).
    pub ls_levels: u32,
    /// Narrower bins on coarse levels (SZ3's α = 1.25, β = 2): level l's bins are
    /// [`level_bin`] of the plane's.
    pub tighten: bool,
}

/// The bin width on level l (anchors: levels + 1) with tightening: the largest odd width
/// ≤ W / min(1.25^(l−1), 2), at least 1, in exact integer arithmetic (the factors 1, 5/4,
/// 25/16, 125/64, then 2).
pub fn level_bin(w: i64, l: u32) -> i64 {
    const NUM: [i64; 4] = [1, 5, 25, 125];
    const DEN: [i64; 4] = [1, 4, 16, 64];
    let k = (l.max(1) - 1) as usize;
    let b = if k < 4 { w * DEN[k] / NUM[k] } else { w / 2 };
    let b = if b % 2 == 0 { b - 1 } else { b };
    b.max(1)
}

/// 1-D interpolation at the middle of `b` and `c` from the support −3s, −s, +s, +3s.
#[inline]
pub fn interp1(a: Option<i64>, b: i64, c: Option<i64>, d: Option<i64>) -> i64 {
    match (a, c, d) {
        (Some(a), Some(c), Some(d)) => round_div(-a + 9 * b + 9 * c - d, 16),
        (None, Some(c), Some(d)) => round_div(3 * b + 6 * c - d, 8),
        (Some(a), Some(c), None) => round_div(-a + 6 * b + 3 * c, 8),
        (_, Some(c), _) => round_div(b + c, 2),
        (Some(a), None, _) => round_div(3 * b - a, 2),
        (None, None, _) => b,
    }
}

/// Stencil values minus `base`; `None` when a point is outside the raster (or, with
/// `usable`, not usable for a fit).
#[inline]
fn features(
    vals: &[i64],
    usable: Option<&[u8]>,
    (w, h): (usize, usize),
    (y, x, s): (usize, usize, usize),
    pass: usize,
    base: i64,
) -> Option<[i64; NF]> {
    let mut f = [0i64; NF];
    for (k, &(dy, dx)) in STENCIL[pass].iter().enumerate() {
        let yy = y as isize + dy * s as isize;
        let xx = x as isize + dx * s as isize;
        if yy < 0 || xx < 0 || yy >= h as isize || xx >= w as isize {
            return None;
        }
        let j = yy as usize * w + xx as usize;
        if usable.is_some_and(|k| k[j] == SKIPPED) {
            return None;
        }
        f[k] = vals[j] - base;
    }
    Some(f)
}

/// The samples of one pass: (vertical?, first row, row step, first column, column step).
fn passes(s: usize) -> [(bool, usize, usize, usize, usize); 2] {
    [(true, s, 2 * s, 0, 2 * s), (false, 0, s, s, 2 * s)]
}

/// Fit one pass's stencil weights on the source (encoder only).
fn fit(p: &Plane, s: usize, pass: usize) -> [i16; NF] {
    let (w, h) = (p.width, p.height);
    let (vert, r0, rs, c0, cs) = passes(s)[pass];
    let mut n = Normal::<NF>::new();
    let src = p.values;
    for y in (r0..h).step_by(rs) {
        for x in (c0..w).step_by(cs) {
            let i = y * w + x;
            if p.kinds[i] == SKIPPED {
                continue;
            }
            let interior = if vert {
                y >= 3 * s && y + 3 * s < h
            } else {
                x >= 3 * s && x + 3 * s < w
            };
            if !interior {
                continue;
            }
            let st = if vert { s * w } else { s };
            let at = |k: isize| src[(i as isize + k * st as isize) as usize];
            let base = round_div(-at(-3) + 9 * at(-1) + 9 * at(1) - at(3), 16);
            if let Some(f) = features(src, Some(p.kinds), (w, h), (y, x, s), pass, base) {
                n.add(&f, (src[i] - base) as f64);
            }
        }
    }
    n.solve()
}

/// Code (encoder) or decode every sample of the plane. `weights` holds the least-squares
/// weights per (level, pass), finest level last: the encoder fills it, the decoder reads it.
/// A decoder that needs only the samples at every 2^`stop`-th row and column stops after the
/// level that completes them (`stop` 0: every level; the coder is then not at its end).
pub fn run<C: BinCoder>(
    p: &Plane,
    cfg: Config,
    weights: &mut Vec<[i16; NF]>,
    coder: &mut C,
    stop: u32,
) -> Result<State> {
    let (w, h) = (p.width, p.height);
    let mut st = State::new(w * h);
    let mut known = vec![false; w * h];
    let mut lvl_of = vec![0u8; w * h];
    let big = 1usize << cfg.levels;
    let mid = p.lo + (p.hi - p.lo) / 2;
    let bin_of = |l: u32| if cfg.tighten { level_bin(p.bin, l) } else { p.bin };
    // 1. The anchor grid, MED on the subsampled grid.
    let bin = bin_of(cfg.levels + 1);
    for y in (0..h).step_by(big) {
        for x in (0..w).step_by(big) {
            let i = y * w + x;
            let g = |dx: isize, dy: isize| -> Option<usize> {
                let xx = x as isize + dx * big as isize;
                let yy = y as isize + dy * big as isize;
                (xx >= 0 && yy >= 0 && xx < w as isize).then(|| yy as usize * w + xx as usize)
            };
            let nb = [g(-1, 0), g(0, -1), g(-1, -1), g(1, -1)];
            let [left, top, tl, tr] = nb.map(|j| j.map(|j| st.rec[j]));
            let (pred, t) = anchor_med(left, top, tl, tr, mid);
            let mut er = 0i64;
            let mut cnt = 0i64;
            let mut sg = 0i32;
            for j in nb.into_iter().flatten() {
                er += st.res[j] as i64;
                cnt += 1;
                sg += st.sign[j] as i32;
            }
            let act = t + er;
            let err = er / cnt.max(1);
            st.code_with(
                p,
                bin,
                i,
                pred,
                || Ctx {
                    act: quarter_bins(act, bin),
                    err: quarter_bins(err, bin),
                    sign: sg,
                    level: LEVELS - 1,
                },
                coder,
            )?;
            known[i] = true;
            lvl_of[i] = (LEVELS - 1) as u8;
        }
    }
    coder.level_done();
    // 2. The levels, coarse to fine.
    let mut next_weights = 0;
    for l in (1..=cfg.levels).rev() {
        if l <= stop {
            // Level l fills the samples of step 2^(l−1): finer than the stop.
            break;
        }
        let s = 1usize << (l - 1);
        let lvl = (l as usize - 1).min(LEVELS - 2) as u8;
        let bin = bin_of(l);
        for (pass, (vert, r0, rs, c0, cs)) in passes(s).into_iter().enumerate() {
            // Index offsets of the stencil and of the context neighbours at this step.
            let (ws, ss) = ((w * s) as isize, s as isize);
            let stencil_off: [isize; NF] = STENCIL[pass].map(|(dy, dx)| dy * ws + dx * ss);
            let nb_off: [isize; 10] = CTX_NB.map(|(dx, dy)| dy * ws + dx * ss);
            let coef = if cfg.ls_levels >= l {
                if C::ENCODES {
                    weights.push(fit(p, s, pass));
                }
                let c = *weights.get(next_weights).ok_or_else(|| {
                    crate::error::Error::corrupt("residual section: missing stencil weights")
                })?;
                next_weights += 1;
                Some(c)
            } else {
                None
            };
            let (len, step) = if vert { (h, s * w) } else { (w, s) };
            for y in (r0..h).step_by(rs) {
                for x in (c0..w).step_by(cs) {
                    let i = y * w + x;
                    let pos = if vert { y } else { x };
                    let at = |k: isize| -> Option<i64> {
                        let q = pos as isize + k * s as isize;
                        (q >= 0 && q < len as isize)
                            .then(|| st.rec[(i as isize + k * step as isize) as usize])
                    };
                    let (a, b, c, d) = if pos >= 3 * s && pos + 3 * s < len {
                        // The whole support is inside (the same values as below).
                        let r = |k: isize| st.rec[(i as isize + k * step as isize) as usize];
                        (Some(r(-3)), r(-1), Some(r(1)), Some(r(3)))
                    } else {
                        let b = at(-1).expect("the point before is inside");
                        (at(-3), b, at(1), at(3))
                    };
                    let mut pred = interp1(a, b, c, d);
                    if let (Some(cf), true) = (coef, a.is_some() && d.is_some()) {
                        let acc = if y >= 3 * s && x >= 3 * s && y + 3 * s < h && x + 3 * s < w {
                            // Every stencil point lies within ±3s: direct offsets.
                            let mut acc = 0i64;
                            for (o, c) in stencil_off.iter().zip(cf) {
                                acc += (st.rec[(i as isize + o) as usize] - pred) * c as i64;
                            }
                            Some(acc)
                        } else {
                            features(&st.rec, None, (w, h), (y, x, s), pass, pred)
                                .map(|f| f.iter().zip(cf).map(|(f, c)| f * c as i64).sum())
                        };
                        if let Some(acc) = acc {
                            pred += round_div(acc, 1 << ls::SHIFT);
                        }
                    }
                    let mut sum = 0i64;
                    let mut cnt = 0i64;
                    let mut sg = 0i32;
                    let mut visit = |j: usize| {
                        if known[j] {
                            sum += st.res[j] as i64;
                            cnt += 1;
                            if lvl_of[j] == lvl {
                                sg += st.sign[j] as i32;
                            }
                        }
                    };
                    if x >= 2 * s && y >= 2 * s && x + s < w && y + s < h {
                        // Every neighbour is inside: no bounds checks (same visits).
                        for o in nb_off {
                            visit((i as isize + o) as usize);
                        }
                    } else {
                        for (dx, dy) in CTX_NB {
                            let xx = x as isize + dx * s as isize;
                            let yy = y as isize + dy * s as isize;
                            if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                                visit(yy as usize * w + xx as usize);
                            }
                        }
                    }
                    let r_act = if cnt == 0 { 0 } else { 2 * sum / cnt };
                    let s_act = match (a, c, d) {
                        (Some(a), Some(c), Some(d)) => (-a + b + c - d).abs() + (b - c).abs() / 4,
                        (_, Some(c), _) => (b - c).abs() / 2,
                        _ => 0,
                    };
                    st.code_with(
                        p,
                        bin,
                        i,
                        pred,
                        || Ctx {
                            act: quarter_bins(r_act + s_act, bin),
                            err: quarter_bins(r_act / 2, bin),
                            sign: sg,
                            level: lvl as usize,
                        },
                        coder,
                    )?;
                    known[i] = true;
                    lvl_of[i] = lvl;
                }
            }
        }
        coder.level_done();
    }
    let _ = FIXED;
    Ok(st)
}
