//! A GeoTIFF's internal mask band: GDAL's per-dataset mask (`GDAL_TIFF_INTERNAL_MASK`, the
//! `.msk` kept inside the file, as COGs carry it).
//!
//! GDAL stores it as another image directory of the same size as the image, with
//! NewSubfileType bit 4 (transparency mask) set and bit 1 (reduced resolution) clear,
//! PhotometricInterpretation 4, one sample of 1 bit (rarely 8), in strips or tiles, most often
//! Deflate- or PackBits-compressed. A sample is valid where its mask sample is non-zero. The
//! GeoTIFF reader takes it from here, band by band like the samples, so the masked samples are
//! invalid however the file is read: they become nodata, as GDAL, QGIS and rasterio
//! treat them. The reduced-resolution masks of overviews are not read (nor are overviews).
//!
//! Everything is checked before use: the directory chain (no cycles, at most
//! [`MAX_DIRECTORIES`] directories), every chunk inside the file, every chunk decoding to
//! exactly its size. A mask vtz cannot decode (another compression, a predictor) is refused
//! with a one-line error naming the mask, never skipped.

use super::ifd::{self, Order, Source, type_size};
use crate::error::{Error, Result};
use std::io::Read;

/// Image directories walked looking for the mask (a COG with many overview levels and their
/// masks has a few dozen).
const MAX_DIRECTORIES: usize = 1024;

const TAG_NEW_SUBFILE_TYPE: u16 = 254;
const TAG_IMAGE_WIDTH: u16 = 256;
const TAG_IMAGE_LENGTH: u16 = 257;
const TAG_BITS_PER_SAMPLE: u16 = 258;
const TAG_COMPRESSION: u16 = 259;
const TAG_STRIP_OFFSETS: u16 = 273;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_ROWS_PER_STRIP: u16 = 278;
const TAG_STRIP_BYTE_COUNTS: u16 = 279;
const TAG_PREDICTOR: u16 = 317;
const TAG_TILE_WIDTH: u16 = 322;
const TAG_TILE_LENGTH: u16 = 323;
const TAG_TILE_OFFSETS: u16 = 324;
const TAG_TILE_BYTE_COUNTS: u16 = 325;

/// NewSubfileType bits.
const FILETYPE_REDUCED: u64 = 1;
const FILETYPE_MASK: u64 = 4;

fn truncated() -> Error {
    Error::corrupt("GeoTIFF is truncated (in its mask band)")
}

/// The tags read here.
const MASK_TAGS: &[u16] = &[
    TAG_NEW_SUBFILE_TYPE,
    TAG_IMAGE_WIDTH,
    TAG_IMAGE_LENGTH,
    TAG_BITS_PER_SAMPLE,
    TAG_COMPRESSION,
    TAG_STRIP_OFFSETS,
    TAG_SAMPLES_PER_PIXEL,
    TAG_ROWS_PER_STRIP,
    TAG_STRIP_BYTE_COUNTS,
    TAG_PREDICTOR,
    TAG_TILE_WIDTH,
    TAG_TILE_LENGTH,
    TAG_TILE_OFFSETS,
    TAG_TILE_BYTE_COUNTS,
];

/// One directory's entries of [`MASK_TAGS`]: tag → (type, count, where the values start).
struct Directory {
    entries: Vec<(u16, u16, u64, u64)>,
    next: u64,
}

/// The directory at `pos`, its entries and the pointer to the next one checked to lie inside
/// the file.
fn read_directory(src: &mut Source<'_>, o: Order, pos: u64) -> Result<Directory> {
    let dir = ifd::directory(src, o, pos)?.ok_or_else(truncated)?;
    let end = dir
        .end(o)
        .and_then(|end| end.checked_add(o.word()))
        .filter(|&end| end <= src.len())
        .ok_or_else(truncated)?;
    let mut entries = Vec::new();
    dir.entries(src, o, |e| {
        let Some(width) = type_size(e.typ) else {
            return Ok(()); // a type no tag read here has
        };
        let len = width.checked_mul(e.count).ok_or_else(truncated)?;
        if !MASK_TAGS.contains(&e.tag) {
            return Ok(());
        }
        entries.push((e.tag, e.typ, e.count, e.data_pos(o, len)));
        Ok(())
    })?;
    let next = o.uint(&src.read_at(end - o.word(), o.word() as usize)?);
    Ok(Directory { entries, next })
}

