//! What GDAL reads beside a raster: world files, PAM `.aux.xml` files and ENVI headers.
//!
//! GDAL (and so QGIS) ignores vtz's own sidecars (`NAME.png.json`, the EXR `vtz_*`
//! attributes), so the formats without georeferencing of their own also get:
//!
//! - a **world file** (`NAME.pgw` beside `NAME.png`): six lines, the pixel size along x, two
//!   rotation terms (0), minus the pixel size along y, then x and y of the *centre* of the
//!   upper-left pixel;
//! - a **PAM file** (`NAME.png.aux.xml`, `NAME.exr.aux.xml`, `NAME.asc.aux.xml`): GDAL's
//!   "persistent auxiliary metadata", with `<SRS>` (the CRS as WKT), `<GeoTransform>` (always
//!   corner-based: x of the upper-left *corner*, pixel width, 0, y of that corner, 0, minus
//!   the pixel height), the band's `<NoDataValue>`, `<Offset>`/`<Scale>` (how stored codes
//!   become values) and what `Raster::gdal_metadata` says (description, units, items).
//! - an **ENVI header** (`NAME.hdr` beside raw `NAME.f32`): GDAL's ENVI driver then reads the
//!   raw samples as a raster (size, float32 little-endian, nodata as `data ignore value`),
//!   placed by `map info` (the upper-left corner, pixel sizes) with the CRS as
//!   `coordinate system string`.
//!
//! vtz's [`Georef::origin`] is the corner for [`RasterType::Area`] and the centre of pixel
//! (0, 0) for [`RasterType::Point`] (SRTM posts), so point rasters are moved by half a pixel
//! into GDAL's corner-based geotransform; the dataset item `AREA_OR_POINT` says which it was.

use crate::formats::crs;
use crate::model::{Georef, RasterType};
use std::borrow::Cow;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The six lines of a world file. Its reference point is the centre of the upper-left pixel
/// (a point raster's own origin, so that one is written exactly as vtz holds it).
pub(crate) fn world_file(g: &Georef) -> Vec<u8> {
    let [dx, dy] = g.pixel_size;
    let [cx, cy] = g.sample_centre(0.0, 0.0);
    // `{}` prints the shortest text that reads back to the same f64, never in exponent form
    // (which some world-file readers do not take).
    format!("{dx}\n0\n0\n{}\n{cx}\n{cy}\n", -dy).into_bytes()
}

/// Where GDAL looks for the world file of `path`: the extension's first and last letters
/// plus `w` (`.png` → `.pgw`), `.wld` when the extension is shorter than two letters.
pub(crate) fn world_file_path(path: &Path) -> PathBuf {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let mut chars = ext.chars();
    match (chars.next(), chars.next_back()) {
        (Some(a), Some(b)) => path.with_extension(format!("{a}{b}w")),
        _ => path.with_extension("wld"),
    }
}

/// `path` + `.aux.xml`: where GDAL keeps a raster's PAM.
pub(crate) fn aux_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".aux.xml");
    PathBuf::from(s)
}

/// What a PAM file says about one single-band raster file.
#[derive(Default)]
pub(crate) struct Pam<'a> {
    /// Placement and CRS (`<SRS>`, `<GeoTransform>`, `AREA_OR_POINT`); `None` leaves them to
    /// the file itself (an `.asc` header and its `.prj`).
    pub georef: Option<&'a Georef>,
    /// The band's nodata as the file stores it (a PNG code, NaN for an EXR).
    pub nodata: Option<f64>,
    /// How the file's stored codes become values (`value = offset + scale · code`), when not
    /// the identity.
    pub offset_scale: Option<(f64, f64)>,
    /// The source's GDAL_METADATA XML.
    pub gdal_metadata: Option<&'a str>,
}

/// One `<Item>` of GDAL_METADATA.
#[derive(Debug, PartialEq)]
struct Item {
    name: String,
    /// `None` for dataset items, the band index for band items.
    sample: Option<u32>,
    role: Option<String>,
    domain: String,
    value: String,
}

