//! Streaming GeoTIFF: a single-band GeoTIFF read band by band (groups of full-width rows) and
//! written band by band as a tiled GeoTIFF, so rasters larger than memory pass through.
//!
//! **Reading** ([`StreamReader`]) opens the file without loading it. The IFD pre-pass walks the
//! first image directory on the file itself, with the bounds checks of `precheck` against the
//! file's length, and copies the tags `precheck` looks at into a small in-memory TIFF of the
//! same kind (chunk offsets and byte counts zeroed; those are checked against the real file).
//! `precheck` itself then checks the layout and size on that copy, so the reader accepts and
//! refuses exactly what [`read`](super::read) does, with the same messages, and the georef,
//! nodata and GDAL_METADATA come from the same functions on the same tag bytes. Samples are
//! decoded chunk by chunk by the `tiff` crate's `read_chunk` over the open file: a band decodes
//! only the strips or tiles that cover its rows, and one chunk row (a strip, or a row of tiles)
//! stays decoded for the next band.
//!
//! **Writing** ([`StreamWriter`]) produces a tiled (256 × 256), Deflate-compressed GeoTIFF.
//! The `tiff` 0.11 encoder writes strips only, so tiles are cut, predicted and compressed
//! here and written straight to the output as their tile row completes; the image directory
//! comes last (its GDAL_NODATA depends on whether any sample was invalid). The directory is
//! encoded by the `tiff` crate (with `write_geo_tags`, so the GeoTIFF tags are those of
//! `write`) into memory as if its file began there, then moved behind the
//! tiles, with its pointers shifted by the distance moved.

// Until the codec calls the streaming reader and writer, the library itself uses neither.

use super::georef::{GeoTags, geo_tags, read_georef, write_geo_tags};
use super::nodata::read_nodata;
use super::precheck::{CHECKED_TAGS, Layout, precheck, type_size};
use super::tags::{enc_err, tag_string, tiff_err};
use super::write::BIGTIFF_THRESHOLD;
use super::{
    TAG_GDAL_METADATA, TAG_STRIP_BYTE_COUNTS, TAG_STRIP_OFFSETS, TAG_TILE_BYTE_COUNTS,
    TAG_TILE_OFFSETS, TAG_TILE_WIDTH, mask,
};
use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{Georef, OutputType, Raster, SampleType, ValueMapping};
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom, Write};
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::encoder::{TiffEncoder, TiffKind, TiffKindBig, TiffKindStandard};
use tiff::tags::Tag;

// ===== reading ==============================================================================

/// Reads a single-band GeoTIFF band by band (full-width groups of rows) without holding the
/// image.
///
/// Memory: the IFD's chunk offsets, one chunk row of decoded samples as `f64` (for a striped
/// file one strip, `rows_per_strip × width`; for a tiled one a row of tiles,
/// `tile_length × width`; a file stored as a single strip is therefore decoded whole), and the
/// band asked for.
pub struct StreamReader {
    dec: Decoder<BufReader<File>>,
    width: usize,
    height: usize,
    sample_type: SampleType,
    nodata: Option<f64>,
    georef: Option<Georef>,
    gdal_metadata: Option<String>,
    /// Width of a chunk: the image width for strips, the tile width for tiles.
    chunk_width: usize,
    /// Rows of a chunk row (at most the image height).
    chunk_rows: usize,
    /// Chunks in a chunk row (1 for strips).
    chunks_across: usize,
    /// The last chunk row decoded.
    cache: Option<ChunkRow>,
    /// The internal mask band, and the file it is read from.
    mask: Option<(mask::Mask, mask::OnDisk)>,
}

/// The samples of one decoded chunk row, full width.
struct ChunkRow {
    index: usize,
    /// First image row it holds.
    y0: usize,
    rows: usize,
    data: Vec<f64>,
}

impl StreamReader {
    /// Open and check the file (same layouts and same errors as [`read`](super::read): sample
    /// types u8/i16/u16/i32/f32/f64, one sample per pixel, strips or tiles,
    /// none/LZW/Deflate/PackBits, predictor 1/2/3; size within `opts.max_samples()`; chunk
    /// offsets and byte counts inside the file) without reading the whole file into memory.
    pub fn open(path: &Path, opts: &ReadOptions) -> Result<StreamReader> {
        let ctx = path.display().to_string();
        let file = File::open(path).map_err(|e| Error::io(&ctx, e))?;
        let len = file.metadata().map_err(|e| Error::io(&ctx, e))?.len();
        let mut f = FileAt {
            r: BufReader::new(file),
            len,
            le: true,
            ctx,
        };
        let (layout, mini) = prepass(&mut f, opts)?;
        let limits = read_limits(&layout, len);

        let mut r = f.r;
        r.seek(SeekFrom::Start(0))
            .map_err(|e| Error::io(&f.ctx, e))?;
        let mut dec = Decoder::new(r)
            .map_err(tiff_err)?
            .with_limits(limits.clone());
        let (w, h) = dec.dimensions().map_err(tiff_err)?;
        if (w as usize, h as usize) != (layout.width, layout.height) {
            return Err(Error::corrupt("GeoTIFF image size disagrees with its tags"));
        }

        // The tags `read` takes its georef, nodata and metadata from, from the same bytes.
        let mut tags = Decoder::new(Cursor::new(&mini[..]))
            .map_err(tiff_err)?
            .with_limits(limits);
        let st = layout.sample_type;
        let georef = read_georef(&mut tags)?;
        let nodata = read_nodata(&mut tags, st)?;
        let gdal_metadata = tag_string(&mut tags, TAG_GDAL_METADATA)?;

        // The internal mask band, read band by band like the samples.
        let mut on_disk = mask::OnDisk {
            file: File::open(path).map_err(|e| Error::io(&f.ctx, e))?,
            len,
        };
        let mask = mask::find(&mut on_disk, layout.width, layout.height)?.map(|m| (m, on_disk));

        let (cw, ch) = dec.chunk_dimensions();
        let chunk_width = (cw as usize).min(layout.width);
        let chunk_rows = (ch as usize).min(layout.height);
        if chunk_width == 0 || chunk_rows == 0 {
            return Err(Error::corrupt(format!(
                "GeoTIFF chunk size {cw}x{ch} is invalid"
            )));
        }
        Ok(StreamReader {
            dec,
            width: layout.width,
            height: layout.height,
            sample_type: st,
            nodata,
            georef,
            gdal_metadata,
            chunk_width,
            chunk_rows,
            chunks_across: layout.width.div_ceil(chunk_width),
            cache: None,
            mask,
        })
    }

