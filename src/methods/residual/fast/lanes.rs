//! The lane coding's kernel (codings 4 and 5, spec/FORMAT.md "Lane coding"): the fast
//! coding's passes, bands, tokens and tables, with every sample of a pass predicted from
//! coarser passes only, so a pass row runs in three phases: (1) predictions, stencil
//! corrections and context classes for the whole row (no sample of the pass itself read:
//! the loops vectorise), (2) the tokens, one tight loop over four interleaved rANS states
//! whose only serial input is the token before, (3) reconstruction `clamp(pred + bin·q)`,
//! vectorised again. Planes hold `value − lo` in i32 lanes where the lattice range and the
//! bin allow ([`fits_i32`]), i64 otherwise: the arithmetic is specified so that neither
//! overflows, so both give the same integers. Rows with skipped or fixed samples take the
//! general token loop; the rest the plain one.

use super::super::coder::quantize;
use super::super::interp::interp1;
use super::super::plane::{CODED, FIXED};
use super::passes::{BandBuf, FINE, Kind, NCOARSE, NW, Pass, half_log, put_row, token};
use crate::entropy::rans::{self, BitReader, BitWriter, LanesDecoder};
use crate::entropy::varint;
use crate::error::{Error, Result};
use crate::predict::med::anchor_med;
use std::ops::{Add, Mul, Neg, Shr, Sub};

/// Contexts: per group, per energy class (the fast coding's).
pub(super) const LNCTX: usize = super::passes::NCTX;
/// Largest stencil weight magnitude (units of 2^-10).
pub const MAX_WEIGHT: i16 = 4096;
/// Stencil differences are clamped to −DIFF ..= DIFF − 1.
const DIFF: i64 = 1 << 15;
/// Lattice ranges and bins below this run in i32 lanes.
const I32_FROM: i64 = 1 << 26;

/// Whether a plane of range `r` (hi − lo) and bin `bin` runs in i32 lanes: every
/// intermediate value then stays below 2^31 (the cubic's 18·2^26, the stencil's
/// 8·2^15·2^12 + 2^26, the reconstruction's 2^26 + 2·2^27).
pub(super) fn fits_i32(r: i64, bin: i64) -> bool {
    r < I32_FROM && bin < I32_FROM
}

/// A sample lane: i32 or i64.
pub(super) trait Lane:
    Copy
    + Ord
    + Default
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Neg<Output = Self>
    + Shr<u32, Output = Self>
{
    fn of(v: i64) -> Self;
    fn wide(self) -> i64;
}

impl Lane for i32 {
    #[inline(always)]
    fn of(v: i64) -> i32 {
        v as i32
    }
    #[inline(always)]
    fn wide(self) -> i64 {
        self as i64
    }
}

impl Lane for i64 {
    #[inline(always)]
    fn of(v: i64) -> i64 {
        v
    }
    #[inline(always)]
    fn wide(self) -> i64 {
        self
    }
}

/// What every band reads.
pub(super) struct Global<'a, T> {
    pub w: usize,
    pub h: usize,
    /// hi − lo: every reconstruction lies in 0 ..= r.
    pub r: T,
    pub lo: i64,
    /// Per sample kinds (empty: every sample coded).
    pub kinds: &'a [u8],
    /// Per raster row: every sample coded (empty: all).
    pub row_coded: &'a [bool],
    /// Source (encoder) or fixed values (decoder), absolute lattice units.
    pub values: &'a [i64],
}

/// The planes so far (value − lo, and min(|bin|, 255)): shared by bands running side by
/// side (each writes a buffer of its own, then [`scatter`]), or held by the one band
/// running, which writes its rows straight into them.
pub(super) enum Planes<'a, T> {
    Shared(&'a [T], &'a [u8]),
    Own(&'a mut [T], &'a mut [u8]),
}

impl<T> Planes<'_, T> {
    #[inline(always)]
    fn get(&self) -> (&[T], &[u8]) {
        match self {
            Planes::Shared(p, m) => (p, m),
            Planes::Own(p, m) => (p, m),
        }
    }
}

