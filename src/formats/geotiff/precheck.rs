//! The IFD pre-pass: the first image directory checked (bounds, layout, size) before decoding,
//! over the file in memory or on disk alike (`ifd::Source`).

use super::ifd::{self, Order, Source, type_size};
use super::{
    TAG_BITS_PER_SAMPLE, TAG_COMPRESSION, TAG_EXTRA_SAMPLES, TAG_GDAL_METADATA, TAG_GDAL_NODATA,
    TAG_GEO_ASCII_PARAMS, TAG_GEO_DOUBLE_PARAMS, TAG_GEO_KEY_DIRECTORY, TAG_IMAGE_LENGTH,
    TAG_IMAGE_WIDTH, TAG_JPEG_TABLES, TAG_MODEL_PIXEL_SCALE, TAG_MODEL_TIEPOINT,
    TAG_MODEL_TRANSFORMATION, TAG_PHOTOMETRIC, TAG_PLANAR_CONFIG, TAG_PREDICTOR,
    TAG_ROWS_PER_STRIP, TAG_SAMPLE_FORMAT, TAG_SAMPLES_PER_PIXEL, TAG_STRIP_BYTE_COUNTS,
    TAG_STRIP_OFFSETS, TAG_TILE_BYTE_COUNTS, TAG_TILE_LENGTH, TAG_TILE_OFFSETS, TAG_TILE_WIDTH,
    TAG_YCBCR_SUBSAMPLING,
};
use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{SampleType, check_size};

/// Tags whose data the pre-pass requires to lie inside the file (the ones the `tiff` decoder
/// or this module reads). Other tags are never read, so a broken one is harmless.
const CHECKED_TAGS: &[u16] = &[
    TAG_IMAGE_WIDTH,
    TAG_IMAGE_LENGTH,
    TAG_BITS_PER_SAMPLE,
    TAG_COMPRESSION,
    TAG_PHOTOMETRIC,
    TAG_STRIP_OFFSETS,
    TAG_SAMPLES_PER_PIXEL,
    TAG_ROWS_PER_STRIP,
    TAG_STRIP_BYTE_COUNTS,
    TAG_PLANAR_CONFIG,
    TAG_PREDICTOR,
    TAG_TILE_WIDTH,
    TAG_TILE_LENGTH,
    TAG_TILE_OFFSETS,
    TAG_TILE_BYTE_COUNTS,
    TAG_EXTRA_SAMPLES,
    TAG_SAMPLE_FORMAT,
    TAG_JPEG_TABLES,
    TAG_YCBCR_SUBSAMPLING,
    TAG_MODEL_PIXEL_SCALE,
    TAG_MODEL_TIEPOINT,
    TAG_MODEL_TRANSFORMATION,
    TAG_GEO_KEY_DIRECTORY,
    TAG_GEO_DOUBLE_PARAMS,
    TAG_GEO_ASCII_PARAMS,
    TAG_GDAL_METADATA,
    TAG_GDAL_NODATA,
];

/// What the pre-pass found out about the first image.
pub(super) struct Layout {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) samples: usize,
    pub(super) sample_type: SampleType,
    /// The file's byte order and kind.
    pub(super) order: Order,
    /// Where the first image directory is.
    pub(super) first_ifd: u64,
}

/// One IFD entry the pre-pass looks at.
struct RawEntry {
    tag: u16,
    typ: u16,
    /// Where the value bytes start (inline in the entry or at the offset it holds).
    data_pos: u64,
    /// Their length in bytes.
    len: u64,
}

/// At most this many bytes of one tag's values are read (a bound on what one tag can make
/// the pre-pass hold, whatever the file's size).
const MAX_TAG_BYTES: u64 = 256 << 20;

/// The unsigned integer values of an entry of type BYTE, SHORT, LONG or LONG8.
fn uints(src: &mut Source<'_>, o: Order, e: &RawEntry) -> Result<Vec<u64>> {
    let size = match e.typ {
        1 | 3 | 4 | 16 => type_size(e.typ).unwrap_or(1),
        _ => {
            return Err(Error::corrupt(format!(
                "GeoTIFF tag {} has type {} where an unsigned integer is expected",
                e.tag, e.typ
            )));
        }
    };
    if e.len > MAX_TAG_BYTES {
        return Err(Error::limit(format!(
            "GeoTIFF tag {} holds {} bytes, over the limit of {MAX_TAG_BYTES}",
            e.tag, e.len
        )));
    }
    // The data range was checked to lie inside the file, so its length is bounded by the file.
    let b = src.read_at(e.data_pos, e.len as usize)?;
    Ok(b.chunks_exact(size as usize).map(|c| o.uint(c)).collect())
}

