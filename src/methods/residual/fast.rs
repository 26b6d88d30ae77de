//! The fast coding (codings 2 and 3, spec/FORMAT.md "Fast coding"): multilevel cubic
//! interpolation with a least-squares stencil on the finest levels (points of coarser
//! levels and of the sample's own band), each bin a token (small values directly, large
//! ones as exponent + raw bits, as JPEG XL's hybrid integers) coded by static rANS under a
//! context of the level and a cheap "energy" (the support's curvature and four
//! neighbours' bins), the contexts clustered by the encoder. Every pass of every level is
//! cut into bands of rows, each its own stream: a sample reads only coarser samples and
//! its own band, so the bands of a pass decode (and encode) on as many cores as there are.

use super::coder::quantize;
use super::interp::{interp1, level_bin};
use super::plane::{CODED, FIXED, Plane};
use crate::container::bytes::ByteReader;
use crate::entropy::rans::{
    self, BitReader, BitWriter, DecTables, EncTable, StreamDecoder, StreamEncoder,
};
use crate::entropy::varint;
use crate::error::{Error, Result};
use rayon::prelude::*;

/// Context groups: level 1's horizontal pass, level 1's vertical pass, level 2, levels ≥ 3,
/// anchors.
const GROUPS: usize = 5;
/// Energy classes per group (half octaves of the energy in quarter bins).
const FINE: usize = 40;
/// Contexts before clustering.
const NCTX: usize = GROUPS * FINE;
/// Tokens: 0..16 themselves, then two per exponent 4 ..= 40.
pub const ALPHABET: usize = 90;
/// Bands of about 2^18 samples: a 3600² tile's finest pass has 25, a 1201² one's 3.
pub const DEFAULT_BAND_LOG2: u8 = 18;
/// Smallest and largest band size exponent a section may hold.
pub const BAND_LOG2: std::ops::RangeInclusive<u8> = 10..=30;

/// Points of the least-squares stencil, (dy, dx) in units of the level's step, per pass
/// (vertical, horizontal): eight of coarser levels, then two of the pass itself, which
/// count only within the sample's band (elsewhere their feature is 0).
const STENCIL: [[(isize, isize); NW]; 2] = [
    [(-1, 0), (1, 0), (-3, 0), (3, 0), (-1, -2), (1, -2), (-1, 2), (1, 2), (0, -2), (-2, 0)],
    [(0, -1), (0, 1), (0, -3), (0, 3), (-1, -1), (-1, 1), (1, -1), (1, 1), (-1, 0), (-2, 0)],
];
/// Stencil points.
pub const NW: usize = 10;
/// A stencil's fit reads about 2^this many samples.
const FIT_SAMPLES_LOG2: u32 = 17;
/// Stencil points of coarser levels.
const NCOARSE: usize = 8;

/// The fast coding's settings.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// Anchor stride 2^levels (1 ..= 12).
    pub levels: u32,
    /// Levels (finest first) with a least-squares correction (0 ..= min(levels, 4)).
    pub ls_levels: u32,
    /// Narrower bins on coarse levels, as coding 1 (coding 3).
    pub tighten: bool,
    /// Let [`resolve`] choose `tighten` from the data.
    pub tighten_auto: bool,
    /// Bands hold about 2^band_log2 samples.
    pub band_log2: u8,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Anchor,
    Vertical,
    Horizontal,
}

/// One pass over the plane: rows r0, r0 + rs, … and columns c0, c0 + cs, … .
#[derive(Clone, Copy, Debug)]
struct Pass {
    kind: Kind,
    /// The level's step (the anchor stride for anchors).
    s: usize,
    r0: usize,
    rs: usize,
    c0: usize,
    cs: usize,
    group: usize,
    bin: i64,
    /// Stencil weights (units of 2^-10), on the finest `ls_levels` levels.
    weights: Option<[i16; NW]>,
}

impl Pass {
    /// Index offsets of the stencil points in a raster `w` wide.
    fn offsets(&self, w: usize) -> [isize; NW] {
        let t = usize::from(self.kind == Kind::Horizontal);
        STENCIL[t].map(|(dy, dx)| (dy * w as isize + dx) * self.s as isize)
    }
    fn level(&self) -> u32 {
        self.s.trailing_zeros() + 1
    }
    fn rows(&self, h: usize) -> usize {
        if self.r0 < h { (h - 1 - self.r0) / self.rs + 1 } else { 0 }
    }
    fn cols(&self, w: usize) -> usize {
        if self.c0 < w { (w - 1 - self.c0) / self.cs + 1 } else { 0 }
    }
    /// The bands: ranges of pass rows, each of max(1, ⌊2^band_log2 / cols⌋) rows but the
    /// last; the anchors are one band.
    fn bands(&self, w: usize, h: usize, band_log2: u8) -> Vec<(usize, usize)> {
        let (rows, cols) = (self.rows(h), self.cols(w));
        if rows == 0 || cols == 0 {
            return Vec::new();
        }
        let per = if self.kind == Kind::Anchor {
            rows
        } else {
            ((1usize << band_log2) / cols).max(1)
        };
        (0..rows.div_ceil(per))
            .map(|b| (b * per, ((b + 1) * per).min(rows)))
            .collect()
    }
}

