//! The CRS as text GDAL reads: WKT from an EPSG code, an EPSG code from a WKT, and `.prj` files.
//!
//! vtz has no PROJ database, so WKT for an EPSG code comes from the `crs-definitions` table
//! (OGC WKT 1 in GDAL's flavour, e.g. `PROJCS["WGS 84 / UTM zone 11N",…,AUTHORITY["EPSG",
//! "32611"]]`), which GDAL reads back as the same EPSG code. A WKT the source gave (say, from
//! a `.prj`) wins over the table, so a `.prj` read with a raster is written back verbatim.

use crate::model::Georef;
use std::borrow::Cow;

/// OGC WKT 1 for an EPSG code, when the table has it (codes above 65535 are not EPSG CRSs).
pub(crate) fn wkt_of_epsg(code: u32) -> Option<&'static str> {
    let code = u16::try_from(code).ok()?;
    crs_definitions::from_code(code).map(|d| d.wkt)
}

/// Whether `s` is a WKT (1 or 2) CRS rather than a PROJ string or an `AUTH:CODE`: a keyword
/// (`PROJCS`, `GEOGCRS`, `COMPD_CS`, …) directly followed by `[` or `(`.
pub(crate) fn looks_like_wkt(s: &str) -> bool {
    let s = s.trim_start();
    let kw = s.find(['[', '(']).map_or("", |i| s[..i].trim_end());
    !kw.is_empty()
        && kw.starts_with(|c: char| c.is_ascii_alphabetic())
        && kw.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The EPSG code of a WKT's root node: its direct child `AUTHORITY["EPSG","n"]` (WKT 1) or
/// `ID["EPSG",n]` (WKT 2). Codes of inner nodes (the datum, the base CRS) do not count, so an
/// unknown projection on WGS 84 is not taken for EPSG:4326. `None` when there is none.
pub(crate) fn epsg_of_wkt(wkt: &str) -> Option<u32> {
    let b = wkt.as_bytes();
    let mut depth = 0usize;
    let mut in_str = false;
    // Start of the keyword being read: just after the last '[', '(' or ','.
    let mut kw_start = 0;
    let mut found = None;
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if in_str {
            // WKT doubles a quote inside a string.
            if c == b'"' {
                if b.get(i + 1) == Some(&b'"') {
                    i += 1;
                } else {
                    in_str = false;
                }
            }
            i += 1;
            continue;
        }
        match c {
            b'"' => in_str = true,
            b'[' | b'(' => {
                if depth == 1 {
                    let kw = wkt[kw_start..i].trim();
                    if kw.eq_ignore_ascii_case("AUTHORITY") || kw.eq_ignore_ascii_case("ID") {
                        if let Some(code) = epsg_authority(&wkt[i + 1..]) {
                            found = Some(code);
                        }
                    }
                }
                depth += 1;
                kw_start = i + 1;
            }
            b']' | b')' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    break;
                }
            }
            b',' => kw_start = i + 1,
            _ => {}
        }
        i += 1;
    }
    found
}

/// The code of an authority node's arguments (`"EPSG","32611"]…` or `"EPSG",32611,…`) when
/// the authority is EPSG.
fn epsg_authority(args: &str) -> Option<u32> {
    let mut parts = args.split([',', ']', ')', '[', '(']);
    let name = parts.next()?.trim().trim_matches('"');
    let code = parts.next()?.trim().trim_matches('"');
    if !name.eq_ignore_ascii_case("EPSG") {
        return None;
    }
    code.parse::<u32>().ok().filter(|&c| c > 0)
}

/// The CRS of a georef as WKT: its own WKT when it has one, else the table's WKT for its
/// EPSG code; `None` when neither is known (then no `.prj` is written).
pub(crate) fn crs_wkt(g: &Georef) -> Option<Cow<'_, str>> {
    if let Some(w) = g.wkt.as_deref().filter(|w| looks_like_wkt(w)) {
        return Some(Cow::Borrowed(w.trim()));
    }
    g.epsg.and_then(wkt_of_epsg).map(Cow::Borrowed)
}

/// The CRS as GDAL's `SetFromUserInput` takes it (what a PAM `<SRS>` holds): WKT when known,
/// else `EPSG:n` (GDAL resolves it from its own database) or the source's PROJ string.
pub(crate) fn crs_user_input(g: &Georef) -> Option<Cow<'_, str>> {
    if let Some(w) = crs_wkt(g) {
        return Some(w);
    }
    if let Some(code) = g.epsg {
        return Some(Cow::Owned(format!("EPSG:{code}")));
    }
    g.wkt
        .as_deref()
        .map(str::trim)
        .filter(|w| !w.is_empty())
        .map(Cow::Borrowed)
}

