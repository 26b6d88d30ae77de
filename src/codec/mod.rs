//! The codec facade: options, rate control and dispatch through the method registry, for
//! encoding a raster into `.vtz` bytes and decoding them back; the public API re-exports
//! what is here.

mod decode;
mod encode;
mod options;
mod rate;
mod resample;
mod surface;
mod tiles;
mod verify;
mod write;

pub use encode::EncodeReport;
pub use options::{DecodeOptions, EncodeOptions, Scale, SectionChoice};
pub use surface::Surface;
pub use tiles::{DEFAULT_TILE, tile_count};
pub use verify::Verified;

use crate::container::tiled::RasterReader;
use crate::container::{ContainerReader, Limits, SF_REQUIRED};
use crate::error::{Error, Result};
use crate::formats::{self, Format, ReadOptions, WriteOptions};
use crate::methods::{self, DecodeJob, Method, Site, Stats};
use crate::model::{Georef, InMemory, Raster, RowSource, SampleType, ValueMapping, Window};
use crate::quant::ErrorBound;
use crate::source::{FileSource, MemorySource, RangeSource, ReadSeekSource, Source};
use std::io::{Cursor, Read, Seek};
use std::path::Path;
use std::sync::Arc;

pub use crate::threads::on_threads;
#[cfg(feature = "internals")]
pub use decode::read_all;

/// Encode a raster into `.vtz` bytes.
pub fn encode(raster: &Raster, opts: &EncodeOptions) -> Result<Vec<u8>> {
    encode_report(raster, opts).map(|(b, _)| b)
}

/// Encode a raster into `.vtz` bytes and report the bound achieved.
pub fn encode_report(raster: &Raster, opts: &EncodeOptions) -> Result<(Vec<u8>, EncodeReport)> {
    encode_progress(raster, opts, &mut |_| {})
}

/// [`encode_report`] with a progress callback: the fraction done, 0 at the start, then
/// never decreasing, 1 at the end.
pub fn encode_progress(
    raster: &Raster,
    opts: &EncodeOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, EncodeReport)> {
    // The methods' own estimates can dip (a sites encoder's worst error rises when stale
    // errors are refreshed): the caller sees only the high-water mark.
    let mut high = 0.0f64;
    progress(0.0);
    let mut mono = |f: f64| {
        let f = if f.is_nan() { 0.0 } else { f.clamp(0.0, 1.0) };
        if f > high {
            high = f;
            progress(f);
        }
    };
    let out = if tiles::tiled(raster.width, raster.height, opts) {
        tiles::encode_tiled(
            &mut InMemory(raster),
            opts,
            Cursor::new(Vec::new()),
            &mut mono,
        )
        .map(|(c, r)| (c.into_inner(), r))
    } else {
        match opts.target_bytes {
            Some(t) => rate::encode_to_size(raster, opts, t, &mut mono),
            None => encode::encode_once(raster, opts, &mut mono),
        }
    };
    if out.is_ok() {
        mono(1.0);
    }
    out
}

/// Encode a raster read band by band (a file larger than memory: see
/// [`crate::formats::open_source`]) into `out`: a raster larger than the tile size
/// ([`EncodeOptions::tile`]) is encoded tile by tile on all cores and written as tiles
/// finish, holding only the tiles in flight; a smaller one is read whole and encoded as by
/// [`encode_report`]. `progress` gets the fraction done.
pub fn encode_stream<W: std::io::Write + Seek>(
    src: &mut dyn RowSource,
    opts: &EncodeOptions,
    mut out: W,
    progress: &mut dyn FnMut(f64),
) -> Result<(W, EncodeReport)> {
    if tiles::tiled(src.width(), src.height(), opts) {
        return tiles::encode_tiled(src, opts, out, progress);
    }
    let r = src.band(0, src.height())?;
    let (bytes, rep) = encode_progress(&r, opts, progress)?;
    out.write_all(&bytes)
        .map_err(|e| Error::io("writing the file", e))?;
    Ok((out, rep))
}

/// Decode `.vtz` bytes into a raster (the primary section).
pub fn decode(bytes: &[u8]) -> Result<Raster> {
    decode_with(bytes, &DecodeOptions::default())
}

