//! Reading: a single-band GeoTIFF decoded band by band (groups of full-width rows) or whole,
//! from any `Read + Seek` source whose position 0 is the file's start: the file in memory
//! ([`read`], over a `Cursor`) or on disk ([`Reader::open`]), so that rasters larger than
//! memory pass through.
//!
//! [`Reader::new`] runs the IFD pre-pass (`precheck`: the first directory's bounds, layout and
//! size) on the source, then opens the `tiff` crate's decoder over it; the georef, nodata and
//! GDAL_METADATA come from the decoder's tags (`georef`, `nodata`). Samples are decoded chunk by
//! chunk by `read_chunk`: a band decodes only the strips or tiles that cover its rows, and the
//! last chunk row it touches (a strip, or a row of tiles) stays decoded for the next band. The
//! internal mask band (`mask`) is read band by band through the same source.

use super::georef::read_georef;
use super::ifd::Source;
use super::nodata::read_nodata;
use super::precheck::{Layout, precheck};
use super::tags::{tag_string, tiff_err};
use super::{TAG_GDAL_METADATA, mask};
use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{Georef, Raster, SampleType};
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};

/// Read a single-band GeoTIFF into a [`Raster`] (values exact as `f64`, nodata and NaN samples
/// and those its internal mask band masks marked invalid, georeferencing from the GeoTIFF
/// tags): a [`Reader`] over the bytes, read whole.
pub fn read(bytes: &[u8], opts: &ReadOptions) -> Result<Raster> {
    let mut r = Reader::new(Cursor::new(bytes), opts)?;
    let georef = r.georef.clone();
    r.rows(0, r.height, georef, false)
}

/// Reads a single-band GeoTIFF band by band (full-width groups of rows) without holding the
/// image.
///
/// Memory: the IFD's chunk offsets, one chunk row of decoded samples as `f64` (for a striped
/// file one strip, `rows_per_strip × width`; for a tiled one a row of tiles,
/// `tile_length × width`; a file stored as a single strip is therefore decoded whole), and the
/// band asked for.
pub struct Reader<R: Read + Seek> {
    dec: Decoder<R>,
    /// The source's length in bytes.
    len: u64,
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
    /// The last chunk row decoded for a band that covers it in part, or last.
    cache: Option<ChunkRow>,
    /// The internal mask band.
    mask: Option<mask::Mask>,
}

/// The samples of one decoded chunk row, full width.
struct ChunkRow {
    index: usize,
    /// First image row it holds.
    y0: usize,
    data: Vec<f64>,
}

impl Reader<BufReader<File>> {
    /// [`Reader::new`] on the file at `path`, which is not read into memory.
    pub fn open(path: &Path, opts: &ReadOptions) -> Result<Self> {
        let ctx = path.display().to_string();
        let file = File::open(path).map_err(|e| Error::io(&ctx, e))?;
        let len = file.metadata().map_err(|e| Error::io(&ctx, e))?.len();
        Reader::with_len(BufReader::new(file), len, opts)
    }
}

impl<R: Read + Seek> Reader<R> {
    /// Open and check the GeoTIFF that `r` holds (from its position 0): sample types
    /// u8/i16/u16/i32/f32/f64, one sample per pixel, strips or tiles,
    /// none/LZW/Deflate/PackBits, predictor 1/2/3; size within `opts.max_samples()`; chunk
    /// offsets and byte counts inside the source. Reads the tags, not the samples.
    ///
    /// Errors: `Corrupt` for a broken or truncated file, `Unsupported` for a layout vtz does
    /// not read, `LimitExceeded` over the sample limit, `Io` when the source fails.
    pub fn new(mut r: R, opts: &ReadOptions) -> Result<Self> {
        let len = r
            .seek(SeekFrom::End(0))
            .map_err(|e| Error::io("reading GeoTIFF", e))?;
        Reader::with_len(r, len, opts)
    }

