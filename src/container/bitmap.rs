//! Bilevel bitmaps (the validity mask, the flat regions) range coded one bit per sample
//! with a context of six neighbours (W, N, NW, NE, WW, NN), as JBIG codes bilevel images:
//! a smooth edge costs a few bits per edge sample, a blank area almost nothing.

use crate::entropy::range::{Bit, Decoder, Encoder};
use crate::error::Result;

/// The context of sample i: the bits of W, N, NW, NE, WW and NN (0 outside the raster).
#[inline]
fn context(bits: &[bool], w: usize, i: usize) -> usize {
    let x = i % w;
    let at = |ok: bool, j: usize| (ok && bits[j]) as usize;
    at(x > 0, i.wrapping_sub(1))
        | at(i >= w, i.wrapping_sub(w)) << 1
        | at(x > 0 && i >= w, i.wrapping_sub(w + 1)) << 2
        | at(x + 1 < w && i >= w, i.wrapping_sub(w).wrapping_add(1)) << 3
        | at(x > 1, i.wrapping_sub(2)) << 4
        | at(i >= 2 * w, i.wrapping_sub(2 * w)) << 5
}

/// Code the bits of a `w`-wide bitmap at the samples `coded` selects (the others are
/// false and cost nothing).
pub fn encode(bits: &[bool], w: usize, coded: impl Fn(usize) -> bool) -> Vec<u8> {
    let mut enc = Encoder::new();
    let mut ctx = [Bit::default(); 64];
    for i in 0..bits.len() {
        if coded(i) {
            enc.encode(&mut ctx[context(bits, w, i)], bits[i]);
        }
    }
    enc.finish()
}

/// Decode `n` bits of a `w`-wide bitmap coded by [`encode`] (the stream must end exactly).
pub fn decode(
    stream: &[u8],
    w: usize,
    n: usize,
    coded: impl Fn(usize) -> bool,
) -> Result<Vec<bool>> {
    let mut dec = Decoder::new(stream)?;
    let mut bits = vec![false; n];
    let mut ctx = [Bit::default(); 64];
    for i in 0..n {
        if coded(i) {
            bits[i] = dec.decode(&mut ctx[context(&bits, w, i)]);
        }
    }
    dec.finish()?;
    Ok(bits)
}