    /// Samples per row.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Rows `y0..y0 + rows`, full width, as a [`Raster`] exactly as [`read`](super::read)
    /// gives that part of the image: values as `f64`, nodata and NaN samples invalid (the mask
    /// is `None` when every sample of the band is valid), the file's nodata, sample type and
    /// GDAL_METADATA (verbatim, except that a GDAL scale/offset of integer samples is the
    /// value mapping, the values `offset + scale · sample`), and the georef moved to the band's top-left
    /// corner ([`Georef::window`]`(0, y0)`).
    ///
    /// Only the chunks covering these rows are decoded; the last chunk row decoded is kept, so
    /// consecutive bands that share a chunk row decode it once. Any order of bands works.
    pub fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        if rows == 0 || y0 >= self.height || rows > self.height - y0 {
            return Err(Error::invalid(format!(
                "rows {y0}..{} are not inside the GeoTIFF's {} rows",
                y0.saturating_add(rows),
                self.height
            )));
        }
        let w = self.width;
        let end = y0 + rows;
        let mut data = Vec::with_capacity(w * rows);
        let mut y = y0;
        while y < end {
            let c = self.chunk_row(y / self.chunk_rows)?;
            let upto = end.min(c.y0 + c.rows);
            data.extend_from_slice(&c.data[(y - c.y0) * w..(upto - c.y0) * w]);
            y = upto;
        }
        if let Some((m, file)) = &mut self.mask {
            for (v, ok) in data.iter_mut().zip(m.rows(file, y0, rows)?) {
                if !ok {
                    *v = f64::NAN;
                }
            }
        }

        // `read` refuses infinite samples other than the nodata value; name the first one by
        // its place in the whole image, as `read` would.
        if let Some(k) = data
            .iter()
            .position(|&v| v.is_infinite() && self.nodata != Some(v))
        {
            let i = y0 * w + k;
            return Err(Error::unsupported(format!(
                "GeoTIFF sample {i} (row {}, col {}) is infinite (only finite values or nodata \
                 are supported)",
                i / w,
                i % w
            )));
        }
        let mut r = Raster::from_values(w, rows, data, self.nodata, self.sample_type)?;
        r.georef = self.georef.as_ref().map(|g| g.window(0, y0));
        r.gdal_metadata = self.gdal_metadata.clone();
        // As `read`: GDAL's scale/offset of integer codes become the value mapping.
        crate::formats::apply_gdal_mapping(&mut r);
        Ok(r)
    }

    /// Chunk row `k`, decoded (from the cache when it is the last one decoded).
    fn chunk_row(&mut self, k: usize) -> Result<&ChunkRow> {
        if self.cache.as_ref().is_none_or(|c| c.index != k) {
            self.cache = None; // at most one chunk row in memory
            let y0 = k * self.chunk_rows;
            let rows = self.chunk_rows.min(self.height - y0);
            let w = self.width;
            let mut data = vec![0.0; w * rows];
            for tx in 0..self.chunks_across {
                let x0 = tx * self.chunk_width;
                let cols = self.chunk_width.min(w - x0);
                let index = u32::try_from(k * self.chunks_across + tx)
                    .map_err(|_| Error::corrupt("GeoTIFF has too many chunks"))?;
                let chunk = self.dec.read_chunk(index).map_err(tiff_err)?;
                let values = samples_f64(chunk, self.sample_type)?;
                if values.len() != cols * rows {
                    return Err(Error::corrupt(format!(
                        "GeoTIFF chunk {index} decoded to {} samples, expected {}",
                        values.len(),
                        cols * rows
                    )));
                }
                for (r, src) in values.chunks_exact(cols).enumerate() {
                    data[r * w + x0..r * w + x0 + cols].copy_from_slice(src);
                }
            }
            self.cache = Some(ChunkRow {
                index: k,
                y0,
                rows,
                data,
            });
        }
        Ok(self.cache.as_ref().expect("filled above"))
    }
}

/// The decoder limits `read` uses: room for the image (so for any chunk of it) and for a
/// compressed chunk as long as the file.
fn read_limits(layout: &Layout, file_len: u64) -> Limits {
    let mut limits = Limits::default();
    let image_bytes = (layout.samples as u64).saturating_mul(layout.sample_type.bits() as u64 / 8);
    limits.decoding_buffer_size = usize::try_from(image_bytes)
        .unwrap_or(usize::MAX)
        .max(Limits::default().decoding_buffer_size);
    limits.intermediate_buffer_size = usize::try_from(file_len)
        .unwrap_or(usize::MAX)
        .max(Limits::default().intermediate_buffer_size);
    limits
}

