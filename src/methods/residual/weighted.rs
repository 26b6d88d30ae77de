//! The scan-order predictor: JPEG XL's self-correcting weighted predictor (four
//! sub-predictors weighted by their recent errors, re-derived from the published algorithm
//! with its "lossless16" constants), corrected by least-squares weights over 14 causal
//! neighbours, one weight set per activity class, which the encoder fits and sends.

use super::coder::{BinCoder, Ctx, act_class, round_div};
use super::ls::{self, Normal};
use super::plane::{Plane, SKIPPED, State, quarter_bins};
use crate::error::{Error, Result};

/// Causal neighbours of the least-squares correction.
pub const NF: usize = 14;
/// Least-squares classes (activity classes, halved).
pub const CLASSES: usize = 8;

/// Largest |P| (the weighted mean, in eighths of a lattice step) a stream may reach. With
/// reconstructions within ±2^38 (`lattice::MAX_UNITS`) every intermediate of the predictor
/// and of its least-squares correction then fits i64: true errors ≤ 2^45 + 2^41, each
/// sub-prediction ≤ 2^50, each sub-predictor error ≤ 2^47, Σ f_k·w_k ≤ 14 · 2^42.1 · 2^15 <
/// 2^61 (spec/FORMAT.md, "Predictor 1"). The weights follow the errors, so P stays near the
/// data; a stream whose P leaves the range is corrupt, and an encoder whose plane would
/// take it there codes it with interpolation instead.
pub const MAX_P: u64 = 1 << 45;

const MAXW: [u64; 4] = [13, 12, 12, 12];
const P1C: i64 = 16;
const P2C: i64 = 10;
const P3C: [i64; 3] = [7, 7, 7];

#[inline]
fn div_lookup(i: u64) -> u64 {
    (1u64 << 24) / (i + 1)
}

/// The neighbours with JPEG XL's border rules.
struct Nb {
    w: i64,
    n: i64,
    nw: i64,
    ne: i64,
    ww: i64,
    nn: i64,
    nne: i64,
}

#[inline]
fn neighbours(rec: &[i64], w: usize, x: usize, y: usize, mid: i64) -> Nb {
    let i = y * w + x;
    let left = if x > 0 {
        rec[i - 1]
    } else if y > 0 {
        rec[i - w]
    } else {
        mid
    };
    let top = if y > 0 { rec[i - w] } else { left };
    let topleft = if x > 0 && y > 0 { rec[i - w - 1] } else { left };
    let topright = if x + 1 < w && y > 0 { rec[i - w + 1] } else { top };
    let leftleft = if x > 1 { rec[i - 2] } else { left };
    let toptop = if y > 1 { rec[i - 2 * w] } else { top };
    let toptopright = if y > 1 && x + 1 < w { rec[i - 2 * w + 1] } else { topright };
    Nb {
        w: left,
        n: top,
        nw: topleft,
        ne: topright,
        ww: leftleft,
        nn: toptop,
        nne: toptopright,
    }
}

/// The weighted predictor's state: two rows of sub-predictor errors and true errors.
struct Wp {
    w: usize,
    pe: [Vec<u64>; 4],
    err: Vec<i64>,
    pred: [i64; 4],
    avg: i64,
}

impl Wp {
    fn new(w: usize) -> Wp {
        let n = (w + 2) * 2;
        Wp {
            w,
            pe: std::array::from_fn(|_| vec![0; n]),
            err: vec![0; n],
            pred: [0; 4],
            avg: 0,
        }
    }

    #[inline]
    fn error_weight(x: u64, maxw: u64) -> u64 {
        let lg = 63 - (x + 1).leading_zeros() as i64;
        let shift = (lg - 5).max(0) as u32;
        4 + ((maxw * div_lookup(x >> shift)) >> shift)
    }

    #[inline]
    fn rows(&self, y: usize) -> (usize, usize) {
        if y & 1 == 1 {
            (0, self.w + 2)
        } else {
            (self.w + 2, 0)
        }
    }

