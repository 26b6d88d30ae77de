//! The representations vtz writes: one folder per method, every one reached through
//! [`REGISTRY`] and nothing else.
//!
//! A method turns a raster into one section payload and back. It uses the shared rooms
//! below it (quant, predict, geometry, entropy, container framing helpers) and never imports
//! another method. Adding a method is a new folder with a type implementing
//! [`Representation`] and one line in the `registry!` below; the codec, `vtz info`, `vtz
//! decode --section NAME`, `--method NAME` and `vtz rd` find it there.

/// Declares each method's folder, its `Method` constant and its place in [`REGISTRY`] —
/// one line per method, in the order `--method best` tries them (on equal sizes the first
/// wins).
macro_rules! registry {
    ($($(#[$doc:meta])* $folder:ident: $konst:ident => $imp:ident,)*) => {
        $(pub(crate) mod $folder;)*

        /// Every method, in the order `--method best` tries them.
        pub(crate) static REGISTRY: &[&dyn Representation] = &[$(&$folder::$imp),*];

        impl Method {
            $($(#[$doc])* pub const $konst: Method = Method(&$folder::$imp);)*
        }
    };
}

registry! {
    /// Greedy Voronoi/Sibson sites (needs a bound, an RMSE or a site count).
    sites: SIBSON => Sibson,
    /// Every sample, predicted and quantized (lossless or within a bound).
    grid: GRID => Grid,
    /// 2-D Haar wavelet, quantized and range coded (the Voronoi paper's baseline).
    haar: HAAR => Haar,
    /// Fractal interpolation surface on every k-th sample (the fractal-interpolation paper).
    fis: FIS => Fis,
    /// Every sample predicted from decoded ones (multilevel interpolation or the weighted
    /// scan predictor), quantized closed loop and context coded on the data's own lattice.
    residual: RESIDUAL => Residual,
}

pub use fis::FisOptions;
pub use haar::HaarOptions;
pub use residual::{COMPACT_EFFORT, DEFAULT_EFFORT};
pub use sites::{Norm, SibsonOptions};

use crate::container::{Header, SectionKind};
use crate::error::{Error, Result};
use crate::model::{Raster, Window};
use std::fmt;
use std::str::FromStr;

/// A representation vtz can write (one per folder of `src/methods/`): `sibson`, `grid`,
/// `haar`, `fis`. Parse one by name with [`FromStr`]; list them with [`Method::all`].
#[derive(Clone, Copy)]
pub struct Method(pub(crate) &'static dyn Representation);

impl Method {
    /// Every method this build knows, in the order `best` tries them.
    pub fn all() -> impl Iterator<Item = Method> {
        REGISTRY.iter().map(|&m| Method(m))
    }

    /// The method's name as the CLI spells it.
    pub fn name(self) -> &'static str {
        self.0.name()
    }

    /// Whether the method keeps statistics of its sections ([`crate::Decoder::stats`]).
    pub fn has_stats(self) -> bool {
        self.0.has_stats()
    }

    /// Parse a method name (or alias), case-insensitive.
    pub fn parse(s: &str) -> Result<Method> {
        by_name(s).map(Method).ok_or_else(|| {
            let names: Vec<_> = Method::all().map(|m| m.name()).collect();
            Error::invalid(format!(
                "unknown method '{}' (best, {})",
                s.to_ascii_lowercase(),
                names.join(", ")
            ))
        })
    }

    /// Parse a `--method` value: `best` (an empty list) or a comma list of methods.
    pub fn parse_list(s: &str) -> Result<Vec<Method>> {
        let parts: Vec<&str> = s.split(',').collect();
        if parts.len() == 1 && parts[0].eq_ignore_ascii_case("best") {
            return Ok(Vec::new());
        }
        parts
            .iter()
            .map(|p| {
                if p.eq_ignore_ascii_case("best") {
                    Err(Error::invalid("'best' cannot be part of a method list"))
                } else {
                    Method::parse(p)
                }
            })
            .collect()
    }
}

impl FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::parse(s)
    }
}

impl PartialEq for Method {
    fn eq(&self, o: &Method) -> bool {
        self.name() == o.name()
    }
}
impl Eq for Method {}

impl fmt::Debug for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Method({})", self.name())
    }
}
impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The settings each method reads, one field per method that has any.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct MethodParams {
    /// Settings of the Sibson method.
    pub sibson: sites::SibsonOptions,
    /// Settings of the FIS method.
    pub fis: fis::FisOptions,
    /// Settings of the Haar method.
    pub haar: haar::HaarOptions,
}