/// Decoded samples as `f64`, checked to be of the type the tags declare (as `read` does).
fn samples_f64(decoded: DecodingResult, st: SampleType) -> Result<Vec<f64>> {
    Ok(match (decoded, st) {
        (DecodingResult::U8(v), SampleType::U8) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::I16(v), SampleType::I16) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::U16(v), SampleType::U16) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::I32(v), SampleType::I32) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::F32(v), SampleType::F32) => v.into_iter().map(f64::from).collect(),
        (DecodingResult::F64(v), SampleType::F64) => v,
        _ => {
            return Err(Error::corrupt(format!(
                "GeoTIFF decoded to a different sample type than its tags declare ({})",
                st.name()
            )));
        }
    })
}

/// The file, read at given positions: the pre-pass's counterpart of `precheck`'s byte slice.
struct FileAt {
    r: BufReader<File>,
    len: u64,
    /// Byte order (known after the first two bytes).
    le: bool,
    ctx: String,
}

impl FileAt {
    /// The `n` bytes at `pos`, or `None` when they run past the end of the file.
    fn bytes(&mut self, pos: u64, n: u64) -> Result<Option<Vec<u8>>> {
        if pos.checked_add(n).is_none_or(|end| end > self.len) {
            return Ok(None);
        }
        let n = usize::try_from(n).map_err(|_| Error::limit("GeoTIFF tag too large"))?;
        self.r
            .seek(SeekFrom::Start(pos))
            .map_err(|e| Error::io(&self.ctx, e))?;
        let mut b = vec![0; n];
        self.r
            .read_exact(&mut b)
            .map_err(|e| Error::io(&self.ctx, e))?;
        Ok(Some(b))
    }
    fn uint_at(&mut self, pos: u64, n: u64) -> Result<Option<u64>> {
        let le = self.le;
        Ok(self.bytes(pos, n)?.map(|b| uint(&b, le)))
    }
}

/// An unsigned integer of 1, 2, 4 or 8 bytes in the given byte order.
fn uint(b: &[u8], le: bool) -> u64 {
    let fold = |acc: u64, &x: &u8| (acc << 8) | u64::from(x);
    if le {
        b.iter().rev().fold(0, fold)
    } else {
        b.iter().fold(0, fold)
    }
}

/// One IFD entry `precheck` looks at, with where its value bytes lie in the file.
struct FileEntry {
    tag: u16,
    typ: u16,
    count: u64,
    data_pos: u64,
    len: u64,
}

/// At most this many bytes of one tag's values are read (the `tiff` decoder's own default
/// limit on a tag's values, which `read` is subject to as well).
const MAX_TAG_BYTES: u64 = 256 << 20;

