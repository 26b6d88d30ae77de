//! Writing: a raster as a striped, Deflate-compressed single-band GeoTIFF.

use super::georef::{GeoTags, geo_tags, write_geo_tags};
use super::tags::enc_err;
use crate::error::{Error, Result};
use crate::formats::samples::f32_samples;
use crate::model::{OutputType, Raster, SampleType, ValueMapping};
use std::io::Cursor;
use tiff::encoder::colortype::{
    ColorType, Gray8, Gray16, Gray32Float, Gray64Float, GrayI16, GrayI32,
};
use tiff::encoder::{
    Compression, DeflateLevel, Predictor, TiffEncoder, TiffKind, TiffKindBig, TiffKindStandard,
    TiffValue,
};

/// Target size of one uncompressed strip when writing. GDAL/libtiff default to 8 KiB strips;
/// 64 KiB keeps strips small enough for windowed reads while giving Deflate (32 KiB window)
/// enough context.
const STRIP_BYTES: u64 = 64 * 1024;

/// Above this many bytes of raw samples the writer switches to BigTIFF (classic TIFF offsets
/// are 32-bit).
pub(super) const BIGTIFF_THRESHOLD: u64 = 3 << 30;

/// Write a raster as a striped, Deflate-compressed single-band GeoTIFF.
///
/// Samples are written as [`OutputType::of`] says: the values in the raster's sample type
/// (identity mapping), in the smallest integer type that holds them (an integer mapping: a
/// u16 PNG mapped by −32768 is written as int16), or the codes in the sample type with the
/// mapping as GDAL_METADATA's `OFFSET`/`SCALE` items (GDAL's band offset and scale); an
/// integer raster whose nodata value is not a code is written as float32 (or float64 when
/// float32 would not hold its values exactly). Integer samples are rounded to the nearest
/// integer; out-of-range values are an error.
pub fn write(r: &Raster) -> Result<Vec<u8>> {
    r.validate()?;
    let out = OutputType::of(r.sample_type, r.mapping, r.nodata);
    if let OutputType::Codes(_, m) = out {
        // The codes, with the mapping as GDAL's band offset and scale.
        let mut c = r.clone();
        for v in &mut c.data {
            *v = out.stored(*v);
        }
        c.nodata = r.nodata.map(|nd| out.stored(nd));
        c.mapping = ValueMapping::default();
        c.gdal_metadata = Some(crate::formats::with_offset_scale(
            r.gdal_metadata.as_deref(),
            m,
        ));
        return write(&c);
    }
    let too_big = || {
        Error::invalid(format!(
            "raster {}x{} is too large for a TIFF",
            r.width, r.height
        ))
    };
    let width = u32::try_from(r.width).map_err(|_| too_big())?;
    let height = u32::try_from(r.height).map_err(|_| too_big())?;
    let has_invalid = r.mask.as_ref().is_some_and(|m| m.contains(&false));
    let st = output_type(r);

    let mut tags = geo_tags(r.georef.as_ref())?;
    tags.gdal_metadata = r.gdal_metadata.clone();
    let size = (width, height);
    match st {
        SampleType::F32 => {
            let data = f32_samples(r, r.nodata.map_or(f32::NAN, |nd| nd as f32))?;
            tags.nodata = match r.nodata {
                Some(nd) => Some(f64::from(nd as f32)),
                None => has_invalid.then_some(f64::NAN),
            };
            encode::<Gray32Float>(size, &data, Predictor::None, &tags)
        }
        SampleType::F64 => {
            let fill = r.nodata.unwrap_or(f64::NAN);
            let data: Vec<f64> = (0..r.len())
                .map(|i| if r.is_valid(i) { r.data[i] } else { fill })
                .collect();
            tags.nodata = r.nodata.or(has_invalid.then_some(f64::NAN));
            encode::<Gray64Float>(size, &data, Predictor::None, &tags)
        }
        _ => {
            // Codes straight in the output type (each checked to fit it first).
            let h = Predictor::Horizontal;
            match st {
                SampleType::U8 => {
                    let (d, nodata) = integer_codes(r, st, has_invalid, |c| c as u8)?;
                    tags.nodata = nodata;
                    encode::<Gray8>(size, &d, h, &tags)
                }
                SampleType::I16 => {
                    let (d, nodata) = integer_codes(r, st, has_invalid, |c| c as i16)?;
                    tags.nodata = nodata;
                    encode::<GrayI16>(size, &d, h, &tags)
                }
                SampleType::U16 => {
                    let (d, nodata) = integer_codes(r, st, has_invalid, |c| c as u16)?;
                    tags.nodata = nodata;
                    encode::<Gray16>(size, &d, h, &tags)
                }
                _ => {
                    let (d, nodata) = integer_codes(r, st, has_invalid, |c| c as i32)?;
                    tags.nodata = nodata;
                    encode::<GrayI32>(size, &d, h, &tags)
                }
            }
        }
    }
}