/// Who a method is: its names and its section type.
pub(crate) struct Identity {
    /// The name the CLI and the API spell it with.
    pub name: &'static str,
    /// Other names `--method` accepts.
    pub aliases: &'static [&'static str],
    /// The section type code its payloads are stored under (spec/FORMAT.md).
    pub section: SectionKind,
    /// The section type's name in the spec, `vtz info` and `--section`.
    pub section_name: &'static str,
    /// Byte offset in its payloads of the stored max error (`f64`, spec/FORMAT.md), which
    /// `vtz verify` checks the decode against.
    pub bound_at: usize,
}

/// What one method is to the codec: its identity, its encoder, its decoder (full and
/// windowed) and its own description of a payload.
pub(crate) trait Representation: Sync {
    /// Its names and section type.
    fn id(&self) -> &'static Identity;
    fn name(&self) -> &'static str {
        self.id().name
    }
    fn aliases(&self) -> &'static [&'static str] {
        self.id().aliases
    }
    fn section(&self) -> SectionKind {
        self.id().section
    }
    fn section_name(&self) -> &'static str {
        self.id().section_name
    }
    /// When the options hold settings that only this method reads: the message for a caller
    /// who set them but chose another method.
    fn own_options(&self, _params: &MethodParams) -> Option<&'static str> {
        None
    }
    /// Whether its own settings are a stopping rule of their own (a site count, an RMSE),
    /// which a size target cannot be combined with.
    fn stops_by_itself(&self, _params: &MethodParams) -> bool {
        false
    }
    /// Its own rate control for a size target, when it has one (a quantizer step to
    /// bisect); otherwise the codec bisects the max-error bound.
    fn rate_knob(&self) -> Option<Knob> {
        None
    }
    /// Copy this method's own settings (and nothing else) from `from` into `to`.
    fn keep_own(&self, _from: &MethodParams, _to: &mut MethodParams) {}
    /// Whether `best` tries it for a lossless request.
    fn lossless_default(&self) -> bool {
        false
    }
    /// Encode the job's raster into a payload that meets the job's request, or say why not.
    fn encode(&self, job: &EncodeJob, progress: &mut dyn FnMut(f64)) -> Result<Encoded>;
    /// Decode the whole raster (invalid samples get the nodata fill).
    fn decode_full(&self, job: &DecodeJob) -> Result<Vec<f64>>;
    /// Decode the job's window; methods that can evaluate a window alone override this.
    fn decode(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        let full = self.decode_full(job)?;
        let (w, h) = (job.header.width as usize, job.header.height as usize);
        if (
            job.window.x,
            job.window.y,
            job.window.width,
            job.window.height,
        ) == (0, 0, w, h)
        {
            // The whole raster: no copy.
            return Ok(full);
        }
        Ok(crop(&full, w, job.window))
    }
    /// The decoded samples at every 2^`j`-th row and column (rows and columns 0, 2^j, …:
    /// ⌈w/2^j⌉ × ⌈h/2^j⌉ values), exactly the full decode's there. A method whose coding has
    /// coarse levels decodes only those (the residual layer's interpolation codings); the
    /// others decode everything and keep every 2^j-th sample.
    fn decode_decimated(&self, job: &DecodeJob, j: u32) -> Result<Vec<f64>> {
        let full = self.decode_full(job)?;
        Ok(decimate(
            &full,
            job.header.width as usize,
            job.header.height as usize,
            j,
        ))
    }
    /// For each overview K = 1, 2, … (element K − 1), the bytes of the payload that
    /// [`Representation::decode_decimated`] with `j` = K reads, when that is less than the
    /// whole (coarser overviews than the last element read what it reads); empty when every
    /// overview reads the whole payload. Version 4 cuts its tile blocks there.
    fn overview_prefixes(&self, _job: &DecodeJob) -> Result<Vec<usize>> {
        Ok(Vec::new())
    }
    /// Whether the payload is progressive (a prefix of `--sites N` / `--level K` decodes).
    fn progressive(&self) -> bool {
        false
    }
    /// Evaluate the method's own continuous surface on the `size` grid scaled by
    /// `num/den` (GDAL's pixel-is-area layout, see `codec::resample`); `None` for methods
    /// without one, whose decoded samples the codec interpolates instead.
    fn decode_scaled(
        &self,
        _job: &DecodeJob,
        _num: u32,
        _den: u32,
        _size: (usize, usize),
    ) -> Result<Option<Scaled>> {
        Ok(None)
    }
    /// The method's own statistics of a payload (what `vtz info --stats` prints); `None`
    /// for a method that keeps none.
    fn describe(&self, _job: &DecodeJob) -> Result<Option<Stats>> {
        Ok(None)
    }
    /// Whether [`Representation::describe`] reports statistics (so its section is worth
    /// reading for them; `vtz info --json` shows a key for each such method).
    fn has_stats(&self) -> bool {
        false
    }
    /// Its encode time per sample relative to the residual layer's at the default effort
    /// (measured: Kauai 1201², one thread, at 1 m and 1 % of the range). The progress bar
    /// of a `best` encode gives each stage this share, so it moves evenly and reaches 100 %.
    fn relative_cost(&self) -> f64 {
        1.0
    }
    /// Whether its encoder reads the flat regions' values (`EncodeJob::flat`); the codec
    /// keeps them per sample only for such a method (they cost 8 bytes per sample).
    fn uses_flat_values(&self) -> bool {
        false
    }
    /// Whether its payloads store sites ([`Representation::sites`]).
    fn stores_sites(&self) -> bool {
        false
    }
    /// The sites a payload stores, in importance order, with their level; `None` for
    /// methods that store no sites.
    fn sites(&self, _job: &DecodeJob) -> Result<Option<Vec<Site>>> {
        Ok(None)
    }
}