impl Directory {
    /// The unsigned values of `tag` (BYTE, SHORT, LONG, LONG8), checked to lie in the file;
    /// `None` when absent.
    fn uints(&self, src: &mut Source<'_>, o: Order, tag: u16) -> Result<Option<Vec<u64>>> {
        let Some(&(_, typ, n, pos)) = self.entries.iter().find(|e| e.0 == tag) else {
            return Ok(None);
        };
        let w = match typ {
            1 => 1,
            3 => 2,
            4 => 4,
            16 => 8,
            _ => {
                return Err(Error::corrupt(format!(
                    "GeoTIFF mask band: tag {tag} has type {typ} where an unsigned integer is \
                     expected"
                )));
            }
        };
        let len = n.checked_mul(w).ok_or_else(truncated)?;
        if pos.checked_add(len).is_none_or(|e| e > src.len()) {
            return Err(truncated());
        }
        let b = src.read_at(pos, len as usize)?;
        Ok(Some(
            b.chunks_exact(w as usize).map(|c| o.uint(c)).collect(),
        ))
    }

    fn scalar(&self, src: &mut Source<'_>, o: Order, tag: u16) -> Result<Option<u64>> {
        Ok(self.uints(src, o, tag)?.and_then(|v| v.first().copied()))
    }
}

/// The mask band of an image: where its chunks are and how to decode them.
#[derive(Debug)]
pub(super) struct Mask {
    width: usize,
    height: usize,
    bits: usize,
    compression: u16,
    /// Chunk size: the tile, or the image width × rows per strip.
    chunk_w: usize,
    chunk_h: usize,
    across: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
}

/// The internal mask band of the first image (`width × height`) of a TIFF of byte order and
/// kind `o` whose first directory is at `first` (as the pre-pass found them), if it has one.
pub(super) fn find(
    src: &mut Source<'_>,
    o: Order,
    first: u64,
    width: usize,
    height: usize,
) -> Result<Option<Mask>> {
    let mut seen = Vec::new();
    let mut pos = first;
    while pos != 0 {
        if seen.contains(&pos) || seen.len() >= MAX_DIRECTORIES {
            return Err(Error::corrupt(
                "GeoTIFF image directories loop or are too many",
            ));
        }
        seen.push(pos);
        let d = read_directory(src, o, pos)?;
        pos = d.next;
        if seen.len() == 1 {
            continue; // the image itself
        }
        let kind = d.scalar(src, o, TAG_NEW_SUBFILE_TYPE)?.unwrap_or(0);
        if kind & FILETYPE_MASK == 0 || kind & FILETYPE_REDUCED != 0 {
            continue;
        }
        let w = d.scalar(src, o, TAG_IMAGE_WIDTH)?.unwrap_or(0);
        let h = d.scalar(src, o, TAG_IMAGE_LENGTH)?.unwrap_or(0);
        if (w, h) != (width as u64, height as u64) {
            continue;
        }
        return mask_of(src, o, &d, width, height).map(Some);
    }
    Ok(None)
}

fn unsupported(what: String) -> Error {
    Error::unsupported(format!(
        "GeoTIFF internal mask band (GDAL's per-dataset mask, NewSubfileType 4) {what}"
    ))
}

fn mask_of(
    src: &mut Source<'_>,
    o: Order,
    d: &Directory,
    width: usize,
    height: usize,
) -> Result<Mask> {
    let spp = d.scalar(src, o, TAG_SAMPLES_PER_PIXEL)?.unwrap_or(1);
    let bits = d.scalar(src, o, TAG_BITS_PER_SAMPLE)?.unwrap_or(1);
    if spp != 1 || !matches!(bits, 1 | 8) {
        return Err(unsupported(format!(
            "has {spp} samples of {bits} bits per pixel (vtz reads 1 sample of 1 or 8 bits)"
        )));
    }
    let compression = d.scalar(src, o, TAG_COMPRESSION)?.unwrap_or(1);
    if !matches!(compression, 1 | 5 | 8 | 32946 | 32773) {
        return Err(unsupported(format!(
            "uses compression {compression} (vtz reads masks with none, LZW, Deflate or \
             PackBits)"
        )));
    }
    let predictor = d.scalar(src, o, TAG_PREDICTOR)?.unwrap_or(1);
    if predictor != 1 {
        return Err(unsupported(format!("uses predictor {predictor}")));
    }
    let tiled = d.entries.iter().any(|e| e.0 == TAG_TILE_OFFSETS);
    let (chunk_w, chunk_h, offsets_tag, counts_tag) = if tiled {
        let tw = d.scalar(src, o, TAG_TILE_WIDTH)?.unwrap_or(0);
        let th = d.scalar(src, o, TAG_TILE_LENGTH)?.unwrap_or(0);
        if tw == 0 || th == 0 || tw > 1 << 16 || th > 1 << 16 {
            return Err(Error::corrupt(format!(
                "GeoTIFF mask band tile size {tw}x{th} is invalid"
            )));
        }
        (
            tw as usize,
            th as usize,
            TAG_TILE_OFFSETS,
            TAG_TILE_BYTE_COUNTS,
        )
    } else {
        let rps = d
            .scalar(src, o, TAG_ROWS_PER_STRIP)?
            .unwrap_or(height as u64)
            .clamp(1, height as u64);
        (
            width,
            rps as usize,
            TAG_STRIP_OFFSETS,
            TAG_STRIP_BYTE_COUNTS,
        )
    };
    let across = width.div_ceil(chunk_w);
    let chunks = across
        .checked_mul(height.div_ceil(chunk_h))
        .ok_or_else(truncated)?;
    let offsets = d.uints(src, o, offsets_tag)?.unwrap_or_default();
    let counts = d.uints(src, o, counts_tag)?.unwrap_or_default();
    if offsets.len() < chunks || counts.len() < chunks {
        return Err(Error::corrupt(format!(
            "GeoTIFF mask band has {} chunk offsets and {} byte counts for {chunks} chunks",
            offsets.len(),
            counts.len()
        )));
    }
    for (k, (&off, &n)) in offsets.iter().zip(&counts).take(chunks).enumerate() {
        if off.checked_add(n).is_none_or(|e| e > src.len()) {
            return Err(Error::corrupt(format!(
                "GeoTIFF is truncated: mask band chunk {k} ({n} bytes at offset {off}) ends \
                 past the end of the file ({} bytes)",
                src.len()
            )));
        }
    }
    Ok(Mask {
        width,
        height,
        bits: bits as usize,
        compression: compression as u16,
        chunk_w,
        chunk_h,
        across,
        offsets,
        counts,
    })
}