/// Walk the first IFD: check that the tags we rely on are well-formed and inside the file,
/// that the layout is supported, and that the size is within the limit.
pub(super) fn precheck(src: &mut Source<'_>, opts: &ReadOptions) -> Result<Layout> {
    let truncated = || Error::corrupt("GeoTIFF is truncated");
    let file_len = src.len();
    let (o, ifd_pos) = ifd::header(src)?;
    let dir = ifd::directory(src, o, ifd_pos)?.ok_or_else(truncated)?;
    if dir.count == 0 {
        return Err(Error::corrupt("GeoTIFF image directory is empty"));
    }
    if dir.end(o).is_none_or(|end| end > file_len) {
        return Err(truncated());
    }

    let mut entries: Vec<RawEntry> = Vec::new();
    dir.entries(src, o, |e| {
        let tag = e.tag;
        if !CHECKED_TAGS.contains(&tag) {
            return Ok(());
        }
        let (typ, cnt) = (e.typ, e.count);
        let size = type_size(typ).ok_or_else(|| {
            Error::corrupt(format!("GeoTIFF tag {tag} has an unknown field type {typ}"))
        })?;
        let len = size.checked_mul(cnt).ok_or_else(truncated)?;
        let data_pos = e.data_pos(o, len);
        if data_pos.checked_add(len).is_none_or(|end| end > file_len) {
            return Err(Error::corrupt(format!(
                "GeoTIFF is truncated or corrupt: tag {tag} ({cnt} values at offset {data_pos}) \
                 ends past the end of the file ({file_len} bytes)"
            )));
        }
        if entries.iter().any(|e| e.tag == tag) {
            return Ok(()); // the decoder keeps the first one too
        }
        entries.push(RawEntry {
            tag,
            typ,
            data_pos,
            len,
        });
        Ok(())
    })?;
    let find = |tag: u16| entries.iter().find(|e| e.tag == tag);
    let mut uints = |tag: u16| -> Result<Option<Vec<u64>>> {
        match find(tag) {
            None => Ok(None),
            Some(e) => {
                let v = uints(src, o, e)?;
                if v.is_empty() {
                    return Err(Error::corrupt(format!("GeoTIFF tag {tag} has no value")));
                }
                Ok(Some(v))
            }
        }
    };
    let mut scalar = |tag: u16| -> Result<Option<u64>> { Ok(uints(tag)?.map(|v| v[0])) };

    let width =
        scalar(TAG_IMAGE_WIDTH)?.ok_or_else(|| Error::corrupt("GeoTIFF has no ImageWidth tag"))?;
    let height = scalar(TAG_IMAGE_LENGTH)?
        .ok_or_else(|| Error::corrupt("GeoTIFF has no ImageLength tag"))?;
    if width == 0 || height == 0 {
        return Err(Error::corrupt(format!(
            "GeoTIFF image size {width}x{height} is empty"
        )));
    }

    // Layout: one sample per pixel of a supported type.
    let spp = scalar(TAG_SAMPLES_PER_PIXEL)?.unwrap_or(1);
    if spp != 1 {
        return Err(Error::unsupported(format!(
            "GeoTIFF with {spp} samples per pixel (only single-band rasters are supported)"
        )));
    }
    match scalar(TAG_PHOTOMETRIC)? {
        Some(1) => {}
        Some(p) => {
            let name = match p {
                0 => "WhiteIsZero",
                2 => "RGB",
                3 => "palette",
                4 => "transparency mask",
                5 => "CMYK",
                6 => "YCbCr",
                8..=10 => "CIE Lab",
                _ => "unknown",
            };
            return Err(Error::unsupported(format!(
                "GeoTIFF with {name} photometric interpretation ({p}) (only grey-scale \
                 BlackIsZero rasters are supported)"
            )));
        }
        None => {
            return Err(Error::unsupported(
                "GeoTIFF without a PhotometricInterpretation tag (the TIFF decoder requires it)",
            ));
        }
    }
    let bits = scalar(TAG_BITS_PER_SAMPLE)?.unwrap_or(1);
    let format = scalar(TAG_SAMPLE_FORMAT)?.unwrap_or(1);
    if ![8, 16, 32, 64].contains(&bits) {
        return Err(Error::unsupported(format!(
            "GeoTIFF with {bits} bits per sample (only 8, 16, 32 and 64 are supported)"
        )));
    }
    let sample_type = match (format, bits) {
        (1, 8) => SampleType::U8,
        (1, 16) => SampleType::U16,
        (2, 16) => SampleType::I16,
        (2, 32) => SampleType::I32,
        (3, 32) => SampleType::F32,
        (3, 64) => SampleType::F64,
        _ => {
            let kind = match format {
                1 => "uint",
                2 => "int",
                3 => "float",
                4 => "untyped (void) ",
                5 => "complex int",
                6 => "complex float",
                _ => "unknown-format ",
            };
            return Err(Error::unsupported(format!(
                "GeoTIFF with {kind}{bits} samples (supported: uint8, int16, uint16, int32, \
                 float32, float64)"
            )));
        }
    };
    let compression = scalar(TAG_COMPRESSION)?.unwrap_or(1);
    match compression {
        1 | 5 | 8 | 32946 | 32773 => {}
        c => {
            let name = match c {
                2 => "CCITT RLE",
                3 | 4 => "CCITT fax",
                6 | 7 => "JPEG",
                34712 => "JPEG 2000",
                34887 => "LERC",
                34925 => "LZMA",
                50000 => "Zstandard",
                50001 => "WebP",
                _ => "unknown",
            };
            return Err(Error::unsupported(format!(
                "GeoTIFF with {name} compression ({c}) (supported: none, LZW, Deflate, PackBits)"
            )));
        }
    }
    match scalar(TAG_PREDICTOR)?.unwrap_or(1) {
        1 | 2 => {}
        3 if !sample_type.is_integer() => {}
        3 => {
            return Err(Error::unsupported(format!(
                "GeoTIFF with the floating-point predictor (3) on {} samples",
                sample_type.name()
            )));
        }
        p => return Err(Error::unsupported(format!("GeoTIFF with predictor {p}"))),
    }
    match scalar(TAG_PLANAR_CONFIG)?.unwrap_or(1) {
        1 | 2 => {}
        p => {
            return Err(Error::corrupt(format!(
                "GeoTIFF has an invalid PlanarConfiguration {p}"
            )));
        }
    }

    let max = opts.max_samples();
    let samples = check_size(width, height, max)?;

    // Chunk layout: every strip / tile must lie inside the file.
    let tiled = find(TAG_TILE_OFFSETS).is_some() || find(TAG_TILE_WIDTH).is_some();
    let (offsets_tag, counts_tag, expected) = if tiled {
        let tw = scalar(TAG_TILE_WIDTH)?.unwrap_or(0);
        let th = scalar(TAG_TILE_LENGTH)?.unwrap_or(0);
        if tw == 0 || th == 0 {
            return Err(Error::corrupt(format!(
                "GeoTIFF tile size {tw}x{th} is invalid"
            )));
        }
        if tw.saturating_mul(th) > max {
            return Err(Error::limit(format!(
                "GeoTIFF tile of {tw}x{th} samples is over the limit of {max}"
            )));
        }
        let n = width.div_ceil(tw).saturating_mul(height.div_ceil(th));
        (TAG_TILE_OFFSETS, TAG_TILE_BYTE_COUNTS, n)
    } else {
        let rps = scalar(TAG_ROWS_PER_STRIP)?
            .unwrap_or(height)
            .clamp(1, height);
        (
            TAG_STRIP_OFFSETS,
            TAG_STRIP_BYTE_COUNTS,
            height.div_ceil(rps),
        )
    };
    let offsets = uints(offsets_tag)?
        .ok_or_else(|| Error::corrupt("GeoTIFF has no strip or tile offsets"))?;
    let counts = uints(counts_tag)?
        .ok_or_else(|| Error::corrupt("GeoTIFF has no strip or tile byte counts"))?;
    if offsets.len() != counts.len() || (offsets.len() as u64) < expected {
        return Err(Error::corrupt(format!(
            "GeoTIFF has {} chunk offsets and {} byte counts for {expected} chunks",
            offsets.len(),
            counts.len()
        )));
    }
    for (i, (&off, &c)) in offsets.iter().zip(&counts).enumerate() {
        if off.checked_add(c).is_none_or(|end| end > file_len) {
            return Err(Error::corrupt(format!(
                "GeoTIFF is truncated: {} {i} ({c} bytes at offset {off}) ends past the end of \
                 the file ({file_len} bytes)",
                if tiled { "tile" } else { "strip" },
            )));
        }
    }

    Ok(Layout {
        width: width as usize,
        height: height as usize,
        samples,
        sample_type,
        order: o,
        first_ifd: ifd_pos,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::{read, write};
    use crate::testutil::{Rng, corpus};
    use std::io::Cursor;
    use tiff::encoder::TiffEncoder;

    // ----- unsupported and broken input ---------------------------------------------------

    #[test]
    fn rgb_is_unsupported() {
        let mut out = Cursor::new(Vec::new());
        TiffEncoder::new(&mut out)
            .unwrap()
            .write_image::<tiff::encoder::colortype::RGB8>(4, 3, &[7u8; 36])
            .unwrap();
        let e = read(out.get_ref(), &opts()).unwrap_err();
        assert!(is_unsupported(&e), "{e}");
        let msg = e.to_string();
        assert!(msg.contains("3 samples per pixel"), "{msg}");
    }

    #[test]
    fn unsupported_layouts() {
        // (case, SHORT tags set on a basic int16 image, what the error names)
        type Case<'a> = (&'a str, &'a [(u16, &'a [u16])], &'a str);
        let cases: &[Case] = &[
            (
                "12-bit",
                &[(TAG_BITS_PER_SAMPLE, &[12])],
                "12 bits per sample",
            ),
            ("1-bit", &[(TAG_BITS_PER_SAMPLE, &[1])], "1 bits per sample"),
            ("palette", &[(TAG_PHOTOMETRIC, &[3])], "palette"),
            ("int8", &[(TAG_BITS_PER_SAMPLE, &[8])], "int8"),
            (
                "uint32",
                &[(TAG_BITS_PER_SAMPLE, &[32]), (TAG_SAMPLE_FORMAT, &[1])],
                "uint32",
            ),
            ("jpeg", &[(TAG_COMPRESSION, &[7])], "JPEG"),
            ("zstd", &[(TAG_COMPRESSION, &[50000])], "Zstandard"),
            (
                "planar 2 bands",
                &[
                    (TAG_SAMPLES_PER_PIXEL, &[2]),
                    (TAG_PLANAR_CONFIG, &[2]),
                    (TAG_BITS_PER_SAMPLE, &[16, 16]),
                    (TAG_SAMPLE_FORMAT, &[2, 2]),
                ],
                "2 samples per pixel",
            ),
            (
                "fp predictor on ints",
                &[(TAG_PREDICTOR, &[3])],
                "predictor",
            ),
        ];
        for &(name, tags, needle) in cases {
            let mut b = Builder::basic(true, 2, 2, 16, 2, 8);
            for &(tag, v) in tags {
                b.short(tag, v);
            }
            let e = read(&b.build(&[0; 8]), &opts()).unwrap_err();
            assert!(is_unsupported(&e), "{name}: {e}");
            assert!(e.to_string().contains(needle), "{name}: {e}");
            assert!(!e.to_string().contains('\n'), "{name}: one line");
        }
        // Planar configuration 2 with one band is just a single band.
        let mut b = Builder::basic(true, 2, 1, 16, 2, 4);
        b.short(TAG_PLANAR_CONFIG, &[2]);
        assert_eq!(
            read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap().data,
            vec![1.0, 2.0]
        );
    }

    #[test]
    fn huge_header_is_a_limit_error() {
        let mut b = Builder::basic(true, 100_000, 100_000, 16, 2, 8);
        b.long(TAG_ROWS_PER_STRIP, &[100_000]);
        let e = read(&b.build(&[0; 8]), &opts()).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");

        // A huge tile is refused too.
        let mut b = Builder::basic(true, 4, 4, 16, 2, 0);
        b.remove(TAG_STRIP_OFFSETS)
            .remove(TAG_STRIP_BYTE_COUNTS)
            .long(TAG_TILE_WIDTH, &[1 << 30])
            .long(TAG_TILE_LENGTH, &[1 << 30])
            .long(TAG_TILE_OFFSETS, &[8])
            .long(TAG_TILE_BYTE_COUNTS, &[8]);
        let e = read(&b.build(&[0; 8]), &opts()).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");

        // The caller's limit applies.
        let bytes = write(&small_i16_raster()).unwrap();
        let small = ReadOptions {
            max_samples: Some(100),
            ..ReadOptions::default()
        };
        let e = read(&bytes, &small).unwrap_err();
        assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
        assert!(read(&bytes, &opts()).is_ok());
    }

    #[test]
    fn garbage_bytes_are_errors() {
        let mut rng = Rng(12345);
        for len in [0usize, 1, 2, 3, 4, 7, 8, 9, 16, 100, 1000, 5000] {
            for prefix in [&b""[..], b"II*\0", b"MM\0*", b"II+\0\x08\0\0\0"] {
                for _ in 0..20 {
                    let mut b = prefix.to_vec();
                    b.extend((0..len).map(|_| rng.next() as u8));
                    assert!(read(&b, &opts()).is_err());
                }
            }
        }
    }

    #[test]
    fn truncations_are_errors() {
        let written = write(&small_i16_raster()).unwrap();
        let vals: Vec<i16> = (0..12).collect();
        let mut b = Builder::basic(true, 4, 3, 16, 2, 24);
        b.double(TAG_MODEL_PIXEL_SCALE, &[1.0, 1.0, 0.0])
            .double(TAG_MODEL_TIEPOINT, &[0.0, 0.0, 0.0, 5.0, 6.0, 0.0])
            .ascii(TAG_GDAL_NODATA, "-1");
        let handmade = b.build(&i16_bytes(true, &vals));
        assert!(read(&handmade, &opts()).is_ok());
        for file in [&written, &handmade] {
            for len in 0..file.len() {
                let r = read(&file[..len], &opts());
                assert!(r.is_err(), "truncated to {len} of {} bytes", file.len());
            }
        }
        let Some(dir) = corpus() else { return };
        let tif = std::fs::read(dir.join("terra_elev_luxembourg.tif")).unwrap();
        for k in 0..50 {
            let len = tif.len() * k / 50;
            assert!(read(&tif[..len], &opts()).is_err(), "truncated to {len}");
        }
    }

    #[test]
    fn mutated_files_never_panic() {
        let mut inputs = vec![write(&small_i16_raster()).unwrap()];
        let mut f = small_i16_raster();
        f.sample_type = SampleType::F32;
        inputs.push(write(&f).unwrap());
        let vals: Vec<f32> = (0..15).map(|i| i as f32).collect();
        let data: Vec<u8> = vals.chunks(5).flat_map(fp_predict_row).collect();
        let mut b = Builder::basic(true, 5, 3, 32, 3, data.len());
        b.short(TAG_PREDICTOR, &[3])
            .double(TAG_MODEL_PIXEL_SCALE, &[1.0, 1.0, 0.0])
            .double(TAG_MODEL_TIEPOINT, &[0.0, 0.0, 0.0, 5.0, 6.0, 0.0])
            .short(TAG_GEO_KEY_DIRECTORY, &[1, 1, 0, 1, 1025, 0, 1, 2]);
        inputs.push(b.build(&data));
        if let Some(dir) = corpus() {
            inputs.push(std::fs::read(dir.join("terra_elev_luxembourg.tif")).unwrap());
        }
        // VTZ_FUZZ_ITERS raises the number of mutations per input for a longer run.
        let iters: usize = std::env::var("VTZ_FUZZ_ITERS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(600);
        let mut rng = Rng(0xdead_beef);
        for input in &inputs {
            for _ in 0..iters {
                let m = mutated(input, &mut rng);
                // Any result is fine; it must not panic or allocate wildly.
                let _ = read(&m, &opts());
            }
        }
    }
}