/// The passes in coding order: anchors, then per level (coarse to fine) vertical and
/// horizontal.
fn passes(cfg: Config, bin: i64) -> Vec<Pass> {
    let bin_of = |l: u32| if cfg.tighten { level_bin(bin, l) } else { bin };
    let big = 1usize << cfg.levels;
    let mut v = vec![Pass {
        kind: Kind::Anchor,
        s: big,
        r0: 0,
        rs: big,
        c0: 0,
        cs: big,
        group: 4,
        bin: bin_of(cfg.levels + 1),
        weights: None,
    }];
    for l in (1..=cfg.levels).rev() {
        let s = 1usize << (l - 1);
        let g = |vert: bool| match l {
            1 => usize::from(vert),
            2 => 2,
            _ => 3,
        };
        v.push(Pass {
            kind: Kind::Vertical,
            s,
            r0: s,
            rs: 2 * s,
            c0: 0,
            cs: 2 * s,
            group: g(true),
            bin: bin_of(l),
            weights: None,
        });
        v.push(Pass {
            kind: Kind::Horizontal,
            s,
            r0: 0,
            rs: s,
            c0: s,
            cs: 2 * s,
            group: g(false),
            bin: bin_of(l),
            weights: None,
        });
    }
    v
}

/// Half-octave logarithm: 2·⌊log2 v⌋ plus the bit below the leading one (v ≥ 1).
#[inline(always)]
fn half_log(v: u64) -> u32 {
    let l = 63 - v.leading_zeros();
    // The bit below the leading one (none for v = 1: (2v >> 0) & 1 = 0); v < 2^63.
    let below = (((v << 1) >> l) & 1) as u32;
    2 * l + below
}

/// Codes (encoder) or reads (decoder) one bin under a context.
pub trait SymCoder {
    const ENCODES: bool;
    fn code(&mut self, ctx: usize, bin: i64) -> Result<i64>;
}

/// The token of a zig-zagged bin v, its raw bits and their count.
#[inline(always)]
fn token(v: u64) -> (u8, u64, u32) {
    if v < 16 {
        (v as u8, 0, 0)
    } else {
        let e = 63 - v.leading_zeros();
        let top = (v >> (e - 1)) & 1;
        ((16 + 2 * (e - 4) + top as u32) as u8, v & ((1 << (e - 1)) - 1), e - 1)
    }
}

/// The encoder's first pass over a band: tokens, their contexts and the raw bits.
#[derive(Default)]
struct Recorder {
    tokens: Vec<u8>,
    ctxs: Vec<u8>,
    raw: BitWriter,
}

impl SymCoder for Recorder {
    const ENCODES: bool = true;
    #[inline(always)]
    fn code(&mut self, ctx: usize, bin: i64) -> Result<i64> {
        let (t, raw, n) = token(varint::zigzag(bin));
        self.tokens.push(t);
        self.ctxs.push(ctx as u8);
        if n > 0 {
            self.raw.put(raw, n);
        }
        Ok(bin)
    }
}

/// The decoder of one band's stream.
struct Reader<'a> {
    ans: StreamDecoder<'a>,
    raw: BitReader<'a>,
    /// Per context, the first slot of its cluster's table.
    base: &'a [usize; NCTX],
    max_bin: u64,
}

impl SymCoder for Reader<'_> {
    const ENCODES: bool = false;
    #[inline(always)]
    fn code(&mut self, ctx: usize, _bin: i64) -> Result<i64> {
        let t = self.ans.symbol(self.base[ctx])? as u64;
        let v = if t < 16 {
            t
        } else {
            let e = (t - 16) / 2 + 4;
            let top = (t - 16) & 1;
            (1 << e) | (top << (e - 1)) | self.raw.get(e as u32 - 1)?
        };
        if v >> 1 > self.max_bin {
            return Err(Error::corrupt(
                "residual section: a bin lies outside the section's value range",
            ));
        }
        Ok(varint::unzigzag(v))
    }
}

/// What every band reads: the plane and what the earlier passes reconstructed.
struct Global<'a> {
    w: usize,
    h: usize,
    kinds: &'a [u8],
    values: &'a [i64],
    lo: i64,
    hi: i64,
    all_coded: bool,
}

impl<'a> Global<'a> {
    /// `kinds` empty: every sample is coded.
    fn new(p: &Plane<'a>) -> Global<'a> {
        Global {
            w: p.width,
            h: p.height,
            kinds: p.kinds,
            values: p.values,
            lo: p.lo,
            hi: p.hi,
            all_coded: p.kinds.is_empty() || p.kinds.iter().all(|&k| k == CODED),
        }
    }
}

/// Where a band reads and writes: reconstructions and bin magnitudes (min(|bin|, 255)) of
/// earlier passes by sample index i, and of its own samples by band index j (pass row by
/// pass row) or sample index.
trait Store {
    fn rec(&self, i: usize) -> i64;
    fn mag(&self, i: usize) -> u8;
    fn own_rec(&self, j: usize, i: usize) -> i64;
    fn own_mag(&self, j: usize, i: usize) -> u8;
    fn set(&mut self, j: usize, i: usize, r: i64, m: u8);
}

/// A band coded beside others: reads the shared planes, writes buffers of its own (then
/// [`scatter`]ed into the planes).
struct Apart<'a> {
    rec: &'a [i64],
    mag: &'a [u8],
    brec: Vec<i64>,
    bmag: Vec<u8>,
}

impl Store for Apart<'_> {
    #[inline(always)]
    fn rec(&self, i: usize) -> i64 {
        self.rec[i]
    }
    #[inline(always)]
    fn mag(&self, i: usize) -> u8 {
        self.mag[i]
    }
    #[inline(always)]
    fn own_rec(&self, j: usize, _: usize) -> i64 {
        self.brec[j]
    }
    #[inline(always)]
    fn own_mag(&self, j: usize, _: usize) -> u8 {
        self.bmag[j]
    }
    #[inline(always)]
    fn set(&mut self, j: usize, _: usize, r: i64, m: u8) {
        self.brec[j] = r;
        self.bmag[j] = m;
    }
}

/// The bands of a pass coded one after the other on one thread: straight into the planes
/// (the same reads as [`Apart`]: a band never reads another band's samples).
struct InPlace<'a> {
    rec: &'a mut [i64],
    mag: &'a mut [u8],
}

