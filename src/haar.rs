//! The Haar section: a 2-D integer Haar (S-transform) pyramid, dead-zone quantized, range
//! coded with per-subband contexts — the wavelet baseline of the Voronoi paper.
//!
//! Samples map to integer codes on a value lattice (the source's code lattice for integer
//! types, step 1 for float data holding integers, a fine lattice for other float data), the
//! codes go through a Mallat pyramid of integer lifting steps (exactly invertible), and
//! the coefficients are quantized with a dead zone and range coded band by band. A
//! `--max-error` bound is met by a closed loop on the quantizer step: the encoder rebuilds
//! every sample exactly as [`decode`] does and checks it against the bound. The byte layout
//! is in spec/FORMAT.md ("Haar section").

use crate::container::Header;
use crate::container::bytes::{ByteReader, PutLe};
use crate::entropy::range::{Bit, Decoder, Encoder, IntModel, UIntModel};
use crate::entropy::varint;
use crate::error::{Error, Result};
use crate::raster::{Raster, SampleType, ValueMapping};

/// Coding 0: S-transform Mallat pyramid, dead-zone quantizer, range-coded bands.
const CODING_PYRAMID: u8 = 0;
/// Quantizer steps are stored in units of 1/16 of a lattice step.
const STEP_UNIT: u64 = 16;
/// Largest step a decoder accepts (in 1/16 units).
const MAX_STEP: u64 = 1 << 52;
/// Largest |lattice code|: keeps every lifting step and quantizer product far from overflow.
const MAX_CODE: f64 = (1u64 << 50) as f64;
/// The encoder adds levels until the LL band is at most this many samples on a side.
const LL_MAX: usize = 32;
/// Non-integer float data gets a lattice of (bound or step) / this.
const LATTICE_DIV: f64 = 16.0;
/// Steps the max-error search tries above its bisection result (up to +25 %).
const SCAN: u64 = 6;

/// Zero-flag contexts per band: neighbourhood class × parent class.
const ZERO_NB: usize = 6;
const ZERO_PARENT: usize = 4;
const ZERO_CTX: usize = ZERO_NB * ZERO_PARENT;
/// Magnitude contexts per band: bit length of |left| + |up| + |parent|, capped.
const MAG_CTX: usize = 8;
/// Sign contexts per band: signs (−, 0, +) of the left, upper and parent coefficients.
const SIGN_CTX: usize = 27;

/// Parameters of the Haar representation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HaarParams {
    /// Max absolute error in data units; 0 means lossless (integer-valued data only).
    pub max_error: f64,
}

// ---------------------------------------------------------------------------------------
// Pyramid geometry and the integer lifting transform
// ---------------------------------------------------------------------------------------

/// Orientation of a band: `LL` (low in both directions), `HL` (high along rows, i.e.
/// horizontal differences), `LH` (high along columns), `HH`.
const LL: usize = 0;
const HL: usize = 1;
const LH: usize = 2;
const HH: usize = 3;

/// One band of the pyramid, a rectangle of the Mallat layout.
#[derive(Clone, Copy, Debug)]
struct Band {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    /// 1 = finest; the LL band has level `levels`.
    level: usize,
    orient: usize,
    /// Index (in [`Pyramid::bands`]) of the same orientation one level coarser.
    parent: Option<usize>,
}

/// Band layout of a `width × height` raster decomposed `levels` times.
#[derive(Clone, Debug)]
struct Pyramid {
    width: usize,
    levels: usize,
    /// `sizes[l]`: size of the LL region after l levels (`sizes[0]` = the raster).
    sizes: Vec<(usize, usize)>,
    /// Coding order: LL, then for level = levels … 1: HL, LH, HH.
    bands: Vec<Band>,
}

/// Levels after which every side is 1 (the most a payload may declare).
fn max_levels(w: usize, h: usize) -> usize {
    let (mut w, mut h, mut l) = (w, h, 0);
    while w > 1 || h > 1 {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
        l += 1;
    }
    l
}

/// The encoder's number of levels: until the LL band is at most [`LL_MAX`] on a side.
fn choose_levels(w: usize, h: usize) -> usize {
    let (mut w, mut h, mut l) = (w, h, 0);
    while w > LL_MAX || h > LL_MAX {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
        l += 1;
    }
    l
}

impl Pyramid {
    fn new(width: usize, height: usize, levels: usize) -> Pyramid {
        let mut sizes = vec![(width, height)];
        for l in 0..levels {
            let (w, h) = sizes[l];
            sizes.push((w.div_ceil(2), h.div_ceil(2)));
        }
        let (lw, lh) = sizes[levels];
        let mut bands = vec![Band {
            x0: 0,
            y0: 0,
            w: lw,
            h: lh,
            level: levels,
            orient: LL,
            parent: None,
        }];
        for level in (1..=levels).rev() {
            let (pw, ph) = sizes[level - 1];
            let (w, h) = sizes[level];
            for orient in [HL, LH, HH] {
                let (x0, bw) = if orient == LH { (0, w) } else { (w, pw - w) };
                let (y0, bh) = if orient == HL { (0, h) } else { (h, ph - h) };
                // The band of this orientation one level up was pushed three entries ago.
                let parent = (level < levels).then(|| bands.len() - 3);
                bands.push(Band {
                    x0,
                    y0,
                    w: bw,
                    h: bh,
                    level,
                    orient,
                    parent,
                });
            }
        }
        Pyramid {
            width,
            levels,
            sizes,
            bands,
        }
    }
}

/// One forward S-transform of a line: pairs (a, b) give d = a − b, s = b + ⌊d/2⌋; the s go
/// to the front, the d to the back; an odd last sample joins the s unchanged.
#[inline]
fn fwd_line(x: &[i64], out: &mut [i64]) {
    let n = x.len();
    let half = n / 2;
    let lo = n - half;
    for i in 0..half {
        let (a, b) = (x[2 * i], x[2 * i + 1]);
        let d = a - b;
        out[i] = b + (d >> 1);
        out[lo + i] = d;
    }
    if n % 2 == 1 {
        out[half] = x[n - 1];
    }
}

/// Inverse of [`fwd_line`], wrapping modulo 2⁶⁴ (garbage input cannot overflow).
#[inline]
fn inv_line(y: &[i64], out: &mut [i64]) {
    let n = y.len();
    let half = n / 2;
    let lo = n - half;
    for i in 0..half {
        let (s, d) = (y[i], y[lo + i]);
        let b = s.wrapping_sub(d >> 1);
        out[2 * i] = b.wrapping_add(d);
        out[2 * i + 1] = b;
    }
    if n % 2 == 1 {
        out[n - 1] = y[half];
    }
}

/// One forward level on the `w × h` top-left region: rows, then columns.
fn fwd_level(a: &mut [i64], stride: usize, w: usize, h: usize, tmp: &mut Vec<i64>) {
    if w >= 2 {
        tmp.resize(w, 0);
        for y in 0..h {
            let row = &mut a[y * stride..][..w];
            tmp.copy_from_slice(row);
            fwd_line(tmp, row);
        }
    }
    if h >= 2 {
        tmp.clear();
        for y in 0..h {
            tmp.extend_from_slice(&a[y * stride..][..w]);
        }
        let half = h / 2;
        let lo = h - half;
        for i in 0..half {
            let (ra, rb) = (&tmp[2 * i * w..][..w], &tmp[(2 * i + 1) * w..][..w]);
            for x in 0..w {
                let d = ra[x] - rb[x];
                a[i * stride + x] = rb[x] + (d >> 1);
                a[(lo + i) * stride + x] = d;
            }
        }
        if h % 2 == 1 {
            a[half * stride..][..w].copy_from_slice(&tmp[(h - 1) * w..][..w]);
        }
    }
}

/// Inverse of [`fwd_level`]: columns, then rows (wrapping arithmetic).
fn inv_level(a: &mut [i64], stride: usize, w: usize, h: usize, tmp: &mut Vec<i64>) {
    if h >= 2 {
        tmp.clear();
        for y in 0..h {
            tmp.extend_from_slice(&a[y * stride..][..w]);
        }
        let half = h / 2;
        let lo = h - half;
        for i in 0..half {
            let (rs, rd) = (&tmp[i * w..][..w], &tmp[(lo + i) * w..][..w]);
            for x in 0..w {
                let b = rs[x].wrapping_sub(rd[x] >> 1);
                a[2 * i * stride + x] = b.wrapping_add(rd[x]);
                a[(2 * i + 1) * stride + x] = b;
            }
        }
        if h % 2 == 1 {
            a[(h - 1) * stride..][..w].copy_from_slice(&tmp[half * w..][..w]);
        }
    }
    if w >= 2 {
        tmp.resize(w, 0);
        for y in 0..h {
            let row = &mut a[y * stride..][..w];
            tmp.copy_from_slice(row);
            inv_line(tmp, row);
        }
    }
}

