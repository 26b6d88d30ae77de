//! The integrity check of a point-set file (`vtz verify` of a version-3 file).

use super::{DecodePoints, decode_points};
use crate::codec::Verified;
use crate::container::Limits;
use crate::container::points::PointsFile;
use crate::error::{Error, Result};

/// Check a point-set file (version 3): its framing, the checksum of every section, a full
/// decode (every point of every column finite, as many points as the header says), and
/// each column's stored statistics against its stored bound (the encoder checked every
/// input point against the bound before it wrote the file, so rmse ≤ max error ≤ bound;
/// the source points are not in the file, so this is as far as the bounds can be checked).
pub fn verify_points(bytes: &[u8], limits: Limits) -> Result<Verified> {
    let f = PointsFile::read(bytes, limits)?;
    let mut unknown = Vec::new();
    for (i, e) in f.entries.iter().enumerate() {
        f.payload(i)?;
        if e.name.starts_with("unknown") {
            unknown.push(i);
        }
    }
    let p = decode_points(
        bytes,
        &DecodePoints {
            limits,
            ..Default::default()
        },
    )?;
    let h = &f.header;
    if p.len() as u64 != h.points {
        return Err(Error::corrupt(format!(
            "decodes to {} points, the header says {}",
            p.len(),
            h.points
        )));
    }
    let mut surfaces = Vec::new();
    for (c, col) in h.columns.iter().enumerate() {
        let at = |what: String| Error::corrupt(format!("column {c} ({}): {what}", col.name));
        if let Some(k) = p.values[c].iter().position(|v| !v.is_finite()) {
            return Err(at(format!("point {k} decodes to {}", p.values[c][k])));
        }
        if col.max_error > col.bound || col.rmse > col.max_error * (1.0 + 1e-9) {
            return Err(at(format!(
                "the stored rmse {} and max error {} do not keep within the stored bound {}",
                col.rmse, col.max_error, col.bound
            )));
        }
        surfaces.push((c, col.name.clone(), col.max_error));
    }
    Ok(Verified {
        sections: f.entries.len(),
        surfaces,
        valid: h.points,
        unknown,
        tiles: 0,
        point_set: true,
    })
}