/// Decode `.vtz` bytes into a raster with options.
pub fn decode_with(bytes: &[u8], opts: &DecodeOptions) -> Result<Raster> {
    let mut d = Decoder::open_with_limits(Arc::new(MemorySource::new(bytes)), opts.limits)?;
    d.options(opts.clone());
    d.decode()
}

/// Decode a `.vtz` from a reader: only the header, the directory and the sections the
/// decode needs are read.
pub fn decode_from<R: Read + Seek + Send + 'static>(
    reader: R,
    opts: &DecodeOptions,
) -> Result<Raster> {
    let mut d = Decoder::with_limits(reader, opts.limits)?;
    d.options(opts.clone());
    d.decode()
}

/// Read a raster file of any format vtz knows, `.vtz` included (decoded).
pub fn read_path(path: &Path, opts: &ReadOptions) -> Result<Raster> {
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    if format != Format::Vtz {
        return formats::read_path(path, opts);
    }
    let ctx = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| Error::io(&ctx, e))?;
    let limits = Limits {
        max_samples: opts.max_samples(),
        ..Limits::default()
    };
    let o = DecodeOptions {
        limits,
        ..Default::default()
    };
    let mut r = decode_from(std::io::BufReader::new(file), &o).map_err(|e| e.context(&ctx))?;
    r.normalize_mask();
    r.validate().map_err(|e| e.context(&ctx))?;
    Ok(r)
}

/// Write a raster file of any format vtz knows (a `.vtz` is encoded losslessly), with its
/// sidecars, atomically.
pub fn write_path(raster: &Raster, path: &Path, opts: &WriteOptions) -> Result<()> {
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    if format != Format::Vtz {
        return formats::write_path(raster, path, opts);
    }
    let bytes = encode(raster, &EncodeOptions::default())?;
    formats::write_file(path, bytes, opts.force)
}

/// Builds an encode: `Encoder::new().max_error(..).method(..).encode(&raster)`.
///
/// ```
/// # let raster = vtz::Raster::from_values(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], None, vtz::SampleType::F32)?;
/// let (bytes, report) = vtz::Encoder::new()
///     .max_error(vtz::ErrorBound::Abs(0.5))
///     .method(vtz::Method::GRID)
///     .encode_report(&raster)?;
/// assert!(report.max_error <= 0.5);
/// # Ok::<(), vtz::Error>(())
/// ```
#[derive(Clone, Debug, Default)]
pub struct Encoder {
    opts: EncodeOptions,
}

impl Encoder {
    /// Lossless, best method.
    pub fn new() -> Encoder {
        Encoder::default()
    }
    /// Start from full options.
    pub fn with_options(opts: EncodeOptions) -> Encoder {
        Encoder { opts }
    }
    /// Guarantee every valid sample within this bound.
    pub fn max_error(mut self, b: ErrorBound) -> Encoder {
        self.opts.max_error = Some(b);
        self
    }
    /// Write this method only (call again to add comparison sections).
    pub fn method(mut self, m: Method) -> Encoder {
        self.opts.methods.push(m);
        self
    }
    /// Aim for a file of at most this many bytes.
    pub fn target_bytes(mut self, n: u64) -> Encoder {
        self.opts.target_bytes = Some(n);
        self
    }
    /// Store this JSON in a metadata section.
    pub fn metadata(mut self, json: impl Into<String>) -> Encoder {
        self.opts.metadata = Some(json.into());
        self
    }
    /// The options as built so far (to set per-method parameters).
    pub fn options_mut(&mut self) -> &mut EncodeOptions {
        &mut self.opts
    }
    /// Encode into `.vtz` bytes.
    pub fn encode(&self, raster: &Raster) -> Result<Vec<u8>> {
        encode(raster, &self.opts)
    }
    /// Encode into `.vtz` bytes with the report.
    pub fn encode_report(&self, raster: &Raster) -> Result<(Vec<u8>, EncodeReport)> {
        encode_report(raster, &self.opts)
    }
    /// Encode with a progress callback (fraction done, 0..1).
    pub fn encode_progress(
        &self,
        raster: &Raster,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(Vec<u8>, EncodeReport)> {
        encode_progress(raster, &self.opts, progress)
    }
}

/// What a file holds, read without decoding a sample (the header and the directory).
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct FileInfo {
    /// The container version (spec/FORMAT.md): 1 untiled, 2 or 4 tiled (4: laid out for
    /// range reads, what vtz writes).
    pub version: u16,
    /// Bytes of the whole file.
    pub file_bytes: u64,
    /// Raster width in samples.
    pub width: u32,
    /// Raster height in samples.
    pub height: u32,
    /// The sample type a decode gives back.
    pub sample_type: SampleType,
    /// How stored integer codes map to values.
    pub mapping: ValueMapping,
    /// The nodata value the source declared.
    pub nodata: Option<f64>,
    /// The range (min, max) of the valid samples.
    pub range: Option<(f64, f64)>,
    /// Where the raster sits, when the source said.
    pub georef: Option<Georef>,
    /// The index of the primary section.
    pub primary: usize,
    /// The section directory, in file order (of a tiled file: its global sections).
    pub sections: Vec<SectionInfo>,
    /// A tiled file's grid and index (container version 2, 4 or 5); `None` for an untiled file.
    pub tiles: Option<TilesInfo>,
}

/// A tiled file's grid and index.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct TilesInfo {
    /// Tile width in samples (the last column may be narrower).
    pub tile_width: u32,
    /// Tile height in samples (the last row may be shorter).
    pub tile_height: u32,
    /// Tiles per row.
    pub cols: u32,
    /// Rows of tiles.
    pub rows: u32,
    /// Samples each tile codes beyond its core on sides with a neighbour (decoders blend
    /// neighbours there).
    pub margin: u32,
    /// Version 5's split: overview K ≥ it reads only the tiles' heads, which lie together
    /// ([`TileInfo::head_bytes`]); `None` in versions 2 and 4.
    pub overview_split: Option<u32>,
    /// The index, in tile order.
    pub tiles: Vec<TileInfo>,
}