/// Forward pyramid in place (codes → coefficients in the Mallat layout).
fn forward(a: &mut [i64], pyr: &Pyramid) {
    let mut tmp = Vec::new();
    for l in 0..pyr.levels {
        let (w, h) = pyr.sizes[l];
        fwd_level(a, pyr.width, w, h, &mut tmp);
    }
}

/// Inverse pyramid in place (coefficients → codes).
fn inverse(a: &mut [i64], pyr: &Pyramid) {
    inverse_down_to(a, pyr, 0);
}

/// Invert the levels coarser than `stop` (levels `levels` … `stop + 1`).
fn inverse_down_to(a: &mut [i64], pyr: &Pyramid, stop: usize) {
    let mut tmp = Vec::new();
    for l in (stop..pyr.levels).rev() {
        let (w, h) = pyr.sizes[l];
        inv_level(a, pyr.width, w, h, &mut tmp);
    }
}

/// One S-transform pair inverted: (s, d) → (b + d, b) with b = s − ⌊d/2⌋; a lone s (odd
/// end) passes through.
#[inline]
fn inv_pair(s: i64, d: Option<i64>) -> (i64, Option<i64>) {
    match d {
        Some(d) => {
            let b = s.wrapping_sub(d >> 1);
            (b.wrapping_add(d), Some(b))
        }
        None => (s, None),
    }
}

/// The finest level's inverse restricted to one block: the level-1 LL value `s` and the
/// block's HL, LH, HH coefficients (absent at odd edges) give its up to 2×2 codes, exactly
/// as [`inv_level`] does (columns, then rows). `[row][col]`.
#[inline]
fn inv_block(s: i64, hl: Option<i64>, lh: Option<i64>, hh: Option<i64>) -> [[Option<i64>; 2]; 2] {
    let (l_top, l_bot) = inv_pair(s, lh);
    let h = hl.map(|hl| inv_pair(hl, hh));
    let (a, b) = inv_pair(l_top, h.map(|h| h.0));
    let bottom = l_bot.map(|lb| inv_pair(lb, h.and_then(|h| h.1)));
    [
        [Some(a), b],
        [bottom.map(|p| p.0), bottom.and_then(|p| p.1)],
    ]
}

// ---------------------------------------------------------------------------------------
// Quantization
// ---------------------------------------------------------------------------------------

/// Dead-zone quantizer of a detail coefficient with step n/16: sign(c)·⌊16|c|/n⌋.
#[inline]
fn quant_detail(c: i64, n: u64) -> i64 {
    // |c| ≤ 2^53 in the encoder, so 16|c| fits.
    let m = (c.unsigned_abs() * STEP_UNIT / n) as i64;
    if c < 0 { -m } else { m }
}

/// [`quant_detail`] with a rounding offset: sign(c)·⌊16|c|/n + round/256⌋ (encoder only).
#[inline]
fn quant_detail_round(c: i64, n: u64, round: u8) -> i64 {
    // |c| ≤ 2^53, so 4096|c| fits; the rest only overflows for absurd steps.
    let m = match (round as u64)
        .checked_mul(n)
        .and_then(|r| r.checked_add(c.unsigned_abs() << 12))
    {
        Some(num) if n < 1 << 56 => (num / (n << 8)) as i64,
        _ => {
            let num = c.unsigned_abs() as u128 * 4096 + round as u128 * n as u128;
            (num / (256 * n as u128)) as i64
        }
    };
    if c < 0 { -m } else { m }
}

/// Reconstruction of a detail coefficient: sign(q)·⌊(|q| + b/256)·n/16⌋ (0 for q = 0).
#[inline]
fn dequant_detail(q: i64, n: u64, bias: u8) -> i64 {
    if q == 0 {
        return 0;
    }
    let m = match (q.unsigned_abs().checked_mul(256)).and_then(|x| (x + bias as u64).checked_mul(n))
    {
        Some(x) => (x / 4096).min(i64::MAX as u64) as i64,
        None => {
            let num = q.unsigned_abs() as u128 * 256 + bias as u128;
            (num * n as u128 / 4096).min(i64::MAX as u128) as i64
        }
    };
    if q < 0 { -m } else { m }
}

/// Uniform (mid-tread) quantizer of an LL coefficient: ⌊(32c + n) / 2n⌋.
#[inline]
fn quant_ll(c: i64, n: u64) -> i64 {
    (32 * c as i128 + n as i128).div_euclid(2 * n as i128) as i64
}

/// Reconstruction of an LL coefficient: ⌊(2qn + 16) / 32⌋, saturated to i64.
#[inline]
fn dequant_ll(q: i64, n: u64) -> i64 {
    (2 * q as i128 * n as i128 + 16)
        .div_euclid(32)
        .clamp(i64::MIN as i128, i64::MAX as i128) as i64
}

/// Quantize every band of `coefs` into `q` (same layout); `round` (in 1/256) shrinks the
/// dead zone and moves every decision threshold down (encoder only).
fn quantize(coefs: &[i64], pyr: &Pyramid, steps: &[u64], round: u8, q: &mut [i64]) {
    for (b, &n) in pyr.bands.iter().zip(steps) {
        for y in b.y0..b.y0 + b.h {
            let row = y * pyr.width + b.x0..y * pyr.width + b.x0 + b.w;
            let (src, dst) = (&coefs[row.clone()], &mut q[row]);
            if b.orient == LL {
                dst.iter_mut()
                    .zip(src)
                    .for_each(|(d, &c)| *d = quant_ll(c, n));
            } else if n == STEP_UNIT {
                dst.copy_from_slice(src);
            } else if round == 0 {
                dst.iter_mut()
                    .zip(src)
                    .for_each(|(d, &c)| *d = quant_detail(c, n));
            } else {
                dst.iter_mut()
                    .zip(src)
                    .for_each(|(d, &c)| *d = quant_detail_round(c, n, round));
            }
        }
    }
}

/// Dequantize `q` in place and run the inverse pyramid: the lattice codes the decoder
/// outputs. Shared by the encoder's closed loop and [`decode`].
fn reconstruct(q: &mut [i64], pyr: &Pyramid, steps: &[u64], bias: u8) {
    dequantize(q, pyr, steps, bias);
    inverse(q, pyr);
}

