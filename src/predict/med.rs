//! The median edge detector (LOCO-I / JPEG-LS) on integer codes, its local-activity
//! contexts, and a range-coded lattice of codes predicted with both.

use crate::entropy::range::{Decoder, Encoder, IntModel};
use crate::error::Result;

/// Activity contexts: bit length of |a−c| + |b−c| + |d−b|, capped.
pub(crate) const CONTEXTS: usize = 24;

/// Context of sample i from the codes already known (left a, up b, up-left c, up-right d).
#[inline]
pub(crate) fn context(codes: &[i64], w: usize, i: usize) -> usize {
    let (x, y) = (i % w, i / w);
    let act: u64 = if y == 0 {
        if x >= 2 {
            codes[i - 1].wrapping_sub(codes[i - 2]).unsigned_abs()
        } else {
            0
        }
    } else {
        let b = codes[i - w];
        let a = if x > 0 { codes[i - 1] } else { b };
        let c = if x > 0 { codes[i - w - 1] } else { b };
        let d = if x + 1 < w { codes[i - w + 1] } else { b };
        a.wrapping_sub(c)
            .unsigned_abs()
            .saturating_add(b.wrapping_sub(c).unsigned_abs())
            .saturating_add(d.wrapping_sub(b).unsigned_abs())
    };
    ((64 - act.leading_zeros()) as usize).min(CONTEXTS - 1)
}

/// LOCO-I / JPEG-LS median edge detector from left `a`, up `b`, up-left `c`.
#[inline]
pub(crate) fn med(a: i64, b: i64, c: i64) -> i64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    if c >= hi {
        lo
    } else if c <= lo {
        hi
    } else {
        a.wrapping_add(b).wrapping_sub(c)
    }
}

/// [`med`] on a sparse grid (the residual layer's anchors), with its activity: from the
/// points left, above, above-left and above-right (`None` outside; `mid` where there is
/// neither left nor above), the missing ones substituted (a = left, else above, else mid;
/// b = above, else a; c = above-left, else a; d = above-right, else b); returns
/// (med(a, b, c), |a − c| + |b − c| + |d − b|).
#[inline(always)]
pub(crate) fn anchor_med(
    left: Option<i64>,
    top: Option<i64>,
    tl: Option<i64>,
    tr: Option<i64>,
    mid: i64,
) -> (i64, i64) {
    let a = left.or(top).unwrap_or(mid);
    let b = top.unwrap_or(a);
    let c = tl.unwrap_or(a);
    let d = tr.unwrap_or(b);
    (med(a, b, c), (a - c).abs() + (b - c).abs() + (d - b).abs())
}

#[inline]
pub(crate) fn predict(codes: &[i64], w: usize, i: usize) -> i64 {
    let (x, y) = (i % w, i / w);
    match (x, y) {
        (0, 0) => 0,
        (_, 0) => codes[i - 1],
        (0, _) => codes[i - w],
        _ => med(codes[i - 1], codes[i - w], codes[i - w - 1]),
    }
}

/// Range-code a fully valid lattice of integer codes, `w` wide, with MED prediction and
/// activity contexts (the FIS section's subgrid heights).
pub(crate) fn encode_lattice(enc: &mut Encoder, codes: &[i64], w: usize) {
    let mut models: Vec<_> = (0..CONTEXTS).map(|_| IntModel::new()).collect();
    for i in 0..codes.len() {
        let res = codes[i].wrapping_sub(predict(codes, w, i));
        models[context(codes, w, i)].encode(enc, res);
    }
}

/// Decode `n` codes written by [`encode_lattice`].
pub(crate) fn decode_lattice(dec: &mut Decoder, w: usize, n: usize) -> Result<Vec<i64>> {
    let mut models: Vec<_> = (0..CONTEXTS).map(|_| IntModel::new()).collect();
    let mut codes = vec![0i64; n];
    for i in 0..n {
        let p = predict(&codes, w, i);
        let res = models[context(&codes, w, i)].decode(dec)?;
        codes[i] = p.wrapping_add(res);
    }
    Ok(codes)
}
