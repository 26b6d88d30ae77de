//! Reading: the pre-checked decode into a [`Raster`].

use super::georef::read_georef;
use super::nodata::read_nodata;
use super::precheck::precheck;
use super::tags::{tag_string, tiff_err};
use super::{TAG_GDAL_METADATA, mask};
use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::model::{Raster, SampleType};
use std::io::Cursor;
use tiff::decoder::{Decoder, DecodingResult, Limits};

/// Read a single-band GeoTIFF into a [`Raster`] (values exact as `f64`, nodata and NaN samples
/// and those its internal mask band masks marked invalid, georeferencing from the GeoTIFF
/// tags).
pub fn read(bytes: &[u8], opts: &ReadOptions) -> Result<Raster> {
    let layout = precheck(bytes, opts)?;

    let mut limits = Limits::default();
    let image_bytes = (layout.samples as u64).saturating_mul(layout.sample_type.bits() as u64 / 8);
    limits.decoding_buffer_size = usize::try_from(image_bytes)
        .unwrap_or(usize::MAX)
        .max(Limits::default().decoding_buffer_size);
    // Chunk byte counts were checked against the file length, so the file length is a safe
    // bound for one compressed chunk (the default of 128 MiB would refuse large single-strip
    // files).
    limits.intermediate_buffer_size = bytes.len().max(Limits::default().intermediate_buffer_size);

    let mut dec = Decoder::new(Cursor::new(bytes))
        .map_err(tiff_err)?
        .with_limits(limits);
    let (w, h) = dec.dimensions().map_err(tiff_err)?;
    if (w as usize, h as usize) != (layout.width, layout.height) {
        return Err(Error::corrupt("GeoTIFF image size disagrees with its tags"));
    }

    let decoded = dec.read_image().map_err(tiff_err)?;
    let st = layout.sample_type;
    let mut data: Vec<f64> = match (decoded, st) {
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
    };
    if data.len() != layout.samples {
        return Err(Error::corrupt(format!(
            "GeoTIFF decoded to {} samples, expected {}",
            data.len(),
            layout.samples
        )));
    }

    // Samples the internal mask band masks are nodata (NaN here, invalid below).
    let mut src = mask::InMemory(bytes);
    if let Some(m) = mask::find(&mut src, layout.width, layout.height)? {
        let valid = m.rows(&mut src, 0, layout.height)?;
        for (v, ok) in data.iter_mut().zip(valid) {
            if !ok {
                *v = f64::NAN;
            }
        }
    }

    let georef = read_georef(&mut dec)?;
    let nodata = read_nodata(&mut dec, st)?;
    let gdal_metadata = tag_string(&mut dec, TAG_GDAL_METADATA)?;

    let mut raster = Raster::from_values(layout.width, layout.height, data, nodata, st).map_err(
        |e| match e {
            Error::InvalidArgument { what } => Error::unsupported(format!(
                "GeoTIFF {what} (only finite values or nodata are supported)"
            )),
            other => other,
        },
    )?;
    raster.georef = georef;
    raster.gdal_metadata = gdal_metadata;
    // GDAL's scale/offset of integer codes: the values GDAL shows are vtz's values.
    crate::formats::apply_gdal_mapping(&mut raster);
    Ok(raster)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::{
        TAG_PREDICTOR, TAG_ROWS_PER_STRIP, TAG_STRIP_BYTE_COUNTS, TAG_STRIP_OFFSETS,
        TAG_TILE_BYTE_COUNTS, TAG_TILE_LENGTH, TAG_TILE_OFFSETS, TAG_TILE_WIDTH,
    };
    use crate::model::RasterType;
    use crate::testutil::corpus;
    use tiff::encoder::colortype::GrayI32;
    use tiff::encoder::{Compression, Predictor, TiffEncoder};

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
        let mut out = Cursor::new(Vec::new());
        {
            let mut enc = TiffEncoder::new(&mut out)
                .unwrap()
                .with_compression(Compression::Lzw)
                .with_predictor(Predictor::Horizontal);
            let mut img = enc.new_image::<GrayI32>(w, h).unwrap();
            img.rows_per_strip(4).unwrap();
            img.write_data(&vals).unwrap();
        }
        let r = read(out.get_ref(), &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::I32);
        assert_eq!(
            r.data,
            vals.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()
        );

        // Hand-made tiles (2x2 tiles of 4x4 over a 6x5 image, uncompressed).
        let (w, h, t) = (6usize, 5usize, 4usize);
        let value = |x: usize, y: usize| (y * 10 + x) as i16;
        let mut data = Vec::new();
        let mut offsets = Vec::new();
        for ty in 0..2 {
            for tx in 0..2 {
                offsets.push(8 + data.len() as u32);
                for y in 0..t {
                    for x in 0..t {
                        let (gx, gy) = (tx * t + x, ty * t + y);
                        let v = if gx < w && gy < h { value(gx, gy) } else { 0 };
                        data.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
        }
        let mut b = Builder::basic(true, w as u32, h as u32, 16, 2, 0);
        b.remove(TAG_STRIP_OFFSETS)
            .remove(TAG_STRIP_BYTE_COUNTS)
            .remove(TAG_ROWS_PER_STRIP)
            .long(TAG_TILE_WIDTH, &[t as u32])
            .long(TAG_TILE_LENGTH, &[t as u32])
            .long(TAG_TILE_OFFSETS, &offsets)
            .long(TAG_TILE_BYTE_COUNTS, &[32; 4]);
        let r = read(&b.build(&data), &opts()).unwrap();
        let want: Vec<f64> = (0..w * h).map(|i| f64::from(value(i % w, i / w))).collect();
        assert_eq!(r.data, want);
    }
}
