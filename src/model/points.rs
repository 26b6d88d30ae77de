//! The point-set model: scattered (x, y) positions with t values per point, beside the raster.
//!
//! Survey points, GPS tracks, lidar ground returns and sonar soundings have no grid: a point
//! set is a list of positions in a CRS's units (f64, so UTM and national grids of 10⁶–10⁷ m
//! keep sub-millimetre precision) and one or more value columns ("bands": elevation, and
//! further numeric columns such as intensity or uncertainty), each with one value per point.

use crate::error::{Error, Result};

/// Scattered points with `t ≥ 1` values each.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PointSet {
    /// Easting (or x) of each point.
    pub x: Vec<f64>,
    /// Northing (or y) of each point.
    pub y: Vec<f64>,
    /// The name of each value column (`z` for elevation when the source did not name it).
    pub names: Vec<String>,
    /// `values[c][i]`: column c's value at point i. Every column has one value per point.
    pub values: Vec<Vec<f64>>,
    /// EPSG code of the positions' CRS when known.
    pub epsg: Option<u32>,
    /// A WKT description of the CRS when the source gave one.
    pub wkt: Option<String>,
}

impl PointSet {
    /// A point set with one elevation column named `z`.
    pub fn from_xyz(x: Vec<f64>, y: Vec<f64>, z: Vec<f64>) -> Result<Self> {
        let p = PointSet {
            x,
            y,
            names: vec!["z".into()],
            values: vec![z],
            epsg: None,
            wkt: None,
        };
        p.validate()?;
        Ok(p)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Number of value columns (t).
    pub fn columns(&self) -> usize {
        self.values.len()
    }

    /// Check the shape and that every coordinate and value is finite; the error names the
    /// first bad point (1-based, as a reader's record number would).
    pub fn validate(&self) -> Result<()> {
        let n = self.x.len();
        if self.y.len() != n {
            return Err(Error::invalid("point set: x and y have different lengths"));
        }
        if self.values.is_empty() {
            return Err(Error::invalid("point set: no value column"));
        }
        if self.names.len() != self.values.len() {
            return Err(Error::invalid("point set: one name per value column"));
        }
        for (c, col) in self.values.iter().enumerate() {
            if col.len() != n {
                return Err(Error::invalid(format!(
                    "point set: column '{}' has {} values for {n} points",
                    self.names[c],
                    col.len()
                )));
            }
        }
        for i in 0..n {
            if !(self.x[i].is_finite() && self.y[i].is_finite()) {
                return Err(Error::invalid(format!(
                    "point {}: position is not a finite number",
                    i + 1
                )));
            }
            for (c, col) in self.values.iter().enumerate() {
                if !col[i].is_finite() {
                    return Err(Error::invalid(format!(
                        "point {}: value of '{}' is not a finite number",
                        i + 1,
                        self.names[c]
                    )));
                }
            }
        }
        Ok(())
    }

    /// The positions' bounding box `[xmin, ymin, xmax, ymax]` (None when empty).
    pub fn bounds(&self) -> Option<[f64; 4]> {
        if self.is_empty() {
            return None;
        }
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in 0..self.len() {
            b[0] = b[0].min(self.x[i]);
            b[1] = b[1].min(self.y[i]);
            b[2] = b[2].max(self.x[i]);
            b[3] = b[3].max(self.y[i]);
        }
        Some(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_names_the_bad_point() {
        let p = PointSet::from_xyz(vec![0.0, 1.0], vec![0.0, f64::NAN], vec![1.0, 2.0]);
        let e = p.unwrap_err().to_string();
        assert!(e.contains("point 2"), "{e}");
        let p = PointSet::from_xyz(vec![0.0, 1.0], vec![0.0, 1.0], vec![1.0, 2.0]).unwrap();
        assert_eq!(p.bounds(), Some([0.0, 0.0, 1.0, 1.0]));
    }
}
