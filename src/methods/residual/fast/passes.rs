//! The fast coding's vocabulary: its constants, settings, passes and bands, the tokens of
//! a bin, and the trait of what codes one.

use super::super::interp::level_bin;
use crate::error::Result;
use rayon::prelude::*;

/// Context groups: level 1's horizontal pass, level 1's vertical pass, level 2, levels ≥ 3,
/// anchors.
pub(super) const GROUPS: usize = 5;
/// Energy classes per group (half octaves of the energy in quarter bins).
pub(super) const FINE: usize = 40;
/// Contexts before clustering.
pub(super) const NCTX: usize = GROUPS * FINE;
/// Tokens: 0..16 themselves, then two per exponent 4 ..= 40.
pub const ALPHABET: usize = 90;
/// Bands of about 2^18 samples: a 3600² tile's finest pass has 25, a 1201² one's 3.
pub const DEFAULT_BAND_LOG2: u8 = 18;
/// Smallest and largest band size exponent a section may hold.
pub const BAND_LOG2: std::ops::RangeInclusive<u8> = 10..=30;

/// Points of the least-squares stencil, (dy, dx) in units of the level's step, per pass
/// (vertical, horizontal): eight of coarser levels, then two of the pass itself, which
/// count only within the sample's band (elsewhere their feature is 0).
pub(super) const STENCIL: [[(isize, isize); NW]; 2] = [
    [(-1, 0), (1, 0), (-3, 0), (3, 0), (-1, -2), (1, -2), (-1, 2), (1, 2), (0, -2), (-2, 0)],
    [(0, -1), (0, 1), (0, -3), (0, 3), (-1, -1), (-1, 1), (1, -1), (1, 1), (-1, 0), (-2, 0)],
];
/// Stencil points.
pub const NW: usize = 10;
/// A stencil's fit reads about 2^this many samples.
pub(super) const FIT_SAMPLES_LOG2: u32 = 17;
/// Stencil points of coarser levels.
pub(super) const NCOARSE: usize = 8;

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
    /// The lane coding (codings 4 and 5): every sample predicted from coarser passes only,
    /// four interleaved rANS states, the token before in the context.
    pub lanes: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Kind {
    Anchor,
    Vertical,
    Horizontal,
}

/// One pass over the plane: rows r0, r0 + rs, … and columns c0, c0 + cs, … .
#[derive(Clone, Copy, Debug)]
pub(super) struct Pass {
    pub(super) kind: Kind,
    /// The level's step (the anchor stride for anchors).
    pub(super) s: usize,
    pub(super) r0: usize,
    pub(super) rs: usize,
    pub(super) c0: usize,
    pub(super) cs: usize,
    pub(super) group: usize,
    pub(super) bin: i64,
    /// Stencil weights (units of 2^-10), on the finest `ls_levels` levels.
    pub(super) weights: Option<[i16; NW]>,
}

impl Pass {
    /// Index offsets of the stencil points in a raster `w` wide.
    pub(super) fn offsets(&self, w: usize) -> [isize; NW] {
        let t = usize::from(self.kind == Kind::Horizontal);
        STENCIL[t].map(|(dy, dx)| (dy * w as isize + dx) * self.s as isize)
    }
    pub(super) fn level(&self) -> u32 {
        self.s.trailing_zeros() + 1
    }
    pub(super) fn rows(&self, h: usize) -> usize {
        if self.r0 < h { (h - 1 - self.r0) / self.rs + 1 } else { 0 }
    }
    pub(super) fn cols(&self, w: usize) -> usize {
        if self.c0 < w { (w - 1 - self.c0) / self.cs + 1 } else { 0 }
    }
    /// How many raster rows above and below its own a sample of the pass reads samples of
    /// earlier passes: the vertical pass's support y ± 3s (its stencil and neighbours lie
    /// within y ± s), the horizontal pass's stencil rows y ± s (its support lies in row
    /// y); the anchors read only anchors. Reads of the pass itself stay in the band.
    pub(super) fn reach(&self) -> usize {
        match self.kind {
            Kind::Anchor => 0,
            Kind::Vertical => 3 * self.s,
            Kind::Horizontal => self.s,
        }
    }
    /// The bands: ranges of pass rows, each of max(1, ⌊2^band_log2 / cols⌋) rows but the
    /// last; the anchors are one band.
    pub(super) fn bands(&self, w: usize, h: usize, band_log2: u8) -> Vec<(usize, usize)> {
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
pub(super) fn passes(cfg: Config, bin: i64) -> Vec<Pass> {
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
pub(super) fn half_log(v: u64) -> u32 {
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
pub(super) fn token(v: u64) -> (u8, u64, u32) {
    if v < 16 {
        (v as u8, 0, 0)
    } else {
        let e = 63 - v.leading_zeros();
        let top = (v >> (e - 1)) & 1;
        ((16 + 2 * (e - 4) + top as u32) as u8, v & ((1 << (e - 1)) - 1), e - 1)
    }
}

/// A band's rows apart from the planes: values and magnitudes, `cols` a pass row.
pub(super) type BandBuf<T> = (Vec<T>, Vec<u8>);

/// Write the bands' buffers (each band's pass rows, `cols` values a row) into the planes,
/// row by row on all threads: both codings' bands side by side end here.
pub(super) fn scatter<T: Copy + Send + Sync>(
    w: usize,
    pass: &Pass,
    bands: &[(usize, usize)],
    bufs: &[BandBuf<T>],
    plane: &mut [T],
    mag: &mut [u8],
) {
    let cols = pass.cols(w);
    // `bands` are consecutive (all of the pass's, or those a window needs), each but the
    // last as many pass rows as the first.
    let (Some(&(first, next)), Some(&(_, end))) = (bands.first(), bands.last()) else {
        return;
    };
    let per = (next - first).max(1);
    plane
        .par_chunks_mut(w)
        .zip(mag.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (rr, mr))| {
            if y < pass.r0 || (y - pass.r0) % pass.rs != 0 {
                return;
            }
            let k = (y - pass.r0) / pass.rs;
            if k < first || k >= end {
                return;
            }
            let b = (k - first) / per;
            let Some((br, bm)) = bufs.get(b) else { return };
            let from = (k - bands[b].0) * cols;
            put_row(&mut rr[pass.c0..], pass.cs, &br[from..from + cols]);
            put_row(&mut mr[pass.c0..], pass.cs, &bm[from..from + cols]);
        });
}

/// `out[k·cs] = row[k]`.
#[inline(always)]
pub(super) fn put_row<V: Copy>(out: &mut [V], cs: usize, row: &[V]) {
    let full = (out.len() / cs).min(row.len());
    if cs == 2 {
        // A constant stride: the stores vectorise.
        for (c, &v) in out.chunks_exact_mut(2).zip(&row[..full]) {
            c[0] = v;
        }
    } else {
        for (c, &v) in out.chunks_exact_mut(cs).zip(&row[..full]) {
            c[0] = v;
        }
    }
    for (k, &v) in row.iter().enumerate().skip(full) {
        out[k * cs] = v;
    }
}