/// The band and dataset facts GDAL_METADATA gives, in PAM terms.
#[derive(Default)]
struct Meta {
    description: Option<String>,
    unit: Option<String>,
    offset: Option<f64>,
    scale: Option<f64>,
    /// (domain, key, value) of the dataset and of band 1.
    dataset: Vec<(String, String, String)>,
    band: Vec<(String, String, String)>,
}

fn meta_of(xml: Option<&str>) -> Meta {
    let mut m = Meta::default();
    // Metadata vtz cannot parse stays in the GeoTIFF and the .vtz; the PAM file just lacks it.
    let Some(items) = xml.and_then(parse_gdal_metadata) else {
        return m;
    };
    for it in items {
        // GDAL writes `xml:` domains as raw XML documents, not as items; vtz leaves them out.
        if it.domain.starts_with("xml:") {
            continue;
        }
        match (it.sample, it.role.as_deref()) {
            (None, _) => m.dataset.push((it.domain, it.name, it.value)),
            (Some(0), Some("description")) => m.description = Some(it.value),
            (Some(0), Some("unittype")) => m.unit = Some(it.value),
            (Some(0), Some("offset")) => m.offset = it.value.trim().parse().ok(),
            (Some(0), Some("scale")) => m.scale = it.value.trim().parse().ok(),
            (Some(0), None) => m.band.push((it.domain, it.name, it.value)),
            // Other bands (vtz rasters have one) and roles PAM has no place for.
            _ => {}
        }
    }
    m
}

/// The PAM XML, or `None` when there is nothing to say.
pub(crate) fn aux_xml(p: &Pam) -> Option<Vec<u8>> {
    let mut meta = meta_of(p.gdal_metadata);
    // The file's own code mapping comes first; GDAL_METADATA's scale/offset (which map the
    // source GeoTIFF's values, vtz's values, to physical ones) apply after it.
    let (offset, scale) = match (p.offset_scale, meta.offset, meta.scale) {
        (None, None, None) => (None, None),
        (own, o, s) => {
            let (o1, s1) = own.unwrap_or((0.0, 1.0));
            let (o2, s2) = (o.unwrap_or(0.0), s.unwrap_or(1.0));
            (Some(o2 + s2 * o1), Some(s2 * s1))
        }
    };
    if let Some(g) = p.georef {
        let aop = match g.raster_type {
            RasterType::Area => "Area",
            RasterType::Point => "Point",
        };
        meta.dataset
            .retain(|(d, k, _)| !(d.is_empty() && k == "AREA_OR_POINT"));
        meta.dataset
            .insert(0, (String::new(), "AREA_OR_POINT".into(), aop.into()));
    }
    let mut x = String::from("<PAMDataset>\n");
    if let Some(g) = p.georef {
        if let Some(srs) = crs::crs_user_input(g) {
            let _ = writeln!(x, "  <SRS>{}</SRS>", esc(&srs));
        }
        let gt = g.geotransform().map(num);
        let _ = writeln!(x, "  <GeoTransform>{}</GeoTransform>", gt.join(", "));
    }
    write_metadata(&mut x, "  ", &meta.dataset);
    let mut band = String::new();
    if let Some(d) = &meta.description {
        let _ = writeln!(band, "    <Description>{}</Description>", esc(d));
    }
    if let Some(u) = &meta.unit {
        let _ = writeln!(band, "    <UnitType>{}</UnitType>", esc(u));
    }
    if let Some(nd) = p.nodata {
        let _ = writeln!(band, "    <NoDataValue>{}</NoDataValue>", num(nd));
    }
    if let (Some(o), Some(s)) = (offset, scale) {
        let _ = writeln!(band, "    <Offset>{}</Offset>", num(o));
        let _ = writeln!(band, "    <Scale>{}</Scale>", num(s));
    }
    write_metadata(&mut band, "    ", &meta.band);
    if !band.is_empty() {
        let _ = write!(
            x,
            "  <PAMRasterBand band=\"1\">\n{band}  </PAMRasterBand>\n"
        );
    }
    if x == "<PAMDataset>\n" {
        return None;
    }
    x.push_str("</PAMDataset>\n");
    Some(x.into_bytes())
}

