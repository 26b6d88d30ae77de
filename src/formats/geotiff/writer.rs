//! Writing band by band: a single-band GeoTIFF written as its rows come, as a tiled (256 × 256),
//! Deflate-compressed GeoTIFF, so rasters larger than memory pass through (`write` writes a
//! raster held whole, striped).
//!
//! The `tiff` 0.11 encoder writes strips only, so tiles are cut, predicted and compressed
//! here and written straight to the output as their tile row completes; the image directory
//! comes last (its GDAL_NODATA depends on whether any sample was invalid). The directory is
//! encoded by the `tiff` crate (with `write_geo_tags`, so the GeoTIFF tags are those of
//! `write`) into memory as if its file began there, then moved behind the
//! tiles, with its pointers shifted by the distance moved.

use super::georef::{GeoTags, geo_tags, write_geo_tags};
use super::ifd::{type_size, uint};
use super::tags::enc_err;
use super::write::BIGTIFF_THRESHOLD;
use crate::error::{Error, Result};
use crate::model::{OutputType, Raster, SampleType, ValueMapping};
use std::io::{Cursor, Seek, SeekFrom, Write};
use tiff::encoder::{TiffEncoder, TiffKind, TiffKindBig, TiffKindStandard};
use tiff::tags::Tag;

/// Tile width and length of the files [`StreamWriter`] writes.
const TILE: usize = 256;

/// Writes a single-band GeoTIFF band by band, as a tiled (256 × 256), Deflate-compressed
/// GeoTIFF (BigTIFF when the raw samples are over 3 GiB, as `write` decides),
/// with the georeferencing tags, GDAL_NODATA and GDAL_METADATA that `write` produces.
///
/// Output sample type: [`OutputType::of`] the sample type, mapping and nodata, as `write`
/// (values in the sample type or the smallest integer type that holds them, or codes with
/// GDAL_METADATA's `OFFSET`/`SCALE`), except that where `write` falls back to float values it
/// writes float64. (`write` picks float32 when every value is exact in float32, which it
/// learns by looking at all values before writing the first; a stream cannot look ahead, and
/// float64 holds every mapped value exactly.) Integer samples use the
/// horizontal predictor, float samples none (as `write`).
///
/// Invalid samples are written as the nodata value; without one, as NaN for floats and, for
/// integers, as the type's minimum (maximum for unsigned types), which is then declared as
/// nodata. `write` would switch to the other end of the range when a valid sample holds that
/// value; a stream cannot, so that case is an error (give the raster a nodata value).
///
/// Memory: one tile row of samples in the output type (`256 × width` samples) and one tile,
/// plus 16 bytes per tile for the tile offsets and byte counts.
pub struct StreamWriter<W: Write + Seek> {
    out: W,
    /// Stream position of the TIFF header (offsets in the file count from it).
    start: u64,
    /// Bytes written after `start`.
    pos: u64,
    width: usize,
    height: usize,
    big: bool,
    /// The sample type written.
    st: SampleType,
    /// The mapping whose codes are written (GDAL's offset and scale), when not the values.
    to_code: Option<ValueMapping>,
    /// The nodata value as written (a code when `to_code` is set).
    nodata: Option<f64>,
    tags: GeoTags,
    /// The value written for invalid samples of an integer type without a nodata value.
    int_fill: f64,
    has_invalid: bool,
    /// Where a valid sample holds `int_fill` (only tracked when there is no nodata value).
    valid_at_fill: Option<(usize, usize)>,
    rows_done: usize,
    /// Samples of the current tile row so far, in the output type, native byte order.
    rows: Vec<u8>,
    rows_buffered: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// An error left the output incomplete: every later call fails.
    failed: bool,
}

/// What the checks of [`StreamWriter`] need of one converted row: where its first invalid
/// sample and its first valid sample holding the fill value are (columns), and its first
/// error (column, error); the row's conversion stops at that error.
#[derive(Default)]
struct RowCheck {
    first_invalid: Option<usize>,
    first_fill: Option<usize>,
    error: Option<(usize, Error)>,
}

/// The conversion of rows into the output type (native byte order).
#[derive(Clone, Copy)]
struct RowConv {
    st: SampleType,
    /// Values become this mapping's codes (rounded) before they are written.
    to_code: Option<ValueMapping>,
    nodata: Option<f64>,
    int_fill: f64,
    /// Whether a valid sample holding the fill value matters (integers without nodata).
    track_fill: bool,
}

