//! GeoJSON FeatureCollections of cells: one Polygon feature per non-empty cell.

use super::Cell;
use crate::error::{Error, Result};
use serde_json::{Map, Value, json};

/// What a cell's site is: the feature properties besides the residual statistics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SiteInfo {
    /// Importance rank (insertion order, 0 first).
    pub rank: usize,
    /// The level the site entered.
    pub level: usize,
    /// The site's value (height).
    pub value: f64,
}

/// What [`geojson`] puts around the features.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeoJsonOptions {
    /// EPSG code of the coordinates: written as the top-level `"crs"` member (GeoJSON 2008
    /// style, `urn:ogc:def:crs:EPSG::n`, which GDAL reads).
    pub epsg: Option<u32>,
    /// Members of the top-level foreign member `"vtz"` (level, reference, the file's bound…).
    pub about: Map<String, Value>,
}

/// A FeatureCollection of `cells` (coordinates as given), one Polygon feature per cell with
/// an area, in order, with properties `rank`, `level`, `value` (from `sites`, same length as
/// `cells`), `samples`, `eps_max` and `eps_rms`. Rings are counter-clockwise and closed
/// (RFC 7946's right-hand rule); numbers keep full precision. One line, ending in a newline.
pub fn geojson(cells: &[Cell], sites: &[SiteInfo], opts: &GeoJsonOptions) -> Result<Vec<u8>> {
    if cells.len() != sites.len() {
        return Err(Error::invalid(format!(
            "{} cells but {} site descriptions",
            cells.len(),
            sites.len()
        )));
    }
    let mut features = Vec::with_capacity(cells.len());
    for (c, s) in cells.iter().zip(sites) {
        if c.polygon.len() < 3 {
            continue;
        }
        let mut ring: Vec<[f64; 2]> = c.polygon.clone();
        if super::polygon_area(&ring) < 0.0 {
            ring.reverse();
        }
        ring.push(ring[0]);
        features.push(json!({
            "type": "Feature",
            "geometry": {"type": "Polygon", "coordinates": [ring]},
            "properties": {
                "rank": s.rank,
                "level": s.level,
                "value": finite(s.value),
                "samples": c.samples,
                "eps_max": finite(c.eps_max),
                "eps_rms": finite(c.eps_rms),
            },
        }));
    }
    let mut top = Map::new();
    top.insert("type".into(), json!("FeatureCollection"));
    if let Some(code) = opts.epsg {
        top.insert(
            "crs".into(),
            json!({"type": "name", "properties": {"name": format!("urn:ogc:def:crs:EPSG::{code}")}}),
        );
    }
    if !opts.about.is_empty() {
        top.insert("vtz".into(), Value::Object(opts.about.clone()));
    }
    top.insert("features".into(), Value::Array(features));
    let mut out = serde_json::to_vec(&Value::Object(top))
        .map_err(|e| Error::invalid(format!("GeoJSON encoding failed: {e}")))?;
    out.push(b'\n');
    Ok(out)
}

/// JSON has no NaN or infinity: those become null.
fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn features_rings_and_crs() {
        let cells = vec![
            Cell {
                polygon: vec![[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]],
                samples: 3,
                eps_max: 2.0,
                eps_rms: 1.0,
            },
            Cell {
                polygon: vec![],
                samples: 0,
                eps_max: 0.0,
                eps_rms: 0.0,
            },
        ];
        let sites = [
            SiteInfo {
                rank: 0,
                level: 0,
                value: 5.5,
            },
            SiteInfo {
                rank: 1,
                level: 1,
                value: f64::NAN,
            },
        ];
        let mut about = Map::new();
        about.insert("level".into(), json!(1));
        let opts = GeoJsonOptions {
            epsg: Some(4326),
            about,
        };
        let v: Value = serde_json::from_slice(&geojson(&cells, &sites, &opts).unwrap()).unwrap();
        assert_eq!(v["crs"]["properties"]["name"], "urn:ogc:def:crs:EPSG::4326");
        assert_eq!(v["vtz"]["level"], 1);
        let f = v["features"].as_array().unwrap();
        assert_eq!(f.len(), 1);
        let ring = f[0]["geometry"]["coordinates"][0].as_array().unwrap();
        assert_eq!(ring.len(), 5);
        assert_eq!(ring[0], ring[4]);
        let pts: Vec<[f64; 2]> = ring[..4]
            .iter()
            .map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()])
            .collect();
        assert_eq!(crate::cells::polygon_area(&pts), 1.0, "counter-clockwise");
        assert_eq!(f[0]["properties"]["samples"], 3);
        assert!(geojson(&cells, &sites[..1], &opts).is_err());
    }
}
