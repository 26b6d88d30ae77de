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
    /// tiles that encode and decode independently (container version 2). `None` = tiles of
    /// [`DEFAULT_TILE`](crate::DEFAULT_TILE) for rasters of more than 4096² samples
    /// (whatever their shape), else untiled; `Some(0)` = never tile (version 1).
    pub tile: Option<u32>,
    /// Threads for a tiled encode (0 = what the machine offers); the bytes are the same
    /// for every value.
    pub threads: usize,
    /// Encoder effort 1..=9, speed against size, as JPEG XL and zstd users know it; `None`
    /// = [`DEFAULT_EFFORT`](crate::DEFAULT_EFFORT). Read by the methods that have choices to
    /// make (the residual layer); decoding speed does not depend on it.
    pub effort: Option<u8>,
}

/// A resampling factor `num/den` (2/1 doubles the resolution, 1/4 quarters it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Scale {
    /// Numerator: output samples per `den` source samples.
    pub num: u32,
    /// Denominator.
    pub den: u32,
}

impl Scale {
    /// Parse `2`, `0.25` or `3/2` (decimals become the nearest fraction with a denominator
    /// of at most 64).
    pub fn parse(s: &str) -> Result<Scale> {
        let bad = || Error::invalid(format!("scale '{s}' is not a positive number or fraction"));
        let (num, den) = if let Some((a, b)) = s.split_once('/') {
            (
                a.trim().parse::<u32>().map_err(|_| bad())?,
                b.trim().parse::<u32>().map_err(|_| bad())?,
            )
        } else {
            let v: f64 = s.trim().parse().map_err(|_| bad())?;
            if !(v > 0.0 && v <= 4096.0) {
                return Err(bad());
            }
            (1..=64u32)
                .map(|d| ((v * d as f64).round().max(1.0) as u32, d))
                .min_by(|a, b| {
                    let ea = (a.0 as f64 / a.1 as f64 - v).abs();
                    let eb = (b.0 as f64 / b.1 as f64 - v).abs();
                    ea.total_cmp(&eb)
                })
                .expect("non-empty")
        };
        if num == 0 || den == 0 {
            return Err(bad());
        }
        Ok(Scale { num, den })
    }
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
    /// Sites section: evaluate the continuous surface on a grid scaled by this factor.
    /// In a tiled file, any method: the decoded samples resampled bilinearly.
    pub scale: Option<Scale>,
    /// Tiled files: a tile that fails its checksum or its decode becomes nodata (listed by
    /// [`Decoder::skipped`](crate::Decoder::skipped)) instead of failing the decode.
    pub skip_corrupt: bool,
    /// Sites files: the surface through the sites (default Sibson, the one coded; the
    /// others ignore the file's bound).
    pub surface: super::surface::Surface,
}