    fn with_len(mut r: R, len: u64, opts: &ReadOptions) -> Result<Self> {
        let layout = precheck(&mut Source::new(&mut r, len), opts)?;
        r.seek(SeekFrom::Start(0))
            .map_err(|e| Error::io("reading GeoTIFF", e))?;
        let mut dec = Decoder::new(r)
            .map_err(tiff_err)?
            .with_limits(read_limits(&layout, len));
        let (w, h) = dec.dimensions().map_err(tiff_err)?;
        if (w as usize, h as usize) != (layout.width, layout.height) {
            return Err(Error::corrupt("GeoTIFF image size disagrees with its tags"));
        }
        let st = layout.sample_type;
        let georef = read_georef(&mut dec)?;
        let nodata = read_nodata(&mut dec, st)?;
        let gdal_metadata = tag_string(&mut dec, TAG_GDAL_METADATA)?;

        // The internal mask band, read band by band like the samples (the decoder seeks
        // before each read of its own, so reading its source in between is harmless).
        let mask = mask::find(
            &mut Source::new(dec.inner(), len),
            layout.order,
            layout.first_ifd,
            layout.width,
            layout.height,
        )?;

        let (cw, ch) = dec.chunk_dimensions();
        let chunk_width = (cw as usize).min(layout.width);
        let chunk_rows = (ch as usize).min(layout.height);
        if chunk_width == 0 || chunk_rows == 0 {
            return Err(Error::corrupt(format!(
                "GeoTIFF chunk size {cw}x{ch} is invalid"
            )));
        }
        Ok(Reader {
            dec,
            len,
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

    /// Rows `y0..y0 + rows`, full width, as a [`Raster`] exactly as [`read`] gives that part of
    /// the image: values as `f64`, nodata and NaN samples invalid (the mask is `None` when
    /// every sample of the band is valid), the file's nodata, sample type and GDAL_METADATA
    /// (verbatim, except that a GDAL scale/offset of integer samples is the value mapping, the
    /// values `offset + scale · sample`), and the georef moved to the band's top-left corner
    /// ([`Georef::window`]`(0, y0)`).
    ///
    /// Only the chunks covering these rows are decoded; the last chunk row decoded is kept, so
    /// consecutive bands that share a chunk row decode it once. Any order of bands works.
    /// Errors: `InvalidArgument` for rows outside the image; those of [`Reader::new`] for
    /// samples that do not decode.
    pub fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        if rows == 0 || y0 >= self.height || rows > self.height - y0 {
            return Err(Error::invalid(format!(
                "rows {y0}..{} are not inside the GeoTIFF's {} rows",
                y0.saturating_add(rows),
                self.height
            )));
        }
        let georef = self.georef.as_ref().map(|g| g.window(0, y0));
        self.rows(y0, rows, georef, true)
    }

    /// Rows `y0..y0 + rows` (inside the image) with the georef given; `keep_last`: whether the
    /// last chunk row they touch stays decoded when they cover it whole (those covered in part
    /// always do; the others are decoded straight into the band).
    fn rows(
        &mut self,
        y0: usize,
        rows: usize,
        georef: Option<Georef>,
        keep_last: bool,
    ) -> Result<Raster> {
        let w = self.width;
        let end = y0 + rows;
        let mut data = vec![0.0; w * rows];
        let mut y = y0;
        while y < end {
            let k = y / self.chunk_rows;
            let top = k * self.chunk_rows;
            let bottom = (top + self.chunk_rows).min(self.height);
            let upto = end.min(bottom);
            let out = &mut data[(y - y0) * w..(upto - y0) * w];
            let whole = y == top && upto == bottom;
            let cached = self.cache.as_ref().is_some_and(|c| c.index == k);
            if whole && !cached && (upto < end || !keep_last) {
                self.decode_chunk_row(k, out)?;
            } else {
                let c = self.chunk_row(k)?;
                out.copy_from_slice(&c.data[(y - c.y0) * w..(upto - c.y0) * w]);
            }
            y = upto;
        }
        if let Some(m) = &self.mask {
            let valid = m.rows(&mut Source::new(self.dec.inner(), self.len), y0, rows)?;
            for (v, ok) in data.iter_mut().zip(valid) {
                if !ok {
                    *v = f64::NAN;
                }
            }
        }

        // Infinite samples other than the nodata value are refused, the first one named by
        // its place in the whole image (integer samples never are).
        let first_infinite = match self.sample_type.is_integer() {
            true => None,
            false => data
                .iter()
                .position(|&v| v.is_infinite() && self.nodata != Some(v)),
        };
        if let Some(k) = first_infinite {
            let i = y0 * w + k;
            return Err(Error::unsupported(format!(
                "GeoTIFF sample {i} (row {}, col {}) is infinite (only finite values or nodata \
                 are supported)",
                i / w,
                i % w
            )));
        }
        let mut r = Raster::from_values(w, rows, data, self.nodata, self.sample_type)?;
        r.georef = georef;
        r.gdal_metadata = self.gdal_metadata.clone();
        // GDAL's scale/offset of integer codes: the values GDAL shows are vtz's values.
        crate::formats::apply_gdal_mapping(&mut r);
        Ok(r)
    }

    /// Chunk row `k`, decoded (from the cache when it is the last one decoded).
    fn chunk_row(&mut self, k: usize) -> Result<&ChunkRow> {
        if self.cache.as_ref().is_none_or(|c| c.index != k) {
            self.cache = None; // at most one chunk row in memory
            let y0 = k * self.chunk_rows;
            let rows = self.chunk_rows.min(self.height - y0);
            let mut data = vec![0.0; self.width * rows];
            self.decode_chunk_row(k, &mut data)?;
            self.cache = Some(ChunkRow { index: k, y0, data });
        }
        Ok(self.cache.as_ref().expect("filled above"))
    }

    /// Decode chunk row `k` into `out`, its rows full width.
    fn decode_chunk_row(&mut self, k: usize, out: &mut [f64]) -> Result<()> {
        let w = self.width;
        let rows = out.len() / w;
        for tx in 0..self.chunks_across {
            let x0 = tx * self.chunk_width;
            let cols = self.chunk_width.min(w - x0);
            let index = u32::try_from(k * self.chunks_across + tx)
                .map_err(|_| Error::corrupt("GeoTIFF has too many chunks"))?;
            let chunk = self.dec.read_chunk(index).map_err(tiff_err)?;
            let place = Place {
                index,
                width: w,
                x0,
                cols,
                rows,
            };
            place.put(chunk, self.sample_type, out)?;
        }
        Ok(())
    }
}

/// Where a decoded chunk goes in its chunk row.
struct Place {
    index: u32,
    /// The chunk row's width.
    width: usize,
    x0: usize,
    cols: usize,
    rows: usize,
}

impl Place {
    /// The decoded samples as `f64` into `out`, checked to be of the type the tags declare and
    /// of the chunk's size.
    fn put(&self, decoded: DecodingResult, st: SampleType, out: &mut [f64]) -> Result<()> {
        match (decoded, st) {
            (DecodingResult::U8(v), SampleType::U8) => self.put_as_f64(&v, out),
            (DecodingResult::I16(v), SampleType::I16) => self.put_as_f64(&v, out),
            (DecodingResult::U16(v), SampleType::U16) => self.put_as_f64(&v, out),
            (DecodingResult::I32(v), SampleType::I32) => self.put_as_f64(&v, out),
            (DecodingResult::F32(v), SampleType::F32) => self.put_as_f64(&v, out),
            (DecodingResult::F64(v), SampleType::F64) => self.put_as_f64(&v, out),
            _ => Err(Error::corrupt(format!(
                "GeoTIFF decoded to a different sample type than its tags declare ({})",
                st.name()
            ))),
        }
    }

    fn put_as_f64<T: Copy + Into<f64>>(&self, v: &[T], out: &mut [f64]) -> Result<()> {
        if v.len() != self.cols * self.rows {
            return Err(Error::corrupt(format!(
                "GeoTIFF chunk {} decoded to {} samples, expected {}",
                self.index,
                v.len(),
                self.cols * self.rows
            )));
        }
        for (src, dst) in v
            .chunks_exact(self.cols)
            .zip(out.chunks_exact_mut(self.width))
        {
            for (d, &s) in dst[self.x0..self.x0 + self.cols].iter_mut().zip(src) {
                *d = s.into();
            }
        }
        Ok(())
    }
}

/// The decoder limits: room for the image (so for any chunk of it) and for a compressed chunk
/// as long as the file (chunk byte counts were checked against the file length, so it bounds
/// one compressed chunk; the default of 128 MiB would refuse large single-strip files).
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

impl<R: Read + Seek + Send> crate::model::RowSource for Reader<R> {
    fn width(&self) -> usize {
        Reader::width(self)
    }
    fn height(&self) -> usize {
        Reader::height(self)
    }
    fn band(&mut self, y0: usize, rows: usize) -> Result<Raster> {
        Reader::band(self, y0, rows)
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
        TAG_BITS_PER_SAMPLE, TAG_COMPRESSION, TAG_GDAL_NODATA, TAG_IMAGE_WIDTH,
        TAG_MODEL_PIXEL_SCALE, TAG_MODEL_TIEPOINT, TAG_PHOTOMETRIC, TAG_PREDICTOR,
        TAG_ROWS_PER_STRIP, TAG_SAMPLES_PER_PIXEL, TAG_STRIP_BYTE_COUNTS, TAG_STRIP_OFFSETS,
        TAG_TILE_BYTE_COUNTS, TAG_TILE_LENGTH, TAG_TILE_OFFSETS, TAG_TILE_WIDTH, write,
    };
    use crate::model::{RasterType, Window};
    use crate::testutil::{Rng, corpus};
    use tiff::encoder::Compression;
    use tiff::encoder::colortype::{Gray16, GrayI16, GrayI32};

    // ----- corpus -----------------------------------------------------------------------

    #[test]
    fn corpus_tifs_match_reference_f32() {
        for_each_corpus_tif(|dir, name, _, r| {
            let reference = std::fs::read(dir.join(format!("{name}.f32"))).unwrap();
            let json: serde_json::Value =
                serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap())
                    .unwrap();
            assert_eq!(r.width as u64, json["width"].as_u64().unwrap(), "{name}");
            assert_eq!(r.height as u64, json["height"].as_u64().unwrap(), "{name}");
            // serde_json (without its float_roundtrip feature) may misread the last bit of
            // a double, so the nodata is compared as the f32 the samples hold.
            let json_nodata = json["nodata"].as_f64();
            assert_eq!(
                r.nodata.map(|v| (v as f32).to_bits()),
                json_nodata.map(|v| (v as f32).to_bits()),
                "{name}: nodata"
            );
            let g = r.georef.as_ref().expect("georeferenced");
            assert_eq!(
                g.pixel_size,
                [json["dx"].as_f64().unwrap(), json["dy"].as_f64().unwrap()],
                "{name}: pixel size"
            );
            assert!(g.geokeys.is_some(), "{name}: geokeys kept");
            assert_eq!(reference.len(), r.len() * 4, "{name}: reference length");
            let mut invalid = 0;
            for (i, chunk) in reference.chunks_exact(4).enumerate() {
                let want = u32::from_le_bytes(chunk.try_into().unwrap());
                let got = if r.is_valid(i) {
                    r.data[i] as f32
                } else {
                    invalid += 1;
                    json_nodata.expect("invalid samples need a nodata") as f32
                };
                assert_eq!(
                    got.to_bits(),
                    want,
                    "{name}: sample {i} is {got}, reference {}",
                    f32::from_bits(want)
                );
            }
            let frac = json["stats"]["nodata_fraction"].as_f64().unwrap();
            assert!(
                (invalid as f64 / r.len() as f64 - frac).abs() < 1e-5,
                "{name}: nodata fraction"
            );
        });
    }

    #[test]
    fn corpus_specifics() {
        let Some(dir) = corpus() else { return };
        let read_name = |n: &str| {
            read(
                &std::fs::read(dir.join(format!("{n}.tif"))).unwrap(),
                &opts(),
            )
            .unwrap()
        };
        let texas = read_name("pysheds_dem_texas");
        assert_eq!(texas.sample_type, SampleType::I16);
        assert_eq!(texas.nodata, Some(-32768.0));
        assert_eq!(texas.mask, None);
        let texas_g = texas.georef.unwrap();
        assert_eq!(texas_g.epsg, Some(4326));
        assert_eq!(texas_g.origin, [-97.4849999999961, 32.82166666666536]);

        let tujunga = read_name("srtm30m_bigtujunga_utm11");
        assert_eq!(
            tujunga.nodata,
            Some(32767.0),
            "declared nodata kept though unused"
        );
        assert_eq!(tujunga.mask, None);
        let g = tujunga.georef.unwrap();
        assert_eq!(g.epsg, Some(32611));
        assert_eq!(g.raster_type, RasterType::Area);
        assert_eq!(g.origin, [376313.6554542635, 3807917.8276283755]);

        let lux = read_name("terra_elev_luxembourg");
        assert!(lux.mask.is_some());

        let vin = read_name("terra_elev_vinschgau");
        assert_eq!(vin.sample_type, SampleType::F32);
        assert_eq!(vin.nodata, Some(-3.3999999521443642e38));
        assert_eq!(vin.georef.unwrap().origin, [598250.0, 5193000.0]);
    }

    // ----- layouts the writer does not produce ---------------------------------------------

    #[test]
    fn float_predictor_3_is_read() {
        let (w, h) = (5usize, 3usize);
        let vals: Vec<f32> = (0..w * h).map(|i| 1000.0 + i as f32 * 0.37).collect();
        let data: Vec<u8> = vals.chunks(w).flat_map(fp_predict_row).collect();
        let mut b = Builder::basic(true, w as u32, h as u32, 32, 3, data.len());
        b.short(TAG_PREDICTOR, &[3]);
        let r = read(&b.build(&data), &opts()).unwrap();
        let want: Vec<f64> = vals.iter().map(|&v| f64::from(v)).collect();
        assert_eq!(r.data, want);
    }

    #[test]
    fn tiled_multi_strip_and_other_encoders() {
        // Written by the tiff crate with LZW and several strips, int32 and uint8.
        let (w, h) = (40u32, 33u32);
        let vals: Vec<i32> = (0..w * h).map(|i| (i as i32 - 600) * 1000).collect();
        let out = tiff_crate_strips::<GrayI32>(w, h, 4, Compression::Lzw, &vals);
        let r = read(&out, &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::I32);
        assert_eq!(
            r.data,
            vals.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()
        );

        // Hand-made tiles (2x2 tiles of 4x4 over a 6x5 image, uncompressed).
        let (w, h) = (6, 5);
        let r = read(&handmade_tiled(true, w, h, 4, 4), &opts()).unwrap();
        let want: Vec<f64> = (0..w * h)
            .map(|i| f64::from(tiled_value(i % w, i / w)))
            .collect();
        assert_eq!(r.data, want);
    }

    // ----- band by band ----------------------------------------------------------------

    /// Rows `y0..y0 + rows` of `whole` as `Reader::band` must give them.
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

    /// Read the file at `path` through `Reader` in bands of `h` rows (in order, then in
    /// reverse), each compared with `read` of the same bytes.
    fn check_bands_equal_read(path: &Path, whole: &Raster, what: &str) {
        for h in [1, 7, 256, whole.height] {
            let mut s = Reader::open(path, &opts()).unwrap();
            assert_eq!((s.width(), s.height()), (whole.width, whole.height));
            let starts: Vec<usize> = (0..whole.height).step_by(h).collect();
            for &y0 in starts.iter().chain(starts.iter().rev().take(3)) {
                let rows = h.min(whole.height - y0);
                let band = s.band(y0, rows).unwrap();
                assert_band(&band, whole, y0, &format!("{what}: band {y0}+{rows}"));
            }
        }
    }

    #[test]
    fn reader_equals_read_on_the_corpus() {
        for_each_corpus_tif(|dir, name, _, whole| {
            check_bands_equal_read(&dir.join(format!("{name}.tif")), &whole, name);
        });
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
            check_bands_equal_read(&path, &whole, &format!("{} striped", st.name()));
        }
        // The tiff crate, LZW with small strips, int16 and uint16.
        let (w, h) = (97u32, 61u32);
        let vals: Vec<i16> = (0..w * h).map(|i| (i as i16).wrapping_mul(37)).collect();
        let out = tiff_crate_strips::<GrayI16>(w, h, 5, Compression::Lzw, &vals);
        let whole = read(&out, &opts()).unwrap();
        let (_d, path) = temp_file(&out);
        check_bands_equal_read(&path, &whole, "LZW strips of 5 rows");

        let vals: Vec<u16> = (0..w * h).map(|i| (i * 13) as u16).collect();
        let out = tiff_crate_strips::<Gray16>(w, h, 1, Compression::Packbits, &vals);
        let whole = read(&out, &opts()).unwrap();
        let (_d, path) = temp_file(&out);
        check_bands_equal_read(&path, &whole, "PackBits strips of 1 row");

        // Hand-made big-endian strips of 4 rows.
        let (w, h) = (7usize, 10usize);
        let vals: Vec<i16> = (0..w * h).map(|i| i as i16 * 300 - 9000).collect();
        let mut b = Builder::basic(false, w as u32, h as u32, 16, 2, 0);
        b.long(TAG_ROWS_PER_STRIP, &[4])
            .long(TAG_STRIP_OFFSETS, &[8, 8 + 56, 8 + 112])
            .long(TAG_STRIP_BYTE_COUNTS, &[56, 56, 28])
            .ascii(TAG_GDAL_NODATA, "-9000");
        let bytes = b.build(&i16_bytes(false, &vals));
        let whole = read(&bytes, &opts()).unwrap();
        assert_eq!(whole.data[1], -8700.0);
        let (_d, path) = temp_file(&bytes);
        check_bands_equal_read(&path, &whole, "big-endian strips of 4 rows");
    }

