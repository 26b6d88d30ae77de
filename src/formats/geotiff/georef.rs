//! The georeferencing tags ↔ [`Georef`]: pixel scale, tiepoint, transformation, GeoKeys; both ways.

use super::nodata::format_nodata;
use super::tags::{enc_err, tag_string, tiff_err, write_ascii};
use super::{
    TAG_GDAL_METADATA, TAG_GEO_ASCII_PARAMS, TAG_GEO_DOUBLE_PARAMS, TAG_MODEL_PIXEL_SCALE,
    TAG_MODEL_TIEPOINT, TAG_MODEL_TRANSFORMATION,
};
use crate::error::{Error, Result};
use crate::model::{GeoKeys, Georef, RasterType};
use std::io::{Read, Seek, Write};
use tiff::decoder::{Decoder, ifd::Value};
use tiff::encoder::{DirectoryEncoder, TiffKind};
use tiff::tags::Tag;

// GeoKeys.
const KEY_MODEL_TYPE: u16 = 1024;
const KEY_RASTER_TYPE: u16 = 1025;
const KEY_GEOGRAPHIC_TYPE: u16 = 2048;
const KEY_PROJECTED_CS_TYPE: u16 = 3072;
const MODEL_TYPE_PROJECTED: u16 = 1;
const MODEL_TYPE_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_AREA: u16 = 1;
const RASTER_PIXEL_IS_POINT: u16 = 2;
const KEY_USER_DEFINED: u16 = 32767;

fn scalar_f64(v: Value) -> Option<f64> {
    Some(match v {
        Value::Double(x) => x,
        Value::Float(x) => f64::from(x),
        Value::Byte(x) => f64::from(x),
        Value::Short(x) => f64::from(x),
        Value::SignedShort(x) => f64::from(x),
        Value::Unsigned(x) => f64::from(x),
        Value::Signed(x) => f64::from(x),
        _ => return None,
    })
}

/// A numeric tag as doubles (GeoTIFF tags are DOUBLE; FLOAT and integers are accepted too).
fn tag_f64s<R: Read + Seek>(dec: &mut Decoder<R>, tag: u16) -> Result<Option<Vec<f64>>> {
    let Some(v) = dec
        .find_tag(Tag::from_u16_exhaustive(tag))
        .map_err(tiff_err)?
    else {
        return Ok(None);
    };
    let bad = || Error::corrupt(format!("GeoTIFF tag {tag} does not hold numbers"));
    let out = match v {
        Value::List(l) => l
            .into_iter()
            .map(scalar_f64)
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(bad)?,
        other => vec![scalar_f64(other).ok_or_else(bad)?],
    };
    if out.iter().any(|x| !x.is_finite()) {
        return Err(Error::corrupt(format!(
            "GeoTIFF tag {tag} holds a non-finite number"
        )));
    }
    Ok(Some(out))
}

/// Value of a GeoKey stored directly in the directory (TIFFTagLocation 0).
fn geokey_short(dir: &[u16], key: u16) -> Option<u16> {
    let n = usize::from(*dir.get(3)?);
    dir.get(4..)?
        .chunks_exact(4)
        .take(n)
        .find(|k| k[0] == key && k[1] == 0)
        .map(|k| k[3])
}