/// The bytes of a `.prj` for this georef: the WKT on one line, then a newline.
pub(crate) fn prj_bytes(g: &Georef) -> Option<Vec<u8>> {
    crs_wkt(g).map(|w| format!("{w}\n").into_bytes())
}

/// The CRS a `.prj` holds: its text (trimmed; bytes that are not UTF-8 are taken as Latin-1,
/// as old ESRI files are) and, when its root names one, the EPSG code. Never fails: a `.prj`
/// vtz cannot interpret is kept as text.
pub(crate) fn parse_prj(bytes: &[u8]) -> (String, Option<u32>) {
    let text = match std::str::from_utf8(bytes) {
        Ok(s) => s.to_string(),
        Err(_) => bytes.iter().map(|&b| char::from(b)).collect(),
    };
    let text = text.trim_start_matches('\u{feff}').trim().to_string();
    let epsg = epsg_of_wkt(&text);
    (text, epsg)
}

/// GeoTIFF's VerticalCSTypeGeoKey and VerticalCitationGeoKey.
const KEY_VERTICAL_CS: u16 = 4096;
const KEY_VERTICAL_CITATION: u16 = 4097;

/// The CRS of a georef in one line for people, both parts of a compound CRS: the horizontal
/// one (`EPSG:n`, else the WKT's root name) and, when the file keeps one, the vertical one
/// (`vertical EPSG:n (name)`) from the GeoTIFF keys (VerticalCSTypeGeoKey, its citation) or
/// from a compound WKT (`COMPD_CS`, `COMPOUNDCRS`: its `VERT_CS`/`VERTCRS` node). `None`
/// when there is neither an EPSG code nor a vertical CRS.
pub(crate) fn crs_summary(g: &Georef) -> Option<String> {
    let wkt = g.wkt.as_deref().filter(|w| looks_like_wkt(w));
    let vertical = g
        .geokeys
        .as_ref()
        .and_then(vertical_of_geokeys)
        .or_else(|| wkt.and_then(vertical_of_wkt));
    let horizontal = match (g.epsg, wkt) {
        (Some(e), _) => Some(format!("EPSG:{e}")),
        (None, Some(w)) if vertical.is_some() => wkt_name(w).map(|n| format!("\"{n}\"")),
        _ => None,
    };
    match (horizontal, vertical) {
        (None, None) => None,
        (Some(h), None) => Some(h),
        (None, Some(v)) => Some(format!("vertical {v}")),
        (Some(h), Some(v)) => Some(format!("{h} + vertical {v}")),
    }
}

/// The first quoted string after the root keyword of a WKT: its name.
fn wkt_name(w: &str) -> Option<&str> {
    let open = w.find(['[', '('])?;
    let rest = &w[open + 1..];
    let a = rest.find('"')?;
    let b = rest[a + 1..].find('"')?;
    Some(&rest[a + 1..a + 1 + b])
}

/// The vertical CRS of GeoTIFF keys: `EPSG:n (citation)`, the citation alone for a
/// user-defined one.
fn vertical_of_geokeys(k: &crate::model::GeoKeys) -> Option<String> {
    let dir = &k.directory;
    let n = usize::from(*dir.get(3)?);
    let key = |id: u16| {
        dir.get(4..)?
            .chunks_exact(4)
            .take(n)
            .find(|e| e[0] == id)
            .map(|e| (e[1], e[2], e[3]))
    };
    let citation = key(KEY_VERTICAL_CITATION).and_then(|(loc, count, off)| {
        (loc == 34737)
            .then(|| {
                k.ascii
                    .get(usize::from(off)..usize::from(off) + usize::from(count))
                    .map(|s| s.trim_end_matches(['|', '\0']).trim().to_string())
            })
            .flatten()
            .filter(|s| !s.is_empty())
    });
    let code = key(KEY_VERTICAL_CS)
        .filter(|e| e.0 == 0)
        .map(|e| e.2)
        .filter(|&c| c != 0);
    match (code, citation) {
        (Some(c), cit) if c != 32767 => Some(match cit {
            Some(t) => format!("EPSG:{c} ({t})"),
            None => format!("EPSG:{c}"),
        }),
        (_, Some(t)) => Some(format!("\"{t}\"")),
        _ => None,
    }
}