/// The IFD pre-pass on the file: `precheck`'s walk of the first IFD with its bounds checks
/// (same order, same messages) against the file's length, then `precheck` itself on a small
/// TIFF holding just the tags it reads (chunk offsets and byte counts zeroed), then the chunk
/// ranges checked against the file. Gives the layout and that small TIFF.
fn prepass(f: &mut FileAt, opts: &ReadOptions) -> Result<(Layout, Vec<u8>)> {
    let truncated = || Error::corrupt("GeoTIFF is truncated");
    let len = f.len;
    let le = match f.bytes(0, 2)?.as_deref() {
        Some(b"II") => true,
        Some(b"MM") => false,
        Some(_) => return Err(Error::corrupt("not a TIFF file (bad byte-order mark)")),
        None => return Err(truncated()),
    };
    f.le = le;
    let mut big = false;
    let ifd_pos = match f.uint_at(2, 2)?.ok_or_else(truncated)? {
        42 => f.uint_at(4, 4)?.ok_or_else(truncated)?,
        43 => {
            big = true;
            if f.uint_at(4, 2)? != Some(8) || f.uint_at(6, 2)? != Some(0) {
                return Err(Error::corrupt("BigTIFF header is invalid"));
            }
            f.uint_at(8, 8)?.ok_or_else(truncated)?
        }
        v => return Err(Error::corrupt(format!("not a TIFF file (version {v})"))),
    };
    if ifd_pos < 8 || ifd_pos >= len {
        return Err(Error::corrupt(format!(
            "GeoTIFF image directory offset {ifd_pos} is outside the file ({len} bytes)"
        )));
    }
    let (count, entry_size, first, inline) = if big {
        (
            f.uint_at(ifd_pos, 8)?.ok_or_else(truncated)?,
            20,
            ifd_pos + 8,
            8,
        )
    } else {
        (
            f.uint_at(ifd_pos, 2)?.ok_or_else(truncated)?,
            12,
            ifd_pos + 2,
            4,
        )
    };
    if count == 0 {
        return Err(Error::corrupt("GeoTIFF image directory is empty"));
    }
    let dir_end = count
        .checked_mul(entry_size)
        .and_then(|n| n.checked_add(first))
        .ok_or_else(truncated)?;
    if dir_end > len {
        return Err(truncated());
    }

    // The entries, read a block at a time.
    const BLOCK: u64 = 4096;
    let mut entries: Vec<FileEntry> = Vec::new();
    let mut k = 0;
    while k < count {
        let n = (count - k).min(BLOCK);
        let block = f
            .bytes(first + k * entry_size, n * entry_size)?
            .ok_or_else(truncated)?;
        for (j, e) in block.chunks_exact(entry_size as usize).enumerate() {
            let tag = uint(&e[..2], le) as u16;
            if !CHECKED_TAGS.contains(&tag) {
                continue;
            }
            let typ = uint(&e[2..4], le) as u16;
            let p = first + (k + j as u64) * entry_size;
            let (cnt, field, field_bytes) = if big {
                (uint(&e[4..12], le), p + 12, &e[12..20])
            } else {
                (uint(&e[4..8], le), p + 8, &e[8..12])
            };
            let size = type_size(typ).ok_or_else(|| {
                Error::corrupt(format!("GeoTIFF tag {tag} has an unknown field type {typ}"))
            })?;
            let dlen = size.checked_mul(cnt).ok_or_else(truncated)?;
            let data_pos = if dlen <= inline {
                field
            } else {
                uint(field_bytes, le)
            };
            if data_pos.checked_add(dlen).is_none_or(|end| end > len) {
                return Err(Error::corrupt(format!(
                    "GeoTIFF is truncated or corrupt: tag {tag} ({cnt} values at offset \
                     {data_pos}) ends past the end of the file ({len} bytes)"
                )));
            }
            if entries.iter().any(|e| e.tag == tag) {
                continue; // the decoder keeps the first one too
            }
            entries.push(FileEntry {
                tag,
                typ,
                count: cnt,
                data_pos,
                len: dlen,
            });
        }
        k += n;
    }

    // The tags' values: verbatim, except the chunk offsets and byte counts, which are zeros in
    // the copy (so `precheck` finds its chunks inside it) and kept aside to check here.
    let is_chunk_tag = |t: u16| {
        [
            TAG_STRIP_OFFSETS,
            TAG_STRIP_BYTE_COUNTS,
            TAG_TILE_OFFSETS,
            TAG_TILE_BYTE_COUNTS,
        ]
        .contains(&t)
    };
    let mut values: Vec<(u16, u16, u64, Vec<u8>)> = Vec::with_capacity(entries.len());
    let mut chunk_values: Vec<(u16, u16, Vec<u8>)> = Vec::new();
    for e in &entries {
        if e.len > MAX_TAG_BYTES {
            return Err(Error::limit(format!(
                "GeoTIFF tag {} holds {} bytes, over the limit of {MAX_TAG_BYTES}",
                e.tag, e.len
            )));
        }
        let data = f.bytes(e.data_pos, e.len)?.ok_or_else(truncated)?;
        if is_chunk_tag(e.tag) {
            values.push((e.tag, e.typ, e.count, vec![0; data.len()]));
            chunk_values.push((e.tag, e.typ, data));
        } else {
            values.push((e.tag, e.typ, e.count, data));
        }
    }
    let mini = mini_tiff(le, big, &mut values)?;
    let layout = precheck(&mini, opts)?;

    // The chunks must lie inside the file (`precheck`'s last check, on the real offsets).
    let tiled = entries
        .iter()
        .any(|e| e.tag == TAG_TILE_OFFSETS || e.tag == TAG_TILE_WIDTH);
    let (offsets_tag, counts_tag) = if tiled {
        (TAG_TILE_OFFSETS, TAG_TILE_BYTE_COUNTS)
    } else {
        (TAG_STRIP_OFFSETS, TAG_STRIP_BYTE_COUNTS)
    };
    let uints = |tag: u16| -> Result<Vec<u64>> {
        let Some((_, typ, data)) = chunk_values.iter().find(|v| v.0 == tag) else {
            return Err(Error::corrupt("GeoTIFF has no strip or tile offsets"));
        };
        let size = type_size(*typ).unwrap_or(0) as usize;
        if !matches!(typ, 1 | 3 | 4 | 16) || size == 0 {
            return Err(Error::corrupt(format!(
                "GeoTIFF tag {tag} has type {typ} where an unsigned integer is expected"
            )));
        }
        Ok(data.chunks_exact(size).map(|b| uint(b, le)).collect())
    };
    let offsets = uints(offsets_tag)?;
    let counts = uints(counts_tag)?;
    for (i, (&o, &c)) in offsets.iter().zip(&counts).enumerate() {
        if o.checked_add(c).is_none_or(|end| end > len) {
            return Err(Error::corrupt(format!(
                "GeoTIFF is truncated: {} {i} ({c} bytes at offset {o}) ends past the end of \
                 the file ({len} bytes)",
                if tiled { "tile" } else { "strip" },
            )));
        }
    }
    Ok((layout, mini))
}

/// A TIFF of the file's kind (classic or BigTIFF) and byte order with one IFD of the given
/// entries (tag, type, count, value bytes), sorted by tag, the values too long for an entry
/// after the IFD. Being of the same kind, it stores inline exactly the values the file stores
/// inline, so the `tiff` decoder reads every value the way it reads the file's (it treats an
/// inline ASCII value differently from one stored apart, for instance).
fn mini_tiff(le: bool, big: bool, entries: &mut Vec<(u16, u16, u64, Vec<u8>)>) -> Result<Vec<u8>> {
    if entries.is_empty() {
        // An IFD needs an entry; `precheck` skips this one and reports what is missing.
        entries.push((0xffff, 1, 1, vec![0]));
    }
    entries.sort_by_key(|e| e.0);
    let put = |out: &mut Vec<u8>, v: u64, n: usize| {
        let b = v.to_le_bytes();
        if le {
            out.extend_from_slice(&b[..n]);
        } else {
            out.extend(b[..n].iter().rev());
        }
    };
    // Sizes of an offset (and count) field, of an entry count, of an entry.
    let (word, count_len, entry_len) = if big { (8, 8, 20) } else { (4, 2, 12) };
    let mut out = Vec::new();
    out.extend_from_slice(if le { b"II" } else { b"MM" });
    if big {
        put(&mut out, 43, 2);
        put(&mut out, 8, 2);
        put(&mut out, 0, 2);
    } else {
        put(&mut out, 42, 2);
    }
    let ifd = out.len() as u64 + word as u64;
    put(&mut out, ifd, word);
    put(&mut out, entries.len() as u64, count_len);
    let mut data_at = ifd + (count_len + entry_len * entries.len() + word) as u64;
    let mut data = Vec::new();
    for (tag, typ, count, bytes) in entries.iter() {
        put(&mut out, u64::from(*tag), 2);
        put(&mut out, u64::from(*typ), 2);
        put(&mut out, *count, word);
        if bytes.len() <= word {
            let mut field = bytes.clone();
            field.resize(word, 0);
            out.extend_from_slice(&field);
        } else {
            if !big && data_at > u64::from(u32::MAX) {
                return Err(Error::limit("GeoTIFF tags are too large"));
            }
            put(&mut out, data_at, word);
            data.extend_from_slice(bytes);
            if bytes.len() % 2 == 1 {
                data.push(0); // values start on a word boundary
            }
            data_at = ifd + (count_len + entry_len * entries.len() + word + data.len()) as u64;
        }
    }
    put(&mut out, 0, word);
    out.extend_from_slice(&data);
    Ok(out)
}

