//! How the residual layer codes one quantization bin: binarized (zero flag, sign, Elias-gamma
//! magnitude) into the adaptive binary range coder, each decision under a context drawn
//! from the bin's level, the local activity and the neighbours' recent residuals.

use crate::entropy::range::{Bit, Decoder, Encoder};
use crate::error::{Error, Result};

/// Level classes: 0 = finest interpolation level (and every scan-order sample) … 3, 4 =
/// anchors.
pub const LEVELS: usize = 5;
/// Activity classes (thresholds [`ACT_T`] in quarter bins).
const NA: usize = 16;
/// Neighbour-residual classes (thresholds [`ERR_T`] in quarter bins).
const NERR: usize = 6;
/// Neighbour-sign classes: negative, zero or mixed, positive.
const NSG: usize = 3;
/// Unary exponent positions with a context of their own.
const NU: usize = 20;
/// Exponent classes of the mantissa bits.
const NE: usize = 34;
/// Largest exponent of a bin's magnitude: |bin| < 2^MAX_EXP.
pub const MAX_EXP: u32 = 48;

const ACT_T: [u32; NA - 1] = [1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192];
const ERR_T: [u32; NERR - 1] = [2, 6, 14, 30, 62];

/// What the contexts of one bin are made of, computed alike by encoder and decoder.
#[derive(Clone, Copy, Default)]
pub struct Ctx {
    /// Local activity in quarter bins (activity · 4 / bin width).
    pub act: u64,
    /// Neighbours' recent |residual| in quarter bins.
    pub err: u64,
    /// Sum of the signs of the neighbours' bins (its sign picks the sign context).
    pub sign: i32,
    /// Level class, < [`LEVELS`].
    pub level: usize,
}

/// The number of thresholds in `t` that are ≤ v.
const fn class(v: u64, t: &[u32]) -> usize {
    let mut k = 0;
    while k < t.len() && t[k] as u64 <= v {
        k += 1;
    }
    k
}

/// [`class`] of 0..256 against [`ACT_T`] and [`ERR_T`], looked up instead of searched.
const fn table(t: &[u32]) -> [u8; 256] {
    let mut out = [0u8; 256];
    let mut v = 0;
    while v < 256 {
        out[v] = class(v as u64, t) as u8;
        v += 1;
    }
    out
}
const ACT_CLASS: [u8; 256] = table(&ACT_T);
const ERR_CLASS: [u8; 256] = table(&ERR_T);

/// Activity class 0..16 of an activity in quarter bins (also the weighted predictor's
/// least-squares class, halved).
#[inline]
pub fn act_class(act: u64) -> usize {
    if act < 256 { ACT_CLASS[act as usize] as usize } else { NA - 1 }
}

#[inline]
fn err_class(err: u64) -> usize {
    if err < 256 { ERR_CLASS[err as usize] as usize } else { NERR - 1 }
}

/// The adaptive models of one stream.
pub struct Models {
    zero: Vec<Bit>,
    sign: Vec<Bit>,
    unary: Vec<Bit>,
    mant: Vec<Bit>,
}

impl Models {
    pub fn new() -> Models {
        let n = LEVELS * NA * NERR;
        Models {
            zero: vec![Bit::default(); n],
            sign: vec![Bit::default(); LEVELS * NSG],
            unary: vec![Bit::default(); n * NU],
            mant: vec![Bit::default(); NE * 3],
        }
    }

    #[inline]
    fn index(c: &Ctx) -> (usize, usize) {
        let zi = (c.level * NA + act_class(c.act)) * NERR + err_class(c.err);
        let si = c.level * NSG + (c.sign.signum() + 1) as usize;
        (zi, si)
    }
}

/// Something that codes (encoder) or recovers (decoder) a bin; the predictors are generic
/// over it, so encoding and decoding run the same code.
pub trait BinCoder {
    /// Code `bin` (ignored when decoding) under `c`; returns the bin.
    fn bin(&mut self, c: &Ctx, bin: i64) -> Result<i64>;
    /// Whether this is the encoder (which knows the source values).
    const ENCODES: bool;
    /// A level (or the anchors) is complete: a decoder notes how many bytes of its stream
    /// it has read ([`BinDecoder::marks`]).
    fn level_done(&mut self) {}
}

/// The encoding side.
pub struct BinEncoder {
    pub m: Models,
    pub enc: Encoder,
}

impl BinCoder for BinEncoder {
    const ENCODES: bool = true;
    #[inline]
    fn bin(&mut self, c: &Ctx, bin: i64) -> Result<i64> {
        let (zi, si) = Models::index(c);
        let m = &mut self.m;
        self.enc.encode(&mut m.zero[zi], bin != 0);
        if bin == 0 {
            return Ok(0);
        }
        self.enc.encode(&mut m.sign[si], bin < 0);
        let t = bin.unsigned_abs();
        let e = 63 - t.leading_zeros() as usize;
        for k in 0..=e {
            self.enc
                .encode(&mut m.unary[zi * NU + k.min(NU - 1)], k < e);
        }
        for k in (0..e).rev() {
            let pos = (e - 1 - k).min(2);
            self.enc
                .encode(&mut m.mant[e.min(NE - 1) * 3 + pos], (t >> k) & 1 == 1);
        }
        Ok(bin)
    }
}

/// The decoding side; `max_bin` bounds a bin's magnitude (a larger one is corrupt data).
pub struct BinDecoder<'a> {
    pub m: Models,
    pub dec: Decoder<'a>,
    pub max_bin: u64,
    /// Bytes of the stream read when the anchors and each level were complete, coarse to
    /// fine (what a decode that stops there needs: the progressive tiles of version 4).
    pub marks: Vec<usize>,
}

impl BinCoder for BinDecoder<'_> {
    const ENCODES: bool = false;
    fn level_done(&mut self) {
        self.marks.push(self.dec.position());
    }
    #[inline]
    fn bin(&mut self, c: &Ctx, _bin: i64) -> Result<i64> {
        let (zi, si) = Models::index(c);
        let m = &mut self.m;
        if !self.dec.decode(&mut m.zero[zi]) {
            return Ok(0);
        }
        let neg = self.dec.decode(&mut m.sign[si]);
        let mut e = 0usize;
        while self.dec.decode(&mut m.unary[zi * NU + e.min(NU - 1)]) {
            e += 1;
            if e as u32 >= MAX_EXP {
                return Err(corrupt());
            }
        }
        let mut v: u64 = 1;
        for k in (0..e).rev() {
            let pos = (e - 1 - k).min(2);
            v = (v << 1) | self.dec.decode(&mut m.mant[e.min(NE - 1) * 3 + pos]) as u64;
        }
        if v > self.max_bin {
            return Err(corrupt());
        }
        Ok(if neg { -(v as i64) } else { v as i64 })
    }
}

#[cold]
fn corrupt() -> Error {
    Error::corrupt("residual section: a bin lies outside the section's value range")
}

/// Closed-loop quantization of residual `r` into a bin of odd width `w` (JPEG-LS NEAR).
#[inline]
pub fn quantize(r: i64, w: i64) -> i64 {
    let near = (w - 1) / 2;
    if r >= 0 {
        (r + near) / w
    } else {
        -((-r + near) / w)
    }
}

/// floor(n / d + 1/2) for d > 0.
#[inline]
pub fn round_div(n: i64, d: i64) -> i64 {
    (2 * n + d).div_euclid(2 * d)
}
