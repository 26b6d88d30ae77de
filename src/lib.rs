//! vtz: a compression codec and file format for elevation data with a hard error bound.
//!
//! Pipeline: raster I/O ([`raster`]) → a representation section ([`grid`]) → entropy coding
//! ([`entropy`]) → the container ([`container`]); decoding runs the same way back.
//!
//! ```no_run
//! use std::path::Path;
//! let dem = vtz::raster::read_path(Path::new("corpus/scape_crater.png"), &Default::default())?;
//! let bytes = vtz::encode(&dem, &vtz::EncodeOptions { max_error: Some(vtz::ErrorBound::Abs(1.0)), ..Default::default() })?;
//! let back = vtz::decode(&bytes)?;
//! assert!(vtz::metrics::compare(&dem, &back)?.max_error <= 1.0);
//! # Ok::<(), vtz::Error>(())
//! ```
#![forbid(unsafe_code)]

pub mod container;
pub mod entropy;
pub mod error;
pub mod fis;
pub mod fsio;
pub mod grid;
pub mod haar;
pub mod metrics;
pub mod raster;
pub mod render;
pub mod sibson;
pub mod sites;
#[cfg(test)]
mod testutil;
pub mod triangulation;

pub use container::Limits;
pub use error::{Error, Result};
pub use raster::{Format, Georef, Raster, RasterType, SampleType};

use container::{Header, SF_REQUIRED, Section, SectionKind};

/// A max-error bound as the user gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ErrorBound {
    /// In data units (e.g. metres).
    Abs(f64),
    /// In percent of the value range (max − min over valid samples).
    PercentOfRange(f64),
}

impl ErrorBound {
    /// Parse `"2.5"` (data units) or `"1%"` (of the value range).
    pub fn parse(s: &str) -> Result<ErrorBound> {
        let t = s.trim();
        let (num, pct) = match t.strip_suffix('%') {
            Some(n) => (n.trim(), true),
            None => (t, false),
        };
        let v: f64 = num
            .parse()
            .map_err(|_| Error::invalid(format!("'{s}' is not an error bound (e.g. 2.5 or 1%)")))?;
        if !(v >= 0.0 && v.is_finite()) {
            return Err(Error::invalid(format!("error bound '{s}' must be ≥ 0")));
        }
        Ok(if pct {
            ErrorBound::PercentOfRange(v)
        } else {
            ErrorBound::Abs(v)
        })
    }

    /// The bound in data units for a raster with this value range.
    pub fn absolute(self, range: Option<(f64, f64)>) -> f64 {
        match self {
            ErrorBound::Abs(v) => v,
            ErrorBound::PercentOfRange(p) => range.map_or(0.0, |(lo, hi)| (hi - lo) * p / 100.0),
        }
    }
}

/// Which representation [`encode`] writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Method {
    /// The smallest of the methods that meet the request (the default).
    #[default]
    Best,
    /// Greedy Voronoi/Sibson sites (needs a bound, an RMSE or a site count).
    Sibson,
    /// Every sample, predicted and quantized (lossless or within a bound).
    Grid,
    /// Fractal interpolation surface on every k-th sample (the fractal-interpolation paper).
    Fis,
    /// 2-D Haar wavelet, quantized and range coded (the Voronoi paper's baseline).
    Haar,
}

impl Method {
    pub fn parse(s: &str) -> Result<Method> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "best" => Method::Best,
            "sibson" | "sites" => Method::Sibson,
            "grid" => Method::Grid,
            "fis" | "fractal" => Method::Fis,
            "haar" | "wavelet" => Method::Haar,
            o => {
                return Err(Error::invalid(format!(
                    "unknown method '{o}' (best, sibson, grid, fis, haar)"
                )));
            }
        })
    }

    /// The method's name as the CLI spells it.
    pub fn name(self) -> &'static str {
        match self {
            Method::Best => "best",
            Method::Sibson => "sibson",
            Method::Grid => "grid",
            Method::Fis => "fis",
            Method::Haar => "haar",
        }
    }

    fn of_kind(k: SectionKind) -> Method {
        match k {
            SectionKind::Sites => Method::Sibson,
            SectionKind::Fis => Method::Fis,
            SectionKind::Haar => Method::Haar,
            _ => Method::Grid,
        }
    }
}