impl Store for InPlace<'_> {
    #[inline(always)]
    fn rec(&self, i: usize) -> i64 {
        self.rec[i]
    }
    #[inline(always)]
    fn mag(&self, i: usize) -> u8 {
        self.mag[i]
    }
    #[inline(always)]
    fn own_rec(&self, _: usize, i: usize) -> i64 {
        self.rec[i]
    }
    #[inline(always)]
    fn own_mag(&self, _: usize, i: usize) -> u8 {
        self.mag[i]
    }
    #[inline(always)]
    fn set(&mut self, _: usize, i: usize, r: i64, m: u8) {
        self.rec[i] = r;
        self.mag[i] = m;
    }
}

/// Per pass constants of the contexts.
#[derive(Clone, Copy)]
struct Ctxs {
    bin: i64,
    /// half_log(bin), subtracted from the energy's.
    hl_bin: u32,
    /// First context of the pass's group.
    first: usize,
}

/// Predict, quantize or read, and reconstruct one sample; returns (rec, magnitude).
/// `t` is the support's curvature (lattice units), `m` the sum of the neighbours'
/// magnitudes.
#[inline(always)]
fn sample<C: SymCoder>(
    g: &Global,
    cx: Ctxs,
    coder: &mut C,
    i: usize,
    p: i64,
    t: i64,
    m: u32,
) -> Result<(i64, u8)> {
    let p = p.clamp(g.lo, g.hi);
    if !g.all_coded && g.kinds[i] != CODED {
        return Ok(if g.kinds[i] == FIXED {
            (g.values[i].clamp(g.lo, g.hi), 0)
        } else {
            (p, 0)
        });
    }
    let e = 4 * (t as u64 + cx.bin as u64 * m as u64) + cx.bin as u64;
    let class = (half_log(e) - cx.hl_bin).min(FINE as u32 - 1) as usize;
    let q = if C::ENCODES {
        quantize(g.values[i] - p, cx.bin)
    } else {
        0
    };
    let b = coder.code(cx.first + class, q)?;
    let r = (p + cx.bin * b).clamp(g.lo, g.hi);
    Ok((r, b.unsigned_abs().min(255) as u8))
}

/// The support's curvature: |−a + b + c − d| + |b − c|/4 with all four, |b − c|/2 with c,
/// else 0.
#[inline(always)]
fn curvature(a: Option<i64>, b: i64, c: Option<i64>, d: Option<i64>) -> i64 {
    match (a, c, d) {
        (Some(a), Some(c), Some(d)) => (-a + b + c - d).abs() + (b - c).abs() / 4,
        (_, Some(c), _) => (b - c).abs() / 2,
        _ => 0,
    }
}

/// The stencil correction: base + round(Σ f_k·w_k / 2^10), f_k = rec[i + o_k] − base for
/// the coarser points and `own[k] − base` for the pass's own (0 where `None`).
#[inline(always)]
///
/// The stencil's first four points are the support b, c, a, d (`bcad`, already read); an
/// own point that does not count is given as `base`.
fn corrected<S: Store>(
    st: &S,
    i: usize,
    offs: &[isize; NW],
    wts: &[i16; NW],
    bcad: [i64; 4],
    own: [i64; 2],
    base: i64,
) -> i64 {
    // Σ (v_k − base)·w_k = Σ v_k·w_k − base·Σ w_k, exactly (integers); Σ w_k is constant
    // per pass and hoisted out of the loops.
    let sum_w: i64 = wts.iter().map(|&w| w as i64).sum();
    let mut acc = 0i64;
    for k in 0..4 {
        acc += bcad[k] * wts[k] as i64;
    }
    for k in 4..NCOARSE {
        acc += st.rec((i as isize + offs[k]) as usize) * wts[k] as i64;
    }
    for k in 0..2 {
        acc += own[k] * wts[NCOARSE + k] as i64;
    }
    acc -= base * sum_w;
    base + ((acc + 512) >> 10)
}

/// Fit a pass's stencil weights on the source (encoder): the samples whose stencil lies
/// inside on pass rows spread to about 2^[`FIT_SAMPLES_LOG2`] samples. `None` when they are not worth their 20
/// bytes: the bits they save are estimated from the squared errors before and after, each
/// plus W²/4 (wide bins hide small improvements).
fn fit(p: &Plane, pass: Pass) -> Option<[i16; NW]> {
    let (w, h) = (p.width, p.height);
    let s = pass.s;
    let offs = pass.offsets(w);
    let along = if pass.kind == Kind::Vertical { (w * s) as isize } else { s as isize };
    // Ten weights are fitted well from ~2^15 samples: rows evenly spread to about that many.
    let step = ((pass.rows(h) * pass.cols(w)) >> FIT_SAMPLES_LOG2).max(1);
    // Calls `f(features, target)` for every sample the fit uses.
    let each = |f: &mut dyn FnMut(&[i64; NW], i64)| {
        for k in (0..pass.rows(h)).step_by(step) {
            let y = pass.r0 + k * pass.rs;
            let rows_in = match pass.kind {
                Kind::Vertical => y >= 3 * s && y + 3 * s < h,
                _ => y >= 2 * s && y + s < h,
            };
            if !rows_in {
                continue;
            }
            for col in 0..pass.cols(w) {
                let x = pass.c0 + col * pass.cs;
                let inside = match pass.kind {
                    Kind::Vertical => x >= 2 * s && x + 2 * s < w,
                    _ => x >= 3 * s && x + 3 * s < w,
                };
                let i = y * w + x;
                if !inside || p.kinds[i] == super::plane::SKIPPED {
                    continue;
                }
                let at = |d: isize| p.values[(i as isize + d * along) as usize];
                let base = (-at(-3) + 9 * (at(-1) + at(1)) - at(3) + 8) >> 4;
                let mut fs = [0i64; NW];
                let mut ok = true;
                for (fk, o) in fs.iter_mut().zip(offs) {
                    let j = (i as isize + o) as usize;
                    ok &= p.kinds[j] != super::plane::SKIPPED;
                    *fk = p.values[j] - base;
                }
                if ok {
                    f(&fs, p.values[i] - base);
                }
            }
        }
    };
    let mut n = super::ls::Normal::<NW>::new();
    each(&mut |fs, t| n.add(fs, t as f64));
    let wt = n.solve();
    if wt == [0; NW] {
        return None;
    }
    let (mut e0, mut e1, mut m) = (0f64, 0f64, 0f64);
    each(&mut |fs, t| {
        let acc: i64 = fs.iter().zip(&wt).map(|(f, w)| f * *w as i64).sum();
        let c = (acc + 512) >> 10;
        e0 += (t * t) as f64;
        e1 += ((t - c) * (t - c)) as f64;
        m += 1.0;
    });
    let q = (pass.bin * pass.bin) as f64 / 4.0;
    let per = 0.5 * ((e0 / m + q) / (e1 / m + q)).log2();
    let samples = (pass.rows(h) * pass.cols(w)) as f64;
    (per * samples > 2.0 * 8.0 * 2.0 * NW as f64).then_some(wt)
}