/// The sample type to write the values in: [`OutputType::of`]'s, float32 rather than float64
/// for an integer raster whose values float32 holds exactly.
fn output_type(r: &Raster) -> SampleType {
    let st = OutputType::of(r.sample_type, r.mapping, r.nodata).sample_type();
    if !r.sample_type.is_integer() || st != SampleType::F64 {
        return st;
    }
    let exact_f32 = |v: f64| f64::from(v as f32) == v;
    let all_f32 = (0..r.len()).all(|i| !r.is_valid(i) || exact_f32(r.data[i]))
        && r.nodata.is_none_or(exact_f32);
    if all_f32 {
        SampleType::F32
    } else {
        SampleType::F64
    }
}

/// Integer codes of every sample (valid ones rounded, invalid ones the fill value) and the
/// nodata value to declare.
fn integer_codes<T>(
    r: &Raster,
    st: SampleType,
    has_invalid: bool,
    cast: impl Fn(i64) -> T,
) -> Result<(Vec<T>, Option<f64>)> {
    let (lo, hi) = st
        .int_range()
        .ok_or_else(|| Error::invalid(format!("{} is not an integer type", st.name())))?;
    let fits = |c: f64| c >= lo && c <= hi;
    let fill = match (r.nodata, has_invalid) {
        (Some(nd), true) => {
            if nd.fract() != 0.0 || !fits(nd) {
                return Err(Error::invalid(format!(
                    "nodata value {nd} cannot be stored in a {} GeoTIFF",
                    st.name()
                )));
            }
            nd
        }
        (Some(_), false) | (None, false) => 0.0,
        (None, true) => {
            // No declared nodata: use the type's minimum (maximum for unsigned types), or the
            // other end of the range if a valid sample already holds that value.
            let prefer = if matches!(st, SampleType::U8 | SampleType::U16) {
                [hi, lo]
            } else {
                [lo, hi]
            };
            let used = |c: f64| (0..r.len()).any(|i| r.is_valid(i) && r.data[i].round() == c);
            prefer.into_iter().find(|&c| !used(c)).ok_or_else(|| {
                Error::invalid(format!(
                    "raster has nodata samples but no nodata value, and both ends of the {} \
                     range are used by valid samples",
                    st.name()
                ))
            })?
        }
    };
    let mut codes = Vec::with_capacity(r.len());
    for (i, &v) in r.data.iter().enumerate() {
        if !r.is_valid(i) {
            codes.push(cast(fill as i64));
            continue;
        }
        let c = v.round();
        if !fits(c) {
            return Err(Error::invalid(format!(
                "sample {v} at row {}, col {} does not fit in {} ({lo}..={hi})",
                i / r.width,
                i % r.width,
                st.name()
            )));
        }
        codes.push(cast(c as i64));
    }
    let nodata = match r.nodata {
        Some(nd) => Some(nd),
        None => has_invalid.then_some(fill),
    };
    Ok((codes, nodata))
}

