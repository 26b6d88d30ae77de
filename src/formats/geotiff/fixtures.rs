//! Test fixtures: a hand-built classic TIFF writer, small and synthetic rasters, raw tags, a
//! bitwise comparison, the streaming writer's output, temporary files.

use super::{StreamWriter, read};
use super::{
    TAG_BITS_PER_SAMPLE, TAG_COMPRESSION, TAG_IMAGE_LENGTH, TAG_IMAGE_WIDTH, TAG_PHOTOMETRIC,
    TAG_ROWS_PER_STRIP, TAG_SAMPLE_FORMAT, TAG_SAMPLES_PER_PIXEL, TAG_STRIP_BYTE_COUNTS,
    TAG_STRIP_OFFSETS,
};
use crate::error::Error;
use crate::formats::ReadOptions;
use crate::model::{Georef, Raster, RasterType, SampleType, Window};
use crate::testutil::{Rng, for_each_corpus};
use std::io::Cursor;
use std::path::{Path, PathBuf};
use tiff::decoder::{Decoder, ifd::Value};
use tiff::encoder::colortype::ColorType;
use tiff::encoder::{Compression, Predictor, TiffEncoder, TiffValue};
use tiff::tags::Tag;

pub(super) const CORPUS_TIFS: &[&str] = &[
    "pysheds_dem_texas",
    "srtm30m_bigtujunga_utm11",
    "terra_elev_luxembourg",
    "terra_elev_vinschgau",
];