impl Mask {
    /// Validity of rows `y0..y0 + rows`, full width, row-major: `true` where the mask lets
    /// the sample through.
    pub(super) fn rows(&self, src: &mut Source<'_>, y0: usize, rows: usize) -> Result<Vec<bool>> {
        let end = y0 + rows;
        debug_assert!(end <= self.height);
        let mut out = vec![false; self.width * rows];
        let row_bytes = (self.chunk_w * self.bits).div_ceil(8);
        for cy in y0 / self.chunk_h..end.div_ceil(self.chunk_h) {
            let top = cy * self.chunk_h;
            // Only the rows inside the image are needed (a strip holds no more; a tile of the
            // last row may, after them).
            let chunk_rows = self.chunk_h.min(self.height - top);
            for cx in 0..self.across {
                let k = cy * self.across + cx;
                let bytes = self.chunk(src, k, row_bytes * chunk_rows)?;
                let left = cx * self.chunk_w;
                let cols = self.chunk_w.min(self.width - left);
                for y in top.max(y0)..(top + chunk_rows).min(end) {
                    let row = &bytes[(y - top) * row_bytes..][..row_bytes];
                    let dst = &mut out[(y - y0) * self.width + left..][..cols];
                    for (x, v) in dst.iter_mut().enumerate() {
                        *v = if self.bits == 1 {
                            row[x / 8] & (0x80 >> (x % 8)) != 0
                        } else {
                            row[x] != 0
                        };
                    }
                }
            }
        }
        Ok(out)
    }

    /// Chunk `k` decompressed: exactly `size` bytes. A chunk of 0 bytes (GDAL's sparse
    /// files) is all zeros: masked, as GDAL reads it.
    fn chunk(&self, src: &mut Source<'_>, k: usize, size: usize) -> Result<Vec<u8>> {
        let n = self.counts[k];
        if n == 0 {
            return Ok(vec![0; size]);
        }
        let raw = src.read_at(self.offsets[k], n as usize)?;
        let bad = |got: usize| {
            Error::corrupt(format!(
                "GeoTIFF mask band chunk {k} decodes to {got} bytes, expected {size}"
            ))
        };
        let out = match self.compression {
            1 => raw,
            8 | 32946 => {
                let mut out = Vec::with_capacity(size);
                flate2::read::ZlibDecoder::new(&raw[..])
                    .take(size as u64)
                    .read_to_end(&mut out)
                    .map_err(|e| {
                        Error::corrupt(format!("GeoTIFF mask band chunk {k} (Deflate): {e}"))
                    })?;
                out
            }
            5 => {
                // Into a buffer of the chunk's size: a hostile chunk cannot expand further.
                let mut out = vec![0u8; size];
                let mut dec =
                    weezl::decode::Decoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8);
                let (mut i, mut o) = (0, 0);
                while o < size {
                    let r = dec.decode_bytes(&raw[i..], &mut out[o..]);
                    i += r.consumed_in;
                    o += r.consumed_out;
                    match r.status {
                        Ok(weezl::LzwStatus::Ok) => {}
                        Ok(_) => break,
                        // What follows the codes the chunk needs may be broken, as libtiff
                        // allows; too few bytes is an error below.
                        Err(e) if o < size => {
                            return Err(Error::corrupt(format!(
                                "GeoTIFF mask band chunk {k} (LZW): {e}"
                            )));
                        }
                        Err(_) => break,
                    }
                }
                out.truncate(o);
                out
            }
            _ => unpack_bits(&raw, size),
        };
        if out.len() < size {
            return Err(bad(out.len()));
        }
        Ok(out)
    }
}