impl RowConv {
    /// Row `y`'s `vals` (valid where `mask` says) into `out`; integer outputs rounded to the
    /// nearest integer (out of range is an error), float32 outputs finite, invalid samples
    /// the nodata value (integers without one: the fill; floats: NaN).
    fn row(&self, vals: &[f64], mask: Option<&[bool]>, y: usize, out: &mut [u8]) -> RowCheck {
        let mut c = RowCheck::default();
        let valid = |x: usize| mask.is_none_or(|m| m[x]);
        let w = vals.len();
        match self.st {
            SampleType::F32 => {
                let fill = self.nodata.map_or(f32::NAN, |nd| nd as f32);
                for (x, (&v, o)) in vals.iter().zip(out.chunks_exact_mut(4)).enumerate() {
                    let s = if valid(x) {
                        let s = v as f32;
                        if !s.is_finite() {
                            let msg = format!(
                                "sample {} (row {y}, col {x}) = {v} does not fit in float32",
                                y * w + x
                            );
                            c.error = Some((x, Error::invalid(msg)));
                            return c;
                        }
                        s
                    } else {
                        c.first_invalid = c.first_invalid.or(Some(x));
                        fill
                    };
                    o.copy_from_slice(&s.to_ne_bytes());
                }
            }
            SampleType::F64 => {
                let fill = self.nodata.unwrap_or(f64::NAN);
                for (x, (&v, o)) in vals.iter().zip(out.chunks_exact_mut(8)).enumerate() {
                    let s = if valid(x) {
                        v
                    } else {
                        c.first_invalid = c.first_invalid.or(Some(x));
                        fill
                    };
                    o.copy_from_slice(&s.to_ne_bytes());
                }
            }
            st => {
                let (lo, hi) = st.int_range().expect("an integer type");
                let bps = (st.bits() / 8) as usize;
                for (x, (&v, o)) in vals.iter().zip(out.chunks_exact_mut(bps)).enumerate() {
                    let code = if valid(x) {
                        let code = self.to_code.map_or(v, |m| m.to_code(v)).round();
                        if !(code >= lo && code <= hi) {
                            let msg = format!(
                                "sample {v} at row {y}, col {x} does not fit in {} ({lo}..={hi})",
                                st.name()
                            );
                            c.error = Some((x, Error::invalid(msg)));
                            return c;
                        }
                        if self.track_fill && code == self.int_fill && c.first_fill.is_none() {
                            c.first_fill = Some(x);
                        }
                        code
                    } else {
                        c.first_invalid = c.first_invalid.or(Some(x));
                        match self.nodata {
                            Some(nd) if nd.fract() != 0.0 || !(nd >= lo && nd <= hi) => {
                                let msg = format!(
                                    "nodata value {nd} cannot be stored in a {} GeoTIFF",
                                    st.name()
                                );
                                c.error = Some((x, Error::invalid(msg)));
                                return c;
                            }
                            Some(nd) => nd,
                            None => self.int_fill,
                        }
                    };
                    let code = code as i64;
                    match st {
                        SampleType::U8 => o[0] = code as u8,
                        SampleType::I16 => o.copy_from_slice(&(code as i16).to_ne_bytes()),
                        SampleType::U16 => o.copy_from_slice(&(code as u16).to_ne_bytes()),
                        _ => o.copy_from_slice(&(code as i32).to_ne_bytes()),
                    }
                }
            }
        }
        c
    }
}

impl<W: Write + Seek> StreamWriter<W> {
    /// Start a `width × height` GeoTIFF on `out` (at its current position). `meta` gives the
    /// sample type, value mapping, nodata, georef (of the whole raster, top-left) and
    /// GDAL_METADATA; its samples and mask are ignored.
    pub fn new(out: W, width: usize, height: usize, meta: &Raster) -> Result<StreamWriter<W>> {
        Self::with_kind(out, width, height, meta, None)
    }

    /// [`StreamWriter::new`], with BigTIFF forced on or off when `big` says (the tests write
    /// small BigTIFFs).
    pub(super) fn with_kind(
        mut out: W,
        width: usize,
        height: usize,
        meta: &Raster,
        big: Option<bool>,
    ) -> Result<StreamWriter<W>> {
        let too_big = || Error::invalid(format!("raster {width}x{height} is too large for a TIFF"));
        if width == 0 || height == 0 {
            return Err(Error::invalid(format!(
                "raster size {width}x{height} is empty"
            )));
        }
        u32::try_from(width).map_err(|_| too_big())?;
        u32::try_from(height).map_err(|_| too_big())?;
        width.checked_mul(TILE * 8).ok_or_else(too_big)?;
        if meta.nodata.is_some_and(f64::is_nan) {
            return Err(Error::invalid("nodata value is NaN"));
        }
        // As `write`, with float64 for the integer rasters `write` writes as float32 or
        // float64 (a stream cannot look ahead to see whether float32 holds every value).
        let kind = OutputType::of(meta.sample_type, meta.mapping, meta.nodata);
        let st = kind.sample_type();
        let to_code = kind.offset_scale();
        let bytes = u64::from(st.bits() / 8);
        let raw = (width as u64)
            .saturating_mul(height as u64)
            .saturating_mul(bytes);
        let big = big.unwrap_or(raw > BIGTIFF_THRESHOLD);
        let mut tags = geo_tags(meta.georef.as_ref())?;
        tags.gdal_metadata = match to_code {
            Some(m) => Some(crate::formats::with_offset_scale(
                meta.gdal_metadata.as_deref(),
                m,
            )),
            None => meta.gdal_metadata.clone(),
        };
        let int_fill = match st.int_range() {
            Some((_, hi)) if matches!(st, SampleType::U8 | SampleType::U16) => hi,
            Some((lo, _)) => lo,
            None => f64::NAN,
        };

        // The header, as the `tiff` crate writes it, with the IFD pointer still 0.
        let mut header = Cursor::new(Vec::new());
        if big {
            TiffEncoder::<_, TiffKindBig>::new_generic(&mut header).map_err(enc_err)?;
        } else {
            TiffEncoder::<_, TiffKindStandard>::new_generic(&mut header).map_err(enc_err)?;
        }
        let header = header.into_inner();
        let start = out
            .stream_position()
            .map_err(|e| Error::io("writing GeoTIFF", e))?;
        out.write_all(&header)
            .map_err(|e| Error::io("writing GeoTIFF", e))?;

        Ok(StreamWriter {
            out,
            start,
            pos: header.len() as u64,
            width,
            height,
            big,
            st,
            to_code,
            nodata: meta.nodata.map(|nd| kind.stored(nd)),
            tags,
            int_fill,
            has_invalid: false,
            valid_at_fill: None,
            rows_done: 0,
            rows: Vec::with_capacity(TILE.min(height) * width * bytes as usize),
            rows_buffered: 0,
            offsets: Vec::new(),
            counts: Vec::new(),
            failed: false,
        })
    }