impl<T: Lane> Global<'_, T> {
    fn coded_row(&self, y: usize) -> bool {
        self.row_coded.is_empty() || self.row_coded[y]
    }
}

/// Per sample kind rows: a row is plain when all its samples are coded.
pub(super) fn row_flags(kinds: &[u8], w: usize, h: usize) -> Vec<bool> {
    if kinds.is_empty() {
        return Vec::new();
    }
    (0..h)
        .map(|y| kinds[y * w..(y + 1) * w].iter().all(|&k| k == CODED))
        .collect()
}

/// The cubic interpolation at the middle of b and c: (−a + 9(b + c) − d + 8) >> 4.
#[inline(always)]
fn cubic<T: Lane>(a: T, b: T, c: T, d: T) -> T {
    (T::of(9) * (b + c) - a - d + T::of(8)) >> 4
}

/// The support's curvature |−a + b + c − d| + |b − c| >> 2.
#[inline(always)]
fn curv<T: Lane>(a: T, b: T, c: T, d: T) -> T {
    let z = T::of(0);
    let u = b + c - a - d;
    let v = b - c;
    u.max(z - u) + (v.max(z - v) >> 2)
}

/// The stencil's correction of `base`: base + (512 + Σ w_k·clamp(t_k − base, ±2^15)) >> 10.
#[inline(always)]
fn corrected<T: Lane>(base: T, taps: [T; NCOARSE], wts: &[T; NCOARSE]) -> T {
    let mut acc = T::of(512);
    for k in 0..NCOARSE {
        acc = acc + (taps[k] - base).clamp(T::of(-DIFF), T::of(DIFF - 1)) * wts[k];
    }
    base + (acc >> 10)
}

/// Per pass constants.
#[derive(Clone, Copy)]
struct PassK<T> {
    bin: T,
    binf: f64,
    hl_bin: u32,
    /// The group's first context (previous token 0, class 0).
    first: u16,
    wts: Option<[T; NCOARSE]>,
}

impl<T: Lane> PassK<T> {
    fn new(pass: &Pass) -> PassK<T> {
        PassK {
            bin: T::of(pass.bin),
            binf: pass.bin as f64,
            hl_bin: half_log(pass.bin as u64),
            first: (pass.group * FINE) as u16,
            wts: pass
                .weights
                .map(|w| std::array::from_fn(|k| T::of(w[k] as i64))),
        }
    }

    /// The context base of a sample: the group's, plus the class of the energy
    /// 4·t + bin·(4m + 1) in half octaves above the bin's.
    #[inline(always)]
    ///
    /// Computed in f64, exactly (4t < 2^44, bin·(4m + 1) < 2^38·2^12: every value and the
    /// sum are whole numbers below 2^53), so that it vectorises: the exponent and the top
    /// mantissa bit of e's bits are hl(e) + 2·1023.
    fn class(&self, t: T, m: i32) -> u16 {
        let e = 4.0 * t.wide() as f64 + self.binf * (4 * m + 1) as f64;
        let hl = ((e.to_bits() >> 51) as u32).wrapping_sub(2 * 1023);
        self.first + hl.wrapping_sub(self.hl_bin).min(FINE as u32 - 1) as u16
    }
}

/// A row's samples at columns 0, st, 2·st, … gathered into `out` (contiguous, so the
/// loops over them vectorise).
#[inline(always)]
fn gather<T: Copy + Default>(row: &[T], st: usize, out: &mut Vec<T>) {
    let (n, full) = (row.len().div_ceil(st), row.len() / st);
    out.resize(n, T::default());
    if st == 2 {
        // A constant stride: the loads vectorise (LLVM's interleaved groups).
        for (o, c) in out[..full].iter_mut().zip(row.chunks_exact(2)) {
            *o = c[0];
        }
    } else {
        for (o, c) in out[..full].iter_mut().zip(row.chunks_exact(st)) {
            *o = c[0];
        }
    }
    if full < n {
        out[full] = row[full * st];
    }
}