/// What a method encodes: the raster, its header, the max error in data units (`None` or 0
/// = lossless) and the caller's options, with the surface it is layered on when it refines
/// another section (reserved for the residual layer; `None` for every method today).
pub(crate) struct EncodeJob<'a> {
    pub raster: &'a Raster,
    pub header: &'a Header,
    pub max_error: Option<f64>,
    pub params: &'a MethodParams,
    /// Encoder effort 1..=9 (speed against size), for the methods that have the choice.
    pub effort: u8,
    /// The flat regions' values (NaN outside them), which the decoder knows before the
    /// method runs: `raster` marks their samples invalid, and a method may use the values
    /// (as known neighbours) but need not represent them.
    pub flat: Option<&'a [f64]>,
    #[allow(dead_code)]
    pub base: Option<&'a [f64]>,
    /// Prefer codings with coarse levels first (a version-4 tile, whose overviews read a
    /// prefix of such a coding): one without them must save more than
    /// [`LEVELS_FIRST_MARGIN`].
    pub levels_first: bool,
    /// `best`: the smallest candidate's payload so far; a method that can tell early that
    /// it will be larger may stop with [`Error::Unmet`] and [`SIZE_CAP_MESSAGE`] (the sites
    /// and FIS encoders do).
    pub size_cap: Option<usize>,
}

/// The message of the error a method gives when it stops at [`EncodeJob::size_cap`]: not a
/// failure to meet the request, so `best` does not report it.
pub(crate) const SIZE_CAP_MESSAGE: &str =
    "stopped early: this method's payload would be larger than a candidate's already encoded";

/// What a coding without coarse levels (the residual layer's weighted scan, and since
/// issue 37 every method but the residual layer in `best`) must save over the smallest
/// coding with them to be kept in a version-4 or -5 tile: an overview reads the whole
/// block of such a tile (in version 5 it lies in the heads), the first chunks of the
/// others'. Measured on the 20000² mosaic of benches/tiles at 1 m (benches/README.md,
/// "Remote reads"): at 3 % (issue 36's first stop) the file grew 1.7 % against no margin
/// and tiles with coarse levels first went from 69 to 265 of 400; at the lane-coded default
/// 66 tiles kept the grid, 0.89 MB of the 2.1 MB a 1024² overview reads. The grid saves 5–27 %
/// on them (the lane coding of each tile alone, `vtz encode --method residual|grid`): at
/// 15 % 30 of them take the lane coding for +0.07 % of the file, and their 0.76 MB leave
/// the heads.
pub const LEVELS_FIRST_MARGIN: f64 = 0.15;

impl EncodeJob<'_> {
    pub fn lossless(&self) -> bool {
        self.max_error.is_none_or(|e| e == 0.0)
    }
}

/// One encoded section payload before it goes into the container.
pub(crate) struct Encoded {
    pub payload: Vec<u8>,
    /// The max error the decoded payload keeps on every valid sample (0 = lossless).
    pub bound: f64,
    /// The method's statistics, when it measures them while encoding.
    pub stats: Option<Stats>,
}

impl From<(Vec<u8>, f64)> for Encoded {
    /// A payload and its bound, without statistics.
    fn from((payload, bound): (Vec<u8>, f64)) -> Encoded {
        Encoded {
            payload,
            bound,
            stats: None,
        }
    }
}

