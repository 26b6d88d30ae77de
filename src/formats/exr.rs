//! OpenEXR height maps: one f32 channel ("Y"), NaN for nodata, vtz metadata in custom attributes.
//!
//! Written files hold a single f32 channel named `Y` (ZIP-compressed scan lines), invalid
//! samples as NaN, and the custom layer attributes `vtz_nodata` (f64: the declared nodata
//! value) and `vtz_georef` (text: the georef as the shared sidecar json object, see
//! [`crate::formats::sidecar`]) when the raster has them. The header's attributes are in name
//! order, so the bytes are the same on every run. GDAL reads neither attribute: the writer
//! of the file set (`formats::encode_path`) adds a PAM `NAME.exr.aux.xml` for it.
//!
//! Reading takes the only channel of a single-part flat image, or the first channel named
//! `height`, `elevation`, `Z`, `Y` or `R` (case-insensitive) when there are several. f32 and
//! f16 channels give [`SampleType::F32`]; u32 channels give [`SampleType::I32`] (or
//! [`SampleType::F64`] when a value exceeds i32).

use crate::error::{Error, Result};
use crate::formats::ReadOptions;
use crate::formats::samples::f32_samples;
use crate::formats::sidecar::GeorefJson;
use crate::model::{Raster, SampleType, check_size};
use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Image, Layer, LayerAttributes,
    MetaData, ReadChannels, ReadLayers, SmallVec, Text, Vec2, WritableImage,
};
use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// Channel name written by [`write()`].
pub const CHANNEL: &str = "Y";
/// Custom attribute holding the declared nodata value (f64).
pub const ATTR_NODATA: &str = "vtz_nodata";
/// Custom attribute holding the georef json (text).
pub const ATTR_GEOREF: &str = "vtz_georef";

/// Channel names taken as the height, in order of preference, when there are several.
const HEIGHT_NAMES: [&str; 5] = ["height", "elevation", "z", "y", "r"];

fn exr_error(e: exr::error::Error) -> Error {
    match e {
        exr::error::Error::NotSupported(m) => Error::unsupported(format!("EXR: {m}")),
        other => Error::corrupt(format!("EXR: {other}")),
    }
}

/// Run a decoding step of the exr crate, turning a panic on hostile input into an error.
fn guarded<T>(f: impl FnOnce() -> exr::error::Result<T>) -> Result<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(exr_error),
        Err(_) => Err(Error::corrupt("EXR: the decoder failed on malformed data")),
    }
}