/// Scratch rows of phase 1, reused from row to row.
#[derive(Default)]
pub(super) struct Scratch<T> {
    g: [Vec<T>; 4],
    m: [Vec<u8>; 4],
    t: Vec<T>,
    mm: Vec<i32>,
}

/// Predictions from four supports, corrected where `taps` gives the stencil's points:
/// `pred[k] = clamp(corrected(cubic(a, b, c, d)), 0, r)` and the curvature `t[k]`.
#[inline(always)]
fn cubic_rows<T: Lane>(a: &[T], b: &[T], c: &[T], d: &[T], r: T, pred: &mut [T], t: &mut [T]) {
    let zero = T::of(0);
    for (((((p, t), &a), &b), &c), &d) in pred
        .iter_mut()
        .zip(t.iter_mut())
        .zip(a)
        .zip(b)
        .zip(c)
        .zip(d)
    {
        *p = cubic(a, b, c, d).clamp(zero, r);
        *t = curv(a, b, c, d);
    }
}

/// The stencil's correction of `pred[k]` over a run of samples: its eight taps (support
/// b, c, a, d, then four of the rows beside) given as slices in step with `pred`.
#[inline(always)]
fn stencil_rows<T: Lane>(taps: [&[T]; NCOARSE], wt: &[T; NCOARSE], r: T, pred: &mut [T]) {
    let zero = T::of(0);
    let n = pred.len();
    let taps = taps.map(|t| &t[..n]);
    for k in 0..n {
        let (a, b, c, d) = (taps[2][k], taps[0][k], taps[1][k], taps[3][k]);
        let base = cubic(a, b, c, d);
        pred[k] = corrected(base, std::array::from_fn(|j| taps[j][k]), wt).clamp(zero, r);
    }
}