/// Replace every quantized coefficient by its reconstruction.
fn dequantize(q: &mut [i64], pyr: &Pyramid, steps: &[u64], bias: u8) {
    for (b, &n) in pyr.bands.iter().zip(steps) {
        for y in b.y0..b.y0 + b.h {
            let row = &mut q[y * pyr.width + b.x0..][..b.w];
            if b.orient == LL {
                row.iter_mut().for_each(|v| *v = dequant_ll(*v, n));
            } else {
                row.iter_mut()
                    .for_each(|v| *v = dequant_detail(*v, n, bias));
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Value lattice
// ---------------------------------------------------------------------------------------

/// How a lattice code becomes an output sample (identical in encoder and decoder).
#[derive(Clone, Copy, Debug)]
struct Lattice {
    step: f64,
    offset: f64,
    out: Output,
}

#[derive(Clone, Copy, Debug)]
enum Output {
    F64,
    F32,
    /// Rounded to the nearest source code, clamped to the type's range.
    Int {
        mapping: ValueMapping,
        lo: f64,
        hi: f64,
    },
}

impl Output {
    fn new(st: SampleType, mapping: ValueMapping) -> Output {
        match st.int_range() {
            Some((lo, hi)) => Output::Int { mapping, lo, hi },
            None if st == SampleType::F32 => Output::F32,
            None => Output::F64,
        }
    }
}

impl Lattice {
    #[inline]
    fn value(&self, code: i64) -> Option<f64> {
        let v = self.offset + self.step * code as f64;
        if !v.is_finite() {
            return None;
        }
        let v = match self.out {
            Output::F64 => v,
            Output::F32 => v as f32 as f64,
            Output::Int { mapping, lo, hi } => {
                let c = ((v - mapping.offset) / mapping.scale).round().clamp(lo, hi);
                mapping.offset + mapping.scale * c
            }
        };
        v.is_finite().then_some(v)
    }
}

// ---------------------------------------------------------------------------------------
// Entropy coding (one generic walk for both directions)
// ---------------------------------------------------------------------------------------

/// The range coder seen from the coefficient walk: the encoder codes the value it is given
/// and returns it, the decoder ignores it and returns what it decodes.
trait Io {
    fn bit(&mut self, ctx: &mut Bit, v: bool) -> bool;
    fn uint(&mut self, m: &mut UIntModel, v: u64) -> Result<u64>;
    fn int(&mut self, m: &mut IntModel, v: i64) -> Result<i64>;
    fn check(&self) -> Result<()>;
}

impl Io for Encoder {
    #[inline]
    fn bit(&mut self, ctx: &mut Bit, v: bool) -> bool {
        self.encode(ctx, v);
        v
    }
    #[inline]
    fn uint(&mut self, m: &mut UIntModel, v: u64) -> Result<u64> {
        m.encode(self, v);
        Ok(v)
    }
    #[inline]
    fn int(&mut self, m: &mut IntModel, v: i64) -> Result<i64> {
        m.encode(self, v);
        Ok(v)
    }
    fn check(&self) -> Result<()> {
        Ok(())
    }
}

impl Io for Decoder<'_> {
    #[inline]
    fn bit(&mut self, ctx: &mut Bit, _: bool) -> bool {
        self.decode(ctx)
    }
    #[inline]
    fn uint(&mut self, m: &mut UIntModel, _: u64) -> Result<u64> {
        m.decode(self)
    }
    #[inline]
    fn int(&mut self, m: &mut IntModel, _: i64) -> Result<i64> {
        m.decode(self)
    }
    fn check(&self) -> Result<()> {
        self.check_in_bounds()
    }
}

/// Adaptive models of one detail band.
struct BandModels {
    any: Bit,
    zero: [Bit; ZERO_CTX],
    sign: [Bit; SIGN_CTX],
    mag: Vec<UIntModel>,
}

impl BandModels {
    fn new() -> Self {
        BandModels {
            any: Bit::default(),
            zero: [Bit::default(); ZERO_CTX],
            sign: [Bit::default(); SIGN_CTX],
            mag: (0..MAG_CTX).map(|_| UIntModel::new()).collect(),
        }
    }
}

#[inline]
fn sign3(v: i64) -> usize {
    (v.signum() + 1) as usize
}

/// Neighbourhood class of the zero flag from a weighted magnitude sum.
#[inline]
fn zero_class(s: u64) -> usize {
    match s {
        0 => 0,
        1..=2 => 1,
        3..=4 => 2,
        5..=8 => 3,
        9..=20 => 4,
        _ => 5,
    }
}

/// Code (encoder) or decode (decoder) every quantized coefficient of `q` (Mallat layout;
/// all zero on entry when decoding). The walk, contexts and models are spec/FORMAT.md's
/// "Haar section"; sharing one walk keeps encoder and decoder in step by construction.
fn code_bands<I: Io>(io: &mut I, q: &mut [i64], pyr: &Pyramid) -> Result<()> {
    let stride = pyr.width;
    // LL band: MED prediction from the left, upper and upper-left codes, one Int model.
    let ll = pyr.bands[0];
    let mut ll_model = IntModel::new();
    for y in 0..ll.h {
        for x in 0..ll.w {
            let i = y * stride + x;
            let p = match (x, y) {
                (0, 0) => 0,
                (_, 0) => q[i - 1],
                (0, _) => q[i - stride],
                _ => med(q[i - 1], q[i - stride], q[i - stride - 1]),
            };
            let r = io.int(&mut ll_model, q[i].wrapping_sub(p))?;
            q[i] = p.wrapping_add(r);
        }
        io.check()?;
    }
    for (k, b) in pyr.bands.iter().enumerate().skip(1) {
        if b.w == 0 || b.h == 0 {
            continue;
        }
        let mut m = BandModels::new();
        // The decoder's q is all zero here, so its `nonzero` is meaningless and ignored.
        let nonzero =
            (b.y0..b.y0 + b.h).any(|y| q[y * stride + b.x0..][..b.w].iter().any(|&v| v != 0));
        if !io.bit(&mut m.any, nonzero) {
            continue;
        }
        let parent = b
            .parent
            .map(|p| pyr.bands[p])
            .filter(|p| p.w > 0 && p.h > 0);
        // The other orientations of this level coded before this band (HL for LH; HL and
        // LH for HH).
        let cross: Vec<Band> = pyr.bands[k + 1 - b.orient..k]
            .iter()
            .copied()
            .filter(|c| c.w > 0 && c.h > 0)
            .collect();
        for y in 0..b.h {
            let row = (b.y0 + y) * stride + b.x0;
            for x in 0..b.w {
                let i = row + x;
                let left = if x > 0 { q[i - 1] } else { 0 };
                let (up, ul, ur) = if y > 0 {
                    let u = i - stride;
                    (
                        q[u],
                        if x > 0 { q[u - 1] } else { 0 },
                        if x + 1 < b.w { q[u + 1] } else { 0 },
                    )
                } else {
                    (0, 0, 0)
                };
                let par = match parent {
                    Some(p) => {
                        let px = (x / 2).min(p.w - 1);
                        let py = (y / 2).min(p.h - 1);
                        q[(p.y0 + py) * stride + p.x0 + px]
                    }
                    None => 0,
                };
                let mut nb = left.unsigned_abs().saturating_mul(2);
                nb = nb.saturating_add(up.unsigned_abs().saturating_mul(2));
                nb = nb.saturating_add(ul.unsigned_abs());
                nb = nb.saturating_add(ur.unsigned_abs());
                for c in &cross {
                    let (cx, cy) = (x.min(c.w - 1), y.min(c.h - 1));
                    nb = nb.saturating_add(q[(c.y0 + cy) * stride + c.x0 + cx].unsigned_abs());
                }
                let pa = par.unsigned_abs();
                let zc = zero_class(nb) * ZERO_PARENT + pa.min(ZERO_PARENT as u64 - 1) as usize;
                let v = q[i];
                if !io.bit(&mut m.zero[zc], v != 0) {
                    q[i] = 0;
                    continue;
                }
                let sc = (sign3(left) * 3 + sign3(up)) * 3 + sign3(par);
                let negative = io.bit(&mut m.sign[sc], v < 0);
                let act = left
                    .unsigned_abs()
                    .saturating_add(up.unsigned_abs())
                    .saturating_add(pa);
                let mc = ((64 - act.leading_zeros()) as usize).min(MAG_CTX - 1);
                let mag = io.uint(&mut m.mag[mc], v.unsigned_abs().wrapping_sub(1))?;
                let mag = i64::try_from(mag)
                    .ok()
                    .and_then(|m| m.checked_add(1))
                    .ok_or_else(|| Error::corrupt("haar section: coefficient out of range"))?;
                q[i] = if negative { -mag } else { mag };
            }
            io.check()?;
        }
    }
    Ok(())
}

use crate::grid::med;

// ---------------------------------------------------------------------------------------
// Encoder
// ---------------------------------------------------------------------------------------

/// How the encoder derives per-band steps from one base step (informative: the steps are
/// stored, a decoder never needs this).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Profile {
    /// Step of level k+1 relative to level k (0.5 = equal steps in orthonormal terms).
    ratio: f64,
    /// Step of HH relative to HL/LH on the same level (2 = equal in orthonormal terms).
    hh: f64,
    /// Step of the LL band relative to the coarsest HL/LH step.
    ll: f64,
    /// Reconstruction bias in 1/256 (δ = bias/256).
    bias: u8,
    /// Band steps below this (in lattice steps) become 1 (lossless band).
    snap: f64,
    /// Quantizer rounding offset in 1/256 (0 = plain dead zone).
    round: u8,
    /// Finest-level repair radius for a max-error bound (0 = none): each 2×2 block with a
    /// sample over the bound tries its three detail codes within ± this.
    repair: i64,
}

/// The profile of [`encode_step`], tuned for RMSE at a given rate on crater: the same step
/// for every band in orthonormal terms (S-transform steps halve per level, HH doubles),
/// midpoint reconstruction.
const MSE_PROFILE: Profile = Profile {
    ratio: 0.5,
    hh: 2.0,
    ll: 1.0,
    bias: 128,
    snap: 1.5,
    round: 0,
    repair: 0,
};

/// All steps 1: lossless on the lattice.
const LOSSLESS_PROFILE: Profile = Profile {
    ratio: 1.0,
    hh: 1.0,
    ll: 1.0,
    bias: 0,
    snap: 1.0,
    round: 0,
    repair: 0,
};

/// Profiles [`encode`] tries for a max-error bound; it keeps the smallest payload. The max
/// error is a noisy function of the steps, so a few spread-out profiles beat any one (on
/// crater each is best at some bound).
const LINF_PROFILES: &[Profile] = &[
    Profile {
        ratio: 0.5,
        hh: 1.5,
        ll: 1.0,
        bias: 96,
        snap: 1.5,
        round: 32,
        repair: 1,
    },
    Profile {
        ratio: 0.6,
        hh: 1.5,
        ll: 1.0,
        bias: 96,
        snap: 1.5,
        round: 32,
        repair: 1,
    },
    Profile {
        ratio: 0.85,
        hh: 1.5,
        ll: 1.0,
        bias: 128,
        snap: 1.5,
        round: 0,
        repair: 1,
    },
];

/// Per-band steps (1/16 units) for base step `base` (1/16 units, the finest HL/LH step).
fn profile_steps(pyr: &Pyramid, base: u64, p: &Profile) -> Vec<u64> {
    let clamp = |s: f64| {
        if s < p.snap * STEP_UNIT as f64 {
            STEP_UNIT
        } else {
            (s.round() as u64).clamp(STEP_UNIT, MAX_STEP)
        }
    };
    pyr.bands
        .iter()
        .map(|b| {
            let f = p.ratio.powi(b.level.max(1) as i32 - 1);
            let f = match b.orient {
                LL => f * p.ll,
                HH => f * p.hh,
                _ => f,
            };
            clamp(base as f64 * f)
        })
        .collect()
}

/// Everything the encoder derives from the raster once: lattice codes and coefficients.
struct Prepared<'a> {
    r: &'a Raster,
    lattice: Lattice,
    pyr: Pyramid,
    coefs: Vec<i64>,
}

/// Map samples to lattice codes (nodata filled smoothly), then transform.
fn prepare(r: &Raster, step: f64, offset: f64, levels: usize) -> Result<Prepared<'_>> {
    let lattice = Lattice {
        step,
        offset,
        out: Output::new(r.sample_type, r.mapping),
    };
    let (w, h) = (r.width, r.height);
    let mut codes = vec![0i64; r.len()];
    for (i, &v) in r.data.iter().enumerate() {
        if r.is_valid(i) {
            let c = ((v - offset) / step).round();
            if c.is_nan() || c.abs() > MAX_CODE {
                return Err(Error::invalid(format!(
                    "haar: sample {v} is more than 2^50 lattice steps of {step} from {offset} \
                     (the bound is too small for this value range; use the grid method)"
                )));
            }
            codes[i] = c as i64;
        }
    }
    if let Some(m) = &r.mask {
        crate::raster::fill_invalid(&mut codes, m, w, h, |a, b, i, len| {
            (a as i128 + (b as i128 - a as i128) * i as i128 / len as i128) as i64
        });
    }
    let pyr = Pyramid::new(w, h, levels);
    forward(&mut codes, &pyr);
    Ok(Prepared {
        r,
        lattice,
        pyr,
        coefs: codes,
    })
}