/// One image for the encoder: its size, samples, predictor and GeoTIFF tags.
struct Image<'a, T> {
    size: (u32, u32),
    data: &'a [T],
    predictor: Predictor,
    tags: &'a GeoTags,
}

fn encode<C>(
    size: (u32, u32),
    data: &[C::Inner],
    predictor: Predictor,
    tags: &GeoTags,
) -> Result<Vec<u8>>
where
    C: ColorType,
    [C::Inner]: TiffValue,
{
    let image = Image {
        size,
        data,
        predictor,
        tags,
    };
    let raw = (data.len() as u64).saturating_mul(u64::from(<C::Inner as TiffValue>::BYTE_LEN));
    if raw > BIGTIFF_THRESHOLD {
        encode_kind::<C, TiffKindBig>(&image)
    } else {
        encode_kind::<C, TiffKindStandard>(&image)
    }
}

fn encode_kind<C, K>(image: &Image<'_, C::Inner>) -> Result<Vec<u8>>
where
    C: ColorType,
    [C::Inner]: TiffValue,
    K: TiffKind,
{
    let (width, height) = image.size;
    let row_bytes = u64::from(width) * u64::from(<C::Inner as TiffValue>::BYTE_LEN);
    let rows_per_strip = (STRIP_BYTES / row_bytes).clamp(1, u64::from(height)) as u32;
    let mut out = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::<_, K>::new_generic(&mut out)
            .map_err(enc_err)?
            .with_compression(Compression::Deflate(DeflateLevel::Balanced))
            .with_predictor(image.predictor);
        let mut strips = enc.new_image::<C>(width, height).map_err(enc_err)?;
        strips.rows_per_strip(rows_per_strip).map_err(enc_err)?;
        write_geo_tags(strips.encoder(), image.tags)?;
        // `write_data` (not `write_strip`) is what switches the compressor on.
        strips.write_data(image.data).map_err(enc_err)?;
    }
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::read;
    use crate::model::ValueMapping;
    use crate::testutil::{Rng, with_holes};
    use tiff::decoder::Decoder;
    use tiff::tags::Tag;

    #[test]
    fn corpus_round_trip_is_identical() {
        for_each_corpus_tif(|_, name, _, a| {
            let bytes = write(&a).unwrap_or_else(|e| panic!("{name}: {e}"));
            let b = read(&bytes, &opts()).unwrap();
            assert_same(&a, &b, name);
            // And once more: the writer is stable.
            assert_eq!(write(&b).unwrap(), bytes, "{name}: second write");
        });
    }

    #[test]
    fn corpus_written_tags_read_back_raw() {
        for_each_corpus_tif(|_, name, src, r| {
            let out = write(&r).unwrap();
            let g = r.georef.as_ref().unwrap();

            let f64s = |b: &[u8], t: Tag| raw_tag(b, t).unwrap().into_f64_vec().unwrap();
            let src_scale = f64s(src, Tag::ModelPixelScaleTag);
            let out_scale = f64s(&out, Tag::ModelPixelScaleTag);
            assert_eq!(out_scale, vec![src_scale[0], src_scale[1], 0.0], "{name}");
            let src_tie = f64s(src, Tag::ModelTiepointTag);
            let out_tie = f64s(&out, Tag::ModelTiepointTag);
            assert_eq!(
                out_tie,
                vec![
                    0.0,
                    0.0,
                    0.0,
                    src_tie[3] - src_tie[0] * src_scale[0],
                    src_tie[4] + src_tie[1] * src_scale[1],
                    0.0
                ],
                "{name}"
            );
            assert_eq!(out_tie[3..5], g.origin, "{name}");

            let shorts = |b: &[u8], t: Tag| raw_tag(b, t).map(|v| v.into_u16_vec().unwrap());
            assert_eq!(
                shorts(&out, Tag::GeoKeyDirectoryTag),
                shorts(src, Tag::GeoKeyDirectoryTag),
                "{name}: GeoKeyDirectory"
            );
            let doubles =
                |b: &[u8]| raw_tag(b, Tag::GeoDoubleParamsTag).map(|v| v.into_f64_vec().unwrap());
            assert_eq!(doubles(&out), doubles(src), "{name}: GeoDoubleParams");
            let ascii =
                |b: &[u8]| raw_tag(b, Tag::GeoAsciiParamsTag).map(|v| v.into_string().unwrap());
            assert_eq!(ascii(&out), ascii(src), "{name}: GeoAsciiParams");

            let nodata = raw_tag(&out, Tag::GdalNodata)
                .unwrap()
                .into_string()
                .unwrap();
            let parsed: f64 = nodata.trim().parse().unwrap();
            assert_eq!(Some(parsed), r.nodata, "{name}: GDAL_NODATA '{nodata}'");

            // Layout: Deflate, predictor 2 for integers, none for floats.
            let mut d = Decoder::new(Cursor::new(&out[..])).unwrap();
            assert_eq!(d.get_tag_u32(Tag::Compression).unwrap(), 8);
            let pred = d.get_tag_u32(Tag::Predictor).unwrap();
            assert_eq!(
                pred,
                if r.sample_type.is_integer() { 2 } else { 1 },
                "{name}"
            );
        });
    }

    #[test]
    fn gdal_metadata_is_read_and_written_back_verbatim() {
        // The corpus GeoTIFF (written by GDAL) carries one dataset item.
        for_each_corpus_tif(|_, name, src, r| {
            let raw = raw_tag(src, Tag::Unknown(42112)).map(|v| v.into_string().unwrap());
            assert_eq!(r.gdal_metadata, raw, "{name}");
            let out = write(&r).unwrap();
            let back = raw_tag(&out, Tag::Unknown(42112)).map(|v| v.into_string().unwrap());
            assert_eq!(back, raw, "{name}: written back");
        });
        if let Some(dir) = crate::testutil::corpus() {
            let src = std::fs::read(dir.join("srtm30m_bigtujunga_utm11.tif")).unwrap();
            let r = read(&src, &opts()).unwrap();
            assert_eq!(
                r.gdal_metadata.as_deref(),
                Some("<GDALMetadata>\n  <Item name=\"DataType\">Generic</Item>\n</GDALMetadata>\n")
            );
        }
        // Non-ASCII UTF-8 and XML entities survive; none written when there is none.
        let mut r = small_i16_raster();
        let xml = "<GDALMetadata>\n  <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">Höhe &amp; Tiefe</Item>\n</GDALMetadata>\n";
        r.gdal_metadata = Some(xml.into());
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.gdal_metadata.as_deref(), Some(xml));
        r.gdal_metadata = None;
        assert!(raw_tag(&write(&r).unwrap(), Tag::Unknown(42112)).is_none());
        // A NUL cannot be stored in a TIFF ASCII tag: a clear error, not a cut string.
        r.gdal_metadata = Some("a\0b".into());
        let e = write(&r).unwrap_err();
        assert!(e.to_string().contains("42112"), "{e}");
    }

    // ----- synthetic round trips ----------------------------------------------------------

    #[test]
    fn nan_holes_without_georef_round_trip() {
        for st in [SampleType::F32, SampleType::F64] {
            let (w, h) = (31, 9);
            let data = with_holes(w * h, 7, 3, |i| i as f64 * 0.25 - 3.0);
            let r = Raster::from_values(w, h, data, None, st).unwrap();
            assert!(r.mask.is_some());
            let bytes = write(&r).unwrap();
            let back = read(&bytes, &opts()).unwrap();
            assert_same(&r, &back, st.name());
            assert_eq!(back.georef, None);
            // GDAL is told that NaN is nodata.
            let nd = raw_tag(&bytes, Tag::GdalNodata)
                .unwrap()
                .into_string()
                .unwrap();
            assert_eq!(nd, "nan");
        }
    }

    #[test]
    fn every_sample_type_round_trips() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let cases: [(SampleType, f64, f64, Option<f64>); 6] = [
            (SampleType::U8, 0.0, 255.0, Some(0.0)),
            (SampleType::I16, -32768.0, 32767.0, Some(-32768.0)),
            (SampleType::U16, 0.0, 65535.0, None),
            (SampleType::I32, -2147483648.0, 2147483647.0, Some(-9999.0)),
            (SampleType::F32, -1e6, 1e6, Some(-3.3999999521443642e38)),
            (SampleType::F64, -1e6, 1e6, Some(-1e300)),
        ];
        for (st, lo, hi, nodata) in cases {
            for (w, h) in [(1, 1), (3, 2), (257, 130), (1, 300), (4000, 3)] {
                let data: Vec<f64> = (0..w * h)
                    .map(|_| {
                        let hole = rng.below(10) == 0;
                        if let (Some(nd), true) = (nodata, hole) {
                            return nd;
                        }
                        let u = rng.next() as f64 / u64::MAX as f64;
                        let v = lo + (hi - lo) * u;
                        match st {
                            SampleType::F32 => f64::from(v as f32),
                            SampleType::F64 => v,
                            // + 0.0: an integer sample has no negative zero.
                            _ => v.round().clamp(lo, hi) + 0.0,
                        }
                    })
                    .collect();
                let mut r = Raster::from_values(w, h, data, nodata, st).unwrap();
                r.georef = Some(small_georef(Some(4326)));
                let back = read(&write(&r).unwrap(), &opts()).unwrap();
                assert_eq!(back.sample_type, st);
                assert_eq!(back.data.len(), r.data.len());
                // The synthesised GeoKeys are new, everything else is identical.
                let g = back.georef.clone().unwrap();
                assert_eq!(g.epsg, Some(4326));
                assert_eq!(
                    g.geokeys.as_ref().unwrap().directory,
                    vec![1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326]
                );
                let mut expect = r.clone();
                expect.georef.as_mut().unwrap().geokeys = g.geokeys.clone();
                assert_same(&expect, &back, &format!("{} {w}x{h}", st.name()));
            }
        }
    }

    #[test]
    fn integer_values_are_rounded_and_range_checked() {
        let r =
            Raster::from_values(4, 1, vec![1.4, 2.6, -3.5, 7.0], None, SampleType::I16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.data, vec![1.0, 3.0, -4.0, 7.0]);

        let r = Raster::from_values(3, 1, vec![1.0, 40000.0, 2.0], None, SampleType::I16).unwrap();
        let e = write(&r).unwrap_err();
        assert!(matches!(e, Error::InvalidArgument { .. }), "{e}");
        assert!(e.to_string().contains("40000"), "{e}");

        let r = Raster::from_values(2, 1, vec![-1.0, 2.0], None, SampleType::U8).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));

        // A nodata value that the type cannot hold is an error only when it must be written.
        let r =
            Raster::from_values(2, 1, vec![1.0, -9999.0], Some(-9999.0), SampleType::U16).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
        let r = Raster::from_values(2, 1, vec![1.0, 2.0], Some(-9999.0), SampleType::U16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "unused out-of-range nodata");
    }

    #[test]
    fn integer_holes_without_nodata_get_a_type_extreme() {
        let data = vec![1.0, f64::NAN, 3.0, -32768.0];
        let r = Raster::from_values(2, 2, data, None, SampleType::I16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        // -32768 is used by a valid sample, so the maximum is used instead.
        assert_eq!(back.nodata, Some(32767.0));
        assert_eq!(back.mask, r.mask);
        assert_eq!(back.data, vec![1.0, 32767.0, 3.0, -32768.0]);

        let r = Raster::from_values(2, 1, vec![5.0, f64::NAN], None, SampleType::U16).unwrap();
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.nodata, Some(65535.0));
        assert_eq!(back.mask, Some(vec![true, false]));
    }

    #[test]
    fn mapped_integer_rasters_follow_the_output_type() {
        // A scale: the codes, with GDAL_METADATA's OFFSET and SCALE (kept items beside).
        let mut r =
            Raster::from_values(3, 1, vec![0.5, 1.25, -7.0], None, SampleType::U16).unwrap();
        r.mapping = ValueMapping {
            scale: 0.25,
            offset: -10.0,
        };
        r.gdal_metadata = Some(
            "<GDALMetadata>\n  <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item>\n</GDALMetadata>"
                .into(),
        );
        let tif = write(&r).unwrap();
        let back = read(&tif, &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::U16);
        assert_eq!(back.mapping, r.mapping);
        assert_eq!(back.data, r.data);
        assert_eq!(back.gdal_metadata, r.gdal_metadata);
        // The items GDAL reads.
        let xml = crate::formats::with_offset_scale(r.gdal_metadata.as_deref(), r.mapping);
        assert!(xml.contains("role=\"unittype\">m</Item>"), "{xml}");
        assert!(
            xml.contains("<Item name=\"OFFSET\" sample=\"0\" role=\"offset\">-10.0</Item>"),
            "{xml}"
        );
        assert!(
            xml.contains("<Item name=\"SCALE\" sample=\"0\" role=\"scale\">0.25</Item>"),
            "{xml}"
        );
        // An offset of -32768 over u16 codes: int16 values.
        let mut r =
            Raster::from_values(3, 1, vec![-37.0, 1486.0, 0.0], None, SampleType::U16).unwrap();
        r.mapping = ValueMapping {
            scale: 1.0,
            offset: -32768.0,
        };
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::I16);
        assert!(back.mapping.is_identity());
        assert_eq!(back.data, r.data);
        // A nodata value that is not a code: float values (float32 when exact).
        let mut r = Raster::from_values(
            3,
            1,
            vec![0.5, 1.25, -9999.1],
            Some(-9999.1),
            SampleType::U16,
        )
        .unwrap();
        r.mapping = ValueMapping {
            scale: 0.25,
            offset: -10.0,
        };
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.sample_type, SampleType::F64);
        assert_eq!(back.data, r.data);
    }

    #[test]
    fn written_file_structure() {
        let r = small_i16_raster();
        let bytes = write(&r).unwrap();
        let mut d = Decoder::new(Cursor::new(&bytes[..])).unwrap();
        assert_eq!(d.dimensions().unwrap(), (23, 17));
        assert_eq!(d.get_tag_u32(Tag::SamplesPerPixel).unwrap(), 1);
        assert_eq!(d.get_tag_u32(Tag::BitsPerSample).unwrap(), 16);
        assert_eq!(d.get_tag_u32(Tag::SampleFormat).unwrap(), 2);
        assert_eq!(d.get_tag_u32(Tag::Compression).unwrap(), 8);
        assert_eq!(d.get_tag_u32(Tag::Predictor).unwrap(), 2);
        assert_eq!(
            d.get_tag_ascii_string(Tag::GdalNodata).unwrap(),
            "-9999".to_string()
        );
        assert_eq!(
            d.get_tag_u16_vec(Tag::GeoKeyDirectoryTag).unwrap(),
            vec![1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32611]
        );
        assert!(d.find_tag(Tag::GeoDoubleParamsTag).unwrap().is_none());
        assert!(d.find_tag(Tag::GeoAsciiParamsTag).unwrap().is_none());
        let back = read(&bytes, &opts()).unwrap();
        assert_eq!(back.georef.as_ref().unwrap().epsg, Some(32611));
        assert_eq!(back.data, r.data);
        assert_eq!(back.mask, r.mask);
    }
}