/// Phase 1 of a pass row: predictions (clamped to 0 ..= r) and context bases of the row's
/// `n` samples, from coarser passes only.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn predict_row<T: Lane>(
    g: &Global<T>,
    (plane, mag): (&[T], &[u8]),
    pass: &Pass,
    kc: &PassK<T>,
    y: usize,
    sc: &mut Scratch<T>,
    pred: &mut [T],
    cb: &mut [u16],
) {
    let (w, h, s) = (g.w, g.h, pass.s);
    let n = pred.len();
    let st = 2 * s;
    let row = |d: usize| &plane[d * w..(d + 1) * w];
    let mrow = |d: usize| &mag[d * w..(d + 1) * w];
    sc.t.resize(n, T::of(0));
    sc.mm.resize(n, 0);
    match pass.kind {
        Kind::Anchor => unreachable!("anchors run sample by sample"),
        Kind::Vertical if y >= 3 * s && y + 3 * s < h => {
            let [ga, gb, gc, gd] = &mut sc.g;
            let [mb, mc, _, _] = &mut sc.m;
            if s == 1 {
                // A constant stride: the gathers vectorise.
                for (o, d) in [
                    (&mut *ga, y - 3),
                    (&mut *gb, y - 1),
                    (&mut *gc, y + 1),
                    (&mut *gd, y + 3),
                ] {
                    gather(row(d), 2, o);
                }
                gather(mrow(y - 1), 2, mb);
                gather(mrow(y + 1), 2, mc);
            } else {
                for (o, d) in [
                    (&mut *ga, y - 3 * s),
                    (&mut *gb, y - s),
                    (&mut *gc, y + s),
                    (&mut *gd, y + 3 * s),
                ] {
                    gather(row(d), st, o);
                }
                gather(mrow(y - s), st, mb);
                gather(mrow(y + s), st, mc);
            }
            cubic_rows(ga, gb, gc, gd, g.r, pred, &mut sc.t);
            if let Some(wt) = &kc.wts {
                // Stencil columns: 2s ≤ x and x + 2s < w, i.e. 1 ≤ k < n − 1 (k·2s < w).
                if n >= 3 {
                    let m = n - 2;
                    stencil_rows(
                        [
                            &gb[1..],
                            &gc[1..],
                            &ga[1..],
                            &gd[1..],
                            &gb[..m],
                            &gc[..m],
                            &gb[2..],
                            &gc[2..],
                        ],
                        wt,
                        g.r,
                        &mut pred[1..n - 1],
                    );
                }
            }
            for ((o, &b), &c) in sc.mm.iter_mut().zip(&mb[..n]).zip(&mc[..n]) {
                *o = b as i32 + c as i32;
            }
            // Interior columns add half the four diagonal neighbours' (rows y ± s, x ± 2s).
            if n >= 3 {
                let m = n - 2;
                let it = sc.mm[1..n - 1]
                    .iter_mut()
                    .zip(&mb[..m])
                    .zip(&mb[2..n])
                    .zip(&mc[..m])
                    .zip(&mc[2..n]);
                for ((((o, &b0), &b1), &c0), &c1) in it {
                    *o += (b0 as i32 + b1 as i32 + c0 as i32 + c1 as i32) >> 1;
                }
            }
        }
        Kind::Horizontal => {
            // Supports at columns x ± s, x ± 3s of x = s + k·2s: the gathered row's
            // k − 1, k, k + 1, k + 2; interior where k ≥ 1 and s + k·2s + 3s < w.
            let [ge, gu, gd, _] = &mut sc.g;
            let [ml, mu, md, _] = &mut sc.m;
            // Rows with both neighbours add half the four diagonal ones' (rows y ± s, x ± s).
            let around = y >= s && y + s < h;
            if around {
                gather(mrow(y - s), st, mu);
                gather(mrow(y + s), st, md);
            }
            let wts = kc.wts.as_ref().filter(|_| y >= s && y + s < h);
            if s == 1 {
                gather(row(y), 2, ge);
                gather(mrow(y), 2, ml);
                if wts.is_some() {
                    gather(row(y - 1), 2, gu);
                    gather(row(y + 1), 2, gd);
                }
            } else {
                gather(row(y), st, ge);
                gather(mrow(y), st, ml);
                if wts.is_some() {
                    gather(row(y - s), st, gu);
                    gather(row(y + s), st, gd);
                }
            }
            let k0 = 1.min(n);
            let k1 = if 4 * s < w {
                ((w - 4 * s - 1) / st + 1).min(n).max(k0)
            } else {
                k0
            };
            if k1 > k0 {
                let m = k1 - k0;
                let (a, b, c, d) = (
                    &ge[k0 - 1..],
                    &ge[k0..],
                    &ge[k0 + 1..],
                    &ge[k0 + 2..k0 + 2 + m],
                );
                cubic_rows(a, b, c, d, g.r, &mut pred[k0..k1], &mut sc.t[k0..k1]);
                if let Some(wt) = wts {
                    stencil_rows(
                        [
                            b,
                            c,
                            a,
                            d,
                            &gu[k0..],
                            &gu[k0 + 1..],
                            &gd[k0..],
                            &gd[k0 + 1..],
                        ],
                        wt,
                        g.r,
                        &mut pred[k0..k1],
                    );
                }
                for ((o, &b), &c) in sc.mm[k0..k1].iter_mut().zip(&ml[k0..]).zip(&ml[k0 + 1..]) {
                    *o = b as i32 + c as i32;
                }
                if around {
                    let it = sc.mm[k0..k1]
                        .iter_mut()
                        .zip(&mu[k0..])
                        .zip(&mu[k0 + 1..])
                        .zip(&md[k0..])
                        .zip(&md[k0 + 1..]);
                    for ((((o, &u0), &u1), &d0), &d1) in it {
                        *o += (u0 as i32 + u1 as i32 + d0 as i32 + d1 as i32) >> 1;
                    }
                }
            }
            let line = row(y);
            let ml = mrow(y);
            for k in (0..k0).chain(k1..n) {
                let x = s + k * st;
                let get = |dd: isize| {
                    let xx = x as isize + dd * s as isize;
                    (xx >= 0 && (xx as usize) < w).then_some(xx as usize)
                };
                let (xa, xc, xd) = (get(-3), get(1), get(3));
                let v = |j: usize| line[j].wide();
                let (av, bv, cv, dv) = (xa.map(v), v(x - s), xc.map(v), xd.map(v));
                pred[k] = T::of(interp1(av, bv, cv, dv).clamp(0, g.r.wide()));
                sc.t[k] = T::of(edge_curv(av, bv, cv, dv));
                sc.mm[k] = ml[x - s] as i32 + xc.map_or(0, |j| ml[j] as i32);
            }
        }
        Kind::Vertical => {
            // Edge rows (the support leaves the raster): few, sample by sample.
            #[allow(clippy::needless_range_loop)]
            for k in 0..n {
                let x = k * st;
                let i = y * w + x;
                let get = |dd: isize| {
                    let yy = y as isize + dd * s as isize;
                    (yy >= 0 && (yy as usize) < h)
                        .then(|| (i as isize + dd * (w * s) as isize) as usize)
                };
                let ib = i - w * s;
                let (ia, ic, id) = (get(-3), get(1), get(3));
                let v = |j: usize| plane[j].wide();
                let (av, bv, cv, dv) = (ia.map(v), v(ib), ic.map(v), id.map(v));
                pred[k] = T::of(interp1(av, bv, cv, dv).clamp(0, g.r.wide()));
                sc.t[k] = T::of(edge_curv(av, bv, cv, dv));
                sc.mm[k] = mag[ib] as i32 + ic.map_or(0, |j| mag[j] as i32);
            }
        }
    }
    for ((o, &t), &m) in cb.iter_mut().zip(&sc.t[..n]).zip(&sc.mm[..n]) {
        *o = kc.class(t, m);
    }
}