/// Scratch buffers of the closed loop.
struct Trial {
    q: Vec<i64>,
    rec: Vec<i64>,
    /// Level-1 blocks to repair (index by · w₁ + bx).
    bad: Vec<usize>,
}

impl Prepared<'_> {
    /// For every sample, the codes whose output is within `e` of it (an interval, since a
    /// code's output value is monotone in the code); everything for invalid samples.
    /// Conservative: never wider than `e` / lattice step + 2 codes each way. Err when the
    /// lattice itself cannot meet `e`.
    fn intervals(&self, e: f64) -> Result<Vec<(i64, i64)>> {
        let (lat, r) = (&self.lattice, self.r);
        let reach = ((e / lat.step).ceil() + 2.0).min(MAX_CODE) as i64;
        let mut iv = vec![(i64::MIN, i64::MAX); r.len()];
        for (i, (&v, slot)) in r.data.iter().zip(iv.iter_mut()).enumerate() {
            if !r.is_valid(i) {
                continue;
            }
            let ok = |k: i64| lat.value(k).is_some_and(|x| (x - v).abs() <= e);
            let k0 = ((v - lat.offset) / lat.step).round() as i64;
            let Some(k) = [k0, k0 - 1, k0 + 1].into_iter().find(|&k| ok(k)) else {
                return Err(Error::invalid(format!(
                    "haar: the value lattice (step {}) alone breaks the max error {e}",
                    lat.step
                )));
            };
            // Start from the exact-arithmetic ends and step to the true ones (a step or two).
            let est = |x: f64| ((x - lat.offset) / lat.step).clamp(-MAX_CODE, MAX_CODE);
            let mut lo = (est(v - e).ceil() as i64).clamp(k - reach, k);
            let mut hi = (est(v + e).floor() as i64).clamp(k, k + reach);
            while lo < k && !ok(lo) {
                lo += 1;
            }
            while lo > k - reach && ok(lo - 1) {
                lo -= 1;
            }
            while hi > k && !ok(hi) {
                hi -= 1;
            }
            while hi < k + reach && ok(hi + 1) {
                hi += 1;
            }
            *slot = (lo, hi);
        }
        Ok(iv)
    }

    /// Quantize with `steps` into `t.q`, rebuild into `t.rec` as the decoder will, and say
    /// whether every code lies in its interval; if not and the profile says so, repair the
    /// finest level where it failed, rebuild and check again.
    fn trial(&self, steps: &[u64], prof: &Profile, iv: &[(i64, i64)], t: &mut Trial) -> bool {
        self.rebuild(steps, prof, t);
        let inside = |(&c, &(lo, hi)): (&i64, &(i64, i64))| lo <= c && c <= hi;
        if t.rec.iter().zip(iv).all(inside) {
            return true;
        }
        if prof.repair == 0 || self.pyr.levels == 0 {
            return false;
        }
        // The level-1 blocks (2×2 samples) holding a sample outside its interval.
        let (w, w1) = (self.pyr.width, self.pyr.sizes[1].0);
        t.bad.clear();
        for (i, p) in t.rec.iter().zip(iv).enumerate() {
            if !inside(p) {
                t.bad.push((i / w / 2) * w1 + (i % w) / 2);
            }
        }
        t.bad.dedup();
        t.bad.sort_unstable();
        t.bad.dedup();
        self.repair(steps, prof, iv, t);
        t.rec.clone_from(&t.q);
        reconstruct(&mut t.rec, &self.pyr, steps, prof.bias);
        t.rec.iter().zip(iv).all(inside)
    }

    /// Quantize and reconstruct (no check, no repair).
    fn rebuild(&self, steps: &[u64], prof: &Profile, t: &mut Trial) {
        quantize(&self.coefs, &self.pyr, steps, prof.round, &mut t.q);
        t.rec.clone_from(&t.q);
        reconstruct(&mut t.rec, &self.pyr, steps, prof.bias);
    }

    /// Max error of the reconstruction `rec` over the valid samples (None if a value is
    /// not finite).
    fn max_error(&self, rec: &[i64]) -> Option<f64> {
        let mut max = 0f64;
        for (i, (&c, &v)) in rec.iter().zip(&self.r.data).enumerate() {
            if self.r.is_valid(i) {
                max = max.max((self.lattice.value(c)? - v).abs());
            }
        }
        Some(max)
    }

    /// Change the finest-level codes of every block listed in `t.bad` (blocks with a sample
    /// outside its interval) to the nearby codes (± `prof.repair`) with the smallest magnitudes that bring all its
    /// samples inside, if any. The finest inverse is local to a block, so this is exact
    /// given the coarser levels; [`Self::trial`] still checks the full reconstruction.
    fn repair(&self, steps: &[u64], prof: &Profile, iv: &[(i64, i64)], t: &mut Trial) {
        let pyr = &self.pyr;
        let stride = pyr.width;
        // The coarser levels as the decoder rebuilds them: the level-1 LL values.
        t.rec.clone_from(&t.q);
        dequantize(&mut t.rec, pyr, steps, prof.bias);
        inverse_down_to(&mut t.rec, pyr, 1);
        let (w, h) = pyr.sizes[0];
        let (w1, h1) = pyr.sizes[1];
        let nb = steps.len();
        let (n_hl, n_lh, n_hh) = (steps[nb - 3], steps[nb - 2], steps[nb - 1]);
        let bias = prof.bias;
        // Whether a block's samples are all inside their intervals for given detail codes.
        let block_ok = |bx: usize, by: usize, s: i64, c: [Option<i64>; 3]| -> bool {
            let deq = |q: Option<i64>, n: u64| q.map(|q| dequant_detail(q, n, bias));
            let codes = inv_block(s, deq(c[0], n_hl), deq(c[1], n_lh), deq(c[2], n_hh));
            codes.iter().enumerate().all(|(dy, row)| {
                row.iter().enumerate().all(|(dx, &code)| {
                    code.is_none_or(|code| {
                        let (lo, hi) = iv[(2 * by + dy) * stride + 2 * bx + dx];
                        lo <= code && code <= hi
                    })
                })
            })
        };
        let rad = prof.repair;
        for &blk in &t.bad {
            let (by, bx) = (blk / w1, blk % w1);
            let (has_h, has_v) = (bx < w / 2, by < h / 2);
            let idx = [
                has_h.then_some(by * stride + w1 + bx),
                has_v.then_some((h1 + by) * stride + bx),
                (has_h && has_v).then_some((h1 + by) * stride + w1 + bx),
            ];
            let cur = idx.map(|i| i.map(|i| t.q[i]));
            let s = t.rec[by * stride + bx];
            if block_ok(bx, by, s, cur) {
                continue;
            }
            let range = |c: Option<i64>| match c {
                Some(c) => (c - rad, c + rad),
                None => (0, 0),
            };
            let ((a0, a1), (b0, b1), (c0, c1)) = (range(cur[0]), range(cur[1]), range(cur[2]));
            // Smallest total magnitude; among equals, the first in this order.
            let mut best: Option<(u64, [Option<i64>; 3])> = None;
            for a in a0..=a1 {
                for b in b0..=b1 {
                    for c in c0..=c1 {
                        let cand = [cur[0].map(|_| a), cur[1].map(|_| b), cur[2].map(|_| c)];
                        let cost: u64 = cand.iter().flatten().map(|v| v.unsigned_abs()).sum();
                        if best.is_none_or(|b| cost < b.0) && block_ok(bx, by, s, cand) {
                            best = Some((cost, cand));
                        }
                    }
                }
            }
            if let Some((_, cand)) = best {
                for (i, c) in idx.iter().zip(cand) {
                    if let (Some(i), Some(c)) = (i, c) {
                        t.q[*i] = c;
                    }
                }
            }
        }
    }

    /// The payload for quantized coefficients `q` (the closed loop's last trial).
    fn payload(&self, q: &[i64], steps: &[u64], bias: u8, bound: f64) -> Vec<u8> {
        let mut out = Vec::new();
        out.put_u8(CODING_PYRAMID);
        out.put_u8(0);
        out.put_u8(self.pyr.levels as u8);
        out.put_u8(bias);
        out.put_f64(self.lattice.step);
        out.put_f64(self.lattice.offset);
        out.put_f64(bound);
        for &s in steps {
            varint::put_u64(&mut out, s);
        }
        let mut enc = Encoder::with_capacity(q.len() / 8);
        let mut q = q.to_vec();
        code_bands(&mut enc, &mut q, &self.pyr).expect("encoding cannot fail");
        out.extend_from_slice(&enc.finish());
        out
    }

    /// Check in debug builds that [`decode`] gives exactly what the closed loop measured.
    fn debug_check(&self, payload: &[u8], rec: &[i64]) {
        if cfg!(debug_assertions) {
            let r = self.r;
            let header = Header::of(r).expect("the raster being encoded");
            let back = decode(payload, &header, r.mask.as_deref()).expect("own payload decodes");
            for (i, (&b, &c)) in back.iter().zip(rec).enumerate() {
                if r.is_valid(i) {
                    assert_eq!(b.to_bits(), self.lattice.value(c).unwrap().to_bits());
                }
            }
        }
    }
}