/// The vertical part of a compound WKT: `EPSG:n (name)` or `"name"`.
fn vertical_of_wkt(w: &str) -> Option<String> {
    let upper = w.to_ascii_uppercase();
    let root = upper.trim_start();
    if !(root.starts_with("COMPD_CS") || root.starts_with("COMPOUNDCRS")) {
        return None;
    }
    let at = ["VERT_CS", "VERTCRS", "VERTICALCRS"]
        .iter()
        .filter_map(|kw| {
            upper
                .match_indices(kw)
                .find(|(i, _)| upper[i + kw.len()..].trim_start().starts_with(['[', '(']))
                .map(|(i, _)| i)
        })
        .min()?;
    let node = &w[at..];
    let name = wkt_name(node);
    Some(match (epsg_of_wkt(node), name) {
        (Some(c), Some(n)) => format!("EPSG:{c} ({n})"),
        (Some(c), None) => format!("EPSG:{c}"),
        (None, Some(n)) => format!("\"{n}\""),
        (None, None) => "(unnamed)".to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::RasterType;

    fn georef(epsg: Option<u32>, wkt: Option<&str>) -> Georef {
        Georef {
            origin: [0.0, 0.0],
            pixel_size: [1.0, 1.0],
            raster_type: RasterType::Area,
            epsg,
            wkt: wkt.map(String::from),
            geokeys: None,
        }
    }

    #[test]
    fn the_table_has_the_codes_vtz_meets_and_names_them_at_the_root() {
        for code in [
            4326, 4269, 4258, 3857, 32611, 32601, 32660, 32701, 32760, 26911, 26918, 28992, 25832,
            25833, 27700, 2056, 3035, 5070,
        ] {
            let w = wkt_of_epsg(code).unwrap_or_else(|| panic!("EPSG:{code} missing"));
            assert!(looks_like_wkt(w), "{code}");
            assert_eq!(epsg_of_wkt(w), Some(code), "{code}: {w}");
        }
        assert!(
            wkt_of_epsg(32611)
                .unwrap()
                .starts_with("PROJCS[\"WGS 84 / UTM zone 11N\"")
        );
        assert!(wkt_of_epsg(4326).unwrap().starts_with("GEOGCS[\"WGS 84\""));
        assert_eq!(wkt_of_epsg(0), None);
        assert_eq!(wkt_of_epsg(1_000_000), None);
    }

    #[test]
    fn epsg_only_from_the_root() {
        // WKT 2 with the code as a number, inner IDs ignored.
        let w2 = r#"PROJCRS["WGS 84 / UTM zone 11N",BASEGEOGCRS["WGS 84",ID["EPSG",4326]],
            CONVERSION["UTM zone 11N",METHOD["Transverse Mercator",ID["EPSG",9807]]],
            ID["EPSG",32611]]"#;
        assert_eq!(epsg_of_wkt(w2), Some(32611));
        // No root authority: the base CRS's code is not the CRS's.
        let custom = r#"PROJCS["custom",GEOGCS["WGS 84",AUTHORITY["EPSG","4326"]],PROJECTION["Mercator_1SP"]]"#;
        assert_eq!(epsg_of_wkt(custom), None);
        // Another authority, quotes inside strings, parentheses.
        assert_eq!(
            epsg_of_wkt(r#"GEOGCS["a ""]"" b",AUTHORITY["ESRI","104000"]]"#),
            None
        );
        assert_eq!(
            epsg_of_wkt(r#"GEOGCS("x",AUTHORITY("epsg", "4269"))"#),
            Some(4269)
        );
        // Garbage never panics.
        for s in [
            "",
            "]",
            "[[[",
            "AUTHORITY[",
            "X[AUTHORITY[\"EPSG\"",
            "X[ID[\"EPSG\",-1]]",
        ] {
            assert_eq!(epsg_of_wkt(s), None, "{s}");
        }
    }

    #[test]
    fn wkt_detection() {
        assert!(looks_like_wkt("  PROJCS[\"x\"]"));
        assert!(looks_like_wkt("COMPD_CS[\"x\"]"));
        assert!(!looks_like_wkt("+proj=longlat +datum=WGS84"));
        assert!(!looks_like_wkt("EPSG:4326"));
        assert!(!looks_like_wkt(""));
    }

    #[test]
    fn crs_choice_prefers_the_sources_wkt() {
        let own = "GEOGCS[\"mine\"]";
        assert_eq!(crs_wkt(&georef(Some(4326), Some(own))).unwrap(), own);
        // A PROJ string is not WKT: the table's WKT for the code is used instead.
        let g = georef(Some(4326), Some("+proj=longlat"));
        assert_eq!(crs_wkt(&g).unwrap(), wkt_of_epsg(4326).unwrap());
        assert_eq!(crs_user_input(&g).unwrap(), wkt_of_epsg(4326).unwrap());
        // Nothing known: no .prj; a PAM SRS still gets what there is.
        let g = georef(None, Some("+proj=longlat"));
        assert_eq!(prj_bytes(&g), None);
        assert_eq!(crs_user_input(&g).unwrap(), "+proj=longlat");
        let g = georef(Some(99999), None);
        assert_eq!(prj_bytes(&g), None);
        assert_eq!(crs_user_input(&g).unwrap(), "EPSG:99999");
        assert_eq!(crs_user_input(&georef(None, None)), None);
        let prj = prj_bytes(&georef(Some(32611), None)).unwrap();
        assert_eq!(
            prj,
            format!("{}\n", wkt_of_epsg(32611).unwrap()).into_bytes()
        );
    }

    #[test]
    fn prj_parsing_keeps_unknown_text() {
        let esri = b"PROJCS[\"NAD_1983_UTM_Zone_11N\",GEOGCS[\"GCS_North_American_1983\"]]\r\n";
        let (t, e) = parse_prj(esri);
        assert_eq!(
            t,
            "PROJCS[\"NAD_1983_UTM_Zone_11N\",GEOGCS[\"GCS_North_American_1983\"]]"
        );
        assert_eq!(e, None);
        let (t, e) = parse_prj(b"\xef\xbb\xbfGEOGCS[\"x\",AUTHORITY[\"EPSG\",\"4326\"]]\n");
        assert_eq!(
            (t.as_str(), e),
            ("GEOGCS[\"x\",AUTHORITY[\"EPSG\",\"4326\"]]", Some(4326))
        );
        // Latin-1 bytes are kept as their characters.
        let (t, _) = parse_prj(b"GEOGCS[\"Bogot\xe1\"]");
        assert_eq!(t, "GEOGCS[\"Bogot\u{e1}\"]");
        let (t, e) = parse_prj(b"not a crs at all");
        assert_eq!((t.as_str(), e), ("not a crs at all", None));
    }

    #[test]
    fn both_parts_of_a_compound_crs() {
        // GDAL's keys for EPSG:32611+5703 (the citation as GDAL writes it).
        let mut g = georef(Some(32611), None);
        g.geokeys = Some(crate::model::GeoKeys {
            directory: vec![
                1, 1, 0, 5, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32611, 4096, 0, 1, 5703,
                4097, 34737, 14, 0,
            ],
            doubles: vec![],
            ascii: "NAVD88 height|".to_string(),
        });
        assert_eq!(
            crs_summary(&g).as_deref(),
            Some("EPSG:32611 + vertical EPSG:5703 (NAVD88 height)")
        );
        // Horizontal only: as before.
        assert_eq!(
            crs_summary(&georef(Some(4326), None)).as_deref(),
            Some("EPSG:4326")
        );
        assert_eq!(crs_summary(&georef(None, None)), None);
        // A compound WKT 1 (GDAL's SRTM one) and a WKT 2.
        let w1 = r#"COMPD_CS["WGS 84 + EGM96 geoid height",GEOGCS["WGS 84",AUTHORITY["EPSG","4326"]],VERT_CS["EGM96 geoid height",VERT_DATUM["EGM96 geoid",2005],AUTHORITY["EPSG","5773"]]]"#;
        assert_eq!(
            crs_summary(&georef(Some(4326), Some(w1))).as_deref(),
            Some("EPSG:4326 + vertical EPSG:5773 (EGM96 geoid height)")
        );
        let w2 = r#"COMPOUNDCRS["NAD83 + NAVD88",GEOGCRS["NAD83"],VERTCRS["NAVD88 height",VDATUM["North American Vertical Datum 1988"]]]"#;
        assert_eq!(
            crs_summary(&georef(None, Some(w2))).as_deref(),
            Some("\"NAD83 + NAVD88\" + vertical \"NAVD88 height\"")
        );
    }
}