/// Read a single-channel OpenEXR height map.
pub fn read(bytes: &[u8], opts: &ReadOptions) -> Result<Raster> {
    let meta = guarded(|| MetaData::read_from_buffered(Cursor::new(bytes), false))?;
    if meta.headers.len() != 1 {
        return Err(Error::unsupported(format!(
            "EXR with {} parts (vtz reads single-part images)",
            meta.headers.len()
        )));
    }
    let header = &meta.headers[0];
    if header.deep {
        return Err(Error::unsupported("deep-data EXR"));
    }
    let names: Vec<String> = header
        .channels
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    let chosen = if names.len() == 1 {
        0
    } else {
        HEIGHT_NAMES
            .iter()
            .find_map(|h| names.iter().position(|n| n.eq_ignore_ascii_case(h)))
            .ok_or_else(|| {
                Error::unsupported(format!(
                    "EXR channels [{}] include no height channel (height, elevation, Z, Y or R)",
                    names.join(", ")
                ))
            })?
    };
    let channel_name = names[chosen].clone();
    let desc = &header.channels.list[chosen];
    if desc.sampling != Vec2(1, 1) {
        return Err(Error::unsupported(format!(
            "EXR channel {channel_name} is subsampled ({}x{})",
            desc.sampling.0, desc.sampling.1
        )));
    }
    let (w, h) = (header.layer_size.0 as u64, header.layer_size.1 as u64);
    let n = check_size(w, h, opts.max_samples())?;
    // All channels are decoded: bound their total too.
    let total = (names.len() as u64).saturating_mul(n as u64);
    if total > opts.max_samples().saturating_mul(4) {
        return Err(Error::limit(format!(
            "EXR of {w}x{h} with {} channels is over the sample limit",
            names.len()
        )));
    }
    let (width, height) = (w as usize, h as usize);

    let image = guarded(|| {
        exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(Cursor::new(bytes))
    })?;
    let layer = &image.layer_data;
    if layer.size != Vec2(width, height) {
        return Err(Error::corrupt("EXR layer size disagrees with its header"));
    }
    let channel = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == channel_name)
        .ok_or_else(|| Error::corrupt(format!("EXR channel {channel_name} was not decoded")))?;
    let (data, sample_type): (Vec<f64>, SampleType) = match &channel.sample_data {
        FlatSamples::F32(v) => (v.iter().map(|&x| x as f64).collect(), SampleType::F32),
        FlatSamples::F16(v) => (
            v.iter().map(|&x| x.to_f32() as f64).collect(),
            SampleType::F32,
        ),
        FlatSamples::U32(v) => {
            let t = if v.iter().all(|&x| x <= i32::MAX as u32) {
                SampleType::I32
            } else {
                SampleType::F64
            };
            (v.iter().map(|&x| x as f64).collect(), t)
        }
    };
    if data.len() != n {
        return Err(Error::corrupt(format!(
            "EXR channel {channel_name} has {} samples, {width}x{height} needs {n}",
            data.len()
        )));
    }
    let attrs = &layer.attributes.other;
    let nodata = match attrs.get(&Text::from(ATTR_NODATA)) {
        None => None,
        Some(AttributeValue::F64(v)) if !v.is_nan() => Some(*v),
        Some(AttributeValue::F32(v)) if !v.is_nan() => Some(*v as f64),
        Some(other) => {
            return Err(Error::corrupt(format!(
                "EXR attribute {ATTR_NODATA} is not a number: {other:?}"
            )));
        }
    };
    let georef = match attrs.get(&Text::from(ATTR_GEOREF)) {
        None => None,
        Some(AttributeValue::Text(t)) => {
            let g: GeorefJson = serde_json::from_slice(t.bytes())
                .map_err(|e| Error::corrupt(format!("EXR attribute {ATTR_GEOREF}: {e}")))?;
            Some(g.into())
        }
        Some(_) => {
            return Err(Error::corrupt(format!(
                "EXR attribute {ATTR_GEOREF} is not text"
            )));
        }
    };
    if let Some(i) = data
        .iter()
        .position(|v| v.is_infinite() && Some(*v) != nodata)
    {
        return Err(Error::corrupt(format!(
            "EXR sample {i} (row {}, col {}) is infinite",
            i / width,
            i % width
        )));
    }
    let mut r = Raster::from_values(width, height, data, nodata, sample_type)?;
    r.georef = georef;
    Ok(r)
}