/// PackBits: runs of literal bytes and repeated bytes, up to `size` bytes of output.
fn unpack_bits(raw: &[u8], size: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(size);
    let mut i = 0;
    while i < raw.len() && out.len() < size {
        let n = raw[i] as i8;
        i += 1;
        if n >= 0 {
            let len = (n as usize + 1).min(raw.len() - i);
            out.extend_from_slice(&raw[i..i + len]);
            i += len;
        } else if n != -128 {
            if let Some(&b) = raw.get(i) {
                out.extend(std::iter::repeat_n(b, (1 - isize::from(n)) as usize));
                i += 1;
            }
        }
    }
    out.truncate(size);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write as _;

    /// One row of validity as 1-bit samples, most significant bit first, padded to a byte.
    fn bits_row(valid: &[bool]) -> Vec<u8> {
        let mut out = vec![0u8; valid.len().div_ceil(8)];
        for (x, &v) in valid.iter().enumerate() {
            if v {
                out[x / 8] |= 0x80 >> (x % 8);
            }
        }
        out
    }

    /// `m.rows` over the file `file` in memory.
    fn rows(m: &Mask, file: &[u8], y0: usize, n: usize) -> Result<Vec<bool>> {
        let mut c = std::io::Cursor::new(file);
        m.rows(&mut Source::new(&mut c, file.len() as u64), y0, n)
    }

    fn one_chunk(w: usize, h: usize, compression: u16, bytes: usize) -> Mask {
        Mask {
            width: w,
            height: h,
            bits: 1,
            compression,
            chunk_w: w,
            chunk_h: h,
            across: 1,
            offsets: vec![0],
            counts: vec![bytes as u64],
        }
    }

    /// GDAL writes masks with Deflate; libtiff-based writers also use none, LZW and PackBits.
    /// Each decodes to the same validity, whole or a few rows at a time.
    #[test]
    fn every_compression_gives_the_same_bits() {
        let (w, h) = (13usize, 5usize);
        let valid: Vec<bool> = (0..w * h).map(|i| (i * 7) % 5 != 0).collect();
        let raw: Vec<u8> = valid.chunks(w).flat_map(bits_row).collect();
        let lzw = weezl::encode::Encoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8)
            .encode(&raw)
            .unwrap();
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&raw).unwrap();
        let deflate = z.finish().unwrap();
        // PackBits: one literal run of the whole chunk (at most 128 bytes).
        let mut packbits = vec![(raw.len() - 1) as u8];
        packbits.extend_from_slice(&raw);
        for (compression, file) in [(1, raw.clone()), (5, lzw), (8, deflate), (32773, packbits)] {
            let m = one_chunk(w, h, compression, file.len());
            let got = rows(&m, &file, 0, h).unwrap();
            assert_eq!(got, valid, "compression {compression}");
            let part = rows(&m, &file, 2, 2).unwrap();
            assert_eq!(
                part,
                valid[2 * w..4 * w],
                "compression {compression}, rows 2..4"
            );
        }
        // A chunk that decodes short is corrupt; a missing (sparse) chunk is all masked.
        let m = one_chunk(w, h, 1, 3);
        let e = rows(&m, &raw, 0, h).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
        let m = one_chunk(w, h, 1, 0);
        assert!(rows(&m, &raw, 0, h).unwrap().iter().all(|v| !v));
    }

    #[test]
    fn packbits_runs() {
        // A run of three 0xAA (-2), a literal of three, the no-op -128, a literal of one.
        let packed = [0xFE, 0xAA, 0x02, 1, 2, 3, 0x80, 0x00, 9];
        assert_eq!(unpack_bits(&packed, 100), [0xAA, 0xAA, 0xAA, 1, 2, 3, 9]);
        assert_eq!(unpack_bits(&packed, 4), [0xAA, 0xAA, 0xAA, 1]);
        // Truncated input stops, never panics.
        assert_eq!(unpack_bits(&[0x05, 1, 2], 100), [1, 2]);
        assert_eq!(unpack_bits(&[0xFE], 100), Vec::<u8>::new());
    }
}
