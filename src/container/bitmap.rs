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
///
/// Row by row, with each row's template bits kept in small shift registers (two bits of
/// the row being decoded, five of the row above, three of the one above that): the same
/// contexts as [`context`], without a division and ten loads per bit (the masks and flat
/// regions of a tiled file's overview are decoded at full resolution: 21 % of an overview
/// of the 20000² mosaic went to [`context`] and the decode loop). The registers index three
/// small tables that place their bits in the context, and the two rows above are kept as
/// bytes padded with zeros past their ends: a 512² web tile's void mask 27.0 M → 20.7 M
/// instructions (callgrind).
pub fn decode(
    stream: &[u8],
    w: usize,
    n: usize,
    coded: impl Fn(usize) -> bool,
) -> Result<Vec<bool>> {
    let mut dec = Decoder::new(stream)?;
    let mut bits = vec![false; n];
    let mut ctx = vec![Bit::default(); CONTEXTS];
    if w == 0 {
        dec.finish()?;
        return Ok(bits);
    }
    // The context from the three registers by table: the ten template bits gathered from
    // w0 (2 bits), w1 (5) and w2 (3) once, instead of ten shifts and masks per bit.
    let t0: [usize; 4] = std::array::from_fn(|v| (v >> 1 & 1) | (v & 1) << 4);
    let t1: [usize; 32] = std::array::from_fn(|v| {
        (v >> 2 & 1) << 1 | (v >> 1 & 1) << 2 | (v >> 3 & 1) << 3 | (v & 1) << 6 | (v >> 4 & 1) << 7
    });
    let t2: [usize; 8] =
        std::array::from_fn(|v| (v >> 1 & 1) << 5 | (v & 1) << 8 | (v >> 2 & 1) << 9);
    // The two rows above as 0/1 bytes with zeros beyond their ends (the template reads up
    // to 3 columns past x), so the loop needs no bounds test per neighbour.
    let mut above1 = vec![0u8; w + 4];
    let mut above2 = vec![0u8; w + 4];
    for start in (0..n).step_by(w) {
        let row = &mut bits[start..(start + w).min(n)];
        // w1: bit j = row above at x − 2 + j; w2: bit j = two rows above at x − 1 + j;
        // w0: bit 0 = this row at x − 2, bit 1 at x − 1.
        let mut w1 =
            (above1[0] as usize) << 2 | (above1[1] as usize) << 3 | (above1[2] as usize) << 4;
        let mut w2 = (above2[0] as usize) << 1 | (above2[1] as usize) << 2;
        let mut w0 = 0usize;
        for (x, out) in row.iter_mut().enumerate() {
            let c = t0[w0] | t1[w1] | t2[w2];
            let bit = coded(start + x) && dec.decode(&mut ctx[c]);
            *out = bit;
            w0 = w0 >> 1 | (bit as usize) << 1;
            w1 = w1 >> 1 | (above1[x + 3] as usize) << 4;
            w2 = w2 >> 1 | (above2[x + 2] as usize) << 2;
        }
        std::mem::swap(&mut above1, &mut above2);
        for (a, &b) in above1.iter_mut().zip(row.iter()) {
            *a = b as u8;
        }
    }
    dec.finish()?;
    Ok(bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The row-by-row decoder's contexts are [`context`]'s (the encoder's): random bitmaps
    /// of narrow and odd widths, with every bit coded and with some skipped, round trip.
    #[test]
    fn the_decoder_reads_back_what_the_encoder_wrote_at_any_width() {
        let mut rng = crate::testutil::Rng(0x9e37_79b9_7f4a_7c15);
        let mut next = move || rng.next();
        for w in [1usize, 2, 3, 4, 5, 17, 64] {
            for h in [1usize, 2, 3, 9] {
                let n = w * h;
                // Blobs more than noise: a bit is often its left neighbour's.
                let mut bits = vec![false; n];
                for i in 0..n {
                    bits[i] = if i > 0 && next() % 4 != 0 {
                        bits[i - 1]
                    } else {
                        next() % 2 == 0
                    };
                }
                let skip = |i: usize| i % 7 != 3;
                for coded in [&(|_| true) as &dyn Fn(usize) -> bool, &skip] {
                    let want: Vec<bool> = (0..n).map(|i| coded(i) && bits[i]).collect();
                    let stream = encode(&want, w, coded);
                    assert_eq!(decode(&stream, w, n, coded).unwrap(), want, "{w} x {h}");
                }
            }
        }
    }
}