/// Run `f(dir, name, bytes, raster)` for each of [`CORPUS_TIFS`] (nothing without the corpus).
pub(super) fn for_each_corpus_tif(mut f: impl FnMut(&Path, &str, &[u8], Raster)) {
    for_each_corpus(CORPUS_TIFS, |dir, name| {
        let tif = std::fs::read(dir.join(format!("{name}.tif"))).unwrap();
        let r = read(&tif, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
        f(dir, name, &tif, r);
    });
}

pub(super) fn opts() -> ReadOptions {
    ReadOptions::default()
}

/// Same raster ([`crate::testutil::assert_same`]), and also the same value mapping and
/// every sample to the bit, invalid samples' fills (NaN included) too.
pub(super) fn assert_same(a: &Raster, b: &Raster, what: &str) {
    crate::testutil::assert_same(a, b, what);
    assert_eq!(a.mapping, b.mapping, "{what}: mapping");
    let differing = a
        .data
        .iter()
        .zip(&b.data)
        .position(|(x, y)| x.to_bits() != y.to_bits());
    assert_eq!(differing, None, "{what}: first differing sample");
}

/// Hand-built classic TIFF: pixel data at offset 8, then the IFD, then long tag values.
pub(super) struct Builder {
    le: bool,
    entries: Vec<(u16, u16, u32, Vec<u8>)>,
}

impl Builder {
    pub(super) fn new(le: bool) -> Self {
        Builder {
            le,
            entries: Vec::new(),
        }
    }
    pub(super) fn set(&mut self, tag: u16, typ: u16, count: u32, bytes: Vec<u8>) -> &mut Self {
        self.entries.retain(|e| e.0 != tag);
        self.entries.push((tag, typ, count, bytes));
        self
    }
    pub(super) fn remove(&mut self, tag: u16) -> &mut Self {
        self.entries.retain(|e| e.0 != tag);
        self
    }
    pub(super) fn short(&mut self, tag: u16, v: &[u16]) -> &mut Self {
        let b = ordered(self.le, v, u16::to_le_bytes, u16::to_be_bytes);
        self.set(tag, 3, v.len() as u32, b)
    }
    pub(super) fn long(&mut self, tag: u16, v: &[u32]) -> &mut Self {
        let b = ordered(self.le, v, u32::to_le_bytes, u32::to_be_bytes);
        self.set(tag, 4, v.len() as u32, b)
    }
    pub(super) fn double(&mut self, tag: u16, v: &[f64]) -> &mut Self {
        let b = ordered(self.le, v, f64::to_le_bytes, f64::to_be_bytes);
        self.set(tag, 12, v.len() as u32, b)
    }
    pub(super) fn ascii(&mut self, tag: u16, s: &str) -> &mut Self {
        let mut b = s.as_bytes().to_vec();
        b.push(0);
        let n = b.len() as u32;
        self.set(tag, 2, n, b)
    }
    /// The usual tags of a single-strip, uncompressed, single-band image.
    pub(super) fn basic(le: bool, w: u32, h: u32, bits: u16, format: u16, data_len: usize) -> Self {
        let mut b = Builder::new(le);
        b.long(TAG_IMAGE_WIDTH, &[w])
            .long(TAG_IMAGE_LENGTH, &[h])
            .short(TAG_BITS_PER_SAMPLE, &[bits])
            .short(TAG_COMPRESSION, &[1])
            .short(TAG_PHOTOMETRIC, &[1])
            .long(TAG_STRIP_OFFSETS, &[8])
            .short(TAG_SAMPLES_PER_PIXEL, &[1])
            .long(TAG_ROWS_PER_STRIP, &[h])
            .long(TAG_STRIP_BYTE_COUNTS, &[data_len as u32])
            .short(TAG_SAMPLE_FORMAT, &[format]);
        b
    }
    pub(super) fn build(&self, data: &[u8]) -> Vec<u8> {
        let le = self.le;
        let u16b = |v: u16| if le { v.to_le_bytes() } else { v.to_be_bytes() };
        let u32b = |v: u32| if le { v.to_le_bytes() } else { v.to_be_bytes() };
        let mut entries = self.entries.clone();
        entries.sort_by_key(|e| e.0);
        let ifd = (8 + data.len() + data.len() % 2) as u32;
        let mut extra_at = ifd + 2 + 12 * entries.len() as u32 + 4;
        let mut out = Vec::new();
        out.extend_from_slice(if le { b"II" } else { b"MM" });
        out.extend_from_slice(&u16b(42));
        out.extend_from_slice(&u32b(ifd));
        out.extend_from_slice(data);
        out.resize(ifd as usize, 0);
        out.extend_from_slice(&u16b(entries.len() as u16));
        let mut extra = Vec::new();
        for (tag, typ, count, bytes) in &entries {
            out.extend_from_slice(&u16b(*tag));
            out.extend_from_slice(&u16b(*typ));
            out.extend_from_slice(&u32b(*count));
            if bytes.len() <= 4 {
                let mut field = bytes.clone();
                field.resize(4, 0);
                out.extend_from_slice(&field);
            } else {
                out.extend_from_slice(&u32b(extra_at));
                extra.extend_from_slice(bytes);
                if bytes.len() % 2 == 1 {
                    extra.push(0);
                }
                extra_at = ifd + 2 + 12 * entries.len() as u32 + 4 + extra.len() as u32;
            }
        }
        out.extend_from_slice(&u32b(0));
        out.extend_from_slice(&extra);
        out
    }
}

/// Values as bytes in the given byte order (little-endian when `le`).
fn ordered<T: Copy, const N: usize>(
    le: bool,
    v: &[T],
    to_le: fn(T) -> [u8; N],
    to_be: fn(T) -> [u8; N],
) -> Vec<u8> {
    v.iter()
        .flat_map(|&x| if le { to_le(x) } else { to_be(x) })
        .collect()
}

pub(super) fn i16_bytes(le: bool, v: &[i16]) -> Vec<u8> {
    ordered(le, v, i16::to_le_bytes, i16::to_be_bytes)
}

pub(super) fn small_georef(epsg: Option<u32>) -> Georef {
    Georef {
        origin: [500000.0, 4649776.5],
        pixel_size: [30.0, 30.0],
        raster_type: RasterType::Area,
        epsg,
        wkt: None,
        geokeys: None,
    }
}

/// A small int16 raster with a georef, nodata and a few invalid samples.
pub(super) fn small_i16_raster() -> Raster {
    let (w, h) = (23, 17);
    let mut data: Vec<f64> = (0..w * h)
        .map(|i| ((i * 37) % 1000) as f64 - 200.0)
        .collect();
    data[5] = -9999.0;
    data[100] = -9999.0;
    let mut r = Raster::from_values(w, h, data, Some(-9999.0), SampleType::I16).unwrap();
    r.georef = Some(small_georef(Some(32611)));
    r
}

pub(super) fn is_unsupported(e: &Error) -> bool {
    matches!(e, Error::Unsupported { .. })
}

pub(super) fn raw_tag(bytes: &[u8], tag: Tag) -> Option<Value> {
    let mut d = Decoder::new(Cursor::new(bytes)).unwrap();
    d.find_tag(tag).unwrap()
}

/// Forward TIFF floating-point predictor (3) on one row of float32 samples.
pub(super) fn fp_predict_row(row: &[f32]) -> Vec<u8> {
    let n = row.len();
    let mut s = vec![0u8; n * 4];
    for (i, v) in row.iter().enumerate() {
        for (k, byte) in v.to_be_bytes().into_iter().enumerate() {
            s[k * n + i] = byte;
        }
    }
    for i in (1..s.len()).rev() {
        s[i] = s[i].wrapping_sub(s[i - 1]);
    }
    s
}

/// `bytes` as a file in a fresh temporary directory.
pub(super) fn temp_file(bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tif");
    std::fs::write(&path, bytes).unwrap();
    (dir, path)
}

/// A raster of type `st` with holes (as nodata when given, else NaN) and a georef.
pub(super) fn synthetic(
    st: SampleType,
    w: usize,
    h: usize,
    nodata: Option<f64>,
    seed: u64,
) -> Raster {
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
    r.gdal_metadata = Some("<GDALMetadata>\n  <Item name=\"x\">y</Item>\n</GDALMetadata>\n".into());
    r
}

/// `r` through `StreamWriter` in bands of `h` rows.
pub(super) fn stream_write(r: &Raster, h: usize) -> Vec<u8> {
    stream_write_kind(r, h, None)
}

/// `r` through `StreamWriter` in bands of `h` rows, BigTIFF when `big` says.
pub(super) fn stream_write_kind(r: &Raster, h: usize, big: Option<bool>) -> Vec<u8> {
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

/// `input` with 1 to 4 random bytes set to 0, 0xff or a random value.
pub(super) fn mutated(input: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut m = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let i = rng.below(m.len() as u64) as usize;
        m[i] = match rng.below(4) {
            0 => 0,
            1 => 0xff,
            _ => rng.next() as u8,
        };
    }
    m
}

/// A `w × h` TIFF of `vals` written by the `tiff` crate in strips of `rows` rows with
/// `compression`, the horizontal predictor with LZW (a layout vtz's writers do not make).
pub(super) fn tiff_crate_strips<C: ColorType>(
    w: u32,
    h: u32,
    rows: u32,
    compression: Compression,
    vals: &[C::Inner],
) -> Vec<u8>
where
    [C::Inner]: TiffValue,
{
    let mut out = Cursor::new(Vec::new());
    let mut enc = TiffEncoder::new(&mut out)
        .unwrap()
        .with_compression(compression);
    if compression == Compression::Lzw {
        enc = enc.with_predictor(Predictor::Horizontal);
    }
    let mut img = enc.new_image::<C>(w, h).unwrap();
    img.rows_per_strip(rows).unwrap();
    img.write_data(vals).unwrap();
    out.into_inner()
}
