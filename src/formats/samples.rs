//! Float32 samples for the writers that store them (GeoTIFF, OpenEXR, raw f32).

use crate::error::{Error, Result};
use crate::model::Raster;

/// Valid sample `i` as float32, or an error naming it when it does not fit.
pub(crate) fn valid_f32(r: &Raster, i: usize) -> Result<f32> {
    let v = r.data[i];
    let s = v as f32;
    if !s.is_finite() {
        return Err(Error::invalid(format!(
            "sample {i} (row {}, col {}) = {v} does not fit in float32",
            i / r.width,
            i % r.width
        )));
    }
    Ok(s)
}

/// Every sample as float32: valid ones by [`valid_f32`], invalid ones `fill`.
pub(crate) fn f32_samples(r: &Raster, fill: f32) -> Result<Vec<f32>> {
    (0..r.len())
        .map(|i| {
            if r.is_valid(i) {
                valid_f32(r, i)
            } else {
                Ok(fill)
            }
        })
        .collect()
}