    /// The prediction in units (internally 3 more bits); `None` when P leaves ±[`MAX_P`].
    #[inline]
    fn predict(&mut self, x: usize, y: usize, nb: &Nb) -> Option<i64> {
        let (cur, prev) = self.rows(y);
        let pos_n = prev + x;
        let pos_ne = if x + 1 < self.w { pos_n + 1 } else { pos_n };
        let pos_nw = if x > 0 { pos_n - 1 } else { pos_n };
        let mut wts = [0u64; 4];
        for (k, wt) in wts.iter_mut().enumerate() {
            let s = self.pe[k][pos_n] + self.pe[k][pos_ne] + self.pe[k][pos_nw];
            *wt = Self::error_weight(s, MAXW[k]);
        }
        let (n, w, ne) = (nb.n << 3, nb.w << 3, nb.ne << 3);
        let te_w = if x == 0 { 0 } else { self.err[cur + x - 1] };
        let te_n = self.err[pos_n];
        let te_nw = self.err[pos_nw];
        let te_ne = self.err[pos_ne];
        let sum_wn = te_n + te_w;
        self.pred[0] = w + ne - n;
        self.pred[1] = n - (((sum_wn + te_ne) * P1C) >> 5);
        self.pred[2] = w - (((sum_wn + te_nw) * P2C) >> 5);
        self.pred[3] = n - ((te_nw * P3C[0] + te_n * P3C[1] + te_ne * P3C[2]) >> 5);
        // The weighted mean without a division.
        let total: u64 = wts.iter().sum();
        let lg = 63 - total.leading_zeros();
        let mut ws = 0u64;
        for wt in wts.iter_mut() {
            *wt >>= lg - 4;
            ws += *wt;
        }
        let mut sum: i128 = (ws >> 1) as i128 - 1;
        for (p, wt) in self.pred.iter().zip(wts) {
            sum += *p as i128 * wt as i128;
        }
        let p = (sum * div_lookup(ws - 1) as i128) >> 24;
        if p.unsigned_abs() > MAX_P as u128 {
            return None;
        }
        let mut p = p as i64;
        if ((te_n ^ te_w) | (te_n ^ te_nw)) <= 0 {
            let hi = w.max(ne).max(n);
            let lo = w.min(ne).min(n);
            p = p.clamp(lo, hi);
        }
        self.avg = p;
        Some((p + 3) >> 3)
    }

    #[inline]
    fn update(&mut self, x: usize, y: usize, val: i64) {
        let (cur, prev) = self.rows(y);
        let v = val << 3;
        self.err[cur + x] = self.avg - v;
        for k in 0..4 {
            let e = ((self.pred[k] - v).unsigned_abs() + 3) >> 3;
            self.pe[k][cur + x] = e;
            self.pe[k][prev + x + 1] += e;
        }
    }
}

/// The 14 causal neighbours minus `base`; `None` near the borders.
#[inline]
fn features(rec: &[i64], w: usize, x: usize, y: usize, base: i64) -> Option<[i64; NF]> {
    if y < 3 || x < 3 || x + 2 >= w {
        return None;
    }
    let i = y * w + x;
    let (w1, w2) = (w, 2 * w);
    let v = [
        rec[i - w1],
        rec[i - 1],
        rec[i - w1 - 1],
        rec[i - w1 + 1],
        rec[i - w2],
        rec[i - 2],
        rec[i - w2 + 1],
        rec[i - w2 - 1],
        rec[i - w1 - 2],
        rec[i - w1 + 2],
        rec[i - w2 - 2],
        rec[i - w2 + 2],
        rec[i - 3],
        rec[i - 3 * w],
    ];
    Some(v.map(|v| v - base))
}