/// Write a raster as a single-channel f32 OpenEXR image (invalid samples as NaN).
pub fn write(r: &Raster) -> Result<Vec<u8>> {
    let samples = f32_samples(r, f32::NAN)?;
    let mut attrs = LayerAttributes::default();
    if let Some(nd) = r.nodata {
        attrs
            .other
            .insert(Text::from(ATTR_NODATA), AttributeValue::F64(nd));
    }
    if let Some(g) = &r.georef {
        let json = serde_json::to_string(&GeorefJson::from(g))
            .map_err(|e| Error::invalid(format!("cannot encode the georef as json: {e}")))?;
        let text = Text::new_or_none(&json).ok_or_else(|| {
            Error::invalid(
                "the georef (WKT or GeoKeys text) has characters an EXR text attribute cannot hold",
            )
        })?;
        attrs
            .other
            .insert(Text::from(ATTR_GEOREF), AttributeValue::Text(text));
    }
    let channel = AnyChannel::new(CHANNEL, FlatSamples::F32(samples));
    let layer = Layer::new(
        (r.width, r.height),
        attrs,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let mut out = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .map_err(|e| Error::invalid(format!("EXR encoding failed: {e}")))?;
    let mut bytes = out.into_inner();
    sort_header_attributes(&mut bytes)?;
    Ok(bytes)
}

/// Put the header's attributes in name order, so the same raster gives the same bytes.
///
/// The exr crate keeps custom attributes (`vtz_nodata`, `vtz_georef`) in a `HashMap` with a
/// random seed and writes them in its iteration order, which changes from run to run. EXR
/// readers take a header's attributes in any order, and sorting them in place keeps the
/// header's length, so the offset table and the chunks after it stay valid as written.
fn sort_header_attributes(bytes: &mut [u8]) -> Result<()> {
    let bad = || Error::invalid("EXR encoding produced a header vtz cannot parse");
    // Magic and version field; a multi-part file would have several headers.
    let flags = u32::from_le_bytes(
        bytes
            .get(4..8)
            .ok_or_else(bad)?
            .try_into()
            .map_err(|_| bad())?,
    );
    if flags & 0x1000 != 0 {
        return Err(bad());
    }
    let nul = |from: usize| -> Result<usize> {
        let rel = bytes
            .get(from..)
            .ok_or_else(bad)?
            .iter()
            .position(|&b| b == 0);
        rel.map(|r| from + r).ok_or_else(bad)
    };
    let start = 8;
    let mut pos = start;
    let mut spans = Vec::new();
    while *bytes.get(pos).ok_or_else(bad)? != 0 {
        let name_end = nul(pos)?;
        let type_end = nul(name_end + 1)?;
        let size = bytes.get(type_end + 1..type_end + 5).ok_or_else(bad)?;
        let size = i32::from_le_bytes(size.try_into().map_err(|_| bad())?);
        let size = usize::try_from(size).map_err(|_| bad())?;
        let end = type_end + 5 + size;
        if end > bytes.len() {
            return Err(bad());
        }
        spans.push((pos, name_end, end));
        pos = end;
    }
    let mut sorted: Vec<(usize, usize, usize)> = spans.clone();
    sorted.sort_by(|a, b| bytes[a.0..a.1].cmp(&bytes[b.0..b.1]));
    let attrs: Vec<u8> = sorted
        .iter()
        .flat_map(|&(a, _, e)| bytes[a..e].iter().copied())
        .collect();
    bytes[start..pos].copy_from_slice(&attrs);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{GeoKeys, Georef, RasterType};
    use crate::testutil::*;
    use exr::prelude::f16;

    fn opts() -> ReadOptions {
        ReadOptions::default()
    }

    fn random_raster(seed: u64, w: usize, h: usize, nodata: Option<f64>) -> Raster {
        let mut rng = Rng(seed);
        let data: Vec<f64> = (0..w * h)
            .map(|_| {
                let u = rng.next();
                if u % 9 == 0 {
                    f64::NAN
                } else {
                    ((u >> 20) as i32 as f32 / 1024.0) as f64
                }
            })
            .collect();
        Raster::from_values(w, h, data, nodata, SampleType::F32).unwrap()
    }

    fn write_channels(w: usize, h: usize, chans: Vec<AnyChannel<FlatSamples>>) -> Vec<u8> {
        let layer = Layer::new(
            (w, h),
            LayerAttributes::default(),
            Encoding::UNCOMPRESSED,
            AnyChannels::sort(SmallVec::from_vec(chans)),
        );
        let mut out = Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .to_buffered(&mut out)
            .unwrap();
        out.into_inner()
    }

    #[test]
    fn random_roundtrip_with_holes() {
        for (seed, nodata) in [(1, None), (2, Some(-9999.0)), (3, Some(-3.4e38))] {
            let mut r = random_raster(seed, 37, 23, nodata);
            if seed == 2 {
                r.georef = Some(Georef {
                    origin: [0.1 + 0.2, -1.0 / 3.0],
                    pixel_size: [1.0 / 3600.0, 2.5],
                    raster_type: RasterType::Point,
                    epsg: Some(4326),
                    wkt: Some("GEOGCS[\"WGS 84\"]".into()),
                    geokeys: Some(GeoKeys {
                        directory: vec![1, 1, 0, 0],
                        doubles: vec![0.1 + 0.7],
                        ascii: "x|".into(),
                    }),
                });
            }
            assert!(r.valid_count() < r.len());
            let b = write(&r).unwrap();
            let back = read(&b, &opts()).unwrap();
            assert_same(&r, &back, "exr round trip");
            assert_same(
                &back,
                &read(&write(&back).unwrap(), &opts()).unwrap(),
                "exr round trip",
            );
        }
    }

    #[test]
    fn channel_choice_and_types() {
        let (w, h) = (3, 2);
        // A single f16 channel with any name.
        let halfs: Vec<f16> = [1.5f32, -2.0, f32::NAN, 4.0, 0.25, 6.0]
            .iter()
            .map(|&x| f16::from_f32(x))
            .collect();
        let b = write_channels(
            w,
            h,
            vec![AnyChannel::new("depth", FlatSamples::F16(halfs))],
        );
        let r = read(&b, &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::F32);
        assert_eq!(r.data[4], 0.25);
        assert!(!r.is_valid(2));
        // Several channels: Z wins over R, G, B.
        let ch = |n: &str, v: f32| AnyChannel::new(n, FlatSamples::F32(vec![v; w * h]));
        let b = write_channels(
            w,
            h,
            vec![ch("R", 1.0), ch("G", 2.0), ch("B", 3.0), ch("Z", 4.0)],
        );
        assert_eq!(read(&b, &opts()).unwrap().data, [4.0; 6]);
        let b = write_channels(w, h, vec![ch("G", 2.0), ch("B", 3.0)]);
        match read(&b, &opts()) {
            Err(Error::Unsupported { what }) => assert!(what.contains("B, G"), "{what}"),
            other => panic!("{other:?}"),
        }
        // u32 channels
        let b = write_channels(
            w,
            h,
            vec![AnyChannel::new("Y", FlatSamples::U32(vec![7; w * h]))],
        );
        let r = read(&b, &opts()).unwrap();
        assert_eq!(r.sample_type, SampleType::I32);
        assert_eq!(r.data, [7.0; 6]);
    }

    #[test]
    fn output_bytes_are_the_same_every_time() {
        let mut r = random_raster(9, 13, 7, Some(-9999.0));
        r.georef = Some(utm11_georef());
        // Each write builds a new HashMap with a new random seed: with two custom attributes,
        // 24 equal writes by chance would be a 2^-23 event.
        let first = write(&r).unwrap();
        for _ in 0..24 {
            assert!(
                write(&r).unwrap() == first,
                "EXR bytes differ between writes"
            );
        }
        assert_same(
            &r,
            &read(&first, &opts()).unwrap(),
            "sorted header reads back",
        );
        // The attribute names, as stored, are in order.
        let mut names = Vec::new();
        let mut pos = 8;
        while first[pos] != 0 {
            let n = first[pos..].iter().position(|&b| b == 0).unwrap();
            let t = first[pos + n + 1..].iter().position(|&b| b == 0).unwrap();
            let at = pos + n + 1 + t + 1;
            let size = i32::from_le_bytes(first[at..at + 4].try_into().unwrap()) as usize;
            names.push(String::from_utf8(first[pos..pos + n].to_vec()).unwrap());
            pos = at + 4 + size;
        }
        assert!(
            names.contains(&ATTR_NODATA.to_string()) && names.contains(&ATTR_GEOREF.to_string())
        );
        let mut sorted = names.clone();
        sorted.sort();
        assert_eq!(names, sorted);
    }

    #[test]
    fn write_rejects_out_of_f32_range() {
        let r = Raster::from_values(1, 1, vec![1e300], None, SampleType::F64).unwrap();
        assert!(matches!(write(&r), Err(Error::InvalidArgument { .. })));
    }

    #[test]
    fn garbage_and_limits() {
        let r = random_raster(5, 5, 4, None);
        let b = write(&r).unwrap();
        for cut in 0..b.len() {
            assert!(read(&b[..cut], &opts()).is_err(), "cut {cut}");
        }
        let mut rng = Rng(77);
        for len in [0, 4, 8, 50, 300, 3000] {
            assert!(read(&rng.bytes(len), &opts()).is_err());
        }
        let mut magic = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
        magic.extend(rng.bytes(500));
        assert!(read(&magic, &opts()).is_err());
        for k in 0..300 {
            let mut c = b.clone();
            let i = (rng.next() as usize) % c.len();
            c[i] ^= 1 << (k % 8);
            let _ = read(&c, &opts());
        }
        let small = ReadOptions {
            max_samples: Some(10),
            ..Default::default()
        };
        assert!(matches!(read(&b, &small), Err(Error::LimitExceeded { .. })));
    }

    #[test]
    fn corpus_rasters() {
        let names = [
            "scape_crater",
            "terra_elev_vinschgau",
            "ahn3_delft_dsm_50cm",
        ];
        for_each_corpus(&names, |dir, name| {
            let mut r = load_raw(dir, name);
            // EXR stores f32 samples: the read-back type is F32.
            r.sample_type = SampleType::F32;
            let back = read(&write(&r).unwrap(), &opts()).unwrap();
            assert_same(&r, &back, "exr round trip");
            assert_eq!(raster_bits(&back), raw_bits(dir, name), "{name}");
            assert_same(
                &back,
                &read(&write(&back).unwrap(), &opts()).unwrap(),
                "exr round trip",
            );
        });
    }
}
