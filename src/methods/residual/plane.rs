//! The integer plane both predictors work on: sample kinds, the source in lattice units
//! (encoder only), the clamp range and the bin width, and what the coding loop leaves
//! behind (reconstruction, |residual|, bin signs).

use super::coder::{BinCoder, Ctx, quantize};
use crate::error::Result;

/// A sample the coder codes.
pub const CODED: u8 = 0;
/// A nodata sample: no bits, it takes its prediction.
pub const SKIPPED: u8 = 1;
/// A sample whose value the decoder already knows (a flat region): no bits, it takes that
/// value.
pub const FIXED: u8 = 2;

/// What the coding loops read.
pub struct Plane<'a> {
    pub width: usize,
    pub height: usize,
    /// Per sample: [`CODED`], [`SKIPPED`] or [`FIXED`].
    pub kinds: &'a [u8],
    /// Per sample, in units: the source (encoder) or, at [`FIXED`] samples, their value
    /// (decoder; anything elsewhere).
    pub values: &'a [i64],
    /// Every reconstruction lies in `lo..=hi`.
    pub lo: i64,
    pub hi: i64,
    /// Bin width (odd, ≥ 1).
    pub bin: i64,
}

/// The coding loop's state: what it has reconstructed so far.
pub struct State {
    pub rec: Vec<i64>,
    /// |reconstruction − prediction| of each reconstructed sample, saturated.
    pub res: Vec<u32>,
    /// Sign of each sample's bin.
    pub sign: Vec<i8>,
}

impl State {
    pub fn new(n: usize) -> State {
        State {
            rec: vec![0; n],
            res: vec![0; n],
            sign: vec![0; n],
        }
    }

    /// Predict, quantize (encoder) or read (decoder) the bin of sample `i`, reconstruct it
    /// as the decoder will and remember it; returns the bin.
    #[inline]
    pub fn code<C: BinCoder>(
        &mut self,
        p: &Plane,
        i: usize,
        pred: i64,
        ctx: impl FnOnce() -> Ctx,
        coder: &mut C,
    ) -> Result<i64> {
        self.code_with(p, p.bin, i, pred, ctx, coder)
    }

    /// [`State::code`] with bins of width `bin` (odd, ≥ 1) instead of the plane's.
    #[inline]
    pub fn code_with<C: BinCoder>(
        &mut self,
        p: &Plane,
        bin: i64,
        i: usize,
        pred: i64,
        ctx: impl FnOnce() -> Ctx,
        coder: &mut C,
    ) -> Result<i64> {
        let pred = pred.clamp(p.lo, p.hi);
        let (r, b) = match p.kinds[i] {
            CODED => {
                let q = if C::ENCODES {
                    quantize(p.values[i] - pred, bin)
                } else {
                    0
                };
                let b = coder.bin(&ctx(), q)?;
                ((pred + b * bin).clamp(p.lo, p.hi), b)
            }
            FIXED => (p.values[i].clamp(p.lo, p.hi), 0),
            _ => (pred, 0),
        };
        self.rec[i] = r;
        self.res[i] = (r - pred).unsigned_abs().min(u32::MAX as u64) as u32;
        self.sign[i] = b.signum() as i8;
        Ok(b)
    }
}

/// Activity or residual in quarter bins, for the contexts.
#[inline]
pub fn quarter_bins(v: i64, bin: i64) -> u64 {
    (v.max(0) as u64).saturating_mul(4) / bin as u64
}
