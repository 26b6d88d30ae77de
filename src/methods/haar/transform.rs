//! The pyramid geometry (band layout) and the integer S-transform lifting steps.

/// The encoder adds levels until the LL band is at most this many samples on a side.
const LL_MAX: usize = 32;

/// Orientation of a band: `LL` (low in both directions), `HL` (high along rows, i.e.
/// horizontal differences), `LH` (high along columns), `HH`.
pub(super) const LL: usize = 0;
pub(super) const HL: usize = 1;
pub(super) const LH: usize = 2;
pub(super) const HH: usize = 3;

/// One band of the pyramid, a rectangle of the Mallat layout.
#[derive(Clone, Copy, Debug)]
pub(super) struct Band {
    pub(super) x0: usize,
    pub(super) y0: usize,
    pub(super) w: usize,
    pub(super) h: usize,
    /// 1 = finest; the LL band has level `levels`.
    pub(super) level: usize,
    pub(super) orient: usize,
    /// Index (in [`Pyramid::bands`]) of the same orientation one level coarser.
    pub(super) parent: Option<usize>,
}

/// Band layout of a `width × height` raster decomposed `levels` times.
#[derive(Clone, Debug)]
pub(super) struct Pyramid {
    pub(super) width: usize,
    pub(super) levels: usize,
    /// `sizes[l]`: size of the LL region after l levels (`sizes[0]` = the raster).
    pub(super) sizes: Vec<(usize, usize)>,
    /// Coding order: LL, then for level = levels … 1: HL, LH, HH.
    pub(super) bands: Vec<Band>,
}

/// How many times `w × h` must be halved (rounding up) until no side exceeds `side`.
fn levels_until(w: usize, h: usize, side: usize) -> usize {
    let (mut w, mut h, mut l) = (w, h, 0);
    while w > side || h > side {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
        l += 1;
    }
    l
}

/// Levels after which every side is 1 (the most a payload may declare).
pub(super) fn max_levels(w: usize, h: usize) -> usize {
    levels_until(w, h, 1)
}

/// The encoder's number of levels: until the LL band is at most [`LL_MAX`] on a side.
pub(super) fn choose_levels(w: usize, h: usize) -> usize {
    levels_until(w, h, LL_MAX)
}

impl Pyramid {
    pub(super) fn new(width: usize, height: usize, levels: usize) -> Pyramid {
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

/// `line` ([`fwd_line`] or [`inv_line`]) applied to each row of the `w × h` top-left
/// region, through `tmp`; rows shorter than 2 are left alone.
fn each_row(
    a: &mut [i64],
    stride: usize,
    w: usize,
    h: usize,
    tmp: &mut Vec<i64>,
    line: fn(&[i64], &mut [i64]),
) {
    if w >= 2 {
        tmp.resize(w, 0);
        for y in 0..h {
            let row = &mut a[y * stride..][..w];
            tmp.copy_from_slice(row);
            line(tmp, row);
        }
    }
}

/// Copy the `w × h` top-left region into `tmp`, rows packed (`tmp` row stride `w`).
fn copy_region(a: &[i64], stride: usize, w: usize, h: usize, tmp: &mut Vec<i64>) {
    tmp.clear();
    for y in 0..h {
        tmp.extend_from_slice(&a[y * stride..][..w]);
    }
}

/// One forward level on the `w × h` top-left region: rows, then columns.
fn fwd_level(a: &mut [i64], stride: usize, w: usize, h: usize, tmp: &mut Vec<i64>) {
    each_row(a, stride, w, h, tmp, fwd_line);
    if h >= 2 {
        copy_region(a, stride, w, h, tmp);
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
        copy_region(a, stride, w, h, tmp);
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
    each_row(a, stride, w, h, tmp, inv_line);
}

/// Forward pyramid in place (codes → coefficients in the Mallat layout).
pub(super) fn forward(a: &mut [i64], pyr: &Pyramid) {
    let mut tmp = Vec::new();
    for l in 0..pyr.levels {
        let (w, h) = pyr.sizes[l];
        fwd_level(a, pyr.width, w, h, &mut tmp);
    }
}

/// Inverse pyramid in place (coefficients → codes).
pub(super) fn inverse(a: &mut [i64], pyr: &Pyramid) {
    inverse_down_to(a, pyr, 0);
}

/// Invert the levels coarser than `stop` (levels `levels` … `stop + 1`).
pub(super) fn inverse_down_to(a: &mut [i64], pyr: &Pyramid, stop: usize) {
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
pub(super) fn inv_block(
    s: i64,
    hl: Option<i64>,
    lh: Option<i64>,
    hh: Option<i64>,
) -> [[Option<i64>; 2]; 2] {
    let (l_top, l_bot) = inv_pair(s, lh);
    let h = hl.map(|hl| inv_pair(hl, hh));
    let (a, b) = inv_pair(l_top, h.map(|h| h.0));
    let bottom = l_bot.map(|lb| inv_pair(lb, h.and_then(|h| h.1)));
    [
        [Some(a), b],
        [bottom.map(|p| p.0), bottom.and_then(|p| p.1)],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    use crate::testutil::Rng;

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(64))]
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
}