    /// The next `band.height` rows (`band.width` must be the width), in order from the top;
    /// any number of rows per call. Values are checked and converted as
    /// `write` does: integer outputs rounded to the nearest integer, out of
    /// range is an error; float32 outputs must be finite in float32; invalid samples become
    /// the nodata value (NaN for floats without one). Tiles are written as each tile row fills.
    ///
    /// A band that does not fit (wrong width, rows past the height) or is not a valid raster
    /// is refused and changes nothing; any other error leaves the output incomplete, and every
    /// later call fails.
    pub fn write_rows(&mut self, band: &Raster) -> Result<()> {
        self.check_not_failed()?;
        if band.width != self.width {
            return Err(Error::invalid(format!(
                "band is {} samples wide, the GeoTIFF {}",
                band.width, self.width
            )));
        }
        if band.height > self.height - self.rows_done {
            return Err(Error::invalid(format!(
                "{} more rows do not fit: {} of the GeoTIFF's {} rows are written",
                band.height, self.rows_done, self.height
            )));
        }
        band.validate()?;
        let rows = self.push_rows(band);
        self.failed = rows.is_err();
        rows
    }

    fn check_not_failed(&self) -> Result<()> {
        if self.failed {
            return Err(Error::invalid(
                "an earlier error left this GeoTIFF stream incomplete",
            ));
        }
        Ok(())
    }

    /// The rows of a checked band into the tile row buffer, tiles out as tile rows fill.
    /// Rows are converted side by side (on the caller's rayon pool); what the checks need of
    /// each row is then taken in row order, so the first problem is the one a sample-by-sample
    /// pass would meet, with the same message.
    fn push_rows(&mut self, band: &Raster) -> Result<()> {
        use rayon::prelude::*;
        let w = self.width;
        let bps = (self.st.bits() / 8) as usize;
        let conv = RowConv {
            st: self.st,
            to_code: self.to_code,
            nodata: self.nodata,
            int_fill: self.int_fill,
            track_fill: self.nodata.is_none() && self.st.is_integer(),
        };
        let mut r0 = 0;
        while r0 < band.height {
            let n = (TILE - self.rows_buffered).min(band.height - r0);
            let at = self.rows.len();
            self.rows.resize(at + n * w * bps, 0);
            let y0 = self.rows_done;
            let checks: Vec<RowCheck> = self.rows[at..]
                .par_chunks_mut(w * bps)
                .enumerate()
                .map(|(k, out)| {
                    let i = (r0 + k) * w;
                    let mask = band.mask.as_deref().map(|m| &m[i..i + w]);
                    conv.row(&band.data[i..i + w], mask, y0 + k, out)
                })
                .collect();
            for (k, c) in checks.into_iter().enumerate() {
                self.take_row(c, y0 + k)?;
            }
            self.rows_done += n;
            self.rows_buffered += n;
            r0 += n;
            if self.rows_buffered == TILE {
                self.flush_tile_row()?;
            }
        }
        Ok(())
    }