/// The lattice for `r`: (step, offset), exact for integer types and integer-valued floats;
/// `fine` (the step for non-integer float data) when given, else an error.
fn choose_lattice(r: &Raster, fine: Option<f64>) -> Result<(f64, f64)> {
    if r.sample_type.is_integer() {
        return Ok((r.mapping.scale.abs(), r.mapping.offset));
    }
    let integral = r
        .data
        .iter()
        .enumerate()
        .all(|(i, &v)| !r.is_valid(i) || (v.round() == v && v.abs() <= MAX_CODE));
    if integral {
        return Ok((1.0, 0.0));
    }
    match fine {
        Some(u) if u > 0.0 && u.is_finite() => Ok((u, r.valid_range().map_or(0.0, |(lo, _)| lo))),
        _ => Err(Error::invalid(
            "the haar method is lossless only on integer-valued data; give a max error \
             or use the grid method for lossless float data",
        )),
    }
}

/// Encode `r` as a Haar-section payload meeting `p.max_error`. Returns the payload and the
/// max error it guarantees (measured over every valid sample, ≤ `p.max_error`).
pub fn encode(r: &Raster, p: &HaarParams) -> Result<(Vec<u8>, f64)> {
    let e = p.max_error;
    if !(e >= 0.0 && e.is_finite()) {
        return Err(Error::invalid(format!(
            "max error {e} must be a finite number ≥ 0"
        )));
    }
    let (u, off) = choose_lattice(r, (e > 0.0).then_some(e / LATTICE_DIV))?;
    let prep = prepare(r, u, off, choose_levels(r.width, r.height))?;
    let (payload, err, rec) = encode_bound(&prep, e, LINF_PROFILES)?;
    prep.debug_check(&payload, &rec);
    Ok((payload, err))
}