/// One tile of a tiled file's index.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct TileInfo {
    /// Its number (row-major).
    pub index: usize,
    /// Its core: the samples it owns.
    pub window: Window,
    /// The samples it codes: the core and its margins.
    pub coded: Window,
    /// Byte offset of its block (version 5: of the block's head).
    pub offset: u64,
    /// Bytes of its block.
    pub bytes: u64,
    /// Bytes of the block at `offset`: in version 5 its head (the chunks of overviews at the
    /// file's split and coarser, stored with every tile's head), else `bytes`.
    pub head_bytes: u64,
    /// Where the rest of the block lies (version 5's tail; `offset + bytes` otherwise).
    pub tail_offset: u64,
    /// The method of its primary section, by the name `--method` takes (`sibson` for a
    /// sites section), or `unknown-N` for a section type this build does not know.
    pub method: String,
    /// Valid samples.
    pub valid: u64,
    /// (min, max) of its valid source samples.
    pub range: Option<(f64, f64)>,
    /// The max error its encoder achieved (0 = lossless).
    pub max_error: f64,
}

impl FileInfo {
    /// Samples in the raster.
    pub fn samples(&self) -> u64 {
        self.width as u64 * self.height as u64
    }
}

/// One entry of the section directory.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct SectionInfo {
    /// Its index in the directory (what `--section N` takes).
    pub index: usize,
    /// The section type's name as spec/FORMAT.md spells it: `sites`, `grid`, `mask`,
    /// `metadata`, … or `unknown-N` (a method section's method is [`SectionInfo::method`],
    /// named as `--method` takes it: the `sites` section is the `sibson` method's).
    pub name: String,
    /// The section type code (spec/FORMAT.md).
    pub code: u16,
    /// The method that wrote it, for representation sections this build knows.
    pub method: Option<Method>,
    /// A decoder that does not know the type must reject the file.
    pub required: bool,
    /// The section a plain decode reads.
    pub primary: bool,
    /// Byte offset of the payload in the file.
    pub offset: u64,
    /// Payload length in bytes.
    pub bytes: u64,
}