/// Options for [`encode`].
#[derive(Clone, Debug, Default)]
pub struct EncodeOptions {
    /// Guarantee every valid sample decodes within this bound; `None` = lossless unless a
    /// site count or RMSE is given.
    pub max_error: Option<ErrorBound>,
    /// Sibson: stop when the RMSE is at most this.
    pub rmse: Option<ErrorBound>,
    /// Sibson: stop at this many sites.
    pub sites: Option<usize>,
    /// Sibson: refinement norm.
    pub norm: sites::Norm,
    pub method: Method,
    /// Also write these methods' sections (for comparison); the smallest of all becomes the
    /// primary section, the others are optional sections `vtz decode --section` can pick.
    pub also: Vec<Method>,
    /// FIS: subgrid spacing k (default: the cheapest k that meets the bound).
    pub fis_k: Option<usize>,
    /// FIS: one fixed vertical scaling factor (the paper's 0.02) instead of fitted ones.
    pub fis_s: Option<f64>,
    /// Haar: a fixed coefficient quantizer step instead of a bound (what size targets
    /// bisect, as the RMSE-optimal rate control for a wavelet).
    pub haar_step: Option<f64>,
    /// Sibson: height step as a multiple of the error target (default 1).
    pub step_factor: Option<f64>,
    /// Aim for a file of at most this many bytes: the smallest max-error bound (found by
    /// bisection) whose file fits. Excludes `max_error`, `rmse` and `sites`.
    pub target_bytes: Option<u64>,
    /// Free-form JSON stored in a metadata section (e.g. provenance).
    pub metadata: Option<String>,
}

/// A rectangle of samples: column, row, width, height.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub x: usize,
    pub y: usize,
    pub width: usize,
    pub height: usize,
}

impl Window {
    /// Parse `x,y,w,h`.
    pub fn parse(s: &str) -> Result<Window> {
        let v: Vec<usize> = s
            .split(',')
            .map(|p| p.trim().parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| Error::invalid(format!("window '{s}' is not x,y,width,height")))?;
        match v[..] {
            [x, y, width, height] => Ok(Window {
                x,
                y,
                width,
                height,
            }),
            _ => Err(Error::invalid(format!(
                "window '{s}' is not x,y,width,height"
            ))),
        }
    }
}

/// Options for [`decode_with`].
#[derive(Clone, Debug, Default)]
pub struct DecodeOptions {
    pub limits: Limits,
    /// Decode this section (index in the directory) instead of the primary one.
    pub section: Option<usize>,
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
    pub scale: Option<Scale>,
}

/// A resampling factor `num/den` (2/1 doubles the resolution, 1/4 quarters it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Scale {
    pub num: u32,
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

/// What [`encode_report`] produced besides the bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodeReport {
    /// Max error guaranteed on every valid sample (0 = lossless), in data units.
    pub max_error: f64,
    /// The method that was written.
    pub method: Method,
    /// Statistics of the sites section, when one was written.
    pub sites: Option<sites::SitesStats>,
}

/// Encode a raster into `.vtz` bytes.
pub fn encode(raster: &Raster, opts: &EncodeOptions) -> Result<Vec<u8>> {
    encode_report(raster, opts).map(|(b, _)| b)
}

/// Encode a raster into `.vtz` bytes and report the bound achieved.
pub fn encode_report(raster: &Raster, opts: &EncodeOptions) -> Result<(Vec<u8>, EncodeReport)> {
    encode_progress(raster, opts, &mut |_| {})
}

/// [`encode_report`] with a progress callback (fraction done, 0..1).
pub fn encode_progress(
    raster: &Raster,
    opts: &EncodeOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, EncodeReport)> {
    match opts.target_bytes {
        Some(t) => encode_to_size(raster, opts, t, progress),
        None => encode_once(raster, opts, progress),
    }
}

