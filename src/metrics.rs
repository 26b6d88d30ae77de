//! Error and size metrics between two rasters: RMSE, max error, % of range, PSNR, bits/sample.

use crate::error::{Error, Result};
use crate::model::Raster;
use crate::quant::Errors;
use serde::Serialize;

/// How far a reconstruction is from a reference, over the reference's valid samples.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    /// Raster width.
    pub width: usize,
    /// Raster height.
    pub height: usize,
    /// Samples valid in the reference.
    pub valid: usize,
    /// Reference samples that are valid but nodata in the other raster.
    pub lost: usize,
    /// Samples nodata in the reference but valid in the other raster.
    pub invented: usize,
    /// Largest absolute difference over samples valid in both.
    pub max_error: f64,
    /// Root mean square difference over samples valid in both.
    pub rmse: f64,
    /// Mean absolute difference over samples valid in both.
    pub mean_abs_error: f64,
    /// max − min of the reference's valid samples.
    pub range: f64,
    /// `max_error` in % of the reference's value range.
    pub max_error_pct: f64,
    /// `rmse` in % of the reference's value range.
    pub rmse_pct: f64,
    /// 20·log10(range / rmse), infinite when identical.
    pub psnr_db: f64,
    /// Every valid sample bit-identical.
    pub identical: bool,
}

/// Compare `b` against the reference `a` (same size required).
pub fn compare(a: &Raster, b: &Raster) -> Result<Comparison> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::invalid(format!(
            "sizes differ: {}x{} and {}x{}",
            a.width, a.height, b.width, b.height
        )));
    }
    let mut errs = Errors::default();
    let (mut valid, mut lost, mut invented) = (0usize, 0usize, 0usize);
    let mut identical = true;
    for i in 0..a.len() {
        match (a.is_valid(i), b.is_valid(i)) {
            (true, true) => {
                identical &= a.data[i].to_bits() == b.data[i].to_bits();
                errs.add(a.data[i], b.data[i]);
                valid += 1;
            }
            (true, false) => {
                lost += 1;
                valid += 1;
            }
            (false, true) => invented += 1,
            (false, false) => {}
        }
    }
    let (max, rmse) = (errs.max, errs.rmse());
    let range = a.valid_range().map_or(0.0, |(lo, hi)| hi - lo);
    let pct = |v: f64| if range > 0.0 { 100.0 * v / range } else { 0.0 };
    Ok(Comparison {
        width: a.width,
        height: a.height,
        valid,
        lost,
        invented,
        max_error: max,
        rmse,
        mean_abs_error: errs.mean_abs(),
        range,
        max_error_pct: pct(max),
        rmse_pct: pct(rmse),
        psnr_db: if rmse > 0.0 {
            20.0 * (range / rmse).log10()
        } else {
            f64::INFINITY
        },
        identical: identical && lost == 0 && invented == 0,
    })
}

/// Bits per sample of a file of `bytes` bytes holding `samples` samples.
pub fn bits_per_sample(bytes: u64, samples: usize) -> f64 {
    8.0 * bytes as f64 / samples.max(1) as f64
}