pub(super) fn read_georef<R: Read + Seek>(dec: &mut Decoder<R>) -> Result<Option<Georef>> {
    let scale = tag_f64s(dec, TAG_MODEL_PIXEL_SCALE)?;
    let tie = tag_f64s(dec, TAG_MODEL_TIEPOINT)?;
    let transform = tag_f64s(dec, TAG_MODEL_TRANSFORMATION)?;
    let directory = match dec.find_tag(Tag::GeoKeyDirectoryTag).map_err(tiff_err)? {
        None => None,
        Some(v) => Some(
            v.into_u16_vec()
                .map_err(|_| Error::corrupt("GeoTIFF GeoKeyDirectoryTag does not hold shorts"))?,
        ),
    };
    let geokeys = match directory {
        None => None,
        Some(directory) => {
            if directory.len() < 4 {
                return Err(Error::corrupt(format!(
                    "GeoTIFF GeoKeyDirectoryTag has {} values, fewer than its 4-value header",
                    directory.len()
                )));
            }
            let doubles = tag_f64s(dec, TAG_GEO_DOUBLE_PARAMS)?.unwrap_or_default();
            let ascii = tag_string(dec, TAG_GEO_ASCII_PARAMS)?.unwrap_or_default();
            Some(GeoKeys {
                directory,
                doubles,
                ascii,
            })
        }
    };

    let placement = match (&scale, &tie, &transform) {
        (Some(s), Some(t), _) => {
            if s.len() < 2 || t.len() < 6 {
                return Err(Error::corrupt(format!(
                    "GeoTIFF ModelPixelScale ({} values) or ModelTiepoint ({} values) is too short",
                    s.len(),
                    t.len()
                )));
            }
            // A negative ScaleY is read as GDAL reads it by default: as a north-up raster
            // (GDAL warns "negative value for ScaleY ... assumes the file was intended to be
            // north-up"); a south-up raster is stored with a ModelTransformation.
            let (sx, sy) = (s[0], s[1].abs());
            let (i, j, x, y) = (t[0], t[1], t[3], t[4]);
            Some(([x - i * sx, y + j * sy], [sx, sy]))
        }
        (None, None, Some(m)) | (Some(_), None, Some(m)) | (None, Some(_), Some(m)) => {
            if m.len() < 16 {
                return Err(Error::corrupt(format!(
                    "GeoTIFF ModelTransformation has {} values, expected 16",
                    m.len()
                )));
            }
            if m[1] != 0.0 || m[4] != 0.0 {
                return Err(Error::unsupported(
                    "GeoTIFF with a rotated or sheared ModelTransformation (only north-up \
                     rasters are supported)",
                ));
            }
            Some(([m[3], m[7]], [m[0], -m[5]]))
        }
        (None, Some(t), None) => {
            return Err(Error::unsupported(format!(
                "GeoTIFF georeferenced by {} tiepoint(s) without a pixel scale (ground control \
                 points are not supported)",
                t.len() / 6
            )));
        }
        (Some(_), None, None) => {
            return Err(Error::unsupported(
                "GeoTIFF with a ModelPixelScale but no ModelTiepoint",
            ));
        }
        (None, None, None) => None,
    };
    let (origin, pixel_size) = match (placement, &geokeys) {
        (Some(p), _) => p,
        (None, Some(_)) => ([0.0, 0.0], [1.0, 1.0]),
        (None, None) => return Ok(None),
    };

    let dir: &[u16] = geokeys.as_ref().map_or(&[], |k| &k.directory);
    let raster_type = match geokey_short(dir, KEY_RASTER_TYPE) {
        Some(RASTER_PIXEL_IS_POINT) => RasterType::Point,
        _ => RasterType::Area,
    };
    let usable = |v: u16| v != 0 && v != KEY_USER_DEFINED;
    let epsg = match geokey_short(dir, KEY_PROJECTED_CS_TYPE) {
        Some(v) => usable(v).then_some(u32::from(v)),
        None if geokey_short(dir, KEY_MODEL_TYPE) == Some(MODEL_TYPE_PROJECTED) => None,
        None => geokey_short(dir, KEY_GEOGRAPHIC_TYPE)
            .filter(|&v| usable(v))
            .map(u32::from),
    };
    Ok(Some(Georef {
        origin,
        pixel_size,
        raster_type,
        epsg,
        wkt: None,
        geokeys,
    }))
}

/// The GeoTIFF tags to write besides the image structure.
#[derive(Default)]
pub(super) struct GeoTags {
    pixel_scale: Option<[f64; 3]>,
    tiepoint: Option<[f64; 6]>,
    /// ModelTransformation, instead of the two above, for a raster that is not north-up.
    transformation: Option<[f64; 16]>,
    key_directory: Option<Vec<u16>>,
    key_doubles: Vec<f64>,
    key_ascii: String,
    /// GDAL_NODATA (NaN is written as "nan").
    pub(super) nodata: Option<f64>,
    /// GDAL_METADATA XML, verbatim.
    pub(super) gdal_metadata: Option<String>,
}