/// Run the pass rows k0..k1 of `pass`.
fn run_band<C: SymCoder, S: Store>(
    g: &Global,
    pass: Pass,
    (k0, k1): (usize, usize),
    coder: &mut C,
    st: &mut S,
) -> Result<()> {
    let (w, h) = (g.w, g.h);
    let cols = pass.cols(w);
    let cx = Ctxs {
        bin: pass.bin,
        hl_bin: half_log(pass.bin as u64),
        first: pass.group * FINE,
    };
    let s = pass.s;
    match pass.kind {
        Kind::Anchor => {
            let big = s;
            let mid = g.lo + (g.hi - g.lo) / 2;
            for k in k0..k1 {
                let y = pass.r0 + k * pass.rs;
                let row = (k - k0) * cols;
                for col in 0..cols {
                    let x = pass.c0 + col * pass.cs;
                    let (i, j) = (y * w + x, row + col);
                    let up = k > k0;
                    let left = (col > 0).then(|| st.own_rec(j - 1, i - big));
                    let top = up.then(|| st.own_rec(j - cols, i - big * w));
                    let tl = (up && col > 0).then(|| st.own_rec(j - cols - 1, i - big * w - big));
                    let tr =
                        (up && col + 1 < cols).then(|| st.own_rec(j - cols + 1, i - big * w + big));
                    let a = left.or(top).unwrap_or(mid);
                    let b = top.unwrap_or(a);
                    let c = tl.unwrap_or(a);
                    let d = tr.unwrap_or(b);
                    let p = if c >= a.max(b) {
                        a.min(b)
                    } else if c <= a.min(b) {
                        a.max(b)
                    } else {
                        a + b - c
                    };
                    let t = (a - c).abs() + (b - c).abs() + (d - b).abs();
                    let m = u32::from(if col > 0 { st.own_mag(j - 1, i - big) } else { 0 })
                        + u32::from(if up { st.own_mag(j - cols, i - big * w) } else { 0 });
                    let (r, mg) = sample(g, cx, coder, i, p, t, m)?;
                    st.set(j, i, r, mg);
                }
            }
        }
        Kind::Vertical => {
            let ws = w * s;
            let offs = pass.offsets(w);
            for k in k0..k1 {
                let y = pass.r0 + k * pass.rs;
                let row = (k - k0) * cols;
                let interior = y >= 3 * s && y + 3 * s < h;
                for col in 0..cols {
                    let x = col * pass.cs;
                    let (i, j) = (y * w + x, row + col);
                    let (p, t, ms) = if interior {
                        let (a, b, c, d) = (
                            st.rec(i - 3 * ws),
                            st.rec(i - ws),
                            st.rec(i + ws),
                            st.rec(i + 3 * ws),
                        );
                        let base = (-a + 9 * (b + c) - d + 8) >> 4;
                        (
                            match pass.weights {
                                Some(wt) if x >= 2 * s && x + 2 * s < w => {
                                    let own = [
                                        st.own_rec(j - 1, i - 2 * s),
                                        if k > k0 { st.own_rec(j - cols, i - 2 * ws) } else { base },
                                    ];
                                    corrected(st, i, &offs, &wt, [b, c, a, d], own, base)
                                }
                                _ => base,
                            },
                            (-a + b + c - d).abs() + (b - c).abs() / 4,
                            u32::from(st.mag(i - ws)) + u32::from(st.mag(i + ws)),
                        )
                    } else {
                        let get = |d: isize| {
                            let yy = y as isize + d * s as isize;
                            (yy >= 0 && (yy as usize) < h).then(|| (i as isize + d * ws as isize) as usize)
                        };
                        let b = st.rec(i - ws);
                        let (a, c, d) = (get(-3), get(1), get(3));
                        let mc = c.map_or(0, |q| u32::from(st.mag(q)));
                        let (a, c, d) = (a.map(|q| st.rec(q)), c.map(|q| st.rec(q)), d.map(|q| st.rec(q)));
                        (
                            interp1(a, b, c, d),
                            curvature(a, b, c, d),
                            u32::from(st.mag(i - ws)) + mc,
                        )
                    };
                    let m = ms
                        + u32::from(if col > 0 { st.own_mag(j - 1, i - 2 * s) } else { 0 })
                        + u32::from(if k > k0 { st.own_mag(j - cols, i - 2 * ws) } else { 0 });
                    let (r, mg) = sample(g, cx, coder, i, p, t, m)?;
                    st.set(j, i, r, mg);
                }
            }
        }
        Kind::Horizontal => {
            // Columns x = s + 2s·col; the whole support x ± s, x ± 3s lies inside for
            // col in lo..hi.
            let lo = 1.min(cols);
            let hi = {
                // x + 3s < w  ⟺  s + 2s·col + 3s < w.
                let mut c = cols;
                while c > lo && s + 2 * s * (c - 1) + 3 * s >= w {
                    c -= 1;
                }
                c
            };
            let offs = pass.offsets(w);
            let ws = w * s;
            for k in k0..k1 {
                let y = k * pass.rs;
                let row = (k - k0) * cols;
                let line = y * w;
                let wts = pass.weights.filter(|_| y >= s && y + s < h);
                let up = k > k0;
                for col in 0..lo {
                    h_edge(g, st, coder, cx, pass, (k, k0, col, cols), line)?;
                }
                for col in lo..hi {
                    let x = s + col * pass.cs;
                    let (i, j) = (line + x, row + col);
                    let (a, b, c, d) =
                        (st.rec(i - 3 * s), st.rec(i - s), st.rec(i + s), st.rec(i + 3 * s));
                    let base = (-a + 9 * (b + c) - d + 8) >> 4;
                    let p = match &wts {
                        Some(wt) => {
                            let own = [
                                if up { st.own_rec(j - cols, i - ws) } else { base },
                                if k > k0 + 1 { st.own_rec(j - 2 * cols, i - 2 * ws) } else { base },
                            ];
                            corrected(st, i, &offs, wt, [b, c, a, d], own, base)
                        }
                        None => base,
                    };
                    let t = (-a + b + c - d).abs() + (b - c).abs() / 4;
                    let m = u32::from(st.mag(i - s))
                        + u32::from(st.mag(i + s))
                        + u32::from(st.own_mag(j - 1, i - 2 * s))
                        + u32::from(if up { st.own_mag(j - cols, i - ws) } else { 0 });
                    let (r, mg) = sample(g, cx, coder, i, p, t, m)?;
                    st.set(j, i, r, mg);
                }
                for col in hi.max(lo)..cols {
                    h_edge(g, st, coder, cx, pass, (k, k0, col, cols), line)?;
                }
            }
        }
    }
    Ok(())
}

