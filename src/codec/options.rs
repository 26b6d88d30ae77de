//! What a caller asks of the codec: error bounds, methods, per-method settings, windows,
//! scales, decode options. Everything the CLI parses has a `FromStr` here.

use crate::container::Limits;
use crate::error::{Error, Result};
use crate::methods::{Method, MethodParams};
use crate::model::Window;
use crate::quant::ErrorBound;
use std::str::FromStr;

/// Options for [`encode`](crate::encode); build them with [`Encoder`](crate::Encoder) or
/// start from `EncodeOptions::default()` (lossless, best method).
#[derive(Clone, Debug, Default)]
#[non_exhaustive]
pub struct EncodeOptions {
    /// Guarantee every valid sample decodes within this bound; `None` = lossless unless a
    /// site count or RMSE is given.
    pub max_error: Option<ErrorBound>,
    /// The methods to write, one section each; the smallest becomes the primary section,
    /// the others optional sections `vtz decode --section` can pick. Empty = `best`: the
    /// smallest of the methods that meet the request, alone.
    pub methods: Vec<Method>,
    /// Settings each method reads (`params.fis.k`, `params.sibson.sites`, …).
    pub params: MethodParams,
    /// Aim for a file of at most this many bytes: the smallest max-error bound (found by
    /// bisection) whose file fits. Excludes `max_error`, `params.sibson.rmse` and `params.sibson.sites`.
    pub target_bytes: Option<u64>,
    /// Free-form JSON stored in a metadata section (e.g. provenance).
    pub metadata: Option<String>,
    /// Tile side in samples: a raster larger than this in either direction is cut into
    /// tiles that encode and decode independently (container version 5). `None` = tiles of
    /// [`DEFAULT_TILE`](crate::DEFAULT_TILE) for rasters of more than 4096² samples
    /// (whatever their shape), else untiled; `Some(0)` = never tile (version 1).
    pub tile: Option<u32>,
    /// Threads for a tiled encode (0 = what the machine offers); the bytes are the same
    /// for every value.
    pub threads: usize,
    /// Encoder effort 1..=9, speed against size, as JPEG XL and zstd users know it; `None`
    /// = [`DEFAULT_EFFORT`](crate::DEFAULT_EFFORT). Read by the methods that have choices to
    /// make (the residual layer: 1–5 its lane coding, the fastest to decode, except 2, its
    /// fast coding; [`COMPACT_EFFORT`](crate::COMPACT_EFFORT) (6) its range-coded predictors,
    /// 6–8 % smaller and 2–6× slower to decode; 7–9 all of them, the smallest kept).
    pub effort: Option<u8>,
    /// Set by the tiled encoder for each tile of a version-4 file: the residual layer
    /// keeps a coding without coarse levels (the weighted scan) only where it saves more
    /// than [`LEVELS_FIRST_MARGIN`](crate::methods::LEVELS_FIRST_MARGIN), since an overview
    /// reads such a tile's whole block instead of its first chunks.
    pub(crate) levels_first: bool,
}

/// A resampling factor `num/den` (2/1 doubles the resolution, 1/4 quarters it), always in
/// lowest terms when it comes from [`Scale::parse`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Scale {
    /// Numerator: output samples per `den` source samples.
    pub num: u32,
    /// Denominator.
    pub den: u32,
}

impl Scale {
    /// Parse `2`, `0.25`, `1e-3` or `3/2` exactly: a decimal is the fraction it writes
    /// (`0.001` is 1/1000), in lowest terms. A value whose numerator or denominator does not
    /// fit 32 bits (`0.3333333333333333`, `1e12`) is refused, never rounded: give it as a
    /// fraction (`1/3`). How large a scale may be is a matter of the output's size, which
    /// the decoder checks against its limits.
    pub fn parse(s: &str) -> Result<Scale> {
        let t = s.trim();
        let bad = || Error::invalid(format!("scale '{t}' is not a positive number or fraction"));
        let (num, den) = match t.split_once('/') {
            Some((a, b)) => {
                let int = |x: &str| {
                    let x = x.trim();
                    if x.is_empty() || !x.bytes().all(|c| c.is_ascii_digit()) {
                        return None;
                    }
                    // Leading zeros are harmless; a value over u128 is certainly over u32.
                    let x = x.trim_start_matches('0');
                    Some(if x.is_empty() {
                        0
                    } else {
                        x.parse::<u128>().unwrap_or(u128::MAX)
                    })
                };
                match (int(a), int(b)) {
                    (Some(a), Some(b)) => (a, b),
                    _ => return Err(bad()),
                }
            }
            None => parse_decimal(t).ok_or_else(bad)?,
        };
        if num == 0 || den == 0 {
            return Err(bad());
        }
        let g = gcd(num, den);
        let (num, den) = (num / g, den / g);
        match (u32::try_from(num), u32::try_from(den)) {
            (Ok(num), Ok(den)) => Ok(Scale { num, den }),
            _ => Err(Error::invalid(format!(
                "scale '{t}' is not representable exactly: a scale is a fraction N/D with N and D from 1 to {} in lowest terms (write e.g. 1/3 for a third)",
                u32::MAX
            ))),
        }
    }

    /// The same factor in lowest terms (a `Scale` built by hand may not be).
    pub(crate) fn reduced(self) -> Scale {
        let g = gcd(self.num.max(1) as u128, self.den.max(1) as u128) as u32;
        Scale {
            num: self.num.max(1) / g,
            den: self.den.max(1) / g,
        }
    }
}

