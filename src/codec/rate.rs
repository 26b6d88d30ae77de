//! Rate control: size targets (`--bps`, `--size`) by bisection on the bound, or on the
//! quantizer step for a wavelet.

use super::encode::EncodeReport;
use super::options::EncodeOptions;
use crate::error::{Error, Result};
use crate::methods::{Method, REGISTRY};
use crate::model::Raster;
use crate::quant::ErrorBound;

/// Bisect the max-error bound (geometrically, between 10⁻⁶ of the range and the range) for
/// the smallest bound whose file is at most `target` bytes.
pub(crate) fn encode_to_size(
    raster: &Raster,
    opts: &EncodeOptions,
    target: u64,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, EncodeReport)> {
    if opts.max_error.is_some() || REGISTRY.iter().any(|m| m.stops_by_itself(&opts.params)) {
        return Err(Error::invalid(
            "a size target excludes --max-error, --rmse and --sites",
        ));
    }
    let range = raster.valid_range().map_or(0.0, |(lo, hi)| hi - lo);
    let mut o = opts.clone();
    o.target_bytes = None;
    let mut try_bound = |e: f64| {
        o.max_error = Some(ErrorBound::Abs(e));
        super::encode::encode_once(raster, &o, &mut |_| {})
    };
    // Lossless first: if it fits, nothing is lost.
    let lossless = {
        let mut l = opts.clone();
        l.target_bytes = None;
        l.methods = Method::all().filter(|m| m.0.lossless_default()).collect();
        l.params = Default::default();
        super::encode::encode_once(raster, &l, &mut |_| {})?
    };
    if lossless.0.len() as u64 <= target || range <= 0.0 {
        return Ok(lossless);
    }
    type Encoded = (Vec<u8>, EncodeReport);
    /// Geometric bisection on a parameter where larger means smaller files: the smallest
    /// value in [lo, hi] whose file fits.
    fn bisect(
        (mut lo, mut hi): (f64, f64),
        steps: usize,
        target: u64,
        what: &str,
        try_x: &mut dyn FnMut(f64) -> Result<Encoded>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<Encoded> {
        let mut best = try_x(hi)?;
        if best.0.len() as u64 > target {
            return Err(Error::invalid(format!(
                "cannot fit in {target} bytes: {} bytes at {what}",
                best.0.len()
            )));
        }
        for k in 0..steps {
            let mid = (lo * hi).sqrt();
            let r = try_x(mid)?;
            if r.0.len() as u64 <= target {
                hi = mid;
                best = r;
            } else {
                lo = mid;
            }
            progress((k + 1) as f64 / steps as f64);
        }
        Ok(best)
    }
    if let [m] = opts.methods[..] {
        if let Some(knob) = m.0.rate_knob() {
            let mut o = opts.clone();
            o.target_bytes = None;
            let mut try_knob = |q: f64| {
                (knob.set)(&mut o.params, q);
                super::encode::encode_once(raster, &o, &mut |_| {})
            };
            let span = (range * knob.span.0, range * knob.span.1);
            return bisect(span, knob.steps, target, knob.what, &mut try_knob, progress);
        }
    }
    bisect(
        (range * 1e-6, range),
        14,
        target,
        "a max error of the whole range",
        &mut try_bound,
        progress,
    )
}
