//! One band of a pass: predict, correct by the stencil, take the context, code or read
//! the token, reconstruct; in place when a pass runs on one thread, into buffers of its
//! own when its bands run side by side.

use crate::predict::med::anchor_med;
use super::passes::{BandBuf, FINE, Kind, NCOARSE, NW, Pass, SymCoder, half_log, scatter};
use super::super::coder::quantize;
use super::super::interp::interp1;
use super::super::plane::{CODED, FIXED, Plane};
use crate::error::Result;
use rayon::prelude::*;

/// What every band reads: the plane and what the earlier passes reconstructed.
pub(super) struct Global<'a> {
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
    pub(super) fn new(p: &Plane<'a>) -> Global<'a> {
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
                    let (p, t) = anchor_med(left, top, tl, tr, mid);
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
/// Run consecutive bands of one pass (all of them, or those a window needs) with a coder
/// each (`make` gives the b-th's, `done` takes it back): on one thread one after the
/// other straight into the planes, else side by side, each into buffers of its own, then
/// written into the planes. The same values either way.
pub(super) fn run_pass<C: SymCoder + Send, T: Send>(
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
    let coded: Vec<(BandBuf<i64>, T)> = {
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
    scatter(g.w, &pass, bands, &bufs, rec, mag);
    Ok(out)
}
