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

/// A value for a data file (CSV columns): the shortest decimal of at most 15 significant
/// digits that reads back to the same 15-digit value (`1404.4070000000002`, a lattice
/// height `offset + step · code` computed in binary, prints `1404.407`; `84808.25` stays
/// `84808.25`). 15 digits is what every binary64 value round-trips through as decimal text,
/// so the difference from the stored binary value is below 5e-15 of it; whole numbers print
/// whole and NaN/infinities as `NaN`/`inf`/`-inf`.
pub fn decimal(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let s = format!("{x:.14e}");
    let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
    let Ok(v) = format!("{m}e{e}").parse::<f64>() else {
        return format!("{x}");
    };
    // Rust's `Display` / `LowerExp` are the shortest text that parses back to `v` exactly;
    // exponents only where plain digits would run long.
    if (1e-5..1e16).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A number for people: the digits that matter and no more. Whole numbers print whole
/// (`1579`, `-32768`); others keep 6 significant digits without trailing zeros (`0.0620`
/// becomes `0.062`, `0.1916875000000001` becomes `0.191688`); tiny and huge magnitudes use
/// exponent notation (`1.5e-9`); infinities and NaN print as `inf`, `-inf`, `NaN`.
pub fn num(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == x.trunc() && x.abs() < 1e15 {
        return format!("{}", x as i64);
    }
    let a = x.abs();
    if !(1e-4..1e15).contains(&a) {
        let s = format!("{x:.5e}");
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = m.trim_end_matches('0').trim_end_matches('.');
        return format!("{m}e{e}");
    }
    let digits = (6 - 1 - a.log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

#[cfg(test)]
mod tests {
    use super::{decimal, num};

    #[test]
    fn decimals_are_the_shortest_15_digit_text() {
        assert_eq!(decimal(1404.4070000000002), "1404.407");
        assert_eq!(decimal(2210.2290000000003), "2210.229");
        assert_eq!(decimal(-1.0219999999999985), "-1.022");
        assert_eq!(decimal(84808.25), "84808.25");
        assert_eq!(decimal(-160.0 + 0.0008333333333333334), "-159.999166666667");
        assert_eq!(decimal(1579.0), "1579");
        assert_eq!(decimal(1e-300), "1e-300");
        assert_eq!(decimal(-0.0), "0");
        assert_eq!(decimal(f64::NAN), "NaN");
        // Within half a unit of the 15th digit, always.
        for x in [
            1.0 / 3.0,
            2.0f64.sqrt() * 1e7,
            -123.456e-5,
            6.431955092190876,
        ] {
            let back: f64 = decimal(x).parse().unwrap();
            assert!((back - x).abs() <= 5e-15 * x.abs(), "{x}");
        }
    }

    #[test]
    fn numbers_print_with_the_digits_that_matter() {
        assert_eq!(num(1579.0), "1579");
        assert_eq!(num(-32768.0), "-32768");
        assert_eq!(num(0.0620), "0.062");
        assert_eq!(num(0.1916875000000001), "0.191688");
        assert_eq!(num(2.5), "2.5");
        assert_eq!(num(0.945), "0.945");
        assert_eq!(num(1.0 / 3.0), "0.333333");
        assert_eq!(num(123456.789), "123457");
        assert_eq!(num(1.5e-9), "1.5e-9");
        assert_eq!(num(f64::INFINITY), "inf");
        assert_eq!(num(-0.0), "0");
    }
}