/// Reads a `.vtz` lazily: [`Decoder::new`] reads the header and the directory (like LERC's
/// blob info), then each call reads only the sections it needs.
///
/// ```
/// # let raster = vtz::Raster::from_values(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], None, vtz::SampleType::I16)?;
/// # let bytes = vtz::encode(&raster, &Default::default())?;
/// let mut dec = vtz::Decoder::new(std::io::Cursor::new(bytes))?;
/// assert_eq!((dec.info().width, dec.info().height), (3, 2));
/// let mut buf = [0i16; 2];
/// dec.window(vtz::Window { x: 1, y: 1, width: 2, height: 1 })
///     .decode_into(&mut buf)?;
/// assert_eq!(buf, [5, 6]);
/// # Ok::<(), vtz::Error>(())
/// ```
pub struct Decoder {
    /// The file, an untiled one as the one-tile case of a tiled one.
    rd: RasterReader,
    info: FileInfo,
    opts: DecodeOptions,
    /// The validity mask, once read for statistics or sites.
    mask: Option<Option<Vec<bool>>>,
    /// Tiles the last decode skipped as corrupt (`DecodeOptions::skip_corrupt`).
    skipped: Vec<String>,
}

impl Decoder {
    /// Open with the default [`Limits`].
    pub fn new<R: Read + Seek + Send + 'static>(reader: R) -> Result<Decoder> {
        Decoder::with_limits(reader, Limits::default())
    }

    /// Open with explicit limits on everything the file (or an option) would allocate.
    pub fn with_limits<R: Read + Seek + Send + 'static>(
        reader: R,
        limits: Limits,
    ) -> Result<Decoder> {
        Decoder::open_with_limits(Arc::new(ReadSeekSource::new(reader)?), limits)
    }

    /// Open a local file (positioned reads of the ranges a decode needs).
    ///
    /// # Errors
    /// [`Error::Io`] naming the path; what [`Decoder::open`] gives.
    pub fn open_path(path: &std::path::Path, limits: Limits) -> Result<Decoder> {
        Decoder::open_with_limits(Arc::new(FileSource::open(path)?), limits)
            .map_err(|e| e.context(path.display()))
    }

    /// Open a file from any [`RangeSource`] (a file, memory, an object over HTTP or on S3)
    /// with the default [`Limits`]: one read of its first
    /// [`HEAD_BYTES`](crate::source::HEAD_BYTES) (a version-4 or -5 file's header, tile index and
    /// global sections), then only the ranges each decode needs.
    pub fn open(src: Arc<dyn RangeSource>) -> Result<Decoder> {
        Decoder::open_with_limits(src, Limits::default())
    }

    /// [`Decoder::open`] with explicit limits.
    pub fn open_with_limits(src: Arc<dyn RangeSource>, limits: Limits) -> Result<Decoder> {
        let reader = Source::open(src)?;
        let file_bytes = reader.len();
        let rd = tiles::open(reader, limits)?;
        let h = rd.header().clone();
        let primary = rd.primary();
        let sections = rd
            .sections()
            .iter()
            .enumerate()
            .map(|(i, e)| SectionInfo {
                index: i,
                name: e.name.clone(),
                code: e.kind.code(),
                method: methods::by_section(e.kind).map(Method),
                required: e.flags & SF_REQUIRED != 0,
                primary: Some(i) == primary,
                offset: e.offset,
                bytes: e.length,
            })
            .collect();
        // What `vtz info` lists of a tiled file's grid (an untiled file's is its one tile).
        let g = rd.grid();
        let tiles = rd.tiled().then(|| TilesInfo {
            tile_width: g.tile_w,
            tile_height: g.tile_h,
            cols: g.cols(),
            rows: g.rows(),
            margin: g.margin,
            overview_split: rd.split(),
            tiles: rd
                .tiles()
                .iter()
                .enumerate()
                .map(|(k, t)| TileInfo {
                    index: k,
                    window: g.rect(k),
                    coded: g.ext(k),
                    offset: t.offset,
                    bytes: t.length,
                    head_bytes: t.head,
                    tail_offset: t.tail_offset,
                    method: methods::by_section(t.kind).map_or_else(
                        || format!("unknown-{}", t.kind.code()),
                        |m| m.name().to_string(),
                    ),
                    valid: t.valid,
                    range: t.range,
                    max_error: t.max_error,
                })
                .collect(),
        });
        let info = FileInfo {
            version: rd.version(),
            file_bytes,
            width: h.width,
            height: h.height,
            sample_type: h.sample_type,
            mapping: h.mapping,
            nodata: h.nodata,
            range: h.range,
            georef: h.georef.clone(),
            primary: primary.unwrap_or(0),
            sections,
            tiles,
        };
        let opts = DecodeOptions {
            limits,
            ..Default::default()
        };
        Ok(Decoder {
            rd,
            info,
            opts,
            mask: None,
            skipped: Vec::new(),
        })
    }

    /// The max error the file guarantees on every valid sample (0 = lossless), read from
    /// the primary section's stored bound without decoding it (a tiled file: its worst
    /// tile's, from the index). Reads one section; the statistics ([`Decoder::stats`])
    /// decode it.
    pub fn max_error(&mut self) -> Result<f64> {
        // A tiled file's tiles keep theirs in the index; an untiled file's one tile, in its
        // primary section.
        let Some(rd) = self.rd.whole() else {
            return Ok(self
                .rd
                .tiles()
                .iter()
                .map(|t| t.max_error)
                .fold(0.0, f64::max));
        };
        let idx = rd.header().primary as usize;
        stored_bound(rd, idx)?.ok_or_else(|| {
            Error::unsupported(format!("the primary section {idx} is not a method's"))
        })
    }

    /// The source's GDAL metadata (the XML of its GDAL_METADATA tag) as a full decode gives
    /// it back, read without decoding a sample: byte for byte when the file is lossless,
    /// without the `STATISTICS_…` items when it is lossy (the decoded samples' statistics
    /// differ from the source's). `None` when the source had none.
    pub fn gdal_metadata(&mut self) -> Result<Option<String>> {
        let Some(xml) = self.rd.gdal_metadata()? else {
            return Ok(None);
        };
        Ok(Some(if self.max_error()? != 0.0 {
            formats::without_statistics(&xml).into_owned()
        } else {
            xml
        }))
    }

    /// The max error each section guarantees, as stored in it (`None` for a section that is
    /// not a method's: the mask, flat regions, metadata); read without decoding. A tiled
    /// file's global sections hold no method (its tiles' bounds are in
    /// [`FileInfo::tiles`]).
    pub fn section_max_errors(&mut self) -> Result<Vec<Option<f64>>> {
        // A tiled file's own sections are metadata.
        let n = self.rd.sections().len();
        match self.rd.whole() {
            None => Ok(vec![None; n]),
            Some(rd) => (0..n).map(|i| stored_bound(rd, i)).collect(),
        }
    }

    /// What the file holds.
    pub fn info(&self) -> &FileInfo {
        &self.info
    }

    /// Decode only this window from now on.
    pub fn window(&mut self, w: Window) -> &mut Self {
        self.opts.window = Some(w);
        self
    }

    /// Decode this section instead of the primary one.
    pub fn section(&mut self, s: SectionChoice) -> &mut Self {
        self.opts.section = s;
        self
    }

    /// Replace the decode options (the limits given at opening stay).
    pub fn options(&mut self, opts: DecodeOptions) -> &mut Self {
        let limits = self.opts.limits;
        self.opts = DecodeOptions { limits, ..opts };
        self
    }

    /// Decode into a raster.
    pub fn decode(&mut self) -> Result<Raster> {
        self.decode_progress(&|_| {})
    }

    /// The tiles the last decode wrote as nodata because they were corrupt
    /// ([`DecodeOptions::skip_corrupt`]), each with its error.
    pub fn skipped(&self) -> &[String] {
        &self.skipped
    }

    /// Check the whole file: every checksum, every section decoded in full, each decode
    /// against the mask, the header's value range widened by the section's stored max
    /// error, and the surfaces against one another (in a tiled file, tile by tile, each
    /// against its index entry). The first problem is the error ([`Error::Corrupt`] for
    /// what the file gets wrong).
    pub fn verify(&mut self) -> Result<Verified> {
        verify::verify_file(&mut self.rd)
    }

    /// [`Decoder::decode`] with a progress callback: the fraction done, 0..1, never
    /// decreasing (it may be called from several threads).
    pub fn decode_progress(&mut self, progress: &(dyn Fn(f64) + Sync)) -> Result<Raster> {
        progress(0.0);
        let (r, skipped) = tiles::decode_all(&mut self.rd, &self.opts, progress)?;
        self.skipped = skipped;
        let r = self.resurface(r)?;
        progress(1.0);
        Ok(r)
    }

    /// Decode band by band: `sink` gets the window's rows top to bottom, a row of tiles at
    /// a time, so a tiled file of any size decodes to a streaming writer in the memory of
    /// one band (an untiled file comes as one band). `--scale` is not available here.
    pub fn decode_bands(
        &mut self,
        sink: &mut dyn FnMut(Raster) -> Result<()>,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<()> {
        if self.opts.scale.is_some() {
            return Err(Error::invalid(
                "a band-by-band decode cannot resample (--scale)",
            ));
        }
        if self.opts.surface != Surface::Sibson && self.info.tiles.is_some() {
            return Err(Error::invalid(
                "another surface than sibson needs an untiled file whose primary section is sites",
            ));
        }
        progress(0.0);
        if self.opts.surface != Surface::Sibson {
            // Another surface is evaluated on the whole grid of an untiled sites file.
            let r = self.decode_progress(progress)?;
            sink(r)?;
        } else {
            self.skipped = tiles::decode_bands(&mut self.rd, &self.opts, sink, progress)?;
        }
        progress(1.0);
        Ok(())
    }

    /// Decode into the caller's buffer of the file's sample type (or a wider one): one
    /// value per sample of the window, row-major. Nodata samples get the declared nodata
    /// value (NaN for floats without one). A value the buffer's type cannot hold is an error,
    /// never a silent change.
    pub fn decode_into<T: Sample>(&mut self, out: &mut [T]) -> Result<()> {
        self.decode_into_as(out, crate::model::OutputType::Values(self.info.sample_type))
    }

    /// The file's [`OutputType`](crate::model::OutputType) (what GDAL's band holds).
    pub fn output_type(&self) -> crate::model::OutputType {
        crate::model::OutputType::of(self.info.sample_type, self.info.mapping, self.info.nodata)
    }

    /// [`Decoder::decode_into`] as `out_type` stores samples: the values, or (for
    /// [`OutputType::Codes`](crate::model::OutputType::Codes)) each value's code
    /// `(value − offset) / scale`, nodata samples the nodata value's code: what a GDAL band
    /// of the file's [`Decoder::output_type`] holds.
    pub fn decode_into_as<T: Sample>(
        &mut self,
        out: &mut [T],
        out_type: crate::model::OutputType,
    ) -> Result<()> {
        let r = self.decode()?;
        if out.len() != r.data.len() {
            return Err(Error::invalid(format!(
                "the buffer holds {} samples, the decode has {}",
                out.len(),
                r.data.len()
            )));
        }
        for (o, &v) in out.iter_mut().zip(&r.data) {
            let v = out_type.stored(v);
            *o = T::from_f64(v).ok_or_else(|| {
                Error::invalid(format!(
                    "the value {v} does not fit the buffer's type {}",
                    T::NAME
                ))
            })?;
        }
        Ok(())
    }

    /// [`Decoder::stats`] of one method: the statistics of its first section (the primary
    /// one where it is that method's), `None` when the file has no section of it or the
    /// method keeps none. What it costs is the method's: the residual layer's reads its
    /// section's header only, the sites' decode the surface.
    pub fn method_stats(&mut self, m: Method) -> Result<Option<Stats>> {
        if !m.has_stats() {
            return Ok(None);
        }
        Ok(self.with_section(m.0, |job| m.0.describe(job))?.flatten())
    }

    /// The statistics each method keeps of its sections: for every method with a section
    /// in the file, its first section (the primary one where it is that method's).
    pub fn stats(&mut self) -> Result<Vec<Stats>> {
        let mut out = Vec::new();
        for m in methods::REGISTRY.iter().filter(|m| m.has_stats()) {
            if let Some(s) = self.with_section(*m, |job| m.describe(job))? {
                out.extend(s);
            }
        }
        Ok(out)
    }

    /// The decode of the sites through another surface than Sibson's (`opts.surface`).
    fn resurface(&mut self, mut r: Raster) -> Result<Raster> {
        if self.opts.surface == Surface::Sibson {
            return Ok(r);
        }
        let primary_sites = self.info.tiles.is_none()
            && self
                .info
                .sections
                .get(self.info.primary)
                .and_then(|s| s.method)
                == Some(Method::SIBSON);
        if !primary_sites || self.opts.section != SectionChoice::Primary {
            return Err(Error::invalid(
                "another surface than sibson needs an untiled file whose primary section is \
                 sites (the other methods are coded against their own surface)",
            ));
        }
        if self.opts.window.is_some() || self.opts.scale.is_some() || self.opts.overview.is_some() {
            return Err(Error::invalid(
                "another surface than sibson decodes the whole grid (no window, scale or overview)",
            ));
        }
        let all = self.sites()?;
        let n = match (self.opts.sites, self.opts.levels) {
            (Some(n), _) => n.min(all.len()),
            (None, Some(k)) => all.iter().take_while(|s| s.level < k).count(),
            (None, None) => all.len(),
        };
        surface::resurface(&mut r, &all[..n], self.opts.surface)?;
        Ok(r)
    }

    /// The stored sites of the file's sites section (the primary one when it is one),
    /// in importance order.
    pub fn sites(&mut self) -> Result<Vec<Site>> {
        for m in methods::REGISTRY.iter().filter(|m| m.stores_sites()) {
            if let Some(Some(s)) = self.with_section(*m, |job| m.sites(job))? {
                return Ok(s);
            }
        }
        Err(Error::invalid("the file has no sites section"))
    }

    /// Run `f` on the whole-raster decode job of method `m`'s section (the primary one
    /// when it is `m`'s, else the first); `None` when the file has no such section.
    fn with_section<T>(
        &mut self,
        m: &dyn methods::Representation,
        f: impl FnOnce(&DecodeJob) -> Result<T>,
    ) -> Result<Option<T>> {
        let Some(rd) = self.rd.whole() else {
            return Err(Error::invalid(format!(
                "the file is tiled ({} tiles): statistics and sites are per tile; encode with --tile 0 for one set",
                self.info.tiles.as_ref().map_or(0, |t| t.tiles.len())
            )));
        };
        let header = rd.header().clone();
        let primary = header.primary as usize;
        let idx = match rd.entries().get(primary) {
            Some(e) if e.kind == m.section() => Some(primary),
            _ => rd.find(m.section()),
        };
        let Some(i) = idx else { return Ok(None) };
        if self.mask.is_none() {
            self.mask = Some(rd.read_mask()?);
        }
        let mask = self.mask.as_ref().and_then(|m| m.as_deref());
        decode::whole_job(rd, i, mask, f).map(Some)
    }
}

