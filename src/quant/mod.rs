//! The value lattice every lossy method quantizes on, output rounding to the sample type,
//! and the one bound check (max error over valid samples).

use crate::container::Header;
use crate::error::{Error, Result};
use crate::model::{Raster, SampleType, ValueMapping};
use std::str::FromStr;

/// A max-error (or RMSE) bound as the user gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ErrorBound {
    /// In data units (e.g. metres).
    Abs(f64),
    /// In percent of the value range (max − min over valid samples).
    PercentOfRange(f64),
}

impl ErrorBound {
    /// Parse `"2.5"` (data units) or `"1%"` (of the value range).
    pub fn parse(s: &str) -> Result<ErrorBound> {
        let t = s.trim();
        let (num, pct) = match t.strip_suffix('%') {
            Some(n) => (n.trim(), true),
            None => (t, false),
        };
        let v: f64 = num
            .parse()
            .map_err(|_| Error::invalid(format!("'{s}' is not an error bound (e.g. 2.5 or 1%)")))?;
        if !(v >= 0.0 && v.is_finite()) {
            return Err(Error::invalid(format!(
                "error bound '{s}' must be a finite number ≥ 0 (e.g. 2.5 or 1%)"
            )));
        }
        Ok(if pct {
            ErrorBound::PercentOfRange(v)
        } else {
            ErrorBound::Abs(v)
        })
    }

    /// The bound in data units for a raster with this value range.
    pub fn absolute(self, range: Option<(f64, f64)>) -> f64 {
        match self {
            ErrorBound::Abs(v) => v,
            ErrorBound::PercentOfRange(p) => range.map_or(0.0, |(lo, hi)| (hi - lo) * p / 100.0),
        }
    }
}

impl FromStr for ErrorBound {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        ErrorBound::parse(s)
    }
}

/// The code of value `v` on the lattice `offset + step · code` (nearest).
#[inline]
pub(crate) fn code_of(v: f64, step: f64, offset: f64) -> i64 {
    ((v - offset) / step).round() as i64
}

/// The value of lattice code `code` (the decoder's formula).
#[inline]
pub(crate) fn height_of(code: i64, step: f64, offset: f64) -> f64 {
    offset + step * code as f64
}

/// Round a surface value to what the output sample type can hold (every decoder's last
/// step, so the encoder checks its bound on exactly these values).
pub(crate) fn finish_value(v: f64, h: &Header) -> f64 {
    finish(v, h.sample_type, h.mapping)
}

/// [`finish_value`] for a sample type and value mapping: f32 rounding, or the nearest
/// source code clamped to the integer type's range.
#[inline]
pub(crate) fn finish(v: f64, st: SampleType, m: ValueMapping) -> f64 {
    st.nearest_value(v, m)
}

/// The one bound check: the max error, sum of squares and mean absolute error of decoded
/// values against the source's valid samples, accumulated in sample order. Every encoder
/// runs it on exactly what its decoder produces; `vtz compare` runs it on two rasters.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Errors {
    pub max: f64,
    sum2: f64,
    /// The sum of squares scaled by 2^-1200 (each error by 2^-600), for errors whose squares
    /// overflow (f64 data over ±1e154): the rmse is then finite (a stored rmse must be).
    sum2_scaled: f64,
    sum1: f64,
    pub n: usize,
}

/// 2^-600: errors up to f64::MAX square to ≤ 2^256 after this scale.
const RMSE_SCALE: f64 = 2.409919865102884e-181;

impl Errors {
    /// Add one sample's decoded value `decoded` against its source value `source`; returns
    /// the absolute error.
    #[inline]
    pub fn add(&mut self, decoded: f64, source: f64) -> f64 {
        let e = (decoded - source).abs();
        self.max = self.max.max(e);
        self.sum2 += e * e;
        self.sum2_scaled += (e * RMSE_SCALE) * (e * RMSE_SCALE);
        self.sum1 += e;
        self.n += 1;
        e
    }

    /// The root mean square error (0 over no samples).
    pub fn rmse(&self) -> f64 {
        let n = self.n.max(1) as f64;
        if self.sum2.is_finite() {
            (self.sum2 / n).sqrt()
        } else {
            ((self.sum2_scaled / n).sqrt() / RMSE_SCALE).min(self.max)
        }
    }

    /// The mean absolute error (0 over no samples).
    pub fn mean_abs(&self) -> f64 {
        self.sum1 / self.n.max(1) as f64
    }

    /// The errors of `decoded` against the valid samples of `r`; `None` when a valid
    /// sample has no decoded value (the decoder would produce a non-finite value).
    pub fn of(r: &Raster, decoded: impl IntoIterator<Item = Option<f64>>) -> Option<Errors> {
        let mut e = Errors::default();
        for (i, (d, &v)) in decoded.into_iter().zip(&r.data).enumerate() {
            if r.is_valid(i) {
                e.add(d?, v);
            }
        }
        Some(e)
    }
}
