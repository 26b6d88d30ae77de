//! GeoPackage output of cells: an SQLite database with one polygon feature table `cells`
//! (OGC GeoPackage 1.3: the required metadata tables, GeoPackage binary geometries).

use super::{Cell, GeoJsonOptions, SiteInfo};
use crate::error::{Error, Result};
use rusqlite::{Connection, params};

fn db(e: rusqlite::Error) -> Error {
    Error::invalid(format!("GeoPackage: {e}"))
}

/// The GeoPackage binary geometry of a polygon ring (closed here): the `GP` header
/// (version 0, little-endian, an xy envelope) and a little-endian WKB Polygon.
fn geometry(ring: &[[f64; 2]], srs_id: i32) -> Vec<u8> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in ring {
        x0 = x0.min(p[0]);
        x1 = x1.max(p[0]);
        y0 = y0.min(p[1]);
        y1 = y1.max(p[1]);
    }
    let mut b = vec![b'G', b'P', 0, 0b0000_0011];
    b.extend_from_slice(&srs_id.to_le_bytes());
    for v in [x0, x1, y0, y1] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.push(1);
    b.extend_from_slice(&3u32.to_le_bytes());
    b.extend_from_slice(&1u32.to_le_bytes());
    b.extend_from_slice(&((ring.len() + 1) as u32).to_le_bytes());
    for p in ring.iter().chain(std::iter::once(&ring[0])) {
        b.extend_from_slice(&p[0].to_le_bytes());
        b.extend_from_slice(&p[1].to_le_bytes());
    }
    b
}

/// `cells` (with their `sites`, as [`super::geojson`] takes them) as the bytes of a
/// GeoPackage (built in memory, so the caller writes it atomically). `wkt` is the CRS's
/// definition when `opts.epsg` is set (GeoPackage stores it beside the code; `undefined` is
/// allowed).
pub fn gpkg(
    cells: &[Cell],
    sites: &[SiteInfo],
    opts: &GeoJsonOptions,
    wkt: Option<&str>,
) -> Result<Vec<u8>> {
    if cells.len() != sites.len() {
        return Err(Error::invalid(format!(
            "{} cells but {} site descriptions",
            cells.len(),
            sites.len()
        )));
    }
    let mut c = Connection::open_in_memory().map_err(db)?;
    c.execute_batch(
        r#"PRAGMA application_id = 1196444487;
         PRAGMA user_version = 10300;
         CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY,
           organization TEXT NOT NULL, organization_coordsys_id INTEGER NOT NULL,
           definition TEXT NOT NULL, description TEXT);
         CREATE TABLE gpkg_contents (table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL,
           identifier TEXT UNIQUE, description TEXT DEFAULT '',
           last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
           min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER,
           CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));
         CREATE TABLE gpkg_geometry_columns (table_name TEXT NOT NULL, column_name TEXT NOT NULL,
           geometry_type_name TEXT NOT NULL, srs_id INTEGER NOT NULL, z TINYINT NOT NULL,
           m TINYINT NOT NULL, CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name));
         INSERT INTO gpkg_spatial_ref_sys VALUES
           ('Undefined cartesian SRS', -1, 'NONE', -1, 'undefined', 'undefined cartesian coordinate reference system'),
           ('Undefined geographic SRS', 0, 'NONE', 0, 'undefined', 'undefined geographic coordinate reference system'),
           ('WGS 84 geodetic', 4326, 'EPSG', 4326, 'GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AXIS["Latitude",NORTH],AXIS["Longitude",EAST],AUTHORITY["EPSG","4326"]]', 'longitude/latitude coordinates in decimal degrees on the WGS 84 spheroid');
         CREATE TABLE cells (fid INTEGER PRIMARY KEY AUTOINCREMENT, geom POLYGON,
           rank INTEGER, level INTEGER, value REAL, samples INTEGER, eps_max REAL, eps_rms REAL);"#,
    )
    .map_err(db)?;
    let srs: i32 = match opts.epsg {
        Some(4326) => 4326,
        Some(code) => {
            let code = i32::try_from(code).map_err(|_| Error::invalid("EPSG code out of range"))?;
            c.execute(
                "INSERT INTO gpkg_spatial_ref_sys VALUES (?1, ?2, 'EPSG', ?2, ?3, NULL)",
                params![format!("EPSG:{code}"), code, wkt.unwrap_or("undefined")],
            )
            .map_err(db)?;
            code
        }
        None => -1,
    };
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    let tx = c.transaction().map_err(db)?;
    {
        let mut ins = tx
            .prepare(
                "INSERT INTO cells (geom, rank, level, value, samples, eps_max, eps_rms)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            )
            .map_err(db)?;
        let fin = |v: f64| v.is_finite().then_some(v);
        for (cell, s) in cells.iter().zip(sites) {
            if cell.polygon.len() < 3 {
                continue;
            }
            let mut ring = cell.polygon.clone();
            if super::polygon_area(&ring) < 0.0 {
                ring.reverse();
            }
            for p in &ring {
                x0 = x0.min(p[0]);
                y0 = y0.min(p[1]);
                x1 = x1.max(p[0]);
                y1 = y1.max(p[1]);
            }
            ins.execute(params![
                geometry(&ring, srs),
                s.rank as i64,
                s.level as i64,
                fin(s.value),
                cell.samples as i64,
                fin(cell.eps_max),
                fin(cell.eps_rms)
            ])
            .map_err(db)?;
        }
    }
    let about = serde_json::Value::Object(opts.about.clone()).to_string();
    tx.execute(
        "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, max_x, max_y, srs_id)
         VALUES ('cells', 'features', 'cells', ?1, ?2, ?3, ?4, ?5, ?6)",
        params![about, x0, y0, x1, y1, srs],
    )
    .map_err(db)?;
    tx.execute(
        "INSERT INTO gpkg_geometry_columns VALUES ('cells', 'geom', 'POLYGON', ?1, 0, 0)",
        params![srs],
    )
    .map_err(db)?;
    tx.commit().map_err(db)?;
    let bytes = c.serialize(rusqlite::MAIN_DB).map_err(db)?;
    Ok(bytes.to_vec())
}