/// The closed loop of [`encode`]: for each profile, the largest base step whose
/// reconstruction meets `e` on every valid sample; the smallest payload wins. Returns the
/// payload, its max error and its reconstructed lattice codes.
fn encode_bound(prep: &Prepared, e: f64, profiles: &[Profile]) -> Result<(Vec<u8>, f64, Vec<i64>)> {
    let iv = prep.intervals(e)?;
    let mut t = Trial {
        q: vec![0; prep.coefs.len()],
        rec: vec![0; prep.coefs.len()],
        bad: Vec::new(),
    };
    let mut best: Option<(Vec<u8>, Vec<i64>)> = None;
    let mut prev: Option<u64> = None;
    if e > 0.0 {
        for prof in profiles {
            // Largest base step that passes: double, then bisect to 1/128.
            let pass = |n: u64, t: &mut Trial| {
                prep.trial(&profile_steps(&prep.pyr, n, prof), prof, &iv, t)
            };
            // Start near the previous profile's step (they land within 2× of each other).
            let start = match prev {
                Some(p) if p / 2 > STEP_UNIT && pass(p / 2, &mut t) => p / 2,
                _ if pass(STEP_UNIT, &mut t) => STEP_UNIT,
                _ => continue,
            };
            let (mut lo, mut hi) = (start, 2 * start);
            while hi < MAX_STEP && pass(hi, &mut t) {
                lo = hi;
                hi *= 2;
            }
            while hi - lo > (lo / 128).max(1) {
                let mid = lo + (hi - lo) / 2;
                if pass(mid, &mut t) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            // The max error is not monotone in the step: look a little further up.
            let top = lo + lo / 4;
            for k in 1..=SCAN {
                let n = lo + (top - lo) * k / SCAN;
                if n > lo && pass(n, &mut t) {
                    lo = n;
                }
            }
            prev = Some(lo);
            let steps = profile_steps(&prep.pyr, lo, prof);
            let passed = pass(lo, &mut t); // rebuild the winner into `t`
            debug_assert!(passed);
            let err = prep.max_error(&t.rec).unwrap_or(f64::INFINITY);
            let payload = prep.payload(&t.q, &steps, prof.bias, err);
            if best.as_ref().is_none_or(|b| payload.len() < b.0.len()) {
                best = Some((payload, t.rec.clone()));
            }
        }
    }
    let (payload, rec) = match best {
        Some(b) => b,
        None => {
            // Every step 1: lossless on the lattice, within `e` (the intervals say so).
            let lossless = vec![STEP_UNIT; prep.pyr.bands.len()];
            let passed = prep.trial(&lossless, &LOSSLESS_PROFILE, &iv, &mut t);
            debug_assert!(passed);
            let err = prep.max_error(&t.rec).unwrap_or(f64::INFINITY);
            (prep.payload(&t.q, &lossless, 0, err), t.rec.clone())
        }
    };
    let err = prep.max_error(&rec).unwrap_or(f64::INFINITY);
    if err.is_nan() || err > e {
        // Cannot happen: every code was checked against its interval.
        return Err(Error::invalid(format!(
            "haar: the closed loop measured {err} over the bound {e}"
        )));
    }
    Ok((payload, err, rec))
}

/// Encode with a fixed coefficient quantization step (rate control by bisection). Returns the
/// payload and the max error it achieves.
///
/// `step` is in data units: the dead-zone step of the finest HL/LH bands (the step of an
/// orthonormal Haar transform's coefficients, all bands alike); coarser bands get the
/// matching S-transform steps, never below one lattice step.
pub fn encode_step(r: &Raster, step: f64) -> Result<(Vec<u8>, f64)> {
    if !(step > 0.0 && step.is_finite()) {
        return Err(Error::invalid(format!(
            "haar quantizer step {step} must be a finite number > 0"
        )));
    }
    encode_step_with(r, step, &MSE_PROFILE)
}

fn encode_step_with(r: &Raster, step: f64, prof: &Profile) -> Result<(Vec<u8>, f64)> {
    let (u, off) = choose_lattice(r, Some(step / LATTICE_DIV))?;
    let prep = prepare(r, u, off, choose_levels(r.width, r.height))?;
    let mut t = Trial {
        q: vec![0; r.len()],
        rec: vec![0; r.len()],
        bad: Vec::new(),
    };
    let base = (step / u * STEP_UNIT as f64).clamp(STEP_UNIT as f64, MAX_STEP as f64) as u64;
    let steps = profile_steps(&prep.pyr, base, prof);
    prep.rebuild(&steps, prof, &mut t);
    let err = prep
        .max_error(&t.rec)
        .ok_or_else(|| Error::invalid("haar: a reconstruction is not finite"))?;
    let payload = prep.payload(&t.q, &steps, prof.bias, err);
    prep.debug_check(&payload, &t.rec);
    Ok((payload, err))
}

// ---------------------------------------------------------------------------------------
// Decoder
// ---------------------------------------------------------------------------------------

fn read_varint(r: &mut ByteReader, field: &str) -> Result<u64> {
    let mut v = 0u64;
    for k in 0..10 {
        let b = r.u8(field)?;
        if k == 9 && b > 1 {
            return Err(r.corrupt(format!("{field} overflows")));
        }
        v |= ((b & 0x7f) as u64) << (7 * k);
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(r.corrupt(format!("{field} overflows")))
}

/// A Haar payload's pyramid levels and value-lattice step (for `vtz info`); checks only
/// those two fields.
pub fn describe(payload: &[u8]) -> Result<(usize, f64)> {
    let mut r = ByteReader::new(payload, "haar section");
    r.take(2, "coding and flags")?;
    let levels = r.u8("levels")? as usize;
    r.u8("bias")?;
    Ok((levels, r.finite_f64("lattice step")?))
}

/// Decode a Haar-section payload (invalid samples get the nodata fill).
pub fn decode(payload: &[u8], header: &Header, mask: Option<&[bool]>) -> Result<Vec<f64>> {
    let mut r = ByteReader::new(payload, "haar section");
    let coding = r.u8("coding")?;
    if coding != CODING_PYRAMID {
        return Err(r.corrupt(format!("coding {coding} is not defined")));
    }
    if r.u8("flags")? != 0 {
        return Err(r.corrupt("reserved flags are not zero"));
    }
    let (w, h) = (header.width as usize, header.height as usize);
    let n = w * h;
    if mask.is_some_and(|m| m.len() != n) {
        return Err(r.corrupt("mask size does not match the raster"));
    }
    let levels = r.u8("levels")? as usize;
    if levels > max_levels(w, h) {
        return Err(r.corrupt(format!(
            "{levels} levels is more than a {w}x{h} raster allows ({})",
            max_levels(w, h)
        )));
    }
    let bias = r.u8("bias")?;
    let step = r.finite_f64("lattice step")?;
    if step <= 0.0 {
        return Err(r.corrupt("lattice step is not positive"));
    }
    let offset = r.finite_f64("lattice offset")?;
    let bound = r.finite_f64("max error")?;
    if bound < 0.0 {
        return Err(r.corrupt("max error is negative"));
    }
    let pyr = Pyramid::new(w, h, levels);
    let mut steps = Vec::with_capacity(pyr.bands.len());
    for _ in 0..pyr.bands.len() {
        let s = read_varint(&mut r, "band step")?;
        if !(STEP_UNIT..=MAX_STEP).contains(&s) {
            return Err(r.corrupt(format!("band step {s}/16 is out of range")));
        }
        steps.push(s);
    }
    let stream = r.take(r.remaining(), "coefficients")?;
    let mut q = vec![0i64; n];
    Decoder::new(stream)
        .and_then(|mut dec| {
            code_bands(&mut dec, &mut q, &pyr)?;
            dec.finish()
        })
        .map_err(|e| e.context("haar section"))?;
    reconstruct(&mut q, &pyr, &steps, bias);
    let lattice = Lattice {
        step,
        offset,
        out: Output::new(header.sample_type, header.mapping),
    };
    let fill = header.nodata.unwrap_or(f64::NAN);
    q.iter()
        .enumerate()
        .map(|(i, &c)| {
            if mask.is_none_or(|m| m[i]) {
                lattice.value(c).ok_or_else(|| {
                    Error::corrupt(format!(
                        "haar section: sample {i} decodes to a non-finite value"
                    ))
                })
            } else {
                Ok(fill)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::path::Path;

    use crate::testutil::Rng;

    fn header_of(r: &Raster) -> Header {
        Header::of(r).expect("small raster")
    }

    /// Midpoint-displacement-like fractal surface: sums of random octaves of bilinear noise.
    fn fractal(w: usize, h: usize, seed: u64, amplitude: f64) -> Vec<f64> {
        let mut rng = Rng(seed);
        let mut out = vec![0.0; w * h];
        let mut cell = 64usize;
        let mut amp = amplitude;
        while cell >= 1 {
            let gw = w / cell + 2;
            let gh = h / cell + 2;
            let grid: Vec<f64> = (0..gw * gh).map(|_| rng.unit() * 2.0 - 1.0).collect();
            for y in 0..h {
                for x in 0..w {
                    let (fx, fy) = (x as f64 / cell as f64, y as f64 / cell as f64);
                    let (ix, iy) = (fx as usize, fy as usize);
                    let (tx, ty) = (fx - ix as f64, fy - iy as f64);
                    let g = |a: usize, b: usize| grid[b * gw + a];
                    let v = g(ix, iy) * (1.0 - tx) * (1.0 - ty)
                        + g(ix + 1, iy) * tx * (1.0 - ty)
                        + g(ix, iy + 1) * (1.0 - tx) * ty
                        + g(ix + 1, iy + 1) * tx * ty;
                    out[y * w + x] += v * amp;
                }
            }
            cell /= 2;
            amp *= 0.5;
        }
        out
    }

    fn crater() -> Raster {
        crate::raster::read_path(
            Path::new(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/corpus/scape_crater.png"
            )),
            &Default::default(),
        )
        .unwrap()
    }

    /// Decode and check every valid sample against `bound` (and the reported error).
    fn check_round_trip(r: &Raster, payload: &[u8], reported: f64, bound: f64) -> Vec<f64> {
        let back = decode(payload, &header_of(r), r.mask.as_deref()).unwrap();
        let mut max = 0f64;
        for (i, &b) in back.iter().enumerate() {
            if r.is_valid(i) {
                max = max.max((b - r.data[i]).abs());
            } else {
                match r.nodata {
                    Some(nd) => assert_eq!(b, nd),
                    None => assert!(b.is_nan()),
                }
            }
        }
        assert!(max <= bound, "max error {max} > bound {bound}");
        assert_eq!(max, reported);
        back
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn lifting_round_trip_is_exact(
            w in 1usize..40,
            h in 1usize..40,
            seed in any::<u64>(),
            shift in 0u32..50,
        ) {
            let mut rng = Rng(seed);
            let data: Vec<i64> = (0..w * h)
                .map(|_| (rng.next() >> (14 + shift)) as i64 - (1i64 << (49 - shift)))
                .collect();
            for levels in [0, 1, choose_levels(w, h), max_levels(w, h)] {
                let pyr = Pyramid::new(w, h, levels);
                let mut a = data.clone();
                forward(&mut a, &pyr);
                inverse(&mut a, &pyr);
                prop_assert_eq!(&a, &data);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Any size, bound, sample type and nodata pattern: the decoded raster meets the
        /// bound the encoder reports, and the reported error is the measured one.
        #[test]
        fn round_trip_meets_the_bound(
            w in 1usize..60, h in 1usize..60, seed in any::<u64>(),
            pct in 0.05f64..30.0, int in any::<bool>(), holes in any::<bool>(),
        ) {
            let mut data = fractal(w, h, seed, 200.0);
            if int {
                data.iter_mut().for_each(|v| *v = v.round());
            }
            let st = if int { SampleType::I16 } else { SampleType::F32 };
            if !int {
                data.iter_mut().for_each(|v| *v = *v as f32 as f64);
            }
            let mut nodata = None;
            if holes {
                nodata = Some(-9999.0);
                let mut rng = Rng(seed ^ 0x5555);
                for v in data.iter_mut() {
                    if rng.unit() < 0.1 {
                        *v = -9999.0;
                    }
                }
            }
            let r = Raster::from_values(w, h, data, nodata, st).unwrap();
            let Some((lo, hi)) = r.valid_range() else { return Ok(()); };
            let bound = ((hi - lo) * pct / 100.0).max(1e-3);
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            check_round_trip(&r, &payload, err, bound);
        }
    }

    #[test]
    fn bands_tile_the_raster() {
        for (w, h) in [
            (1, 1),
            (1, 17),
            (17, 1),
            (5, 3),
            (336, 459),
            (64, 64),
            (9, 2),
        ] {
            for levels in 0..=max_levels(w, h) {
                let pyr = Pyramid::new(w, h, levels);
                let mut seen = vec![0u8; w * h];
                for b in &pyr.bands {
                    for y in b.y0..b.y0 + b.h {
                        for x in b.x0..b.x0 + b.w {
                            seen[y * w + x] += 1;
                        }
                    }
                }
                assert!(seen.iter().all(|&s| s == 1), "{w}x{h} levels {levels}");
            }
        }
    }

    #[test]
    fn lossless_is_bit_exact_on_integer_data() {
        for (w, h) in [(1, 1), (1, 30), (30, 1), (37, 23), (64, 64), (3, 2)] {
            let data: Vec<f64> = fractal(w, h, 7, 500.0)
                .iter()
                .map(|v| (v + 1000.0).round())
                .collect();
            for st in [SampleType::I16, SampleType::F32, SampleType::F64] {
                let r = Raster::from_values(w, h, data.clone(), None, st).unwrap();
                let (payload, err) = encode(&r, &HaarParams { max_error: 0.0 }).unwrap();
                assert_eq!(err, 0.0);
                let back = check_round_trip(&r, &payload, 0.0, 0.0);
                assert_eq!(back, r.data);
            }
        }
        let r = crater();
        let (payload, err) = encode(&r, &HaarParams::default()).unwrap();
        assert_eq!(err, 0.0);
        check_round_trip(&r, &payload, 0.0, 0.0);
    }

    #[test]
    fn negative_value_scale() {
        // u16 codes with value = 100 − 0.5·code: the lattice runs the other way.
        let (w, h) = (29, 17);
        let mapping = ValueMapping {
            scale: -0.5,
            offset: 100.0,
        };
        let data: Vec<f64> = fractal(w, h, 17, 2000.0)
            .iter()
            .map(|v| mapping.to_value((v + 3000.0).round()))
            .collect();
        let mut r = Raster::from_values(w, h, data, None, SampleType::U16).unwrap();
        r.mapping = mapping;
        for bound in [0.0, 3.0] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            let back = check_round_trip(&r, &payload, err, bound);
            for &b in &back {
                assert_eq!(mapping.to_value(mapping.to_code(b).round()), b);
            }
        }
    }

    /// An 11×7 raster with nodata, 4 levels (odd sizes, empty bands), bound 2.
    fn golden_raster() -> Raster {
        let (w, h) = (11, 7);
        let data: Vec<f64> = fractal(w, h, 19, 60.0)
            .iter()
            .enumerate()
            .map(|(i, v)| {
                if i % 13 == 5 {
                    -1.0
                } else {
                    (v + 200.0).round()
                }
            })
            .collect();
        Raster::from_values(w, h, data, Some(-1.0), SampleType::I16).unwrap()
    }

    /// A payload the encoder wrote for [`golden_raster`] (4 levels, steps 1 to 4.4, bias
    /// 96/256) and what it decodes to: a change here is a format change.
    const GOLDEN: &[u8] = &[
        0, 0, 4, 96, 0, 0, 0, 0, 0, 0, 240, 63, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 64,
        16, 16, 16, 16, 16, 16, 16, 16, 16, 35, 47, 47, 71, 63, 218, 115, 91, 43, 218, 47, 76, 47,
        210, 190, 138, 178, 3, 244, 6, 0, 0, 0,
    ];
    const GOLDEN_DECODED: [i16; 77] = [
        242, 242, 241, 241, 240, -1, 241, 241, 239, 239, 238, 242, 242, 241, 241, 240, 240, 241,
        -1, 239, 239, 238, 242, 242, 238, 238, 243, 240, 237, 237, 238, -1, 237, 242, 242, 238,
        238, 236, 239, 237, 237, 238, 238, 237, -1, 240, 238, 238, 235, 235, 237, 237, 237, 237,
        236, 240, 240, -1, 238, 235, 235, 237, 237, 237, 237, 236, 240, 240, 235, 235, -1, 236,
        235, 235, 236, 236, 235,
    ];

    #[test]
    fn format_is_frozen() {
        let r = golden_raster();
        let back = decode(GOLDEN, &header_of(&r), r.mask.as_deref()).unwrap();
        let expected: Vec<f64> = GOLDEN_DECODED.iter().map(|&v| v as f64).collect();
        assert_eq!(back, expected);
        for (i, (&b, &v)) in back.iter().zip(&r.data).enumerate() {
            assert!(!r.is_valid(i) || (b - v).abs() <= 2.0);
        }
    }

    #[test]
    fn lossless_non_integer_float_is_refused() {
        let r = Raster::from_values(4, 4, vec![0.5; 16], None, SampleType::F32).unwrap();
        assert!(matches!(
            encode(&r, &HaarParams::default()),
            Err(Error::InvalidArgument { .. })
        ));
        // ... but a bound works.
        let (payload, err) = encode(&r, &HaarParams { max_error: 0.01 }).unwrap();
        check_round_trip(&r, &payload, err, 0.01);
    }

    #[test]
    fn lossy_meets_the_bound_on_a_fractal_surface() {
        let (w, h) = (101, 77);
        let data = fractal(w, h, 3, 300.0);
        for st in [SampleType::F32, SampleType::F64] {
            let data: Vec<f64> = if st == SampleType::F32 {
                data.iter().map(|&v| v as f32 as f64).collect()
            } else {
                data.clone()
            };
            let r = Raster::from_values(w, h, data, None, st).unwrap();
            let mut last = usize::MAX;
            for bound in [0.01, 0.3, 1.0, 5.0, 30.0] {
                let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
                check_round_trip(&r, &payload, err, bound);
                assert!(payload.len() < last, "{st:?} {bound}: {}", payload.len());
                last = payload.len();
            }
        }
        // Integer data with a mapping (decimetres + offset): outputs stay on the code lattice.
        let data: Vec<f64> = data
            .iter()
            .map(|v| (v * 10.0).round() / 10.0 - 50.0)
            .collect();
        let mut r = Raster::from_values(w, h, data, None, SampleType::I16).unwrap();
        r.mapping = ValueMapping {
            scale: 0.1,
            offset: -50.0,
        };
        r.data = r
            .data
            .iter()
            .map(|&v| r.mapping.to_value(r.mapping.to_code(v).round()))
            .collect();
        for bound in [0.0, 0.25, 2.0] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            let back = check_round_trip(&r, &payload, err, bound);
            for &b in &back {
                let c = r.mapping.to_code(b).round();
                assert_eq!(r.mapping.to_value(c), b);
            }
        }
    }

    #[test]
    fn lossy_meets_the_bound_on_crater() {
        let r = crater();
        let mut last = usize::MAX;
        for bound in [1.0, 3.0, 10.0, 30.0] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            check_round_trip(&r, &payload, err, bound);
            assert!(payload.len() < last);
            last = payload.len();
        }
        for step in [2.0, 20.0, 200.0] {
            let (payload, err) = encode_step(&r, step).unwrap();
            check_round_trip(&r, &payload, err, f64::INFINITY);
        }
    }

    #[test]
    fn nodata_samples_get_the_fill() {
        let (w, h) = (45, 31);
        let mut data: Vec<f64> = fractal(w, h, 11, 200.0).iter().map(|v| v.round()).collect();
        for (i, v) in data.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            // a hole, a full invalid row, a ragged edge
            if (x > 10 && x < 20 && y > 5 && y < 12) || y == 20 || x + y < 6 {
                *v = -9999.0;
            }
        }
        for nodata in [Some(-9999.0), None] {
            let mut data = data.clone();
            if nodata.is_none() {
                data.iter_mut()
                    .filter(|v| **v == -9999.0)
                    .for_each(|v| *v = f64::NAN);
            }
            let r = Raster::from_values(w, h, data, nodata, SampleType::I16).unwrap();
            assert!(r.mask.is_some());
            for bound in [0.0, 2.0, 20.0] {
                let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
                check_round_trip(&r, &payload, err, bound);
            }
        }
        // Nothing valid at all.
        let r = Raster::from_values(3, 5, vec![f64::NAN; 15], None, SampleType::F32).unwrap();
        let (payload, err) = encode(&r, &HaarParams { max_error: 1.0 }).unwrap();
        check_round_trip(&r, &payload, err, 1.0);
    }

    #[test]
    fn f32_output_rounding_is_in_the_loop() {
        // Large values with small bounds: the f32 rounding is a sizeable part of the error.
        let (w, h) = (40, 33);
        let data: Vec<f64> = fractal(w, h, 5, 50.0)
            .iter()
            .map(|v| (v + 4000.0) as f32 as f64)
            .collect();
        let r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
        for bound in [0.001, 0.01, 0.1] {
            let (payload, err) = encode(&r, &HaarParams { max_error: bound }).unwrap();
            let back = check_round_trip(&r, &payload, err, bound);
            assert!(back.iter().all(|&v| v as f32 as f64 == v));
        }
    }

    /// A 71×45 raster (2 levels, odd sizes) and its payload at a bound of 3.
    fn sample_payload() -> (Raster, Vec<u8>) {
        static SAMPLE: std::sync::OnceLock<(Raster, Vec<u8>)> = std::sync::OnceLock::new();
        SAMPLE
            .get_or_init(|| {
                let (w, h) = (71, 45);
                let data: Vec<f64> = fractal(w, h, 13, 100.0).iter().map(|v| v.round()).collect();
                let r = Raster::from_values(w, h, data, None, SampleType::I16).unwrap();
                let (payload, _) = encode(&r, &HaarParams { max_error: 3.0 }).unwrap();
                assert_eq!(payload[2], 2);
                (r, payload)
            })
            .clone()
    }

    #[test]
    fn every_truncation_is_an_error() {
        let (r, payload) = sample_payload();
        let golden = golden_raster();
        for (r, payload) in [(&r, payload.as_slice()), (&golden, GOLDEN)] {
            let (header, mask) = (header_of(r), r.mask.as_deref());
            decode(payload, &header, mask).unwrap();
            for cut in 0..payload.len() {
                assert!(decode(&payload[..cut], &header, mask).is_err(), "cut {cut}");
            }
            let mut longer = payload.to_vec();
            longer.push(0);
            assert!(decode(&longer, &header, mask).is_err());
        }
    }

    #[test]
    fn bad_metadata_is_rejected() {
        let (r, payload) = sample_payload();
        let header = header_of(&r);
        decode(&payload, &header, None).unwrap();
        let bad = |at: usize, bytes: &[u8]| {
            let mut p = payload.clone();
            p[at..at + bytes.len()].copy_from_slice(bytes);
            match decode(&p, &header, None) {
                Err(Error::Corrupt { .. }) => {}
                other => panic!("byte {at}: {other:?}"),
            }
        };
        bad(0, &[1]); // coding
        bad(1, &[1]); // reserved flags
        bad(2, &[max_levels(71, 45) as u8 + 1]); // levels
        bad(4, &0f64.to_le_bytes()); // lattice step
        bad(4, &(-1f64).to_le_bytes());
        bad(4, &f64::NAN.to_le_bytes());
        bad(12, &f64::INFINITY.to_le_bytes()); // offset
        bad(20, &(-1f64).to_le_bytes()); // max error
        bad(28, &[15]); // a band step below 1
        // a mask of the wrong size
        assert!(decode(&payload, &header, Some(&[true; 3])).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn garbage_never_panics(
            bytes in prop::collection::vec(any::<u8>(), 0..200),
            w in 1u32..40,
            h in 1u32..40,
            levels in 0u8..8,
            st in 0u8..6,
        ) {
            let header = Header {
                width: w,
                height: h,
                sample_type: SampleType::from_code(st).unwrap(),
                primary: 0,
                mapping: Default::default(),
                nodata: None,
                range: None,
                georef: None,
            };
            let _ = decode(&bytes, &header, None);
            // A plausible header in front of the garbage reaches the coefficient decoder.
            let mut p = vec![0u8, 0, levels, 100];
            p.put_f64(0.5);
            p.put_f64(-3.0);
            p.put_f64(1.0);
            p.extend_from_slice(&bytes);
            let _ = decode(&p, &header, None);
        }

        #[test]
        fn flipped_bytes_never_panic(at in 0usize..10_000, xor in 1u8..=255) {
            let (r, mut payload) = sample_payload();
            let at = at % payload.len();
            payload[at] ^= xor;
            let _ = decode(&payload, &header_of(&r), None);
        }
    }

    /// Rate–distortion on crater (run with `--ignored --nocapture`): prints bps, RMSE and
    /// L∞ in % of the range for a few steps, bisects the step for 1.6 and 0.16 bits/sample
    /// (1:10 and 1:100 against 16-bit samples), and the max-error mode at a few bounds.
    #[test]
    #[ignore]
    fn crater_rate_distortion() {
        let r = crater();
        let (lo, hi) = r.valid_range().unwrap();
        let range = hi - lo;
        let n = r.len() as f64;
        let header = header_of(&r);
        let stats = |payload: &[u8]| {
            let back = decode(payload, &header, None).unwrap();
            let mut se = 0.0;
            let mut mx = 0f64;
            for (a, b) in back.iter().zip(&r.data) {
                se += (a - b) * (a - b);
                mx = mx.max((a - b).abs());
            }
            (
                payload.len() as f64 * 8.0 / n,
                (se / n).sqrt() / range * 100.0,
                mx / range * 100.0,
            )
        };
        let t = std::time::Instant::now();
        let (lossless, _) = encode(&r, &HaarParams::default()).unwrap();
        eprintln!(
            "lossless: {} bytes, {:.4} bps ({:?})",
            lossless.len(),
            lossless.len() as f64 * 8.0 / n,
            t.elapsed()
        );
        for step in [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0] {
            let (p, _) = encode_step(&r, step).unwrap();
            let (bps, rmse, linf) = stats(&p);
            eprintln!("step {step}: {bps:.4} bps, RMSE {rmse:.4} %, L∞ {linf:.3} %");
        }
        for target in [1.6, 0.16] {
            let (mut a, mut b) = (0.5f64, 2000.0f64);
            for _ in 0..40 {
                let mid = (a * b).sqrt();
                let (p, _) = encode_step(&r, mid).unwrap();
                if p.len() as f64 * 8.0 / n > target {
                    a = mid;
                } else {
                    b = mid;
                }
            }
            let t = std::time::Instant::now();
            let (p, _) = encode_step(&r, b).unwrap();
            let te = t.elapsed();
            let t = std::time::Instant::now();
            decode(&p, &header, None).unwrap();
            let td = t.elapsed();
            let (bps, rmse, linf) = stats(&p);
            eprintln!(
                "target {target} bps: step {b:.3}, {bps:.4} bps, RMSE {rmse:.4} %, L∞ {linf:.3} % (enc {te:?}, dec {td:?})"
            );
        }
        for pct in [0.1, 0.3, 1.0, 3.0, 10.0] {
            let t = std::time::Instant::now();
            let (p, err) = encode(
                &r,
                &HaarParams {
                    max_error: range * pct / 100.0,
                },
            )
            .unwrap();
            let te = t.elapsed();
            let (bps, rmse, linf) = stats(&p);
            eprintln!(
                "max error {pct} %: {} bytes, {bps:.4} bps, RMSE {rmse:.4} %, L∞ {linf:.3} % (err {err}, enc {te:?})",
                p.len()
            );
        }
    }
}