/// `<Metadata>` blocks, one per domain in order of first appearance.
fn write_metadata(x: &mut String, indent: &str, items: &[(String, String, String)]) {
    let mut domains: Vec<&str> = Vec::new();
    for (d, _, _) in items {
        if !domains.contains(&d.as_str()) {
            domains.push(d);
        }
    }
    for d in domains {
        if d.is_empty() {
            let _ = writeln!(x, "{indent}<Metadata>");
        } else {
            let _ = writeln!(x, "{indent}<Metadata domain=\"{}\">", esc(d));
        }
        for (_, k, v) in items.iter().filter(|(dd, _, _)| dd == d) {
            let _ = writeln!(x, "{indent}  <MDI key=\"{}\">{}</MDI>", esc(k), esc(v));
        }
        let _ = writeln!(x, "{indent}</Metadata>");
    }
}

/// A number as GDAL's `CPLAtof` reads it back exactly: Rust's shortest round-trip form
/// (`1e-5`, `30.0`), `nan`, `inf`, `-inf`.
fn num(v: f64) -> String {
    if v.is_nan() {
        "nan".into()
    } else {
        format!("{v:?}")
    }
}

/// XML text or attribute escaping.
fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            c => o.push(c),
        }
    }
    o
}

/// The inverse of [`esc`], plus `&apos;` and numeric character references.
fn unesc(s: &str) -> Option<String> {
    let mut o = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('&') {
        o.push_str(&rest[..i]);
        let end = rest[i..].find(';')? + i;
        let ent = &rest[i + 1..end];
        let c = match ent {
            "amp" => '&',
            "lt" => '<',
            "gt" => '>',
            "quot" => '"',
            "apos" => '\'',
            _ => {
                let n = if let Some(h) = ent.strip_prefix("#x").or(ent.strip_prefix("#X")) {
                    u32::from_str_radix(h, 16).ok()?
                } else {
                    ent.strip_prefix('#')?.parse().ok()?
                };
                char::from_u32(n)?
            }
        };
        o.push(c);
        rest = &rest[end + 1..];
    }
    o.push_str(rest);
    Some(o)
}

/// The items of a GDAL_METADATA document (`<GDALMetadata><Item name="…" [sample="n"]
/// [role="…"] [domain="…"]>value</Item>…</GDALMetadata>`, as GDAL's GeoTIFF driver writes
/// it). `None` when it is not such a document; vtz then writes no items from it.
fn parse_gdal_metadata(xml: &str) -> Option<Vec<Item>> {
    let body = xml.trim();
    let body = body
        .strip_prefix("<GDALMetadata>")?
        .strip_suffix("</GDALMetadata>")?;
    let mut items = Vec::new();
    let mut rest = body.trim_start();
    while !rest.is_empty() {
        rest = rest.strip_prefix("<Item")?;
        let close = rest.find('>')?;
        let (attrs, empty) = match rest[..close].strip_suffix('/') {
            Some(a) => (a, true),
            None => (&rest[..close], false),
        };
        rest = &rest[close + 1..];
        let value = if empty {
            String::new()
        } else {
            let end = rest.find("</Item>")?;
            // GDAL escapes a value before its XML writer escapes the text again (`a&b` is
            // stored as `a&amp;amp;b`), and unescapes twice when reading. A text escaped only
            // once (not written by GDAL) keeps its once-unescaped form.
            let once = unesc(&rest[..end])?;
            let v = unesc(&once).unwrap_or(once);
            rest = &rest[end + "</Item>".len()..];
            v
        };
        let mut it = Item {
            name: String::new(),
            sample: None,
            role: None,
            domain: String::new(),
            value,
        };
        for (k, v) in parse_attrs(attrs)? {
            match k {
                "name" => it.name = v,
                "sample" => it.sample = Some(v.trim().parse().ok()?),
                "role" => it.role = Some(v),
                "domain" => it.domain = v,
                _ => {}
            }
        }
        if it.name.is_empty() {
            return None;
        }
        items.push(it);
        rest = rest.trim_start();
    }
    Some(items)
}