    /// The checks of row `y`, in order: its own first error, or the error of a valid
    /// sample holding the fill value in a raster with invalid samples and no nodata value,
    /// whichever a sample-by-sample pass meets first.
    fn take_row(&mut self, c: RowCheck, y: usize) -> Result<()> {
        // Where, within the row, "has invalid samples" and "a valid sample holds the fill"
        // both hold (0: from the row's start).
        let inv = if self.has_invalid {
            Some(0)
        } else {
            c.first_invalid
        };
        let fill = if self.valid_at_fill.is_some() {
            Some(0)
        } else {
            c.first_fill
        };
        let both = inv.zip(fill).map(|(a, b)| a.max(b));
        if let Some((q, e)) = c.error {
            // A sample's own error comes before the check after it.
            if both.is_none_or(|p| q <= p) {
                return Err(e);
            }
        }
        self.has_invalid |= c.first_invalid.is_some();
        if self.valid_at_fill.is_none() {
            self.valid_at_fill = c.first_fill.map(|x| (y, x));
        }
        if let (Some(_), Some((fy, fx))) = (both, self.valid_at_fill) {
            return Err(Error::invalid(format!(
                "raster has nodata samples but no nodata value, and the valid sample \
                 at row {fy}, col {fx} holds {}, the value a streamed {} GeoTIFF \
                 gives them (give the raster a nodata value)",
                self.int_fill,
                self.st.name()
            )));
        }
        Ok(())
    }

    /// Cut the buffered rows into tiles, compress them and write them out.
    ///
    /// Hand-written (the `tiff` encoder writes strips only): each tile is `TILE × TILE`
    /// samples, the parts outside the image zero; integer tiles get the horizontal predictor
    /// (each tile row differenced from its left neighbour, wrapping, in the sample's own width),
    /// then zlib-wrapped Deflate at level 3 (below). Tiles go in row-major order, so
    /// `TileOffsets` lists them as TIFF wants.
    fn flush_tile_row(&mut self) -> Result<()> {
        use rayon::prelude::*;
        let bps = (self.st.bits() / 8) as usize;
        let row_bytes = self.width * bps;
        let tile_row_bytes = TILE * bps;
        let (rows, rows_buffered, width, integer) = (
            &self.rows,
            self.rows_buffered,
            self.width,
            self.st.is_integer(),
        );
        // Tiles compress in parallel (on the caller's rayon pool) and are written in order,
        // so the bytes do not depend on the thread count.
        let compressed: Vec<std::io::Result<Vec<u8>>> = (0..width)
            .step_by(TILE)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|x0| {
                let cols = TILE.min(width - x0);
                let mut tile = vec![0u8; TILE * tile_row_bytes];
                for r in 0..rows_buffered {
                    let src = &rows[r * row_bytes + x0 * bps..][..cols * bps];
                    tile[r * tile_row_bytes..][..cols * bps].copy_from_slice(src);
                }
                if integer {
                    for row in tile.chunks_exact_mut(tile_row_bytes) {
                        horizontal_predict(row, bps);
                    }
                }
                // Level 3: on the 3600² SRTM1 tile (i16, 1 m) 0.7 % more bytes than level 6
                // for a third of its instructions (deflate 6.9 G → 2.3 G of a 17.7 G decode
                // to GeoTIFF; levels 1, 2, 4 and 5 were larger or slower, callgrind).
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(3));
                z.write_all(&tile)?;
                z.finish()
            })
            .collect();
        let io = |e| Error::io("writing GeoTIFF", e);
        for c in compressed {
            let c = c.map_err(io)?;
            self.out.write_all(&c).map_err(io)?;
            self.offsets.push(self.pos);
            self.counts.push(c.len() as u64);
            self.pos += c.len() as u64;
        }
        self.rows.clear();
        self.rows_buffered = 0;
        Ok(())
    }

    /// Write the last partial tile row and the image directory; an error if fewer than
    /// `height` rows were written. Gives the output back, positioned after the file.
    pub fn finish(mut self) -> Result<W> {
        self.check_not_failed()?;
        if self.rows_done != self.height {
            return Err(Error::invalid(format!(
                "GeoTIFF stream finished after {} of its {} rows",
                self.rows_done, self.height
            )));
        }
        if self.rows_buffered > 0 {
            self.flush_tile_row()?;
        }
        self.tags.nodata = match self.st {
            SampleType::F32 => match self.nodata {
                Some(nd) => Some(f64::from(nd as f32)),
                None => self.has_invalid.then_some(f64::NAN),
            },
            SampleType::F64 => self.nodata.or(self.has_invalid.then_some(f64::NAN)),
            _ => self.nodata.or(self.has_invalid.then_some(self.int_fill)),
        };
        let ifd = if self.big {
            self.encode_ifd::<TiffKindBig>()?
        } else {
            self.encode_ifd::<TiffKindStandard>()?
        };
        let header_len: u64 = if self.big { 16 } else { 8 };
        // The directory goes at the next multiple of 8, so moving it keeps its alignment.
        let base = self.pos.next_multiple_of(8);
        let (moved, ifd_at) = relocate(ifd, self.big, base - header_len)?;
        let io = |e| Error::io("writing GeoTIFF", e);
        let pad = [0u8; 8];
        self.out
            .write_all(&pad[..(base - self.pos) as usize])
            .map_err(io)?;
        self.out.write_all(&moved).map_err(io)?;
        let end = base + moved.len() as u64;
        // The header's pointer to the directory.
        let pointer = if self.big {
            ifd_at.to_ne_bytes().to_vec()
        } else {
            u32::try_from(ifd_at)
                .map_err(|_| Error::limit("GeoTIFF is over 4 GiB, too large for a classic TIFF"))?
                .to_ne_bytes()
                .to_vec()
        };
        let pointer_at = if self.big { 8 } else { 4 };
        self.out
            .seek(SeekFrom::Start(self.start + pointer_at))
            .map_err(io)?;
        self.out.write_all(&pointer).map_err(io)?;
        self.out
            .seek(SeekFrom::Start(self.start + end))
            .map_err(io)?;
        self.out.flush().map_err(io)?;
        Ok(self.out)
    }

    /// The image directory encoded by the `tiff` crate as the only IFD of an in-memory file
    /// that begins with the header (so its pointers count from there).
    fn encode_ifd<K: TiffKind>(&self) -> Result<Vec<u8>> {
        let mut buf = Cursor::new(Vec::new());
        {
            let mut enc = TiffEncoder::<_, K>::new_generic(&mut buf).map_err(enc_err)?;
            let mut d = enc.image_directory().map_err(enc_err)?;
            let (format, predictor) = match self.st {
                SampleType::U8 | SampleType::U16 => (1u16, 2u16),
                SampleType::I16 | SampleType::I32 => (2, 2),
                SampleType::F32 | SampleType::F64 => (3, 1),
            };
            let offsets = self
                .offsets
                .iter()
                .map(|&o| K::convert_offset(o))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(enc_err)?;
            let counts = self
                .counts
                .iter()
                .map(|&c| K::convert_offset(c))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(enc_err)?;
            let e = enc_err;
            d.write_tag(Tag::ImageWidth, self.width as u32).map_err(e)?;
            d.write_tag(Tag::ImageLength, self.height as u32)
                .map_err(e)?;
            d.write_tag(Tag::BitsPerSample, self.st.bits() as u16)
                .map_err(e)?;
            d.write_tag(Tag::Compression, 8u16).map_err(e)?; // Deflate (Adobe)
            d.write_tag(Tag::PhotometricInterpretation, 1u16)
                .map_err(e)?; // BlackIsZero
            d.write_tag(Tag::SamplesPerPixel, 1u16).map_err(e)?;
            d.write_tag(Tag::Predictor, predictor).map_err(e)?;
            d.write_tag(Tag::TileWidth, TILE as u32).map_err(e)?;
            d.write_tag(Tag::TileLength, TILE as u32).map_err(e)?;
            d.write_tag(Tag::TileOffsets, K::convert_slice(&offsets))
                .map_err(e)?;
            d.write_tag(Tag::TileByteCounts, K::convert_slice(&counts))
                .map_err(e)?;
            d.write_tag(Tag::SampleFormat, format).map_err(e)?;
            write_geo_tags(&mut d, &self.tags)?;
            d.finish().map_err(e)?;
        }
        Ok(buf.into_inner())
    }
}