/// A sample of a horizontal pass whose support leaves the raster (no stencil).
#[inline(always)]
fn h_edge<C: SymCoder, S: Store>(
    g: &Global,
    st: &mut S,
    coder: &mut C,
    cx: Ctxs,
    pass: Pass,
    (k, k0, col, cols): (usize, usize, usize, usize),
    line: usize,
) -> Result<()> {
    let (w, s) = (g.w, pass.s);
    let x = s + col * pass.cs;
    let (i, j) = (line + x, (k - k0) * cols + col);
    let get = |d: isize| {
        let xx = x as isize + d * s as isize;
        (xx >= 0 && (xx as usize) < w).then(|| (i as isize + d * s as isize) as usize)
    };
    let b = st.rec(i - s);
    let (a, c, d) = (get(-3), get(1), get(3));
    let mc = c.map_or(0, |q| u32::from(st.mag(q)));
    let (a, c, d) = (a.map(|q| st.rec(q)), c.map(|q| st.rec(q)), d.map(|q| st.rec(q)));
    let m = u32::from(st.mag(i - s))
        + mc
        + u32::from(if col > 0 { st.own_mag(j - 1, i - 2 * s) } else { 0 })
        + u32::from(if k > k0 { st.own_mag(j - cols, i - w * s) } else { 0 });
    let (r, mg) = sample(g, cx, coder, i, interp1(a, b, c, d), curvature(a, b, c, d), m)?;
    st.set(j, i, r, mg);
    Ok(())
}

/// A band's reconstructions and magnitudes, pass row by pass row.
type BandBuf = (Vec<i64>, Vec<u8>);

/// Run the bands of one pass with a coder each (`make` gives band b's, `done` takes it
/// back): on one thread one after the other straight into the planes, else side by side,
/// each into buffers of its own, then written into the planes. The same values either way.
fn run_pass<C: SymCoder + Send, T: Send>(
    g: &Global,
    pass: Pass,
    bands: &[(usize, usize)],
    (rec, mag): (&mut [i64], &mut [u8]),
    make: impl Fn(usize) -> Result<C> + Sync,
    done: impl Fn(C) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    if bands.len() <= 1 || rayon::current_num_threads() == 1 {
        let mut st = InPlace { rec, mag };
        let mut out = Vec::with_capacity(bands.len());
        for (b, &band) in bands.iter().enumerate() {
            let mut c = make(b)?;
            run_band(g, pass, band, &mut c, &mut st)?;
            out.push(done(c)?);
        }
        return Ok(out);
    }
    let cols = pass.cols(g.w);
    let coded: Vec<(BandBuf, T)> = {
        let (rec, mag) = (&*rec, &*mag);
        bands
            .par_iter()
            .enumerate()
            .map(|(b, &band)| {
                let n = (band.1 - band.0) * cols;
                let mut st = Apart {
                    rec,
                    mag,
                    brec: vec![0; n],
                    bmag: vec![0; n],
                };
                let mut c = make(b)?;
                run_band(g, pass, band, &mut c, &mut st)?;
                Ok(((st.brec, st.bmag), done(c)?))
            })
            .collect::<Result<_>>()?
    };
    let (bufs, out): (Vec<_>, Vec<_>) = coded.into_iter().unzip();
    scatter(g.w, pass, bands, &bufs, rec, mag);
    Ok(out)
}