/// The curvature where the support leaves the raster: as [`curv`] with all four points,
/// |b − c| >> 1 with c, else 0.
fn edge_curv(a: Option<i64>, b: i64, c: Option<i64>, d: Option<i64>) -> i64 {
    match (a, c, d) {
        (Some(a), Some(c), Some(d)) => (b + c - a - d).abs() + ((b - c).abs() >> 2),
        (_, Some(c), _) => (b - c).abs() >> 1,
        _ => 0,
    }
}

/// Phase 2: what codes (encoder) or reads (decoder) the tokens of a row.
pub(super) trait Tokens<T: Lane> {
    /// The bins of a row's samples; `kinds`: the row's kinds at its samples' columns
    /// (`None`: all coded); `src`: the sources (encoder).
    fn row<S: Fn(usize) -> i64, K: Fn(usize) -> u8>(
        &mut self,
        cb: &[u16],
        pred: &[T],
        src: &S,
        kinds: Option<&K>,
        bin: T,
        q: &mut [T],
    ) -> Result<()>;
}

/// Passes with at least this many columns code their bands in four interleaved states,
/// others in one (four states' 16 bytes would be a large share of a small band's).
pub(super) const MANY_FROM: usize = 64;

/// The interleaved states of a band of `pass` in a raster `w` wide, less one (a mask on the
/// column index: 3 or 0).
pub(super) fn state_mask(pass: &Pass, w: usize) -> usize {
    if pass.cols(w) >= MANY_FROM { 3 } else { 0 }
}

/// The encoder's record of a band: tokens with their context and state, the raw bits.
#[derive(Default)]
pub(super) struct Recorder {
    pub syms: Vec<(u16, u8, u8)>,
    pub raw: BitWriter,
    /// [`state_mask`] of the band's pass.
    pub mask: usize,
}