pub(super) fn geo_tags(georef: Option<&Georef>) -> Result<GeoTags> {
    let mut tags = GeoTags::default();
    let Some(g) = georef else {
        return Ok(tags);
    };
    if g.origin.iter().chain(&g.pixel_size).any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "georeferencing has a non-finite origin or pixel size",
        ));
    }
    let [dx, dy] = g.pixel_size;
    let [x0, y0] = g.origin;
    if dx > 0.0 && dy > 0.0 {
        tags.pixel_scale = Some([dx, dy, 0.0]);
        tags.tiepoint = Some([0.0, 0.0, 0.0, x0, y0, 0.0]);
    } else {
        // South-up (row 0 at the south: y grows with the row) or east-to-west: ModelPixelScale
        // cannot say so (GDAL reads a negative ScaleY as north-up), so the placement goes in a
        // ModelTransformation, as GDAL writes such a raster. Rows stay in the source's order.
        tags.transformation = Some([
            dx, 0.0, 0.0, x0, //
            0.0, -dy, 0.0, y0, //
            0.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        ]);
    }
    let raster_type = match g.raster_type {
        RasterType::Area => RASTER_PIXEL_IS_AREA,
        RasterType::Point => RASTER_PIXEL_IS_POINT,
    };
    match &g.geokeys {
        Some(k) => {
            let mut dir = k.directory.clone();
            set_raster_type_key(&mut dir, raster_type)?;
            tags.key_directory = Some(dir);
            tags.key_doubles = k.doubles.clone();
            tags.key_ascii = k.ascii.clone();
        }
        None => tags.key_directory = synth_geokeys(g.epsg, raster_type),
    }
    Ok(tags)
}

/// Make GTRasterTypeGeoKey in a verbatim directory agree with the raster type. A missing key
/// means PixelIsArea, so it is only added for PixelIsPoint.
fn set_raster_type_key(dir: &mut Vec<u16>, raster_type: u16) -> Result<()> {
    let bad = || Error::corrupt("the stored GeoKey directory is malformed");
    let n = usize::from(*dir.get(3).ok_or_else(bad)?);
    let keys_end = 4 + 4 * n;
    if dir.len() < keys_end {
        return Err(bad());
    }
    let mut insert_at = keys_end;
    for k in 0..n {
        let p = 4 + 4 * k;
        if dir[p] == KEY_RASTER_TYPE {
            dir[p + 1] = 0;
            dir[p + 2] = 1;
            dir[p + 3] = raster_type;
            return Ok(());
        }
        if dir[p] > KEY_RASTER_TYPE && insert_at == keys_end {
            insert_at = p;
        }
    }
    if raster_type == RASTER_PIXEL_IS_AREA {
        return Ok(());
    }
    dir[3] = u16::try_from(n + 1).map_err(|_| bad())?;
    dir.splice(insert_at..insert_at, [KEY_RASTER_TYPE, 0, 1, raster_type]);
    Ok(())
}

/// A minimal GeoKey directory for an EPSG code and raster type; None when there is nothing to
/// say (no EPSG code and PixelIsArea, the default).
fn synth_geokeys(epsg: Option<u32>, raster_type: u16) -> Option<Vec<u16>> {
    let code = epsg.and_then(|e| u16::try_from(e).ok());
    if code.is_none() && raster_type == RASTER_PIXEL_IS_AREA {
        return None;
    }
    let mut keys: Vec<[u16; 4]> = Vec::new();
    if let Some(code) = code {
        let geographic = (4000..5000).contains(&code);
        let model = if geographic {
            MODEL_TYPE_GEOGRAPHIC
        } else {
            MODEL_TYPE_PROJECTED
        };
        keys.push([KEY_MODEL_TYPE, 0, 1, model]);
        keys.push([KEY_RASTER_TYPE, 0, 1, raster_type]);
        let key = if geographic {
            KEY_GEOGRAPHIC_TYPE
        } else {
            KEY_PROJECTED_CS_TYPE
        };
        keys.push([key, 0, 1, code]);
    } else {
        keys.push([KEY_RASTER_TYPE, 0, 1, raster_type]);
    }
    let mut dir = vec![1, 1, 0, keys.len() as u16];
    dir.extend(keys.into_iter().flatten());
    Some(dir)
}