/// GDAL_METADATA without its `STATISTICS_*` items (minimum, maximum, mean, standard
/// deviation, valid percent), which describe the whole source raster: a window or a resampled
/// decode has other statistics, and GDAL would report the stale ones as its own. The rest is
/// kept byte for byte; a document vtz cannot parse is kept whole.
pub(crate) fn without_statistics(xml: &str) -> Cow<'_, str> {
    match drop_items(xml, |attrs, _| {
        attrs
            .iter()
            .any(|(k, v)| *k == "name" && v.starts_with("STATISTICS_"))
    }) {
        Some(out) => Cow::Owned(out),
        None => Cow::Borrowed(xml),
    }
}

/// `xml` without the `<Item>`s for which `drop(attributes, text)` holds (each with the white
/// space that led up to it, its line), the rest byte for byte; `None` when nothing was
/// dropped or the document cannot be parsed.
fn drop_items(xml: &str, mut drop: impl FnMut(&[(&str, String)], &str) -> bool) -> Option<String> {
    let mut out = String::with_capacity(xml.len());
    let mut rest = xml;
    let mut changed = false;
    while let Some(i) = rest.find("<Item") {
        let close = rest[i..].find('>').map(|c| i + c)?;
        let tag = &rest[i + "<Item".len()..close];
        let (attrs, text, end) = match tag.strip_suffix('/') {
            Some(a) => (a, "", close + 1),
            None => {
                let e = rest[close..].find("</Item>")?;
                (
                    tag,
                    &rest[close + 1..close + e],
                    close + e + "</Item>".len(),
                )
            }
        };
        let attrs = parse_attrs(attrs)?;
        if drop(&attrs, text) {
            out.push_str(rest[..i].trim_end_matches([' ', '\t', '\r', '\n']));
            changed = true;
        } else {
            out.push_str(&rest[..end]);
        }
        rest = &rest[end..];
    }
    if !changed {
        return None;
    }
    out.push_str(rest);
    Some(out)
}

/// Band 1's offset and scale items (`sample="0"`, `role="offset"` / `role="scale"`) of a
/// GDAL_METADATA document: the document without them (`None` when it held nothing else)
/// and their values (offset, scale; `None` when absent or not a number). A document vtz
/// cannot parse gives itself and no values.
pub(crate) fn take_offset_scale(xml: &str) -> (Option<String>, Option<f64>, Option<f64>) {
    let (mut offset, mut scale) = (None, None);
    let rest = drop_items(xml, |attrs, text| {
        let band0 = attrs.iter().any(|(k, v)| *k == "sample" && v.trim() == "0");
        let role = attrs
            .iter()
            .find(|(k, _)| *k == "role")
            .map(|(_, v)| v.as_str());
        let slot = match (band0, role) {
            (true, Some("offset")) => &mut offset,
            (true, Some("scale")) => &mut scale,
            _ => return false,
        };
        let once = unesc(text).unwrap_or_default();
        let v = unesc(&once).unwrap_or(once);
        // An item that is not a number stays where it is.
        match v.trim().parse::<f64>().ok().filter(|x| x.is_finite()) {
            Some(x) => {
                *slot = Some(x);
                true
            }
            None => false,
        }
    });
    match rest {
        None => (Some(xml.to_string()), None, None),
        Some(r) => {
            let empty = parse_gdal_metadata(&r).is_some_and(|items| items.is_empty());
            ((!empty).then_some(r), offset, scale)
        }
    }
}

/// The value mapping a GeoTIFF's GDAL scale and offset (band 1's GDAL_METADATA `SCALE` /
/// `OFFSET` items) give its integer samples, and the metadata without those items; `None`
/// when the samples are not integers or the items are absent, the identity or unusable (a
/// zero scale, values that overflow). GDAL's values are `offset + scale · sample`: vtz's
/// values are the same, so a bound is in GDAL's units (metres), not the stored codes'.
pub(crate) fn gdal_mapping(
    st: crate::model::SampleType,
    xml: Option<&str>,
) -> Option<(crate::model::ValueMapping, Option<String>)> {
    let (lo, hi) = st.int_range()?;
    let (rest, o, s) = take_offset_scale(xml?);
    if o.is_none() && s.is_none() {
        return None;
    }
    let m = crate::model::ValueMapping {
        offset: o.unwrap_or(0.0),
        scale: s.unwrap_or(1.0),
    };
    let usable = m.scale != 0.0 && m.to_value(lo).is_finite() && m.to_value(hi).is_finite();
    (usable && !m.is_identity()).then_some((m, rest))
}

