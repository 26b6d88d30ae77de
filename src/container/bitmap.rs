//! Bilevel bitmaps (the validity mask, the flat regions) range coded one bit per sample
//! with a context of ten neighbours, as JBIG codes bilevel images:
//! a smooth edge costs a few bits per edge sample, a blank area almost nothing.

use crate::entropy::range::{Bit, Decoder, Encoder};
use crate::error::Result;

/// Context bits: 10 neighbours (as JBIG's ten-pixel template), 1024 contexts.
const CONTEXTS: usize = 1 << 10;

/// The context of sample i at column x: the bits of W, N, NW, NE, WW, NN, (x−2, y−1),
/// (x+2, y−1), (x−1, y−2), (x+1, y−2), one bit each in that order from bit 0 (0 outside
/// the raster).
#[inline]
fn context(bits: &[bool], w: usize, i: usize) -> usize {
    let x = i % w;
    let y = i / w;
    if y >= 2 && x >= 2 && x + 2 < w {
        // Inside: every neighbour exists (the same bits as below, without the checks).
        let b = |j: usize| bits[j] as usize;
        let (n, nn) = (i - w, i - 2 * w);
        return b(i - 1)
            | b(n) << 1
            | b(n - 1) << 2
            | b(n + 1) << 3
            | b(i - 2) << 4
            | b(nn) << 5
            | b(n - 2) << 6
            | b(n + 2) << 7
            | b(nn - 1) << 8
            | b(nn + 1) << 9;
    }
    let at = |dx: isize, dy: usize| -> usize {
        let xx = x as isize + dx;
        if y < dy || xx < 0 || xx >= w as isize {
            0
        } else {
            bits[(y - dy) * w + xx as usize] as usize
        }
    };
    at(-1, 0)
        | at(0, 1) << 1
        | at(-1, 1) << 2
        | at(1, 1) << 3
        | at(-2, 0) << 4
        | at(0, 2) << 5
        | at(-2, 1) << 6
        | at(2, 1) << 7
        | at(-1, 2) << 8
        | at(1, 2) << 9
}

/// Code the bits of a `w`-wide bitmap at the samples `coded` selects (the others are
/// false and cost nothing).
pub fn encode(bits: &[bool], w: usize, coded: impl Fn(usize) -> bool) -> Vec<u8> {
    let mut enc = Encoder::new();
    let mut ctx = vec![Bit::default(); CONTEXTS];
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
    let mut ctx = vec![Bit::default(); CONTEXTS];
    for i in 0..n {
        if coded(i) {
            bits[i] = dec.decode(&mut ctx[context(&bits, w, i)]);
        }
    }
    dec.finish()?;
    Ok(bits)
}