/// Bisect the max-error bound (geometrically, between 10⁻⁶ of the range and the range) for
/// the smallest bound whose file is at most `target` bytes.
fn encode_to_size(
    raster: &Raster,
    opts: &EncodeOptions,
    target: u64,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, EncodeReport)> {
    if opts.max_error.is_some() || opts.rmse.is_some() || opts.sites.is_some() {
        return Err(Error::invalid(
            "a size target excludes --max-error, --rmse and --sites",
        ));
    }
    let range = raster.valid_range().map_or(0.0, |(lo, hi)| hi - lo);
    let mut o = opts.clone();
    o.target_bytes = None;
    let mut try_bound = |e: f64| {
        o.max_error = Some(ErrorBound::Abs(e));
        encode_once(raster, &o, &mut |_| {})
    };
    // Lossless first: if it fits, nothing is lost.
    let lossless = {
        let mut l = opts.clone();
        l.target_bytes = None;
        l.method = Method::Grid;
        l.also.clear();
        (l.fis_k, l.fis_s, l.haar_step) = (None, None, None);
        encode_once(raster, &l, &mut |_| {})?
    };
    if lossless.0.len() as u64 <= target || range <= 0.0 {
        return Ok(lossless);
    }
    type Encoded = (Vec<u8>, EncodeReport);
    /// Geometric bisection on a parameter where larger means smaller files: the smallest
    /// value in [lo, hi] whose file fits.
    fn bisect(
        (mut lo, mut hi): (f64, f64),
        steps: usize,
        target: u64,
        what: &str,
        try_x: &mut dyn FnMut(f64) -> Result<Encoded>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<Encoded> {
        let mut best = try_x(hi)?;
        if best.0.len() as u64 > target {
            return Err(Error::invalid(format!(
                "cannot fit in {target} bytes: {} bytes at {what}",
                best.0.len()
            )));
        }
        for k in 0..steps {
            let mid = (lo * hi).sqrt();
            let r = try_x(mid)?;
            if r.0.len() as u64 <= target {
                hi = mid;
                best = r;
            } else {
                lo = mid;
            }
            progress((k + 1) as f64 / steps as f64);
        }
        Ok(best)
    }
    if opts.method == Method::Haar && opts.also.is_empty() {
        // The wavelet's own rate control: the smallest coefficient step (data units) whose
        // file fits.
        let mut o = opts.clone();
        o.target_bytes = None;
        let mut try_step = |q: f64| {
            o.haar_step = Some(q);
            encode_once(raster, &o, &mut |_| {})
        };
        let span = (range * 1e-6, range * 4.0);
        return bisect(
            span,
            24,
            target,
            "the coarsest Haar step",
            &mut try_step,
            progress,
        );
    }
    bisect(
        (range * 1e-6, range),
        14,
        target,
        "a max error of the whole range",
        &mut try_bound,
        progress,
    )
}

/// One encoded representation, before it goes into the container.
struct Candidate {
    kind: SectionKind,
    payload: Vec<u8>,
    bound: f64,
    stats: Option<sites::SitesStats>,
}

/// Encode `raster` with one concrete method (not `Best`).
fn encode_method(
    m: Method,
    raster: &Raster,
    header: &Header,
    opts: &EncodeOptions,
    e: Option<f64>,
    progress: &mut dyn FnMut(f64),
) -> Result<Candidate> {
    let sibson_asked = opts.sites.is_some() || opts.rmse.is_some();
    if m != Method::Sibson && sibson_asked {
        return Err(Error::invalid("--sites and --rmse need the sibson method"));
    }
    if m != Method::Fis && (opts.fis_k.is_some() || opts.fis_s.is_some()) {
        return Err(Error::invalid("the FIS options need the fis method"));
    }
    if m != Method::Haar && opts.haar_step.is_some() {
        return Err(Error::invalid("a Haar step needs the haar method"));
    }
    let lossless = e.is_none_or(|e| e == 0.0);
    Ok(match m {
        Method::Sibson => {
            if lossless && !sibson_asked {
                return Err(Error::invalid(
                    "the sibson method needs --max-error, --rmse or --sites",
                ));
            }
            let sp = sites::SitesParams {
                max_error: e,
                rmse: opts.rmse.map(|b| b.absolute(header.range)),
                max_sites: opts.sites,
                norm: opts.norm,
                step_factor: opts.step_factor,
            };
            let (payload, stats) = sites::encode(raster, header, &sp, progress)?;
            Candidate {
                kind: SectionKind::Sites,
                payload,
                bound: stats.max_error,
                stats: Some(stats),
            }
        }
        Method::Grid => {
            let (payload, bound) = grid::encode(
                raster,
                &grid::GridParams {
                    max_error: e.unwrap_or(0.0),
                },
            )?;
            Candidate {
                kind: SectionKind::Grid,
                payload,
                bound,
                stats: None,
            }
        }
        Method::Haar => {
            let (payload, bound) = match opts.haar_step {
                Some(step) => haar::encode_step(raster, step)?,
                None => haar::encode(
                    raster,
                    &haar::HaarParams {
                        max_error: e.unwrap_or(0.0),
                    },
                )?,
            };
            Candidate {
                kind: SectionKind::Haar,
                payload,
                bound,
                stats: None,
            }
        }
        Method::Fis => {
            if lossless && opts.fis_k.is_none() {
                return Err(Error::invalid(
                    "the fis method needs --max-error or --fis-k",
                ));
            }
            let (payload, st) = fis::encode(
                raster,
                &fis::FisParams {
                    max_error: e.filter(|&e| e > 0.0),
                    k: opts.fis_k,
                    fixed_s: opts.fis_s,
                },
            )?;
            Candidate {
                kind: SectionKind::Fis,
                payload,
                bound: st.max_error,
                stats: None,
            }
        }
        Method::Best => unreachable!("encode_method takes a concrete method"),
    })
}

fn encode_once(
    raster: &Raster,
    opts: &EncodeOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, EncodeReport)> {
    raster.validate()?;
    let mut header = Header::of(raster)?;
    let e = opts.max_error.map(|b| b.absolute(header.range));
    let sibson_asked = opts.sites.is_some() || opts.rmse.is_some();
    let lossless = e.is_none_or(|e| e == 0.0) && !sibson_asked;
    let mut cands: Vec<Candidate> = Vec::new();
    if opts.method == Method::Best {
        // Every method that can meet the request; the smallest wins. A method that cannot
        // (e.g. FIS at a bound no subgrid reaches) simply drops out.
        let tries: &[Method] = if sibson_asked {
            &[Method::Sibson]
        } else if lossless {
            &[Method::Grid]
        } else {
            &[Method::Sibson, Method::Grid, Method::Haar, Method::Fis]
        };
        let mut last_err = None;
        for &m in tries {
            match encode_method(m, raster, &header, opts, e, progress) {
                Ok(c) => cands.push(c),
                Err(err) => last_err = Some(err),
            }
        }
        if cands.is_empty() {
            return Err(last_err.expect("one method was tried"));
        }
        let i = (0..cands.len())
            .min_by_key(|&i| cands[i].payload.len())
            .expect("non-empty");
        cands = vec![cands.swap_remove(i)];
    } else {
        cands.push(encode_method(
            opts.method,
            raster,
            &header,
            opts,
            e,
            progress,
        )?);
    }
    for &m in &opts.also {
        if m == Method::Best {
            return Err(Error::invalid("'best' cannot be an additional section"));
        }
        if cands.iter().any(|c| Method::of_kind(c.kind) == m) {
            continue;
        }
        let mut o = opts.clone();
        if m != Method::Sibson {
            o.sites = None;
            o.rmse = None;
        }
        if m != Method::Fis {
            o.fis_k = None;
            o.fis_s = None;
        }
        if m != Method::Haar {
            o.haar_step = None;
        }
        cands.push(encode_method(m, raster, &header, &o, e, progress)?);
    }
    let primary = (0..cands.len())
        .min_by_key(|&i| cands[i].payload.len())
        .expect("non-empty");
    let mut sections = Vec::new();
    if let Some(m) = &raster.mask {
        if m.iter().any(|&b| !b) {
            sections.push(Section {
                kind: SectionKind::Mask,
                flags: SF_REQUIRED,
                payload: container::mask::encode(m),
            });
        }
    }
    header.primary = (sections.len() + primary) as u16;
    let report = EncodeReport {
        max_error: cands[primary].bound,
        method: Method::of_kind(cands[primary].kind),
        sites: cands[primary].stats.clone(),
    };
    for (i, c) in cands.into_iter().enumerate() {
        sections.push(Section {
            kind: c.kind,
            // Comparison sections are optional: a decoder that lacks their method skips them.
            flags: if i == primary { SF_REQUIRED } else { 0 },
            payload: c.payload,
        });
    }
    if let Some(meta) = &opts.metadata {
        serde_json::from_str::<serde_json::Value>(meta)
            .map_err(|e| Error::invalid(format!("metadata is not JSON: {e}")))?;
        sections.push(Section {
            kind: SectionKind::Metadata,
            flags: 0,
            payload: meta.as_bytes().to_vec(),
        });
    }
    Ok((container::write(&header, &sections), report))
}

/// Decode `.vtz` bytes into a raster (the primary section).
pub fn decode(bytes: &[u8]) -> Result<Raster> {
    decode_with(bytes, &DecodeOptions::default())
}

/// Decode `.vtz` bytes into a raster with options.
pub fn decode_with(bytes: &[u8], opts: &DecodeOptions) -> Result<Raster> {
    let mut rd = container::ContainerReader::new(std::io::Cursor::new(bytes), opts.limits)?;
    let header = rd.header().clone();
    let mask = rd.read_mask()?;
    let idx = opts.section.unwrap_or(header.primary as usize);
    let entry = rd
        .entries()
        .get(idx)
        .ok_or_else(|| Error::invalid(format!("the file has no section {idx}")))?
        .clone();
    let (w, h) = (header.width as usize, header.height as usize);
    let win = opts.window.unwrap_or(Window {
        x: 0,
        y: 0,
        width: w,
        height: h,
    });
    if win.width == 0
        || win.height == 0
        || win.x.checked_add(win.width).is_none_or(|e| e > w)
        || win.y.checked_add(win.height).is_none_or(|e| e > h)
    {
        return Err(Error::invalid(format!(
            "window {},{},{},{} is not inside the {w}x{h} raster",
            win.x, win.y, win.width, win.height
        )));
    }
    let payload = rd.read_section(idx)?;
    let data = match entry.kind {
        SectionKind::Grid => {
            if opts.sites.is_some() || opts.levels.is_some() {
                return Err(Error::invalid(
                    "--sites and --level need a sites section (this one is a grid)",
                ));
            }
            if opts.scale.is_some() {
                return Err(Error::invalid(
                    "--scale needs a sites section (this one is a grid)",
                ));
            }
            let full = grid::decode(&payload, &header, mask.as_deref())?;
            crop(&full, w, win)
        }
        SectionKind::Sites if opts.scale.is_some() => {
            if opts.window.is_some() {
                return Err(Error::invalid("--scale and --window cannot be combined"));
            }
            let s = opts.scale.expect("checked");
            let d =
                sites::decode_sites(&payload, &header, mask.as_deref(), opts.levels, opts.sites)?;
            let (data, m, ow, oh) =
                sites::render_scaled(&d, &header, mask.as_deref(), s.num, s.den)?;
            let f = s.den as f64 / s.num as f64;
            let georef = header.georef.as_ref().map(|g| {
                let mut g = g.clone();
                if g.raster_type == RasterType::Area {
                    g.origin[0] += 0.5 * g.pixel_size[0] * (1.0 - f);
                    g.origin[1] -= 0.5 * g.pixel_size[1] * (1.0 - f);
                }
                g.pixel_size = [g.pixel_size[0] * f, g.pixel_size[1] * f];
                g
            });
            let mut r = Raster {
                width: ow,
                height: oh,
                data,
                mask: Some(m),
                nodata: header.nodata,
                sample_type: header.sample_type,
                mapping: header.mapping,
                georef,
            };
            r.normalize_mask();
            return Ok(r);
        }
        SectionKind::Sites => {
            let d =
                sites::decode_sites(&payload, &header, mask.as_deref(), opts.levels, opts.sites)?;
            sites::render(
                &d,
                &header,
                mask.as_deref(),
                (win.x, win.y, win.width, win.height),
                if opts.threads == 0 {
                    sites::default_threads()
                } else {
                    opts.threads
                },
            )?
        }
        SectionKind::Fis | SectionKind::Haar => {
            if opts.sites.is_some() || opts.levels.is_some() || opts.scale.is_some() {
                return Err(Error::invalid(format!(
                    "--sites, --level and --scale need a sites section (this one is {})",
                    entry.kind.name()
                )));
            }
            let full = if entry.kind == SectionKind::Fis {
                fis::decode(&payload, &header, mask.as_deref())?
            } else {
                haar::decode(&payload, &header, mask.as_deref())?
            };
            crop(&full, w, win)
        }
        k => {
            return Err(Error::unsupported(format!(
                "decoding a {} section is not implemented by this version",
                k.name()
            )));
        }
    };
    let mut r = Raster {
        width: win.width,
        height: win.height,
        data,
        mask: mask.map(|m| crop(&m, w, win)),
        nodata: header.nodata,
        sample_type: header.sample_type,
        mapping: header.mapping,
        georef: header.georef.as_ref().map(|g| g.window(win.x, win.y)),
    };
    r.normalize_mask();
    Ok(r)
}

fn crop<T: Copy>(v: &[T], width: usize, win: Window) -> Vec<T> {
    let mut out = Vec::with_capacity(win.width * win.height);
    for y in win.y..win.y + win.height {
        out.extend_from_slice(&v[y * width + win.x..y * width + win.x + win.width]);
    }
    out
}

/// The section kind a method writes (`Best` has none: it names the grid, the fallback).
pub fn section_kind(m: Method) -> SectionKind {
    match m {
        Method::Sibson => SectionKind::Sites,
        Method::Fis => SectionKind::Fis,
        Method::Haar => SectionKind::Haar,
        Method::Grid | Method::Best => SectionKind::Grid,
    }
}

/// The payload of a file's first section of `kind`, with the header (`None` when the file
/// has no such section).
pub fn section_payload(
    bytes: &[u8],
    kind: SectionKind,
    limits: Limits,
) -> Result<Option<(Header, Vec<u8>)>> {
    let mut rd = container::ContainerReader::new(std::io::Cursor::new(bytes), limits)?;
    let header = rd.header().clone();
    match rd.find(kind) {
        Some(i) => Ok(Some((header, rd.read_section(i)?))),
        None => Ok(None),
    }
}

/// A file's header and section list, for `vtz info`.
#[derive(Clone, Debug)]
pub struct FileInfo {
    pub file_bytes: u64,
    pub header: Header,
    pub sections: Vec<container::SectionEntry>,
}

/// Read a file's header and directory without decoding samples.
pub fn info(bytes: &[u8], limits: Limits) -> Result<FileInfo> {
    let rd = container::ContainerReader::new(std::io::Cursor::new(bytes), limits)?;
    Ok(FileInfo {
        file_bytes: bytes.len() as u64,
        header: rd.header().clone(),
        sections: rd.entries().to_vec(),
    })
}

/// A file's sites section (the primary one when it is one, else the first), with the header
/// and the decoded validity mask: what `vtz info --stats`, `vtz sites` and `vtz render
/// --sites` need.
pub fn sites_section(bytes: &[u8], limits: Limits) -> Result<(Header, Option<Vec<bool>>, Vec<u8>)> {
    let mut rd = container::ContainerReader::new(std::io::Cursor::new(bytes), limits)?;
    let header = rd.header().clone();
    let mask = rd.read_mask()?;
    let idx = match rd.entries().get(header.primary as usize) {
        Some(e) if e.kind == SectionKind::Sites => header.primary as usize,
        _ => rd
            .find(SectionKind::Sites)
            .ok_or_else(|| Error::invalid("the file has no sites section"))?,
    };
    let payload = rd.read_section(idx)?;
    Ok((header, mask, payload))
}