/// A raster read from a GeoTIFF of integer codes with a GDAL scale/offset
/// ([`gdal_mapping`]): its values (and nodata) become `offset + scale · code`, its mapping
/// that one, its GDAL_METADATA loses the two items (a writer puts them back from the
/// mapping). Anything else is left as it is.
pub(crate) fn apply_gdal_mapping(r: &mut crate::model::Raster) {
    if !r.mapping.is_identity() {
        return;
    }
    let Some((m, rest)) = gdal_mapping(r.sample_type, r.gdal_metadata.as_deref()) else {
        return;
    };
    for v in &mut r.data {
        *v = m.to_value(*v);
    }
    r.nodata = r.nodata.map(|nd| m.to_value(nd));
    r.mapping = m;
    r.gdal_metadata = rest;
}

/// GDAL_METADATA saying band 1's values are `offset + scale · stored sample` for `mapping`
/// (the codes a GeoTIFF stores): `xml` (or a new document) with its own offset/scale items
/// applied after `mapping` (as [`aux_xml`] composes them) and replaced by one `OFFSET` and
/// one `SCALE` item, as GDAL writes them.
pub(crate) fn with_offset_scale(xml: Option<&str>, mapping: crate::model::ValueMapping) -> String {
    let (rest, o2, s2) = match xml {
        Some(x) => take_offset_scale(x),
        None => (None, None, None),
    };
    let (o2, s2) = (o2.unwrap_or(0.0), s2.unwrap_or(1.0));
    let (offset, scale) = (o2 + s2 * mapping.offset, s2 * mapping.scale);
    let items = format!(
        "  <Item name=\"OFFSET\" sample=\"0\" role=\"offset\">{}</Item>\n  \
         <Item name=\"SCALE\" sample=\"0\" role=\"scale\">{}</Item>\n",
        num(offset),
        num(scale)
    );
    match rest
        .as_deref()
        .and_then(|r| r.rfind("</GDALMetadata>").map(|i| (r, i)))
    {
        Some((r, i)) => {
            let head = r[..i].trim_end_matches([' ', '\t', '\r', '\n']);
            format!("{head}\n{items}{}", &r[i..])
        }
        None => format!("<GDALMetadata>\n{items}</GDALMetadata>"),
    }
}

/// `k="v" k2='v2'` pairs.
fn parse_attrs(mut s: &str) -> Option<Vec<(&str, String)>> {
    let mut out = Vec::new();
    loop {
        s = s.trim_start();
        if s.is_empty() {
            return Some(out);
        }
        let eq = s.find('=')?;
        let key = s[..eq].trim();
        let after = s[eq + 1..].trim_start();
        let q = after.chars().next().filter(|&c| c == '"' || c == '\'')?;
        let end = after[1..].find(q)? + 1;
        out.push((key, unesc(&after[1..end])?));
        s = &after[end + 1..];
    }
}