/// Fit the least-squares weights per class on the source (encoder only): the same scan,
/// run losslessly on the source values.
pub fn fit(p: &Plane) -> Vec<[i16; NF]> {
    let mut normals: Vec<Normal<NF>> = (0..CLASSES).map(|_| Normal::new()).collect();
    let (w, h) = (p.width, p.height);
    let mid = p.lo + (p.hi - p.lo) / 2;
    let mut wp = Wp::new(w);
    let mut rec = vec![0i64; w * h];
    let mut err = vec![0u32; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let nb = neighbours(&rec, w, x, y, mid);
            let Some(base) = wp.predict(x, y, &nb) else {
                // The source takes the predictor out of its range: `run` fails too (or
                // soon after), and the encoder keeps another coding.
                return vec![[0; NF]; CLASSES];
            };
            let act = activity(&nb, &err, w, x, i);
            let cls = class(act, p.bin);
            let pred = base.clamp(p.lo, p.hi);
            let r = if p.kinds[i] == SKIPPED {
                pred
            } else {
                if let Some(f) = features(&rec, w, x, y, base) {
                    normals[cls].add(&f, (p.values[i] - base) as f64);
                }
                p.values[i]
            };
            rec[i] = r;
            err[i] = (r - pred).unsigned_abs().min(u32::MAX as u64) as u32;
            wp.update(x, y, r);
        }
    }
    normals.iter().map(Normal::solve).collect()
}

/// CALIC's error energy: dh + dv + 2|e_W|.
#[inline]
fn activity(nb: &Nb, err: &[u32], w: usize, x: usize, i: usize) -> i64 {
    let dh = (nb.w - nb.ww).abs() + (nb.n - nb.nw).abs() + (nb.n - nb.ne).abs();
    let dv = (nb.w - nb.nw).abs() + (nb.n - nb.nn).abs() + (nb.ne - nb.nne).abs();
    let e_w = if x > 0 { err[i - 1] as i64 } else { 0 };
    let _ = w;
    dh + dv + 2 * e_w
}

#[inline]
fn class(act: i64, bin: i64) -> usize {
    (act_class(quarter_bins(act, bin)) * CLASSES / 16).min(CLASSES - 1)
}

/// Code (encoder) or decode every sample in scan order with the weights `weights` (one set
/// per class).
pub fn run<C: BinCoder>(p: &Plane, weights: &[[i16; NF]], coder: &mut C) -> Result<State> {
    let (w, h) = (p.width, p.height);
    let mid = p.lo + (p.hi - p.lo) / 2;
    let mut st = State::new(w * h);
    let mut wp = Wp::new(w);
    let bin = p.bin;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let nb = neighbours(&st.rec, w, x, y, mid);
            let base = wp.predict(x, y, &nb).ok_or_else(|| {
                Error::corrupt("residual section: the weighted prediction leaves ±2^45 eighths")
            })?;
            let act = activity(&nb, &st.res, w, x, i);
            let mut pred = base;
            if let (Some(f), Some(cf)) = (features(&st.rec, w, x, y, base), weights.get(class(act, bin))) {
                let s: i64 = f.iter().zip(cf).map(|(f, c)| f * *c as i64).sum();
                pred += round_div(s, 1 << ls::SHIFT);
            }
            let e = |j: usize| st.res[j] as u64;
            let e_w = if x > 0 { e(i - 1) } else { 0 };
            let e_n = if y > 0 { e(i - w) } else { 0 };
            let e_nw = if x > 0 && y > 0 { e(i - w - 1) } else { 0 };
            let e_ne = if x + 1 < w && y > 0 { e(i - w + 1) } else { 0 };
            let sg = if x > 0 { st.sign[i - 1] as i32 } else { 0 }
                + if y > 0 { st.sign[i - w] as i32 } else { 0 };
            let errq = (2 * (e_w + e_n) + e_nw + e_ne).saturating_mul(2) / bin as u64;
            st.code(
                p,
                i,
                pred,
                || Ctx {
                    act: quarter_bins(act, bin),
                    err: errq,
                    sign: sg,
                    level: 0,
                },
                coder,
            )?;
            wp.update(x, y, st.rec[i]);
        }
    }
    Ok(st)
}