/// What a method decodes: a payload, the header and mask, the window and the decode options
/// a progressive method reads (`sites`, `levels`, `threads`).
pub(crate) struct DecodeJob<'a> {
    pub payload: &'a [u8],
    pub header: &'a Header,
    pub mask: Option<&'a [bool]>,
    pub window: Window,
    pub sites: Option<usize>,
    pub levels: Option<usize>,
    pub threads: usize,
    /// The flat regions' values (NaN outside them); `mask` already marks their samples
    /// invalid, and the codec writes their values over whatever the method decodes there.
    pub flat: Option<&'a crate::container::flat::Flat>,
    /// The decoded surface of the section this one refines (reserved for the residual
    /// layer; `None` for every method today).
    #[allow(dead_code)]
    pub base: Option<&'a [f64]>,
    /// Fraction of the decode done (0..1); methods that take long call it as they go.
    pub progress: &'a (dyn Fn(f64) + Sync),
}

/// A method's own rate control: a parameter where larger means smaller files, bisected
/// geometrically over `span` × the value range in `steps` steps.
pub(crate) struct Knob {
    /// What the largest value is, for the message when even it does not fit.
    pub what: &'static str,
    pub span: (f64, f64),
    pub steps: usize,
    /// Set the parameter in the method's settings.
    pub set: fn(&mut MethodParams, f64),
}

/// A surface evaluated on a resampled grid: values, validity, width, height.
pub(crate) type Scaled = (Vec<f64>, Vec<bool>, usize, usize);

/// A method's own statistics of one section (what `vtz info --stats` shows).
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct Stats {
    /// The method that wrote the section.
    pub method: Method,
    /// Named values, in the method's order (the keys of `vtz info --stats --json`).
    pub values: Vec<(&'static str, StatValue)>,
    /// The same for people, one line each.
    pub lines: Vec<String>,
}

/// One statistic's value.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum StatValue {
    /// A count.
    Count(u64),
    /// A measured number.
    Number(f64),
    /// A list of counts (e.g. sites per level).
    Counts(Vec<u64>),
}

impl Stats {
    /// The value named `key`.
    pub fn get(&self, key: &str) -> Option<&StatValue> {
        self.values.iter().find(|(k, _)| *k == key).map(|(_, v)| v)
    }
    /// The count named `key`.
    pub fn count(&self, key: &str) -> Option<u64> {
        match self.get(key)? {
            StatValue::Count(n) => Some(*n),
            _ => None,
        }
    }
    /// The number named `key` (a count converts).
    pub fn number(&self, key: &str) -> Option<f64> {
        match self.get(key)? {
            StatValue::Number(v) => Some(*v),
            StatValue::Count(n) => Some(*n as f64),
            StatValue::Counts(_) => None,
        }
    }
}

/// One stored site of a sites section.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Site {
    /// Position in importance order (0 = inserted first).
    pub rank: usize,
    /// The progressive level it belongs to.
    pub level: usize,
    /// Column of the sample it sits on.
    pub col: usize,
    /// Row of the sample it sits on (0 = north).
    pub row: usize,
    /// The stored (quantized) height.
    pub height: f64,
}

/// The method registered under `name` or one of its aliases (case-insensitive).
pub(crate) fn by_name(name: &str) -> Option<&'static dyn Representation> {
    let n = name.to_ascii_lowercase();
    REGISTRY
        .iter()
        .copied()
        .find(|m| m.name() == n || m.section_name() == n || m.aliases().contains(&n.as_str()))
}

/// The method whose sections have type `kind`.
pub(crate) fn by_section(kind: SectionKind) -> Option<&'static dyn Representation> {
    REGISTRY.iter().copied().find(|m| m.section() == kind)
}

/// Crop a full decode to a window.
/// Every 2^`j`-th sample of every 2^`j`-th row of a `w` × `h` raster (from row and column 0).
pub(crate) fn decimate<T: Copy>(v: &[T], w: usize, h: usize, j: u32) -> Vec<T> {
    let s = 1usize << j;
    let mut out = Vec::with_capacity(w.div_ceil(s) * h.div_ceil(s));
    for y in (0..h).step_by(s) {
        out.extend(v[y * w..y * w + w].iter().step_by(s).copied());
    }
    out
}

pub(crate) fn crop<T: Copy>(v: &[T], width: usize, win: Window) -> Vec<T> {
    let mut out = Vec::with_capacity(win.width * win.height);
    for y in win.y..win.y + win.height {
        out.extend_from_slice(&v[y * width + win.x..y * width + win.x + win.width]);
    }
    out
}