impl<T: Lane> Tokens<T> for Recorder {
    #[inline(always)]
    fn row<S: Fn(usize) -> i64, K: Fn(usize) -> u8>(
        &mut self,
        cb: &[u16],
        pred: &[T],
        src: &S,
        kinds: Option<&K>,
        bin: T,
        q: &mut [T],
    ) -> Result<()> {
        let bin = bin.wide();
        let binf = bin as f64;
        for k in 0..q.len() {
            if kinds.is_some_and(|kd| kd(k) != CODED) {
                q[k] = T::of(0);
                continue;
            }
            let r = src(k) - pred[k].wide();
            let b = if bin == 1 {
                r
            } else {
                quantize_f64(r, bin, binf)
            };
            let v = varint::zigzag(b);
            let (t, raw, nb) = token(v);
            self.syms.push((cb[k], t, (k & self.mask) as u8));
            if nb > 0 {
                self.raw.put(raw, nb);
            }
            q[k] = T::of(v as i64);
        }
        Ok(())
    }
}

/// [`quantize`] with the division in f64 (a few cycles, where a 64-bit integer division
/// takes tens): exact, since |r| + (bin − 1)/2 < 2^40 and bin < 2^39 keep the quotient's
/// distance to the next whole number (≥ 1/(|r| + bin)) far above f64's rounding.
#[inline(always)]
fn quantize_f64(r: i64, bin: i64, binf: f64) -> i64 {
    let near = (bin - 1) / 2;
    let q = ((r.abs() + near) as f64 / binf) as i64;
    debug_assert_eq!(q * r.signum(), quantize(r, bin));
    if r >= 0 { q } else { -q }
}

/// The decoder of one band's stream.
pub(super) struct Reader<'a> {
    pub ans: LanesDecoder<'a>,
    pub raw: BitReader<'a>,
    /// Per context, its cluster's table (padded to 256 entries, so the context's 8 bits
    /// index them without a check).
    pub tables: &'a [&'a [u32; rans::TOTAL as usize]; 256],
    pub max_bin: u64,
    /// [`state_mask`] of the band's pass.
    pub mask: usize,
}

impl Reader<'_> {
    /// A token ≥ 16's zig-zagged bin: exponent and top bit from the token, the rest raw.
    #[cold]
    fn escape(&mut self, t: u32) -> Result<i64> {
        let t = t as u64;
        let e = (t - 16) / 2 + 4;
        let top = (t - 16) & 1;
        let v = (1 << e) | (top << (e - 1)) | self.raw.get(e as u32 - 1)?;
        if v >> 1 > self.max_bin {
            return Err(Error::corrupt(
                "residual section: a bin lies outside the section's value range",
            ));
        }
        Ok(v as i64)
    }

    /// The next token's zig-zagged bin.
    #[inline(always)]
    fn one<T: Lane>(&mut self, lane: usize, ctx: u16) -> Result<T> {
        let t = self
            .ans
            .symbol(lane & self.mask, self.tables[(ctx & 255) as usize])?;
        Ok(if t < 16 {
            T::of(t as i64)
        } else {
            T::of(self.escape(t)?)
        })
    }
}

impl<T: Lane> Tokens<T> for Reader<'_> {
    #[inline(always)]
    fn row<S: Fn(usize) -> i64, K: Fn(usize) -> u8>(
        &mut self,
        cb: &[u16],
        _pred: &[T],
        _src: &S,
        kinds: Option<&K>,
        _bin: T,
        q: &mut [T],
    ) -> Result<()> {
        let n = q.len();
        let cb = &cb[..n];
        if let Some(kd) = kinds {
            for k in 0..n {
                q[k] = if kd(k) != CODED {
                    T::of(0)
                } else {
                    self.one(k % 4, cb[k])?
                };
            }
            return Ok(());
        }
        let mut qs = q.chunks_exact_mut(4);
        let mut cs = cb.chunks_exact(4);
        for (q4, c4) in (&mut qs).zip(&mut cs) {
            for l in 0..4 {
                q4[l] = self.one(l, c4[l])?;
            }
        }
        for (l, (q, &c)) in qs
            .into_remainder()
            .iter_mut()
            .zip(cs.remainder())
            .enumerate()
        {
            *q = self.one(l, c)?;
        }
        Ok(())
    }
}