/// Write the bands' buffers back into the planes, row by row on all threads.
fn scatter(
    w: usize,
    pass: Pass,
    bands: &[(usize, usize)],
    bufs: &[BandBuf],
    rec: &mut [i64],
    mag: &mut [u8],
) {
    let cols = pass.cols(w);
    let per = bands.first().map_or(1, |b| b.1 - b.0).max(1);
    rec.par_chunks_mut(w)
        .zip(mag.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (rr, mr))| {
            if y < pass.r0 || (y - pass.r0) % pass.rs != 0 {
                return;
            }
            let k = (y - pass.r0) / pass.rs;
            let b = k / per;
            let Some((br, bm)) = bufs.get(b) else { return };
            let from = (k - bands[b].0) * cols;
            for (col, (&v, &m)) in br[from..from + cols].iter().zip(&bm[from..from + cols]).enumerate() {
                let x = pass.c0 + col * pass.cs;
                rr[x] = v;
                mr[x] = m;
            }
        });
}

/// Estimated bits of coding `counts` with its own table (data and table).
fn cost(counts: &[u64]) -> f64 {
    let n: u64 = counts.iter().sum();
    if n == 0 {
        return 7.0;
    }
    let f = rans::normalize(counts);
    let data: f64 = counts
        .iter()
        .zip(&f)
        .filter(|(c, _)| **c > 0)
        .map(|(&c, &f)| c as f64 * (rans::PREC as f64 - (f as f64).log2()))
        .sum();
    data + rans::table_bits(&f) as f64
}

/// Cluster each group's energy classes into runs of adjacent classes (greedy: merge the
/// neighbouring pair that saves the most bits while one does). Returns per context its
/// cluster and the clusters' summed counts.
fn cluster(counts: &[[u64; ALPHABET]]) -> (Vec<u8>, Vec<[u64; ALPHABET]>) {
    let mut map = vec![0u8; NCTX];
    let mut out: Vec<[u64; ALPHABET]> = Vec::new();
    for g in 0..GROUPS {
        // Runs: (first class, counts, cost).
        let mut runs: Vec<(usize, [u64; ALPHABET], f64)> = (0..FINE)
            .map(|c| {
                let h = counts[g * FINE + c];
                (c, h, cost(&h))
            })
            .collect();
        loop {
            let mut best: Option<(usize, f64, [u64; ALPHABET], f64)> = None;
            for k in 0..runs.len().saturating_sub(1) {
                let mut m = runs[k].1;
                for (a, b) in m.iter_mut().zip(&runs[k + 1].1) {
                    *a += b;
                }
                let c = cost(&m);
                let gain = runs[k].2 + runs[k + 1].2 - c;
                if gain > 0.0 && best.as_ref().is_none_or(|b| gain > b.1) {
                    best = Some((k, gain, m, c));
                }
            }
            let Some((k, _, m, c)) = best else { break };
            runs[k].1 = m;
            runs[k].2 = c;
            runs.remove(k + 1);
        }
        for (r, run) in runs.iter().enumerate() {
            let end = runs.get(r + 1).map_or(FINE, |n| n.0);
            for c in run.0..end {
                map[g * FINE + c] = out.len() as u8;
            }
            out.push(run.1);
        }
    }
    (map, out)
}

/// Narrower coarse bins pay when bins are wide against the finest level's prediction
/// error: from W ≥ 4σ, σ the RMS of the cubic prediction error of level 1's horizontal
/// pass on the source (where its support is not flat water). (Measured, W/σ: White Mountains 1.5 loses, 5.5 and 17.6 win; Half
/// Dome 0.8 loses, 5.7 and 19 win; Crater Lake 2.8 loses, 10.5 ties, 31 wins.)
const TIGHT_FROM_SIGMAS: f64 = 4.0;
/// … and never below bins of 7 lattice steps, where narrowing rounds coarse bins down to
/// (nearly) lossless ones (Istria at 1 m, W = 3, σ < 0.75: 423 169 bytes plain, 507 837
/// narrowed; Crater Lake at 0.3 %, W = 5: 14 447 against 15 849; Istria at 0.3 %, W = 7:
/// narrowed wins, 188 575 against 194 890).
const TIGHT_FROM_BIN: i64 = 7;

/// `cfg` with `tighten` decided when it is left to the data.
pub fn resolve(p: &Plane, cfg: Config) -> Config {
    if !cfg.tighten_auto {
        return cfg;
    }
    let (w, h) = (p.width, p.height);
    // The horizontal pass of level 1 on rows spread to about 2^15 samples.
    let step = ((h * (w / 2)) >> FIT_SAMPLES_LOG2).max(1);
    let (mut e, mut n) = (0f64, 0f64);
    for y in (0..h).step_by(step) {
        for x in (3..w.saturating_sub(3)).step_by(2) {
            let i = y * w + x;
            // Coded samples only: flat regions (fixed) would make σ small.
            let ok = |j: usize| p.kinds.get(j).is_none_or(|&k| k == CODED);
            if !(ok(i) && ok(i - 3) && ok(i - 1) && ok(i + 1) && ok(i + 3)) {
                continue;
            }
            let v = p.values;
            if v[i - 3] == v[i - 1] && v[i - 1] == v[i + 1] && v[i + 1] == v[i + 3] {
                // Flat water the flat section did not take: it says nothing of the terrain.
                continue;
            }
            let base = (-v[i - 3] + 9 * (v[i - 1] + v[i + 1]) - v[i + 3] + 8) >> 4;
            e += ((v[i] - base) as f64).powi(2);
            n += 1.0;
        }
    }
    let sigma = if n > 0.0 { (e / n).sqrt() } else { 0.0 };
    Config {
        tighten: p.bin as f64 >= TIGHT_FROM_SIGMAS * sigma && p.bin >= TIGHT_FROM_BIN,
        tighten_auto: false,
        ..cfg
    }
}

/// What [`encode`] returns: stencil weights, the coding's bytes, the reconstruction.
pub type Encoded = (Vec<[i16; NW]>, Vec<u8>, Vec<i64>);