impl std::fmt::Display for Scale {
    /// `2`, `1/2`, `3/2`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.den == 1 {
            write!(f, "{}", self.num)
        } else {
            write!(f, "{}/{}", self.num, self.den)
        }
    }
}

fn gcd(mut a: u128, mut b: u128) -> u128 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// `digits[.digits][e[±]digits]` as an exact fraction; `None` when it is not one (or is so
/// long that it could never fit a `Scale`, which the caller then reports as unrepresentable
/// through an overflowing value).
fn parse_decimal(t: &str) -> Option<(u128, u128)> {
    let (mant, exp) = match t.find(['e', 'E']) {
        Some(i) => (&t[..i], Some(&t[i + 1..])),
        None => (t, None),
    };
    let exp: i64 = match exp {
        Some(e) => {
            let d = e.strip_prefix('+').unwrap_or(e);
            let digits = d.strip_prefix('-').unwrap_or(d);
            if digits.is_empty() || !digits.bytes().all(|c| c.is_ascii_digit()) {
                return None;
            }
            d.parse()
                .unwrap_or(if d.starts_with('-') { -1000 } else { 1000 })
        }
        None => 0,
    };
    let (int, frac) = mant.split_once('.').unwrap_or((mant, ""));
    if (int.is_empty() && frac.is_empty())
        || !int.bytes().chain(frac.bytes()).all(|c| c.is_ascii_digit())
    {
        return None;
    }
    let all = format!("{int}{frac}");
    let mut digits = all.trim_start_matches('0');
    let mut frac_len = frac.len() as i64 - exp;
    while digits.len() > 1 && digits.ends_with('0') {
        digits = &digits[..digits.len() - 1];
        frac_len -= 1;
    }
    // Too many digits or too large an exponent for any 32-bit fraction: u128::MAX stands
    // for "too large" and reaches the unrepresentable message.
    let big = (u128::MAX, 1);
    if digits.is_empty() {
        return Some((0, 1));
    }
    if digits.len() > 30 || !(-30..=30).contains(&frac_len) {
        return Some(big);
    }
    let m: u128 = digits.parse().ok()?;
    let p = 10u128.pow(frac_len.unsigned_abs() as u32);
    Some(if frac_len >= 0 {
        (m, p)
    } else {
        (m.saturating_mul(p), 1)
    })
}

impl FromStr for Scale {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Scale::parse(s)
    }
}

/// Which section a decoder reads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum SectionChoice {
    /// The file's primary section.
    #[default]
    Primary,
    /// The section at this index of the directory.
    Index(usize),
    /// The first section written by this method.
    Method(Method),
}

impl FromStr for SectionChoice {
    type Err = Error;
    /// An index (`1`) or a method name (`haar`).
    fn from_str(s: &str) -> Result<Self> {
        match s.parse::<usize>() {
            Ok(i) => Ok(SectionChoice::Index(i)),
            Err(_) => Method::parse(s).map(SectionChoice::Method),
        }
    }
}

/// Options for [`decode_with`](crate::decode_with) and the [`Decoder`](crate::Decoder).
#[derive(Clone, Debug, Default)]
#[non_exhaustive]
pub struct DecodeOptions {
    /// Limits on everything the file or an option would allocate.
    pub limits: Limits,
    /// Decode this section instead of the primary one.
    pub section: SectionChoice,
    /// Sites section: decode only the first N sites (a coarser surface).
    pub sites: Option<usize>,
    /// Sites section: decode only the first K levels.
    pub levels: Option<usize>,
    /// Decode only this window.
    pub window: Option<Window>,
    /// Threads for evaluating the surface (0 = what the machine offers). The output is
    /// bit-identical for every value.
    pub threads: usize,
    /// Decode at this factor times the resolution, GDAL's way (⌊w·s⌋ × ⌊h·s⌋ samples over
    /// the same extent, pixel size / s): a sites section evaluates its surface there,
    /// every other section and a tiled file interpolate the decoded samples (bicubic; the
    /// README's `--scale`). A scale of 1 is the plain decode.
    pub scale: Option<Scale>,
    /// Decode overview level K ≥ 1 (GDAL's overviews, `vtz decode --overview K`):
    /// ⌈w/2^K⌉ × ⌈h/2^K⌉ samples, pixel size × 2^K, the same corner; `window` is then in
    /// the overview's samples. Sample (x, y) is a decoded sample of the source at (x·2^K,
    /// y·2^K): an untiled file's full decode there, bit for bit; in a tiled file, the
    /// decode of the tile whose core holds that position, at the point of the tile's own
    /// 2^K lattice nearest it (at most 2^(K−1) samples away; no blending across tile
    /// margins). The residual layer's interpolation codings decode only their coarse
    /// levels for it (about 1/4^K of the work); other methods decode in full.
    pub overview: Option<u32>,
    /// Tiled files: a tile that fails its checksum or its decode becomes nodata (listed by
    /// [`Decoder::skipped`](crate::Decoder::skipped)) instead of failing the decode.
    pub skip_corrupt: bool,
    /// Sites files: the surface through the sites (default Sibson, the one coded; the
    /// others ignore the file's bound).
    pub surface: super::surface::Surface,
}