/// Phase 3: from zig-zagged bins v (b = v/2 or −(v+1)/2), reconstructions
/// clamp(pred + bin·b) and magnitudes min(|b|, 255).
#[inline(always)]
fn reconstruct<T: Lane>(pred: &[T], q: &[T], bin: T, r: T, rec: &mut [T], mag: &mut [u8]) {
    let zero = T::of(0);
    let n = rec.len();
    let (pred, q, mag) = (&pred[..n], &q[..n], &mut mag[..n]);
    for k in 0..n {
        let v = q[k];
        let half = v >> 1;
        // v odd: b = −half − 1 = half − v; even: b = half.
        let odd = v - half - half;
        let b = half - odd * v;
        rec[k] = (pred[k] + bin * b).clamp(zero, r);
        // |b| = v − half.
        mag[k] = (v - half).min(T::of(255)).wide() as u8;
    }
}

/// A band's reconstructions and magnitudes, pass row by pass row.
/// Run the pass rows k0..k1 of `pass` (not the anchors) into buffers of their own.
#[inline(always)]
pub(super) fn run_band<T: Lane, C: Tokens<T>>(
    g: &Global<T>,
    planes: &mut Planes<T>,
    pass: &Pass,
    (k0, k1): (usize, usize),
    coder: &mut C,
) -> Result<BandBuf<T>> {
    let w = g.w;
    let cols = pass.cols(w);
    let kc = PassK::<T>::new(pass);
    let own = matches!(planes, Planes::Own(..));
    let rows = if own { 1 } else { k1 - k0 };
    let mut rec = vec![T::of(0); rows * cols];
    let mut mag = vec![0u8; rows * cols];
    let mut pred = vec![T::of(0); cols];
    let mut cb = vec![0u16; cols];
    let mut q = vec![T::of(0); cols];
    let mut kinds_row: Vec<u8> = Vec::with_capacity(cols);
    let mut sc = Scratch::default();
    for k in k0..k1 {
        let y = pass.r0 + k * pass.rs;
        predict_row(g, planes.get(), pass, &kc, y, &mut sc, &mut pred, &mut cb);
        let at = |c: usize| y * w + pass.c0 + c * pass.cs;
        let src = |c: usize| g.values[at(c)] - g.lo;
        let j = if own { 0 } else { (k - k0) * cols };
        let (rr, mr) = (&mut rec[j..j + cols], &mut mag[j..j + cols]);
        if g.coded_row(y) {
            coder.row(&cb, &pred, &src, None::<&fn(usize) -> u8>, kc.bin, &mut q)?;
            reconstruct(&pred, &q, kc.bin, g.r, rr, mr);
        } else {
            // The row's kinds gathered once (they are strided in the plane): the coder reads
            // them, and the fixed samples are looked for only in a row that has one.
            kinds_row.clear();
            kinds_row.extend(
                g.kinds
                    .get(at(0)..)
                    .unwrap_or(&[])
                    .iter()
                    .step_by(pass.cs)
                    .take(cols),
            );
            let kr = &kinds_row;
            let kd = |c: usize| kr[c];
            coder.row(&cb, &pred, &src, Some(&kd), kc.bin, &mut q)?;
            reconstruct(&pred, &q, kc.bin, g.r, rr, mr);
            // A fixed sample keeps the value put into the plane before the passes ran.
            if kr.contains(&FIXED) {
                let (pl, _) = planes.get();
                for (c, &kind) in kr.iter().enumerate() {
                    if kind == FIXED {
                        rr[c] = pl[at(c)];
                    }
                }
            }
        }
        if let Planes::Own(p, m) = planes {
            let line = y * w + pass.c0..(y + 1) * w;
            put_row(&mut p[line.clone()], pass.cs, rr);
            put_row(&mut m[line], pass.cs, mr);
        }
    }
    Ok((rec, mag))
}