/// Encode the plane: the stencil weights (per pass with a correction, coarsest first), the
/// fast coding's bytes (after the section's fixed fields, weights and exceptions) and the
/// reconstruction.
pub fn encode(p: &Plane, cfg: Config) -> Result<Encoded> {
    let (w, h) = (p.width, p.height);
    let n = w * h;
    let mut rec = vec![0i64; n];
    let mut mag = vec![0u8; n];
    let mut streams: Vec<Recorder> = Vec::new();
    // The stencils worth their bytes, fitted on the source before any pass runs; the
    // section stores the finest levels' sets down to the coarsest level using one (zeros
    // for a pass without).
    let mut all = passes(cfg, p.bin);
    let fits: Vec<Option<[i16; NW]>> = all
        .par_iter()
        .map(|&pass| {
            (pass.kind != Kind::Anchor && pass.level() <= cfg.ls_levels)
                .then(|| fit(p, pass))
                .flatten()
        })
        .collect();
    let ls_levels = all
        .iter()
        .zip(&fits)
        .filter(|(_, f)| f.is_some())
        .map(|(pass, _)| pass.level())
        .max()
        .unwrap_or(0);
    let mut weights = Vec::new();
    for (pass, f) in all.iter_mut().zip(fits) {
        if pass.kind != Kind::Anchor && pass.level() <= ls_levels {
            weights.push(f.unwrap_or([0; NW]));
            pass.weights = f;
        }
    }
    let g = Global::new(p);
    for pass in all {
        let bands = pass.bands(w, h, cfg.band_log2);
        streams.extend(run_pass(
            &g,
            pass,
            &bands,
            (&mut rec, &mut mag),
            |_| Ok(Recorder::default()),
            Ok,
        )?);
    }
    // Tables from the counts of every stream.
    let mut counts = vec![[0u64; ALPHABET]; NCTX];
    for s in &streams {
        for (&t, &c) in s.tokens.iter().zip(&s.ctxs) {
            counts[c as usize][t as usize] += 1;
        }
    }
    let (map, clusters) = cluster(&counts);
    let freqs: Vec<Vec<u32>> = clusters.iter().map(|c| rans::normalize(c)).collect();
    let enc: Vec<EncTable> = freqs.iter().map(|f| EncTable::new(f)).collect();
    let mut bits = BitWriter::default();
    for g in 0..GROUPS {
        for c in 1..FINE {
            let k = g * FINE + c;
            bits.put(u64::from(map[k] != map[k - 1]), 1);
        }
    }
    for f in &freqs {
        rans::write_table(&mut bits, f);
    }
    let tables = bits.finish();
    let coded: Vec<(Vec<u8>, Vec<u8>)> = streams
        .into_par_iter()
        .map(|s| {
            let ans = StreamEncoder::encode(
                &enc,
                s.tokens
                    .iter()
                    .zip(&s.ctxs)
                    .map(|(&t, &c)| (map[c as usize] as usize, t)),
            );
            (ans, s.raw.finish())
        })
        .collect();
    let mut out = vec![cfg.band_log2];
    varint::put_u64(&mut out, tables.len() as u64);
    out.extend_from_slice(&tables);
    for (a, r) in &coded {
        varint::put_u64(&mut out, a.len() as u64);
        varint::put_u64(&mut out, r.len() as u64);
    }
    for (a, r) in &coded {
        out.extend_from_slice(a);
        out.extend_from_slice(r);
    }
    Ok((weights, out, rec))
}