/// Horizontal differencing (TIFF predictor 2) of one row of `bps`-byte native-endian integers.
fn horizontal_predict(row: &mut [u8], bps: usize) {
    match bps {
        1 => {
            for i in (1..row.len()).rev() {
                row[i] = row[i].wrapping_sub(row[i - 1]);
            }
        }
        2 => {
            for i in (1..row.len() / 2).rev() {
                let get = |k: usize| u16::from_ne_bytes([row[2 * k], row[2 * k + 1]]);
                let d = get(i).wrapping_sub(get(i - 1));
                row[2 * i..2 * i + 2].copy_from_slice(&d.to_ne_bytes());
            }
        }
        _ => {
            for i in (1..row.len() / 4).rev() {
                let get = |k: usize| {
                    u32::from_ne_bytes(row[4 * k..4 * k + 4].try_into().expect("4 bytes"))
                };
                let d = get(i).wrapping_sub(get(i - 1));
                row[4 * i..4 * i + 4].copy_from_slice(&d.to_ne_bytes());
            }
        }
    }
}

/// Move the in-memory file `file` (header, then the directory and its values, in native byte
/// order as the `tiff` crate writes) by `shift` bytes: returns what follows the header, with
/// every pointer in the directory shifted, and where the directory now starts.
///
/// Hand-written: the `tiff` encoder counts positions from where it began writing, and it
/// cannot begin behind tiles it did not write itself.
fn relocate(mut file: Vec<u8>, big: bool, shift: u64) -> Result<(Vec<u8>, u64)> {
    let bad = || Error::invalid("GeoTIFF encoding failed: unexpected directory layout");
    let ne = |b: &[u8]| -> u64 {
        if cfg!(target_endian = "little") {
            uint(b, true)
        } else {
            uint(b, false)
        }
    };
    let (header_len, ptr_len, count_len, entry_len) =
        if big { (16, 8, 8, 20) } else { (8, 4, 2, 12) };
    let ifd = ne(file.get(header_len - ptr_len..header_len).ok_or_else(bad)?) as usize;
    let n = ne(file.get(ifd..ifd + count_len).ok_or_else(bad)?) as usize;
    for k in 0..n {
        let e = ifd + count_len + k * entry_len;
        let entry = file.get(e..e + entry_len).ok_or_else(bad)?;
        let typ = ne(&entry[2..4]) as u16;
        let count = ne(&entry[4..4 + ptr_len]);
        let size = type_size(typ).ok_or_else(bad)?;
        if size.saturating_mul(count) <= ptr_len as u64 {
            continue; // the value is in the entry itself
        }
        let field = e + 4 + ptr_len;
        let moved = ne(&file[field..field + ptr_len]) + shift;
        if big {
            file[field..field + 8].copy_from_slice(&moved.to_ne_bytes());
        } else {
            let moved = u32::try_from(moved)
                .map_err(|_| Error::limit("GeoTIFF is over 4 GiB, too large for a classic TIFF"))?;
            file[field..field + 4].copy_from_slice(&moved.to_ne_bytes());
        }
    }
    Ok((file.split_off(header_len), ifd as u64 + shift))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::{read, write};
    use crate::model::ValueMapping;
    use tiff::decoder::Decoder;

    #[test]
    fn writer_round_trips_through_read() {
        let cases: Vec<(SampleType, Option<f64>)> = vec![
            (SampleType::I16, Some(-9999.0)),
            (SampleType::I16, None),
            (SampleType::U16, Some(0.0)),
            (SampleType::U16, None),
            (SampleType::F32, Some(-3.3999999521443642e38)),
            (SampleType::F32, None),
            (SampleType::U8, Some(255.0)),
            (SampleType::I32, None),
            (SampleType::F64, None),
        ];
        for (k, (st, nodata)) in cases.into_iter().enumerate() {
            for (w, h) in [(1, 1), (600, 530), (256, 256), (257, 3), (3, 700)] {
                let what = format!("{} nodata {nodata:?} {w}x{h}", st.name());
                let r = synthetic(st, w, h, nodata, 100 + k as u64);
                let bytes = stream_write(&r, 100);
                let back = read(&bytes, &opts()).unwrap();
                // What `write` gives, but for the synthesised GeoKeys (none in either).
                let via_write = read(&write(&r).unwrap(), &opts()).unwrap();
                assert_same(&back, &via_write, &what);
                assert_eq!(back.gdal_metadata, r.gdal_metadata, "{what}");
                assert_eq!(back.georef, via_write.georef, "{what}");
                let mut want = r.clone();
                if r.mask.is_some() && r.nodata.is_none() && st.is_integer() {
                    want.nodata = back.nodata; // the type's end, declared
                    for (i, v) in want.data.iter_mut().enumerate() {
                        if !r.is_valid(i) {
                            *v = back.nodata.unwrap();
                        }
                    }
                }
                want.georef = back.georef.clone();
                assert_same(&back, &want, &what);
                // Structure: tiles of 256, Deflate, predictor 2 for integers.
                let mut d = Decoder::new(Cursor::new(&bytes[..])).unwrap();
                assert_eq!(d.get_tag_u32(Tag::TileWidth).unwrap(), 256);
                assert_eq!(d.get_tag_u32(Tag::TileLength).unwrap(), 256);
                assert_eq!(d.get_tag_u32(Tag::Compression).unwrap(), 8);
                let pred = d.get_tag_u32(Tag::Predictor).unwrap();
                assert_eq!(pred, if st.is_integer() { 2 } else { 1 }, "{what}");
            }
        }
    }

    #[test]
    fn writer_bigtiff_reads_back_the_same() {
        for (st, nodata) in [(SampleType::I16, None), (SampleType::F64, Some(-1e300))] {
            let r = synthetic(st, 300, 270, nodata, 31);
            let classic = stream_write_kind(&r, 50, Some(false));
            let big = stream_write_kind(&r, 50, Some(true));
            assert_eq!(&classic[..4], b"II*\0");
            assert_eq!(&big[..4], b"II+\0");
            let a = read(&classic, &opts()).unwrap();
            let b = read(&big, &opts()).unwrap();
            assert_same(&a, &b, st.name());
            assert_eq!(a.gdal_metadata, b.gdal_metadata);
            assert_eq!(
                stream_write(&r, 300),
                classic,
                "small rasters are classic TIFFs"
            );
        }
    }

    #[test]
    fn writer_keeps_corpus_tags() {
        for_each_corpus_tif(|_, name, _, r| {
            let bytes = stream_write(&r, 256);
            let via_write = write(&r).unwrap();
            let back = read(&bytes, &opts()).unwrap();
            assert_same(&back, &r, name);
            assert_eq!(back.gdal_metadata, r.gdal_metadata, "{name}");
            for t in [
                Tag::ModelPixelScaleTag,
                Tag::ModelTiepointTag,
                Tag::GeoKeyDirectoryTag,
                Tag::GeoDoubleParamsTag,
                Tag::GeoAsciiParamsTag,
                Tag::GdalNodata,
                Tag::Unknown(42112),
            ] {
                assert_eq!(
                    raw_tag(&bytes, t),
                    raw_tag(&via_write, t),
                    "{name}: tag {t:?}"
                );
            }
        });
    }

    #[test]
    fn writer_output_does_not_depend_on_the_band_heights() {
        for (st, nodata) in [
            (SampleType::I16, Some(-9999.0)),
            (SampleType::F32, None),
            (SampleType::U8, None),
        ] {
            let r = synthetic(st, 530, 600, nodata, 9);
            let all = stream_write(&r, r.height);
            assert_eq!(stream_write(&r, 1), all, "{}", st.name());
            assert_eq!(stream_write(&r, 100), all, "{}", st.name());
            assert_eq!(stream_write(&r, 256), all, "{}", st.name());
        }
    }

    #[test]
    fn writer_mapped_integers_follow_the_output_type() {
        // Scale 0.25: the codes, with GDAL's offset and scale; read back as the mapping.
        let mut r = Raster::from_values(
            3,
            2,
            vec![0.5, 1.25, -7.0, 0.0, 2.0, 3.0],
            None,
            SampleType::U16,
        )
        .unwrap();
        r.mapping = ValueMapping {
            scale: 0.25,
            offset: -10.0,
        };
        let back = read(&stream_write(&r, 1), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::U16);
        assert_eq!(back.mapping, r.mapping);
        assert_eq!(back.data, r.data);
        let striped = read(&super::super::write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(
            (striped.sample_type, striped.mapping),
            (back.sample_type, back.mapping)
        );
        // u16 codes mapped by -32768: int16 values, no mapping left.
        let mut r = Raster::from_values(
            2,
            2,
            vec![-37.0, 1486.0, -32768.0, 0.0],
            Some(-32768.0),
            SampleType::U16,
        )
        .unwrap();
        r.mapping = ValueMapping {
            scale: 1.0,
            offset: -32768.0,
        };
        let back = read(&stream_write(&r, 1), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::I16);
        assert!(back.mapping.is_identity());
        assert_eq!(back.data, r.data);
        assert_eq!(back.nodata, Some(-32768.0));
        assert_eq!(back.mask, r.mask);
    }

    #[test]
    fn writer_checks_values_and_rows() {
        let meta = Raster::from_values(4, 3, vec![0.0; 12], None, SampleType::I16).unwrap();
        let new = || StreamWriter::new(Cursor::new(Vec::new()), 4, 3, &meta).unwrap();
        let row = |v: Vec<f64>| Raster::from_values(4, 1, v, None, SampleType::I16).unwrap();

        // Rounded, then range checked with the whole-raster row number.
        let mut w = new();
        w.write_rows(&row(vec![1.4, 2.6, -3.5, 7.0])).unwrap();
        let e = w
            .write_rows(&row(vec![1.0, 40000.0, 2.0, 3.0]))
            .unwrap_err();
        assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
        assert!(e.to_string().contains("40000 at row 1, col 1"), "{e}");

        // Too few, too many rows, the wrong width.
        let mut w = new();
        w.write_rows(&row(vec![1.0; 4])).unwrap();
        let e = w.finish().err().unwrap();
        assert!(e.to_string().contains("1 of its 3 rows"), "{e}");
        let mut w = new();
        let four = Raster::from_values(4, 4, vec![0.0; 16], None, SampleType::I16).unwrap();
        assert!(w.write_rows(&four).is_err());
        let narrow = Raster::from_values(3, 1, vec![0.0; 3], None, SampleType::I16).unwrap();
        assert!(w.write_rows(&narrow).is_err());

        // Rounding as `write`: one round trip.
        let mut w = new();
        for _ in 0..3 {
            w.write_rows(&row(vec![1.4, 2.6, -3.5, 7.0])).unwrap();
        }
        let back = read(&w.finish().unwrap().into_inner(), &opts()).unwrap();
        assert_eq!(back.data[..4], [1.0, 3.0, -4.0, 7.0]);

        // Holes without nodata where a valid sample holds the fill value.
        let mut w = new();
        w.write_rows(&row(vec![-32768.0, 1.0, 2.0, 3.0])).unwrap();
        let e = w
            .write_rows(&row(vec![f64::NAN, 1.0, 2.0, 3.0]))
            .unwrap_err();
        assert!(
            e.to_string().contains("give the raster a nodata value"),
            "{e}"
        );
        // After that, the stream is unusable.
        let e = w.write_rows(&row(vec![1.0; 4])).unwrap_err();
        assert!(e.to_string().contains("incomplete"), "{e}");
        assert!(w.finish().is_err());

        // Within one band, the first problem in sample order wins: a hole, then a valid
        // sample at the fill value, then an out-of-range one (the fill error), and the
        // other way round (the range error), also when rows of one band convert side by
        // side.
        let band = |v: Vec<f64>| Raster::from_values(4, 3, v, None, SampleType::I16).unwrap();
        let mut v = vec![1.0; 12];
        (v[5], v[6], v[7]) = (f64::NAN, -32768.0, 40000.0);
        let e = new().write_rows(&band(v.clone())).unwrap_err();
        assert!(e.to_string().contains("row 1, col 2 holds -32768"), "{e}");
        (v[6], v[7]) = (40000.0, -32768.0);
        let e = new().write_rows(&band(v.clone())).unwrap_err();
        assert!(e.to_string().contains("40000 at row 1, col 2"), "{e}");
        // The fill value in one row, the hole in a later one: the error names the first.
        let mut v = vec![1.0; 12];
        (v[1], v[6], v[9]) = (-32768.0, -32768.0, f64::NAN);
        let e = new().write_rows(&band(v)).unwrap_err();
        assert!(e.to_string().contains("row 0, col 1 holds -32768"), "{e}");

        // A nodata value the type cannot hold, once it must be written.
        let mut meta = meta.clone();
        meta.nodata = Some(-1e9);
        let mut w = StreamWriter::new(Cursor::new(Vec::new()), 4, 3, &meta).unwrap();
        w.write_rows(&row(vec![1.0; 4])).unwrap();
        let holes =
            Raster::from_values(4, 1, vec![1.0, -1e9, 1.0, 1.0], Some(-1e9), SampleType::I16)
                .unwrap();
        let e = w.write_rows(&holes).unwrap_err();
        assert!(e.to_string().contains("cannot be stored"), "{e}");

        // float32 overflow.
        let meta = Raster::from_values(1, 1, vec![0.0], None, SampleType::F32).unwrap();
        let mut w = StreamWriter::new(Cursor::new(Vec::new()), 1, 1, &meta).unwrap();
        let big = Raster::from_values(1, 1, vec![1e300], None, SampleType::F32).unwrap();
        assert!(w.write_rows(&big).is_err());
    }

    #[test]
    fn writer_starts_at_the_stream_position() {
        let r = synthetic(SampleType::I16, 40, 30, Some(-9999.0), 1);
        let mut out = Cursor::new(b"prefix".to_vec());
        out.seek(SeekFrom::End(0)).unwrap();
        let mut w = StreamWriter::new(out, 40, 30, &r).unwrap();
        w.write_rows(&r).unwrap();
        let bytes = w.finish().unwrap().into_inner();
        assert_eq!(&bytes[..6], b"prefix");
        assert_eq!(bytes[6..], stream_write(&r, 30));
    }

    #[test]
    fn gdal_reads_the_tiled_output() {
        use std::process::Command;
        let gdalinfo = Command::new("gdalinfo").arg("--version").output();
        if !gdalinfo.is_ok_and(|o| o.status.success()) {
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED (gdalinfo not found): gdal_reads_the_tiled_output"
            );
            return;
        }
        for (st, nodata, gdal_nodata, big) in [
            (
                SampleType::I16,
                Some(-9999.0),
                serde_json::json!(-9999.0),
                false,
            ),
            (SampleType::F32, None, serde_json::json!("NaN"), false),
            (SampleType::U16, None, serde_json::json!(65535.0), true),
        ] {
            let r = synthetic(st, 600, 530, nodata, 21);
            let bytes = stream_write_kind(&r, 77, Some(big));
            let (dir, path) = temp_file(&bytes);
            let o = Command::new("gdalinfo")
                .arg("-json")
                .arg(&path)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(j["size"], serde_json::json!([600, 530]));
            let band = &j["bands"][0];
            assert_eq!(band["block"], serde_json::json!([256, 256]));
            assert_eq!(band["noDataValue"], gdal_nodata, "{}", st.name());
            let g = r.georef.as_ref().unwrap();
            let gt: Vec<f64> = j["geoTransform"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert_eq!(
                gt,
                vec![
                    g.origin[0],
                    g.pixel_size[0],
                    0.0,
                    g.origin[1],
                    0.0,
                    -g.pixel_size[1]
                ]
            );

            // GDAL decodes the tiles (predictor, padding, Deflate) to the same samples: its
            // uncompressed striped copy reads back as ours does.
            let copy = dir.path().join("copy.tif");
            let o = Command::new("gdal_translate")
                .args(["-q", "-co", "COMPRESS=NONE", "-co", "TILED=NO"])
                .arg(&path)
                .arg(&copy)
                .output();
            match o {
                Ok(o) if o.status.success() => {
                    let ours = read(&bytes, &opts()).unwrap();
                    let mut gdals = read(&std::fs::read(&copy).unwrap(), &opts()).unwrap();
                    // GDAL writes GeoKeys of its own; the placement must agree.
                    let (a, b) = (
                        gdals.georef.as_ref().unwrap(),
                        ours.georef.as_ref().unwrap(),
                    );
                    assert_eq!((a.origin, a.pixel_size), (b.origin, b.pixel_size));
                    gdals.georef = ours.georef.clone();
                    assert_same(&gdals, &ours, &format!("{} via gdal_translate", st.name()));
                }
                _ => {
                    let _ = writeln!(
                        std::io::stderr(),
                        "SKIPPED (gdal_translate not found): gdal_reads_the_tiled_output, \
                         decoding part"
                    );
                }
            }
        }
    }
}