    /// The sample at `(x, y)` of [`handmade_tiled`]'s TIFFs (-1000 is their nodata).
    fn tiled_value(x: usize, y: usize) -> i16 {
        ((y * 131 + x * 7) % 2000) as i16 - 1000
    }

    /// A hand-made uncompressed tiled int16 TIFF (tiles `tw × th`) with a nodata value, in
    /// little- or big-endian byte order.
    fn handmade_tiled(le: bool, w: usize, h: usize, tw: usize, th: usize) -> Vec<u8> {
        let (across, down) = (w.div_ceil(tw), h.div_ceil(th));
        let mut data = Vec::new();
        let mut offsets = Vec::new();
        for ty in 0..down {
            for tx in 0..across {
                offsets.push(8 + data.len() as u32);
                for y in 0..th {
                    for x in 0..tw {
                        let (gx, gy) = (tx * tw + x, ty * th + y);
                        let v = if gx < w && gy < h {
                            tiled_value(gx, gy)
                        } else {
                            0
                        };
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
            .ascii(TAG_GDAL_NODATA, "-1000")
            .double(TAG_MODEL_PIXEL_SCALE, &[2.0, 3.0, 0.0])
            .double(TAG_MODEL_TIEPOINT, &[0.0, 0.0, 0.0, 100.0, 900.0, 0.0]);
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
            check_bands_equal_read(&path, &whole, &format!("{} tiled", st.name()));
        }
        // Our own output as BigTIFF.
        let r = synthetic(SampleType::F32, 300, 270, Some(-9999.0), 77);
        let bytes = stream_write_kind(&r, 100, Some(true));
        assert_eq!(&bytes[..4], b"II+\0");
        let whole = read(&bytes, &opts()).unwrap();
        let (_d, path) = temp_file(&bytes);
        check_bands_equal_read(&path, &whole, "BigTIFF");
        // Hand-made tiles, smaller than and larger than the image, several per row, in both
        // byte orders.
        for le in [true, false] {
            for (w, h, tw, th) in [(37, 29, 16, 16), (5, 300, 16, 32), (20, 9, 32, 16)] {
                let bytes = handmade_tiled(le, w, h, tw, th);
                let whole = read(&bytes, &opts()).unwrap();
                assert!(whole.mask.is_some());
                let (_d, path) = temp_file(&bytes);
                let what = format!("{w}x{h} in {tw}x{th} tiles, le {le}");
                check_bands_equal_read(&path, &whole, &what);
            }
        }
    }

    #[test]
    fn reader_keeps_one_chunk_row() {
        let r = synthetic(SampleType::I16, 600, 530, Some(-9999.0), 3);
        let bytes = stream_write(&r, 530);
        let (_d, path) = temp_file(&bytes);
        let mut s = Reader::open(&path, &opts()).unwrap();
        s.band(250, 10).unwrap(); // tile rows 0 and 1; row 1 stays
        let c = s.cache.as_ref().unwrap();
        assert_eq!(
            (c.index, c.y0, c.data.len() / 600, c.data.len()),
            (1, 256, 256, 256 * 600)
        );
        s.band(300, 5).unwrap();
        assert_eq!(s.cache.as_ref().unwrap().index, 1);
        s.band(529, 1).unwrap();
        let c = s.cache.as_ref().unwrap();
        assert_eq!((c.index, c.data.len() / 600), (2, 18));
    }

    #[test]
    fn reader_refuses_what_read_refuses_with_the_same_message() {
        let mut inputs: Vec<Vec<u8>> = Vec::new();
        // Unsupported layouts.
        for tags in [
            &[(TAG_BITS_PER_SAMPLE, &[12u16][..])][..],
            &[(TAG_PHOTOMETRIC, &[3])],
            &[(TAG_COMPRESSION, &[7])],
            &[(TAG_PREDICTOR, &[3])],
            &[(TAG_SAMPLES_PER_PIXEL, &[2])],
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
        b.remove(TAG_IMAGE_WIDTH);
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
            let got = match Reader::open(&path, &opts()) {
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
        // apart (NUL handling, non-ASCII text); bands of the file on disk must follow `read` of its bytes either way.
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
                b.set(TAG_GDAL_NODATA, 2, 6, b"-9999 ".to_vec());
                let bytes = b.build(&i16_bytes(le, &vals));
                let (_d, path) = temp_file(&bytes);
                let banded = Reader::open(&path, &opts()).and_then(|mut s| s.band(0, 2));
                match (read(&bytes, &opts()), banded) {
                    (Ok(whole), Ok(band)) => assert_band(&band, &whole, 0, &format!("{k}")),
                    (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{k}"),
                    (a, b) => panic!("{k}: read {a:?}, bands {b:?}"),
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
        check_bands_equal_read(&path, &whole, "short metadata in a BigTIFF");
    }

    /// The file read from disk in bands of 5 rows, or its first error.
    fn bands_of_file(path: &Path) -> Result<Vec<Raster>> {
        let mut s = Reader::open(path, &opts())?;
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
                assert!(bands_of_file(&path).is_err(), "truncated to {len}");
            }
        }
        // Mutations: the bands and `read` of the bytes agree on success, and on the samples.
        let mut rng = Rng(0x5eed);
        for input in &inputs {
            for _ in 0..150 {
                let m = mutated(input, &mut rng);
                std::fs::write(&path, &m).unwrap();
                let banded = bands_of_file(&path);
                match (read(&m, &opts()), banded) {
                    (Ok(whole), Ok(bands)) => {
                        for (b, band) in bands.iter().enumerate() {
                            assert_band(band, &whole, b * 5, "mutated");
                        }
                    }
                    (Err(_), Err(_)) => {}
                    (a, b) => panic!("read {:?}, bands {:?}", a.map(|_| ()), b.map(|_| ())),
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
        let mut s = Reader::open(&path, &opts()).unwrap();
        assert!(s.band(0, 1).is_err());
        assert!(s.band(290, 10).is_ok(), "other tile rows still read");
        let e = s.band(0, 300).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
    }

    #[test]
    fn band_outside_the_image_is_an_error() {
        let bytes = write(&small_i16_raster()).unwrap();
        let (_d, path) = temp_file(&bytes);
        let mut s = Reader::open(&path, &opts()).unwrap();
        for (y0, rows) in [(0, 0), (17, 1), (10, 8), (usize::MAX, 2)] {
            assert!(
                matches!(s.band(y0, rows), Err(Error::InvalidArgument { .. })),
                "{y0}+{rows}"
            );
        }
        assert!(s.band(16, 1).is_ok());
    }
}