/// A varint (LEB128, at most 10 bytes) from the section.
fn read_varint(rd: &mut ByteReader, what: &str) -> Result<u64> {
    let mut v = 0u64;
    for k in 0..10 {
        let b = rd.u8(what)?;
        if k == 9 && b > 1 {
            break;
        }
        v |= ((b & 0x7f) as u64) << (7 * k);
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(rd.corrupt(format!("{what} is not a varint")))
}

/// Decode the plane from the rest of the section (`rd` just after the exceptions).
/// `values` holds the fixed samples' values; `max_bin` bounds a bin's magnitude.
pub fn decode(
    rd: &mut ByteReader,
    p: &Plane,
    levels: u32,
    tighten: bool,
    weights: &[[i16; NW]],
    max_bin: u64,
) -> Result<Vec<i64>> {
    let (w, h) = (p.width, p.height);
    let band_log2 = rd.u8("band size")?;
    if !BAND_LOG2.contains(&band_log2) {
        return Err(rd.corrupt(format!("band size 2^{band_log2} (2^10 ..= 2^30)")));
    }
    let cfg = Config {
        levels,
        ls_levels: weights.len() as u32 / 2,
        tighten,
        tighten_auto: false,
        band_log2,
    };
    let tlen = read_varint(rd, "tables length")?;
    let tbytes = rd.take(usize::try_from(tlen).unwrap_or(usize::MAX), "tables")?;
    let mut br = BitReader::new(tbytes, "tables");
    let mut map = [0usize; NCTX];
    let mut clusters = 0usize;
    for g in 0..GROUPS {
        if g > 0 {
            clusters += 1;
        }
        map[g * FINE] = clusters;
        for c in 1..FINE {
            clusters += br.get(1)? as usize;
            map[g * FINE + c] = clusters;
        }
    }
    let clusters = clusters + 1;
    let mut tables = Vec::with_capacity(clusters);
    for _ in 0..clusters {
        tables.push(rans::read_table(&mut br, ALPHABET)?);
    }
    br.finish()?;
    let dec = DecTables::new(&tables);
    let base: [usize; NCTX] = map.map(|c| c * rans::TOTAL as usize);
    // The streams: lengths first, then the bytes.
    let passes = passes(cfg, p.bin);
    let mut lens = Vec::new();
    for pass in &passes {
        for _ in 0..pass.bands(w, h, band_log2).len() {
            let a = read_varint(rd, "stream length")?;
            let r = read_varint(rd, "stream length")?;
            lens.push((a, r));
        }
    }
    let mut slices = Vec::with_capacity(lens.len());
    for (a, r) in lens {
        let a = rd.take(usize::try_from(a).unwrap_or(usize::MAX), "entropy stream")?;
        let r = rd.take(usize::try_from(r).unwrap_or(usize::MAX), "raw bits")?;
        slices.push((a, r));
    }
    rd.finish()?;
    let n = w * h;
    let mut rec = vec![0i64; n];
    let mut mag = vec![0u8; n];
    let g = Global::new(p);
    let mut next = 0;
    let mut next_w = weights.iter();
    for mut pass in passes {
        if pass.kind != Kind::Anchor && pass.level() <= cfg.ls_levels {
            // All-zero weights correct nothing: the plain prediction (the same values).
            pass.weights = next_w.next().copied().filter(|w| *w != [0; NW]);
        }
        let bands = pass.bands(w, h, band_log2);
        let mine = &slices[next..next + bands.len()];
        next += bands.len();
        run_pass(
            &g,
            pass,
            &bands,
            (&mut rec, &mut mag),
            |b| {
                let (a, r) = mine[b];
                Ok(Reader {
                    ans: StreamDecoder::new(a, &dec)?,
                    raw: BitReader::new(r, "raw bits"),
                    base: &base,
                    max_bin,
                })
            },
            |mut rdr| {
                rdr.ans.finish()?;
                rdr.raw.finish()
            },
        )?;
    }
    Ok(rec)
}

/// `round_div` is the same rounding the interior fast paths write as `(n + 8) >> 4`.
#[cfg(test)]
mod tests {
    use super::super::coder::round_div;
    use super::*;

    #[test]
    fn the_interior_rounding_is_round_div() {
        for n in -1000..1000 {
            assert_eq!((n + 8) >> 4, round_div(n, 16));
        }
    }

    /// A smooth surface with noise, a hole (skipped) and a fixed patch, on a lattice.
    fn plane_data(w: usize, h: usize) -> (Vec<u8>, Vec<i64>) {
        let mut s = 7u64;
        let mut kinds = vec![CODED; w * h];
        let mut values = vec![0i64; w * h];
        for y in 0..h {
            for x in 0..w {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let i = y * w + x;
                let (fx, fy) = (x as f64 / 7.0, y as f64 / 5.0);
                values[i] = (400.0 * fx.sin() * fy.cos() + 30.0 * (fx * fy).sqrt()) as i64
                    + ((s >> 60) as i64 - 8);
                if (x as isize - 20).pow(2) + (y as isize - 15).pow(2) < 40 {
                    kinds[i] = super::super::plane::SKIPPED;
                }
                if (50..58).contains(&x) && (30..40).contains(&y) {
                    kinds[i] = FIXED;
                    values[i] = 77;
                }
            }
        }
        (kinds, values)
    }

    #[test]
    fn bands_round_trip_on_any_thread_count_and_every_prefix_fails() {
        let (w, h) = (97, 83);
        let (kinds, values) = plane_data(w, h);
        for (bin, tighten, ls) in [(1, false, 3), (5, false, 2), (41, true, 3), (301, true, 0)] {
            let p = Plane {
                width: w,
                height: h,
                kinds: &kinds,
                values: &values,
                lo: *values.iter().min().unwrap(),
                hi: *values.iter().max().unwrap(),
                bin,
            };
            let cfg = Config {
                levels: 4,
                ls_levels: ls,
                tighten,
                tighten_auto: false,
                band_log2: 10,
            };
            let (wts, bytes, rec) = encode(&p, cfg).unwrap();
            assert!(wts.len() <= 2 * ls as usize);
            for (i, (&r, &k)) in rec.iter().zip(&kinds).enumerate() {
                if k == CODED {
                    assert!((r - values[i]).abs() <= bin / 2, "bin {bin}: sample {i}");
                } else if k == FIXED {
                    assert_eq!(r, 77);
                }
            }
            let max_bin = (p.hi - p.lo) as u64 / super::super::narrowest_bin(bin, 4, tighten) as u64 + 1;
            for threads in [1, 2, 3] {
                let back = crate::methods::with_threads(threads, || {
                    decode(&mut ByteReader::new(&bytes, "t"), &p, 4, tighten, &wts, max_bin)
                })
                .unwrap();
                assert_eq!(back, rec, "bin {bin}, {threads} threads");
            }
            for cut in (0..bytes.len()).step_by(7) {
                let r = decode(&mut ByteReader::new(&bytes[..cut], "t"), &p, 4, tighten, &wts, max_bin);
                assert!(r.is_err(), "bin {bin}: a prefix of {cut} bytes decoded");
            }
            // One flipped bit in the streams decodes to an error or other samples, never a
            // panic.
            for k in (bytes.len() / 2..bytes.len()).step_by(13) {
                let mut bad = bytes.clone();
                bad[k] ^= 0x10;
                let _ = decode(&mut ByteReader::new(&bad, "t"), &p, 4, tighten, &wts, max_bin);
            }
        }
    }

    #[test]
    fn tokens_cover_every_bin() {
        for v in [0u64, 1, 15, 16, 17, 31, 32, 1000, (1 << 41) - 1] {
            let (t, raw, n) = token(v);
            assert!((t as usize) < ALPHABET);
            let back = if t < 16 {
                t as u64
            } else {
                let e = (t as u64 - 16) / 2 + 4;
                (1 << e) | (((t as u64 - 16) & 1) << (e - 1)) | raw
            };
            assert_eq!(back, v);
            assert!(n < 41);
        }
    }
}