/// [`run_band`] as a `pulp` operation: its loops inlined into a function compiled for the
/// instruction set `pulp::Arch::dispatch` finds.
pub(super) struct Band<'a, 'g, 'p, T, C> {
    pub g: &'a Global<'g, T>,
    pub planes: &'a mut Planes<'p, T>,
    pub pass: &'a Pass,
    pub band: (usize, usize),
    pub coder: &'a mut C,
}

impl<T: Lane, C: Tokens<T>> pulp::WithSimd for Band<'_, '_, '_, T, C> {
    type Output = Result<BandBuf<T>>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
        run_band(self.g, self.planes, self.pass, self.band, self.coder)
    }
}

/// The anchors (one band): predicted sample by sample from the anchors before (MED), in
/// row order.
pub(super) fn run_anchors<T: Lane>(
    g: &Global<T>,
    plane: &[T],
    pass: &Pass,
    coder: &mut dyn AnchorTokens,
) -> Result<BandBuf<T>> {
    let w = g.w;
    let (rows, cols) = (pass.rows(g.h), pass.cols(w));
    let kc = PassK::<T>::new(pass);
    let big = pass.s;
    let mid = g.r.wide() / 2;
    let mut rec = vec![T::of(0); rows * cols];
    let mut mag = vec![0u8; rows * cols];
    for k in 0..rows {
        let y = k * big;
        for col in 0..cols {
            let x = col * big;
            let (i, j) = (y * w + x, k * cols + col);
            let up = k > 0;
            let own = |j: usize| rec[j].wide();
            let left = (col > 0).then(|| own(j - 1));
            let top = up.then(|| own(j - cols));
            let tl = (up && col > 0).then(|| own(j - cols - 1));
            let tr = (up && col + 1 < cols).then(|| own(j - cols + 1));
            let (p, t) = anchor_med(left, top, tl, tr, mid);
            let m = i32::from(if col > 0 { mag[j - 1] } else { 0 })
                + i32::from(if up { mag[j - cols] } else { 0 });
            let cbase = kc.class(T::of(t), m) as usize;
            let kind = if g.kinds.is_empty() {
                CODED
            } else {
                g.kinds[i]
            };
            let (r, q) = if kind == CODED {
                let src = g.values.get(i).map_or(0, |v| v - g.lo);
                let q = coder.one(col % 4, cbase, p, src, pass.bin)?;
                // (Each coder masks the column to its band's states.)
                ((p + pass.bin * q).clamp(0, g.r.wide()), q)
            } else if kind == FIXED {
                // The value put into the plane before the passes ran.
                (plane[i].wide(), 0)
            } else {
                (p, 0)
            };
            rec[j] = T::of(r);
            mag[j] = q.unsigned_abs().min(255) as u8;
        }
    }
    Ok((rec, mag))
}

/// Codes or reads one anchor's bin.
pub(super) trait AnchorTokens {
    fn one(&mut self, lane: usize, ctx: usize, pred: i64, src: i64, bin: i64) -> Result<i64>;
}

impl AnchorTokens for Recorder {
    fn one(&mut self, lane: usize, ctx: usize, pred: i64, src: i64, bin: i64) -> Result<i64> {
        let b = quantize(src - pred, bin);
        let (t, raw, nb) = token(varint::zigzag(b));
        self.syms.push((ctx as u16, t, (lane & self.mask) as u8));
        if nb > 0 {
            self.raw.put(raw, nb);
        }
        Ok(b)
    }
}

impl AnchorTokens for Reader<'_> {
    fn one(&mut self, lane: usize, ctx: usize, _: i64, _: i64, _: i64) -> Result<i64> {
        Ok(varint::unzigzag(
            Reader::one::<i64>(self, lane, ctx as u16)? as u64,
        ))
    }
}

/// Stencil weights a lane section may hold: the coarser points' (the pass's own two are 0)
/// within ±[`MAX_WEIGHT`].
pub(super) fn weights_ok(w: &[i16; NW]) -> bool {
    w[NCOARSE..].iter().all(|&v| v == 0) && w.iter().all(|&v| v.abs() <= MAX_WEIGHT)
}