/// The ENVI header that lets GDAL read a raw little-endian float32 file of `width` ×
/// `height` samples (row 0 north), with its nodata value and placement when known.
pub(crate) fn envi_header(
    width: usize,
    height: usize,
    nodata: Option<f64>,
    georef: Option<&Georef>,
) -> Vec<u8> {
    let mut h = String::from("ENVI\ndescription = {vtz raw float32 samples}\n");
    let _ = write!(
        h,
        "samples = {width}\nlines = {height}\nbands = 1\nheader offset = 0\n\
         file type = ENVI Standard\ndata type = 4\ninterleave = bsq\nbyte order = 0\n"
    );
    if let Some(nd) = nodata {
        let _ = writeln!(h, "data ignore value = {nd}");
    }
    if let Some(g) = georef {
        let [x0, dx, _, y0, _, ndy] = g.geotransform();
        // Reference pixel (1, 1) in ENVI's 1-based pixel coordinates is the upper-left
        // corner of the first pixel, which is GDAL's geotransform origin.
        let _ = writeln!(
            h,
            "map info = {{Arbitrary, 1, 1, {x0}, {y0}, {dx}, {}}}",
            -ndy
        );
        if let Some(wkt) = crs::crs_wkt(g) {
            let _ = writeln!(h, "coordinate system string = {{{wkt}}}");
        }
    }
    h.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Raster, SampleType, ValueMapping};

    /// A GeoTIFF's GDAL scale/offset over integer codes becomes the value mapping (values
    /// in GDAL's units), the items leave the metadata, and a writer puts them back.
    #[test]
    fn gdal_scale_offset_is_the_value_mapping_and_back() {
        let xml = "<GDALMetadata>\n  <Item name=\"SCALE\" sample=\"0\" role=\"scale\">10</Item>\n  \
                   <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">metre</Item>\n  \
                   <Item name=\"OFFSET\" sample=\"0\" role=\"offset\">-5</Item>\n</GDALMetadata>";
        let mut r = Raster::from_values(
            3,
            1,
            vec![1.0, -7.0, -32768.0],
            Some(-32768.0),
            SampleType::I16,
        )
        .unwrap();
        r.gdal_metadata = Some(xml.into());
        apply_gdal_mapping(&mut r);
        assert_eq!(
            r.mapping,
            ValueMapping {
                scale: 10.0,
                offset: -5.0
            }
        );
        assert_eq!(r.data, vec![5.0, -75.0, -327685.0]);
        assert_eq!(r.nodata, Some(-327685.0));
        assert_eq!(r.mask, Some(vec![true, true, false]));
        let rest = r.gdal_metadata.clone().unwrap();
        assert!(
            !rest.contains("role=\"scale\"") && !rest.contains("role=\"offset\""),
            "{rest}"
        );
        assert!(rest.contains("role=\"unittype\">metre</Item>"), "{rest}");
        let back = with_offset_scale(Some(&rest), r.mapping);
        let (_, o, s) = take_offset_scale(&back);
        assert_eq!((o, s), (Some(-5.0), Some(10.0)));
        // Float samples, and the identity, stay as they are.
        let mut f = Raster::from_values(1, 1, vec![1.5], None, SampleType::F32).unwrap();
        f.gdal_metadata = Some(xml.into());
        apply_gdal_mapping(&mut f);
        assert!(f.mapping.is_identity() && f.gdal_metadata.as_deref() == Some(xml));
        let one = "<GDALMetadata><Item name=\"SCALE\" sample=\"0\" role=\"scale\">1</Item></GDALMetadata>";
        assert!(gdal_mapping(SampleType::I16, Some(one)).is_none());
        // Only scale/offset items: none are left.
        let only = "<GDALMetadata>\n  <Item name=\"SCALE\" sample=\"0\" role=\"scale\">0.1</Item>\n</GDALMetadata>";
        assert_eq!(
            gdal_mapping(SampleType::U16, Some(only)),
            Some((
                ValueMapping {
                    scale: 0.1,
                    offset: 0.0
                },
                None
            ))
        );
        assert!(
            with_offset_scale(
                None,
                ValueMapping {
                    scale: 0.1,
                    offset: 2.0
                }
            )
            .starts_with(
                "<GDALMetadata>\n  <Item name=\"OFFSET\" sample=\"0\" role=\"offset\">2.0</Item>"
            )
        );
    }

    #[test]
    fn envi_header_places_the_raw_samples() {
        let h = String::from_utf8(envi_header(1197, 643, Some(32767.0), Some(&utm()))).unwrap();
        for line in [
            "samples = 1197",
            "lines = 643",
            "data type = 4",
            "byte order = 0",
            "data ignore value = 32767",
            "map info = {Arbitrary, 1, 1, 376313.6554542635, 3807917.8276283755, 30, 30}",
        ] {
            assert!(h.lines().any(|l| l == line), "{line} in\n{h}");
        }
        assert!(h.contains("coordinate system string = {PROJCS[\"WGS 84 / UTM zone 11N\""));
        let bare = String::from_utf8(envi_header(2, 3, None, None)).unwrap();
        assert!(!bare.contains("map info") && !bare.contains("ignore"));
    }

    fn utm() -> Georef {
        crate::testutil::utm11_georef()
    }

    fn kauai() -> Georef {
        Georef {
            origin: [-160.0, 23.0],
            pixel_size: [1.0 / 1200.0, 1.0 / 1200.0],
            raster_type: RasterType::Point,
            epsg: Some(4326),
            wkt: None,
            geokeys: None,
        }
    }

    #[test]
    fn geotransform_is_corner_based() {
        let g = utm();
        assert_eq!(
            g.geotransform(),
            [376313.6554542635, 30.0, 0.0, 3807917.8276283755, 0.0, -30.0]
        );
        let gt = kauai().geotransform();
        let half = 0.5 / 1200.0;
        assert_eq!(
            gt,
            [
                -160.0 - half,
                1.0 / 1200.0,
                0.0,
                23.0 + half,
                0.0,
                -1.0 / 1200.0
            ]
        );
    }

    #[test]
    fn world_file_numbers() {
        // Area: the centre of the upper-left pixel is half a pixel in from the corner.
        let w = String::from_utf8(world_file(&utm())).unwrap();
        assert_eq!(w, "30\n0\n0\n-30\n376328.6554542635\n3807902.8276283755\n");
        // Point: the origin itself, exactly.
        let w = String::from_utf8(world_file(&kauai())).unwrap();
        let lines: Vec<f64> = w.lines().map(|l| l.parse().unwrap()).collect();
        assert_eq!(lines, [1.0 / 1200.0, 0.0, 0.0, -1.0 / 1200.0, -160.0, 23.0]);
        assert!(!w.contains('e'), "no exponent form: {w}");
        assert_eq!(world_file_path(Path::new("d/x.png")), Path::new("d/x.pgw"));
        assert_eq!(world_file_path(Path::new("x.tiff")), Path::new("x.tfw"));
        assert_eq!(world_file_path(Path::new("x")), Path::new("x.wld"));
        assert_eq!(aux_path(Path::new("d/x.exr")), Path::new("d/x.exr.aux.xml"));
    }

    const META: &str = "<GDALMetadata>\n  <Item name=\"DataType\">Generic</Item>\n  \
        <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">Height &amp;amp; depth</Item>\n  \
        <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item>\n  \
        <Item name=\"OFFSET\" sample=\"0\" role=\"offset\">10</Item>\n  \
        <Item name=\"SCALE\" sample=\"0\" role=\"scale\">0.5</Item>\n  \
        <Item name=\"source\" sample=\"0\">SRTM &amp;lt;v3&amp;gt; &amp;quot;1&amp;quot;</Item>\n  \
        <Item name=\"x\" domain=\"IMAGERY\">&#x263A;</Item>\n  \
        <Item name=\"y\" domain=\"xml:XMP\">&lt;x/&gt;</Item>\n  \
        <Item name=\"other\" sample=\"1\">ignored</Item>\n</GDALMetadata>\n";

    #[test]
    fn gdal_metadata_items() {
        let items = parse_gdal_metadata(META).unwrap();
        assert_eq!(items.len(), 9);
        assert_eq!(items[1].value, "Height & depth");
        assert_eq!(items[1].role.as_deref(), Some("description"));
        assert_eq!(items[5].value, "SRTM <v3> \"1\"");
        assert_eq!(items[6].value, "\u{263A}");
        // Escaped once only (not GDAL's way): the once-unescaped text.
        let once = "<GDALMetadata><Item name=\"a\">x &amp; y</Item></GDALMetadata>";
        assert_eq!(parse_gdal_metadata(once).unwrap()[0].value, "x & y");
        assert_eq!(items[6].domain, "IMAGERY");
        assert_eq!(
            parse_gdal_metadata("<GDALMetadata></GDALMetadata>"),
            Some(vec![])
        );
        for bad in [
            "",
            "<GDALMetadata>",
            "<GDALMetadata><Item>x</Item></GDALMetadata>",
            "<GDALMetadata><Item name=\"a\">x</GDALMetadata>",
            "<GDALMetadata><Item name=\"a\" sample=\"z\">x</Item></GDALMetadata>",
            "<GDALMetadata><Item name=\"a\">&bogus;</Item></GDALMetadata>",
            "<GDALMetadata><Other/></GDALMetadata>",
        ] {
            assert_eq!(parse_gdal_metadata(bad), None, "{bad}");
        }
    }

    #[test]
    fn statistics_are_dropped_the_rest_kept() {
        let xml = "<GDALMetadata>\n  <Item name=\"DataType\">Generic</Item>\n  \
            <Item name=\"STATISTICS_MAXIMUM\" sample=\"0\">2311</Item>\n  \
            <Item name=\"STATISTICS_MEAN\" sample=\"0\"/>\n  \
            <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item>\n</GDALMetadata>\n";
        assert_eq!(
            without_statistics(xml),
            "<GDALMetadata>\n  <Item name=\"DataType\">Generic</Item>\n  \
             <Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item>\n</GDALMetadata>\n"
        );
        // Nothing to drop, or nothing vtz can parse: the very same text.
        assert!(matches!(without_statistics(META), Cow::Borrowed(_)));
        let odd = "<GDALMetadata><Item name=STATISTICS_MEAN>1</Item></GDALMetadata>";
        assert_eq!(without_statistics(odd), odd);
        assert_eq!(
            without_statistics("<Item name=\"STATISTICS_X\">"),
            "<Item name=\"STATISTICS_X\">"
        );
    }

    #[test]
    fn aux_xml_content() {
        let g = kauai();
        let xml = aux_xml(&Pam {
            georef: Some(&g),
            nodata: Some(0.0),
            offset_scale: Some((-32768.0, 1.0)),
            gdal_metadata: Some(META),
        })
        .unwrap();
        let xml = String::from_utf8(xml).unwrap();
        let wkt = esc(crs::wkt_of_epsg(4326).unwrap());
        let gt = g.geotransform().map(num).join(", ");
        let want = format!(
            "<PAMDataset>\n  <SRS>{wkt}</SRS>\n  <GeoTransform>{gt}</GeoTransform>\n  \
             <Metadata>\n    <MDI key=\"AREA_OR_POINT\">Point</MDI>\n    \
             <MDI key=\"DataType\">Generic</MDI>\n  </Metadata>\n  \
             <Metadata domain=\"IMAGERY\">\n    <MDI key=\"x\">\u{263A}</MDI>\n  </Metadata>\n  \
             <PAMRasterBand band=\"1\">\n    <Description>Height &amp; depth</Description>\n    \
             <UnitType>m</UnitType>\n    <NoDataValue>0.0</NoDataValue>\n    \
             <Offset>-16374.0</Offset>\n    <Scale>0.5</Scale>\n    <Metadata>\n      \
             <MDI key=\"source\">SRTM &lt;v3&gt; &quot;1&quot;</MDI>\n    </Metadata>\n  \
             </PAMRasterBand>\n</PAMDataset>\n"
        );
        assert_eq!(xml, want);
        // Its numbers read back exactly.
        let gt_text = xml
            .split("<GeoTransform>")
            .nth(1)
            .unwrap()
            .split('<')
            .next()
            .unwrap();
        let back: Vec<f64> = gt_text.split(", ").map(|t| t.parse().unwrap()).collect();
        assert_eq!(back, g.geotransform());
    }

    #[test]
    fn aux_xml_only_when_there_is_something_to_say() {
        assert_eq!(aux_xml(&Pam::default()), None);
        let nan = aux_xml(&Pam {
            nodata: Some(f64::NAN),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(
            String::from_utf8(nan).unwrap(),
            "<PAMDataset>\n  <PAMRasterBand band=\"1\">\n    <NoDataValue>nan</NoDataValue>\n  \
             </PAMRasterBand>\n</PAMDataset>\n"
        );
        // Metadata vtz cannot parse adds nothing.
        assert_eq!(
            aux_xml(&Pam {
                gdal_metadata: Some("<not gdal>"),
                ..Default::default()
            }),
            None
        );
        // A CRS vtz cannot name: placement only.
        let mut g = utm();
        g.epsg = None;
        let xml = String::from_utf8(
            aux_xml(&Pam {
                georef: Some(&g),
                ..Default::default()
            })
            .unwrap(),
        )
        .unwrap();
        assert!(
            !xml.contains("<SRS>") && xml.contains("<GeoTransform>"),
            "{xml}"
        );
    }
}
