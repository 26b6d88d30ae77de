//! Float32 samples for the writers that store them (GeoTIFF, OpenEXR, raw f32), and the
//! rounding check of every writer whose storage cannot hold every value.

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

/// The largest change a writer's codes make to a valid sample: nothing about the data
/// changes silently, so a writer that would round refuses unless the caller allows it.
#[derive(Default)]
pub(crate) struct Rounding {
    worst: Option<(usize, f64, f64)>,
}

impl Rounding {
    pub(crate) fn note(&mut self, i: usize, v: f64, stored: f64) {
        let d = (stored - v).abs();
        if d > 0.0 && self.worst.is_none_or(|(_, a, b)| d > (b - a).abs()) {
            self.worst = Some((i, v, stored));
        }
    }

    /// `hint` follows the message (e.g. other formats that keep the values).
    pub(crate) fn check(&self, r: &Raster, round: bool, what: &str, hint: &str) -> Result<()> {
        match self.worst {
            Some((i, v, stored)) if !round => {
                let num = crate::metrics::num;
                Err(Error::invalid(format!(
                    "{what} cannot hold these values exactly: sample {i} (row {}, col {}) = {} would become {} (a change of {}); pass --round to accept the rounding{hint}",
                    i / r.width,
                    i % r.width,
                    num(v),
                    num(stored),
                    num((stored - v).abs())
                )))
            }
            _ => Ok(()),
        }
    }
}

/// Refuse to store valid samples as float32 when float32 would change them (float64 data,
/// int32 beyond 2^24), unless the caller allows rounding.
pub(crate) fn check_f32(r: &Raster, round: bool, what: &str) -> Result<()> {
    let mut worst = Rounding::default();
    for (i, &v) in r.data.iter().enumerate() {
        if r.is_valid(i) {
            worst.note(i, v, v as f32 as f64);
        }
    }
    worst.check(
        r,
        round,
        what,
        ", or write .tif, which keeps the source's sample type",
    )
}