// ===== writing ==============================================================================

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
    fn with_kind(
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

impl crate::model::RowSource for StreamReader {
    fn width(&self) -> usize {
        StreamReader::width(self)
    }
    fn height(&self) -> usize {
        StreamReader::height(self)
    }
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        StreamReader::band(self, y0, rows)
    }
    fn notes(&self) -> Vec<String> {
        match self.mask {
            Some(_) => vec![
                "the GeoTIFF's internal mask band (GDAL's per-dataset mask) is read: the \
                 samples it masks are nodata"
                    .to_string(),
            ],
            None => Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::{
        TAG_PREDICTOR, TAG_ROWS_PER_STRIP, TAG_TILE_LENGTH, read, write,
    };
    use crate::model::{ValueMapping, Window};
    use crate::testutil::Rng;
    use std::path::PathBuf;
    use tiff::encoder::colortype::{Gray16, GrayI16};
    use tiff::encoder::{Compression, Predictor};

    /// `bytes` as a file in a fresh temporary directory.
    fn temp_file(bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.tif");
        std::fs::write(&path, bytes).unwrap();
        (dir, path)
    }

    /// Rows `y0..y0 + rows` of `whole` as `StreamReader::band` must give them.
    fn rows_of(whole: &Raster, y0: usize, rows: usize) -> Raster {
        let mut r = whole.crop(Window {
            x: 0,
            y: y0,
            width: whole.width,
            height: rows,
        });
        r.normalize_mask();
        r.georef = whole.georef.as_ref().map(|g| g.window(0, y0));
        r.gdal_metadata = whole.gdal_metadata.clone();
        r
    }

    fn assert_band(band: &Raster, whole: &Raster, y0: usize, what: &str) {
        let want = rows_of(whole, y0, band.height);
        assert_same(band, &want, what);
        assert_eq!(band.georef, want.georef, "{what}: georef");
        assert_eq!(
            band.gdal_metadata, want.gdal_metadata,
            "{what}: gdal_metadata"
        );
    }

    /// Read the file at `path` through `StreamReader` in bands of `h` rows (in order, then in
    /// reverse), each compared with `read` of the same bytes.
    fn check_stream_equals_read(path: &Path, whole: &Raster, what: &str) {
        for h in [1, 7, 256, whole.height] {
            let mut s = StreamReader::open(path, &opts()).unwrap();
            assert_eq!((s.width(), s.height()), (whole.width, whole.height));
            let starts: Vec<usize> = (0..whole.height).step_by(h).collect();
            for &y0 in starts.iter().chain(starts.iter().rev().take(3)) {
                let rows = h.min(whole.height - y0);
                let band = s.band(y0, rows).unwrap();
                assert_band(&band, whole, y0, &format!("{what}: band {y0}+{rows}"));
            }
        }
    }

    // ----- reading ----------------------------------------------------------------------

    #[test]
    fn reader_equals_read_on_the_corpus() {
        for_each_corpus_tif(|dir, name, _, whole| {
            check_stream_equals_read(&dir.join(format!("{name}.tif")), &whole, name);
        });
    }

    /// A raster of type `st` with holes (as nodata when given, else NaN) and a georef.
    fn synthetic(st: SampleType, w: usize, h: usize, nodata: Option<f64>, seed: u64) -> Raster {
        let mut rng = Rng(seed);
        // Inside the type's range, off its ends (the fill values of integer holes).
        let (lo, hi) = st
            .int_range()
            .map_or((-1e5, 1e5), |(lo, hi)| (lo + 1.0, hi - 1.0));
        let data: Vec<f64> = (0..w * h)
            .map(|i| {
                if rng.below(9) == 0 {
                    return nodata.unwrap_or(f64::NAN);
                }
                // A smooth surface plus noise, within the type's range.
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let v = (x * 0.05).sin() * 0.3 + (y * 0.031).cos() * 0.2 + 0.5;
                let v = lo + (hi - lo) * v.clamp(0.0, 1.0);
                match st {
                    SampleType::F32 => f64::from((v + rng.below(100) as f64 * 0.01) as f32),
                    SampleType::F64 => v + rng.below(100) as f64 * 1e-3,
                    _ => v.round().clamp(lo, hi) + 0.0,
                }
            })
            .collect();
        let mut r = Raster::from_values(w, h, data, nodata, st).unwrap();
        r.georef = Some(small_georef(Some(32611)));
        r.gdal_metadata =
            Some("<GDALMetadata>\n  <Item name=\"x\">y</Item>\n</GDALMetadata>\n".into());
        r
    }

    const TYPES: [(SampleType, Option<f64>); 7] = [
        (SampleType::U8, Some(0.0)),
        (SampleType::I16, Some(-9999.0)),
        (SampleType::U16, None),
        (SampleType::I32, Some(-2147483648.0)),
        (SampleType::F32, Some(-3.4028234663852886e38)),
        (SampleType::F32, None),
        (SampleType::F64, Some(-1e300)),
    ];

    #[test]
    fn reader_equals_read_on_striped_files() {
        for (k, &(st, nodata)) in TYPES.iter().enumerate() {
            let r = synthetic(st, 301, 530, nodata, 7 + k as u64);
            // write.rs: 64 KiB strips.
            let bytes = write(&r).unwrap();
            let whole = read(&bytes, &opts()).unwrap();
            let (_d, path) = temp_file(&bytes);
            check_stream_equals_read(&path, &whole, &format!("{} striped", st.name()));
        }
        // The tiff crate, LZW with small strips, int16 and uint16.
        let (w, h) = (97u32, 61u32);
        let vals: Vec<i16> = (0..w * h).map(|i| (i as i16).wrapping_mul(37)).collect();
        let mut out = Cursor::new(Vec::new());
        {
            let mut enc = TiffEncoder::new(&mut out)
                .unwrap()
                .with_compression(Compression::Lzw)
                .with_predictor(Predictor::Horizontal);
            let mut img = enc.new_image::<GrayI16>(w, h).unwrap();
            img.rows_per_strip(5).unwrap();
            img.write_data(&vals).unwrap();
        }
        let whole = read(out.get_ref(), &opts()).unwrap();
        let (_d, path) = temp_file(out.get_ref());
        check_stream_equals_read(&path, &whole, "LZW strips of 5 rows");

        let vals: Vec<u16> = (0..w * h).map(|i| (i * 13) as u16).collect();
        let mut out = Cursor::new(Vec::new());
        {
            let mut enc = TiffEncoder::new(&mut out)
                .unwrap()
                .with_compression(Compression::Packbits);
            let mut img = enc.new_image::<Gray16>(w, h).unwrap();
            img.rows_per_strip(1).unwrap();
            img.write_data(&vals).unwrap();
        }
        let whole = read(out.get_ref(), &opts()).unwrap();
        let (_d, path) = temp_file(out.get_ref());
        check_stream_equals_read(&path, &whole, "PackBits strips of 1 row");

        // Hand-made big-endian strips of 4 rows.
        let (w, h) = (7usize, 10usize);
        let vals: Vec<i16> = (0..w * h).map(|i| i as i16 * 300 - 9000).collect();
        let mut b = Builder::basic(false, w as u32, h as u32, 16, 2, 0);
        b.long(TAG_ROWS_PER_STRIP, &[4])
            .long(TAG_STRIP_OFFSETS, &[8, 8 + 56, 8 + 112])
            .long(TAG_STRIP_BYTE_COUNTS, &[56, 56, 28])
            .ascii(super::super::TAG_GDAL_NODATA, "-9000");
        let bytes = b.build(&i16_bytes(false, &vals));
        let whole = read(&bytes, &opts()).unwrap();
        assert_eq!(whole.data[1], -8700.0);
        let (_d, path) = temp_file(&bytes);
        check_stream_equals_read(&path, &whole, "big-endian strips of 4 rows");
    }

    /// A hand-made uncompressed tiled int16 TIFF (tiles `tw × th`) with a nodata value, in
    /// little- or big-endian byte order.
    fn handmade_tiled(le: bool, w: usize, h: usize, tw: usize, th: usize) -> Vec<u8> {
        let value = |x: usize, y: usize| ((y * 131 + x * 7) % 2000) as i16 - 1000;
        let (across, down) = (w.div_ceil(tw), h.div_ceil(th));
        let mut data = Vec::new();
        let mut offsets = Vec::new();
        for ty in 0..down {
            for tx in 0..across {
                offsets.push(8 + data.len() as u32);
                for y in 0..th {
                    for x in 0..tw {
                        let (gx, gy) = (tx * tw + x, ty * th + y);
                        let v = if gx < w && gy < h { value(gx, gy) } else { 0 };
                        data.extend_from_slice(&i16_bytes(le, &[v]));
                    }
                }
            }
        }
        let mut b = Builder::basic(le, w as u32, h as u32, 16, 2, 0);
        b.remove(TAG_STRIP_OFFSETS)
            .remove(TAG_STRIP_BYTE_COUNTS)
            .remove(TAG_ROWS_PER_STRIP)
            .long(TAG_TILE_WIDTH, &[tw as u32])
            .long(TAG_TILE_LENGTH, &[th as u32])
            .long(TAG_TILE_OFFSETS, &offsets)
            .long(
                TAG_TILE_BYTE_COUNTS,
                &vec![(tw * th * 2) as u32; offsets.len()],
            )
            .ascii(super::super::TAG_GDAL_NODATA, "-1000")
            .double(super::super::TAG_MODEL_PIXEL_SCALE, &[2.0, 3.0, 0.0])
            .double(
                super::super::TAG_MODEL_TIEPOINT,
                &[0.0, 0.0, 0.0, 100.0, 900.0, 0.0],
            );
        b.build(&data)
    }

    #[test]
    fn reader_equals_read_on_tiled_files() {
        // Our own tiled output, every sample type.
        for (k, &(st, nodata)) in TYPES.iter().enumerate() {
            let r = synthetic(st, 600, 530, nodata, 70 + k as u64);
            let bytes = stream_write(&r, 100);
            let whole = read(&bytes, &opts()).unwrap();
            let (_d, path) = temp_file(&bytes);
            check_stream_equals_read(&path, &whole, &format!("{} tiled", st.name()));
        }
        // Our own output as BigTIFF.
        let r = synthetic(SampleType::F32, 300, 270, Some(-9999.0), 77);
        let bytes = stream_write_kind(&r, 100, Some(true));
        assert_eq!(&bytes[..4], b"II+\0");
        let whole = read(&bytes, &opts()).unwrap();
        let (_d, path) = temp_file(&bytes);
        check_stream_equals_read(&path, &whole, "BigTIFF");
        // Hand-made tiles, smaller than and larger than the image, several per row, in both
        // byte orders.
        for le in [true, false] {
            for (w, h, tw, th) in [(37, 29, 16, 16), (5, 300, 16, 32), (20, 9, 32, 16)] {
                let bytes = handmade_tiled(le, w, h, tw, th);
                let whole = read(&bytes, &opts()).unwrap();
                assert!(whole.mask.is_some());
                let (_d, path) = temp_file(&bytes);
                let what = format!("{w}x{h} in {tw}x{th} tiles, le {le}");
                check_stream_equals_read(&path, &whole, &what);
            }
        }
    }

    #[test]
    fn reader_keeps_one_chunk_row() {
        let r = synthetic(SampleType::I16, 600, 530, Some(-9999.0), 3);
        let bytes = stream_write(&r, 530);
        let (_d, path) = temp_file(&bytes);
        let mut s = StreamReader::open(&path, &opts()).unwrap();
        s.band(250, 10).unwrap(); // tile rows 0 and 1; row 1 stays
        let c = s.cache.as_ref().unwrap();
        assert_eq!(
            (c.index, c.y0, c.rows, c.data.len()),
            (1, 256, 256, 256 * 600)
        );
        s.band(300, 5).unwrap();
        assert_eq!(s.cache.as_ref().unwrap().index, 1);
        s.band(529, 1).unwrap();
        let c = s.cache.as_ref().unwrap();
        assert_eq!((c.index, c.rows), (2, 18));
    }

    #[test]
    fn reader_refuses_what_read_refuses_with_the_same_message() {
        let mut inputs: Vec<Vec<u8>> = Vec::new();
        // Unsupported layouts.
        for tags in [
            &[(super::super::TAG_BITS_PER_SAMPLE, &[12u16][..])][..],
            &[(super::super::TAG_PHOTOMETRIC, &[3])],
            &[(super::super::TAG_COMPRESSION, &[7])],
            &[(TAG_PREDICTOR, &[3])],
            &[(super::super::TAG_SAMPLES_PER_PIXEL, &[2])],
        ] {
            let mut b = Builder::basic(true, 2, 2, 16, 2, 8);
            for &(tag, v) in tags {
                b.short(tag, v);
            }
            inputs.push(b.build(&[0; 8]));
        }
        // A strip and a tile outside the file, a missing width, an empty directory.
        let mut b = Builder::basic(true, 2, 2, 16, 2, 8);
        b.long(TAG_STRIP_OFFSETS, &[1 << 20]);
        inputs.push(b.build(&[0; 8]));
        let mut b = Builder::basic(true, 4, 4, 16, 2, 0);
        b.remove(TAG_STRIP_OFFSETS)
            .remove(TAG_STRIP_BYTE_COUNTS)
            .long(TAG_TILE_WIDTH, &[16])
            .long(TAG_TILE_LENGTH, &[16])
            .long(TAG_TILE_OFFSETS, &[100_000])
            .long(TAG_TILE_BYTE_COUNTS, &[512]);
        inputs.push(b.build(&[0; 512]));
        let mut b = Builder::basic(true, 2, 2, 16, 2, 8);
        b.remove(super::super::TAG_IMAGE_WIDTH);
        inputs.push(b.build(&[0; 8]));
        inputs.push(b"II*\0\x08\0\0\0\0\0\0\0\0\0".to_vec());
        inputs.push(b"MM\0+\0\x08\0\0\0\0\0\0\0\0\0\x10".to_vec());
        inputs.push(b"GIF89a".to_vec());
        // A huge image over the sample limit.
        let mut b = Builder::basic(true, 100_000, 100_000, 16, 2, 8);
        b.long(TAG_ROWS_PER_STRIP, &[100_000]);
        inputs.push(b.build(&[0; 8]));
        let mut tiled = handmade_tiled(true, 37, 29, 16, 16);
        tiled.truncate(tiled.len() - 3);
        inputs.push(tiled);

        for (k, bytes) in inputs.iter().enumerate() {
            let want = read(bytes, &opts()).unwrap_err().to_string();
            let (_d, path) = temp_file(bytes);
            let got = match StreamReader::open(&path, &opts()) {
                Ok(_) => panic!("input {k}: opened, read says {want}"),
                Err(e) => e.to_string(),
            };
            assert_eq!(got, want, "input {k}");
        }
        // The tile outside the file.
        let e = read(&inputs[6], &opts()).unwrap_err().to_string();
        assert!(e.contains("tile 0") && e.contains("past the end"), "{e}");
    }

    #[test]
    fn tag_values_are_read_as_read_reads_them() {
        // The `tiff` decoder reads an ASCII value kept in its entry differently from one stored
        // apart (NUL handling, non-ASCII text); the stream must follow `read` either way.
        let metadata: [&[u8]; 7] = [
            b"ab\0cd\0",
            "Höh\0".as_bytes(),
            "Höhe und Tiefe\0".as_bytes(),
            b"ab\0",
            b"x",
            b"\0",
            b"abcdefgh",
        ];
        let vals: Vec<i16> = (0..6).collect();
        for le in [true, false] {
            for (k, m) in metadata.iter().enumerate() {
                let mut b = Builder::basic(le, 3, 2, 16, 2, 12);
                b.set(TAG_GDAL_METADATA, 2, m.len() as u32, m.to_vec());
                b.set(super::super::TAG_GDAL_NODATA, 2, 6, b"-9999 ".to_vec());
                let bytes = b.build(&i16_bytes(le, &vals));
                let (_d, path) = temp_file(&bytes);
                let streamed = StreamReader::open(&path, &opts()).and_then(|mut s| s.band(0, 2));
                match (read(&bytes, &opts()), streamed) {
                    (Ok(whole), Ok(band)) => assert_band(&band, &whole, 0, &format!("{k}")),
                    (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{k}"),
                    (a, b) => panic!("{k}: read {a:?}, stream {b:?}"),
                }
            }
        }
        // In a BigTIFF, values of up to 8 bytes are kept in their entry.
        let mut r = synthetic(SampleType::I16, 20, 10, None, 4);
        r.gdal_metadata = Some("abcdef".into());
        let bytes = stream_write_kind(&r, 10, Some(true));
        let whole = read(&bytes, &opts()).unwrap();
        assert_eq!(whole.gdal_metadata.as_deref(), Some("abcdef"));
        let (_d, path) = temp_file(&bytes);
        check_stream_equals_read(&path, &whole, "short metadata in a BigTIFF");
    }

    /// Everything the stream gives for the file, or its first error.
    fn stream_all(path: &Path) -> Result<Vec<Raster>> {
        let mut s = StreamReader::open(path, &opts())?;
        let mut out = Vec::new();
        for y0 in (0..s.height()).step_by(5) {
            let rows = 5.min(s.height() - y0);
            out.push(s.band(y0, rows)?);
        }
        Ok(out)
    }

    #[test]
    fn truncated_and_mutated_files_give_errors_not_panics() {
        let r = synthetic(SampleType::I16, 300, 270, Some(-9999.0), 11);
        let mut inputs = vec![
            stream_write(&r, 7),
            write(&r).unwrap(),
            handmade_tiled(true, 37, 29, 16, 16),
        ];
        if let Some(dir) = crate::testutil::corpus() {
            inputs.push(std::fs::read(dir.join("terra_elev_luxembourg.tif")).unwrap());
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.tif");
        for input in &inputs {
            for k in 0..40 {
                let len = input.len() * k / 40;
                std::fs::write(&path, &input[..len]).unwrap();
                assert!(stream_all(&path).is_err(), "truncated to {len}");
            }
        }
        // Mutations: the stream and `read` agree on success, and on the samples.
        let mut rng = Rng(0x5eed);
        for input in &inputs {
            for _ in 0..150 {
                let mut m = input.clone();
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(m.len() as u64) as usize;
                    m[i] = match rng.below(4) {
                        0 => 0,
                        1 => 0xff,
                        _ => rng.next() as u8,
                    };
                }
                std::fs::write(&path, &m).unwrap();
                let streamed = stream_all(&path);
                match (read(&m, &opts()), streamed) {
                    (Ok(whole), Ok(bands)) => {
                        for (b, band) in bands.iter().enumerate() {
                            assert_band(band, &whole, b * 5, "mutated");
                        }
                    }
                    (Err(_), Err(_)) => {}
                    (a, b) => panic!("read {:?}, stream {:?}", a.map(|_| ()), b.map(|_| ())),
                }
            }
        }
    }

    #[test]
    fn corrupt_tile_data_is_an_error_in_the_band() {
        let r = synthetic(SampleType::I16, 300, 300, Some(-9999.0), 5);
        let mut bytes = stream_write(&r, 300);
        // Garble the middle of the first tile's compressed data.
        for b in &mut bytes[40..60] {
            *b = 0xa5;
        }
        let (_d, path) = temp_file(&bytes);
        let mut s = StreamReader::open(&path, &opts()).unwrap();
        assert!(s.band(0, 1).is_err());
        assert!(s.band(290, 10).is_ok(), "other tile rows still read");
        let e = s.band(0, 300).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
    }

    #[test]
    fn band_outside_the_image_is_an_error() {
        let bytes = write(&small_i16_raster()).unwrap();
        let (_d, path) = temp_file(&bytes);
        let mut s = StreamReader::open(&path, &opts()).unwrap();
        for (y0, rows) in [(0, 0), (17, 1), (10, 8), (usize::MAX, 2)] {
            assert!(
                matches!(s.band(y0, rows), Err(Error::InvalidArgument { .. })),
                "{y0}+{rows}"
            );
        }
        assert!(s.band(16, 1).is_ok());
    }

    // ----- writing ----------------------------------------------------------------------

    /// `r` through `StreamWriter` in bands of `h` rows.
    fn stream_write(r: &Raster, h: usize) -> Vec<u8> {
        stream_write_kind(r, h, None)
    }

    /// `r` through `StreamWriter` in bands of `h` rows, BigTIFF when `big` says.
    fn stream_write_kind(r: &Raster, h: usize, big: Option<bool>) -> Vec<u8> {
        let out = Cursor::new(Vec::new());
        let mut w = StreamWriter::with_kind(out, r.width, r.height, r, big).unwrap();
        for y0 in (0..r.height).step_by(h) {
            let rows = h.min(r.height - y0);
            let mut band = r.crop(Window {
                x: 0,
                y: y0,
                width: r.width,
                height: rows,
            });
            band.normalize_mask();
            w.write_rows(&band).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

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