/// The max error stored in section `idx` of an untiled file at its method's
/// `Identity::bound_at`; `None` when the section is not a method's.
fn stored_bound<R: Read + Seek>(rd: &mut ContainerReader<R>, idx: usize) -> Result<Option<f64>> {
    let kind = rd
        .entries()
        .get(idx)
        .ok_or_else(|| Error::corrupt(format!("no section {idx}")))?
        .kind;
    let Some(m) = methods::by_section(kind) else {
        return Ok(None);
    };
    let payload = rd.read_section(idx)?;
    let off = m.id().bound_at;
    payload
        .get(off..off + 8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
        .filter(|b| b.is_finite() && *b >= 0.0)
        .map(Some)
        .ok_or_else(|| Error::corrupt(format!("section {idx} has no valid stored max error")))
}

/// Read a file's header and directory without decoding samples.
pub fn info(bytes: &[u8], limits: Limits) -> Result<FileInfo> {
    Decoder::open_with_limits(Arc::new(MemorySource::new(bytes)), limits).map(|d| d.info)
}

/// A sample type a caller's buffer can have ([`Decoder::decode_into`]). Sealed.
pub trait Sample: Copy + sealed::Sealed {
    #[doc(hidden)]
    const NAME: &'static str;
    #[doc(hidden)]
    fn from_f64(v: f64) -> Option<Self>;
}

mod sealed {
    pub trait Sealed {}
}

macro_rules! int_sample {
    ($($t:ty),*) => {$(
        impl sealed::Sealed for $t {}
        impl Sample for $t {
            const NAME: &'static str = stringify!($t);
            fn from_f64(v: f64) -> Option<Self> {
                (v.fract() == 0.0 && v >= <$t>::MIN as f64 && v <= <$t>::MAX as f64)
                    .then_some(v as $t)
            }
        }
    )*};
}
int_sample!(u8, i16, u16, i32);

impl sealed::Sealed for f32 {}
impl Sample for f32 {
    const NAME: &'static str = "f32";
    fn from_f64(v: f64) -> Option<Self> {
        (v.is_nan() || v as f32 as f64 == v).then_some(v as f32)
    }
}
impl sealed::Sealed for f64 {}
impl Sample for f64 {
    const NAME: &'static str = "f64";
    fn from_f64(v: f64) -> Option<Self> {
        Some(v)
    }
}