pub(super) fn write_geo_tags<W: Write + Seek, K: TiffKind>(
    e: &mut DirectoryEncoder<'_, W, K>,
    tags: &GeoTags,
) -> Result<()> {
    if let Some(s) = &tags.pixel_scale {
        e.write_tag(Tag::ModelPixelScaleTag, &s[..])
            .map_err(enc_err)?;
    }
    if let Some(t) = &tags.tiepoint {
        e.write_tag(Tag::ModelTiepointTag, &t[..])
            .map_err(enc_err)?;
    }
    if let Some(m) = &tags.transformation {
        e.write_tag(Tag::from_u16_exhaustive(TAG_MODEL_TRANSFORMATION), &m[..])
            .map_err(enc_err)?;
    }
    if let Some(d) = &tags.key_directory {
        e.write_tag(Tag::GeoKeyDirectoryTag, &d[..])
            .map_err(enc_err)?;
        if !tags.key_doubles.is_empty() {
            e.write_tag(Tag::GeoDoubleParamsTag, &tags.key_doubles[..])
                .map_err(enc_err)?;
        }
        if !tags.key_ascii.is_empty() {
            write_ascii(e, Tag::GeoAsciiParamsTag, &tags.key_ascii)?;
        }
    }
    if let Some(xml) = &tags.gdal_metadata {
        write_ascii(e, Tag::from_u16_exhaustive(TAG_GDAL_METADATA), xml)?;
    }
    if let Some(nd) = tags.nodata {
        write_ascii(e, Tag::GdalNodata, &format_nodata(nd))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::geotiff::fixtures::*;
    use crate::formats::geotiff::{TAG_GEO_KEY_DIRECTORY, read, write};

    #[test]
    fn raster_type_point_is_written_into_the_geokeys() {
        // Synthesised keys.
        let mut r = small_i16_raster();
        r.georef.as_mut().unwrap().raster_type = RasterType::Point;
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.georef.as_ref().unwrap().raster_type, RasterType::Point);

        // Verbatim keys without GTRasterTypeGeoKey: the key is inserted in order.
        let keys = GeoKeys {
            directory: vec![
                1, 1, 0, 3, 1024, 0, 1, 2, 2048, 0, 1, 4326, 2054, 34736, 1, 0,
            ],
            doubles: vec![0.0174532925199433],
            ascii: "WGS 84|".to_string(),
        };
        let mut g = r.georef.clone().unwrap();
        g.geokeys = Some(keys.clone());
        g.raster_type = RasterType::Area;
        r.georef = Some(g.clone());
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_eq!(back.georef.as_ref().unwrap().geokeys.as_ref(), Some(&keys));
        g.raster_type = RasterType::Point;
        r.georef = Some(g);
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        let bg = back.georef.unwrap();
        assert_eq!(bg.raster_type, RasterType::Point);
        assert_eq!(bg.epsg, Some(4326));
        let k = bg.geokeys.unwrap();
        assert_eq!(
            k.directory,
            vec![
                1, 1, 0, 4, 1024, 0, 1, 2, 1025, 0, 1, 2, 2048, 0, 1, 4326, 2054, 34736, 1, 0
            ]
        );
        assert_eq!(k.doubles, keys.doubles);
        assert_eq!(k.ascii, keys.ascii);

        // And an existing key is overwritten.
        let mut dir = k.directory.clone();
        set_raster_type_key(&mut dir, RASTER_PIXEL_IS_AREA).unwrap();
        assert_eq!(dir[8..12], [1025, 0, 1, 1]);
    }

    #[test]
    fn non_ascii_geoascii_params_survive() {
        let mut r = small_i16_raster();
        let g = r.georef.as_mut().unwrap();
        g.geokeys = Some(GeoKeys {
            directory: vec![1, 1, 0, 2, 1024, 0, 1, 1, 1026, 34737, 26, 0],
            doubles: vec![],
            ascii: "Réseau géodésique français|".to_string(),
        });
        g.epsg = None;
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "non-ASCII citation");
    }

    #[test]
    fn geokeys_without_placement_are_kept() {
        let vals: Vec<i16> = (0..6).collect();
        let mut b = Builder::basic(true, 3, 2, 16, 2, 12);
        b.short(TAG_GEO_KEY_DIRECTORY, &[1, 1, 0, 1, 3072, 0, 1, 32633]);
        let r = read(&b.build(&i16_bytes(true, &vals)), &opts()).unwrap();
        let g = r.georef.clone().unwrap();
        assert_eq!((g.origin, g.pixel_size), ([0.0, 0.0], [1.0, 1.0]));
        assert_eq!(g.epsg, Some(33633 - 1000));
        assert_eq!(g.geokeys.as_ref().unwrap().directory[7], 32633);
        let back = read(&write(&r).unwrap(), &opts()).unwrap();
        assert_same(&r, &back, "geokeys only");

        // No georeferencing tags at all: no georef.
        let b = Builder::basic(true, 3, 2, 16, 2, 12);
        let r = read(&b.build(&i16_bytes(true, &vals)), &opts()).unwrap();
        assert_eq!(r.georef, None);
        assert_eq!(r.nodata, None);
        assert_eq!(r.data, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    }

    #[test]
    fn epsg_rules() {
        let dir = |keys: &[[u16; 4]]| {
            let mut d = vec![1, 1, 0, keys.len() as u16];
            d.extend(keys.iter().flatten());
            d
        };
        let epsg_of = |d: Vec<u16>| {
            let mut b = Builder::basic(true, 1, 1, 16, 2, 2);
            b.short(TAG_GEO_KEY_DIRECTORY, &d);
            read(&b.build(&[0, 0]), &opts())
                .unwrap()
                .georef
                .unwrap()
                .epsg
        };
        assert_eq!(
            epsg_of(dir(&[[1024, 0, 1, 2], [2048, 0, 1, 4326]])),
            Some(4326)
        );
        assert_eq!(epsg_of(dir(&[[2048, 0, 1, 4269]])), Some(4269));
        assert_eq!(epsg_of(dir(&[[2048, 0, 1, 32767]])), None);
        assert_eq!(epsg_of(dir(&[[2048, 0, 1, 0]])), None);
        assert_eq!(
            epsg_of(dir(&[
                [1024, 0, 1, 1],
                [2048, 0, 1, 4326],
                [3072, 0, 1, 32767]
            ])),
            None,
            "user-defined projection on a known datum is not the datum's code"
        );
        assert_eq!(epsg_of(dir(&[[1024, 0, 1, 1], [2048, 0, 1, 4326]])), None);
        assert_eq!(
            epsg_of(dir(&[
                [1024, 0, 1, 1],
                [2048, 0, 1, 4326],
                [3072, 0, 1, 32633]
            ])),
            Some(32633)
        );
        // A directory that claims more keys than it holds is read without panicking.
        assert_eq!(epsg_of(vec![1, 1, 0, 9, 3072, 0, 1, 2056]), Some(2056));
        assert_eq!(epsg_of(vec![1, 1, 0, 9, 3072, 0]), None);
    }

    #[test]
    fn model_transformation() {
        let mut b = Builder::basic(true, 2, 1, 16, 2, 4);
        let m = [
            10.0, 0.0, 0.0, 1000.0, 0.0, -20.0, 0.0, 5000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ];
        b.double(TAG_MODEL_TRANSFORMATION, &m);
        let r = read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap();
        let g = r.georef.unwrap();
        assert_eq!(g.origin, [1000.0, 5000.0]);
        assert_eq!(g.pixel_size, [10.0, 20.0]);
        assert_eq!(g.geokeys, None);

        let mut rotated = m;
        rotated[1] = 0.5;
        b.double(TAG_MODEL_TRANSFORMATION, &rotated);
        let e = read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap_err();
        assert!(is_unsupported(&e), "{e}");

        // Ground control points only.
        let mut b = Builder::basic(true, 2, 1, 16, 2, 4);
        b.double(TAG_MODEL_TIEPOINT, &[0.0; 12]);
        let e = read(&b.build(&[1, 0, 2, 0]), &opts()).unwrap_err();
        assert!(is_unsupported(&e), "{e}");
    }

    /// South-up (row 0 at the south) is written as GDAL writes it, with a ModelTransformation
    /// (a negative ModelPixelScale Y is what GDAL reads as north-up), and reads back the same.
    #[test]
    fn south_up_is_written_with_a_model_transformation() {
        let mut r = small_i16_raster();
        let g = r.georef.as_mut().unwrap();
        g.pixel_size[1] = -g.pixel_size[1];
        let south_up = r.georef.clone().unwrap();
        let bytes = write(&r).unwrap();
        let back = read(&bytes, &opts()).unwrap();
        let bg = back.georef.clone().unwrap();
        assert_eq!(
            (bg.origin, bg.pixel_size, bg.raster_type, bg.epsg),
            (
                south_up.origin,
                south_up.pixel_size,
                south_up.raster_type,
                south_up.epsg
            )
        );
        let mut dec = tiff::decoder::Decoder::new(std::io::Cursor::new(&bytes[..])).unwrap();
        assert!(dec.find_tag(Tag::ModelPixelScaleTag).unwrap().is_none());
        let m = tag_f64s(&mut dec, TAG_MODEL_TRANSFORMATION)
            .unwrap()
            .unwrap();
        let [dx, dy] = south_up.pixel_size;
        let [x0, y0] = south_up.origin;
        assert_eq!(m[..8], [dx, 0.0, 0.0, x0, 0.0, -dy, 0.0, y0]);

        // North-up stays on ModelPixelScale + ModelTiepoint.
        let n = small_i16_raster();
        let bytes = write(&n).unwrap();
        let mut dec = tiff::decoder::Decoder::new(std::io::Cursor::new(&bytes[..])).unwrap();
        assert!(dec.find_tag(Tag::ModelTransformationTag).unwrap().is_none());
        assert!(dec.find_tag(Tag::ModelPixelScaleTag).unwrap().is_some());
    }

    /// A negative ModelPixelScale Y, as vtz wrote south-up rasters before: GDAL reads it as
    /// north-up ("negative value for ScaleY"), and so does vtz.
    #[test]
    fn a_negative_scale_y_is_read_as_gdal_reads_it() {
        let mut b = Builder::basic(false, 2, 2, 16, 2, 8);
        b.double(TAG_MODEL_PIXEL_SCALE, &[2.0, -3.0, 0.0]);
        b.double(TAG_MODEL_TIEPOINT, &[0.0, 0.0, 0.0, 100.0, 200.0, 0.0]);
        let r = read(&b.build(&i16_bytes(false, &[1, 2, 3, 4])), &opts()).unwrap();
        let g = r.georef.unwrap();
        assert_eq!((g.origin, g.pixel_size), ([100.0, 200.0], [2.0, 3.0]));
    }

    #[test]
    fn tiepoint_not_at_origin() {
        let mut b = Builder::basic(false, 2, 2, 16, 2, 8);
        b.double(TAG_MODEL_PIXEL_SCALE, &[2.0, 3.0, 0.0]);
        b.double(TAG_MODEL_TIEPOINT, &[1.0, 1.0, 0.0, 102.0, 197.0, 0.0]);
        let r = read(&b.build(&i16_bytes(false, &[1, -2, 300, -32768])), &opts()).unwrap();
        assert_eq!(
            r.data,
            vec![1.0, -2.0, 300.0, -32768.0],
            "big-endian samples"
        );
        let g = r.georef.unwrap();
        assert_eq!(g.origin, [100.0, 200.0]);
        assert_eq!(g.pixel_size, [2.0, 3.0]);
    }
}
