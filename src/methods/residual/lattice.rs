//! The integer domain the residual layer codes in: every value is `offset + (k · mul) / div`
//! for an integer k, rounded to the sample type. Detected from the data (the source's own
//! codes for integer types; whole numbers, decimal steps 0.1 … 0.0001 or a power-of-two
//! step for floats), so that lossless means exact lattice indices and a bound below half a
//! step means lossless.

use rayon::prelude::*;
use crate::model::{Raster, SampleType};
use crate::quant::finish;

/// Largest |k| (and clamp range) the layer codes: keeps every predictor's integer arithmetic
/// far from i64 overflow (spec/FORMAT.md, residual section).
pub const MAX_UNITS: i64 = 1 << 38;

/// How lattice indices map to values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    pub mul: f64,
    pub div: f64,
    pub offset: f64,
}

impl Domain {
    /// The value of index `k` before rounding to the sample type (the decoder's formula:
    /// one multiplication, one division, one addition, each rounded to nearest f64).
    #[inline]
    pub fn raw(&self, k: i64) -> f64 {
        self.offset + (k as f64 * self.mul) / self.div
    }

    /// The nearest index of `v`.
    #[inline]
    pub fn index(&self, v: f64) -> f64 {
        ((v - self.offset) * self.div / self.mul).round()
    }

    /// Value step between neighbouring indices.
    pub fn unit(&self) -> f64 {
        (self.mul / self.div).abs()
    }
}

/// The indices of `r`'s valid samples on `d` (0 elsewhere), if every one is exactly on it
/// but at most `misses` (the exceptions, whose index is the nearest one).
fn exact(r: &Raster, d: Domain) -> Option<Vec<i64>> {
    near(r, d, 0).map(|(k, _)| k)
}

/// [`exact`] allowing up to `misses` samples off the lattice: their indices (sorted).
fn near(r: &Raster, d: Domain, misses: usize) -> Option<(Vec<i64>, Vec<usize>)> {
    let mut out = vec![0i64; r.len()];
    // On the whole numbers (most DEMs), a whole value v in range is its own index and its
    // own finished value: the same answer as the general test below, without its roundings
    // (a library call each on baseline x86-64).
    let whole = d == Domain { mul: 1.0, div: 1.0, offset: 0.0 };
    let own_value: fn(f64) -> bool = match (r.sample_type, r.sample_type.int_range()) {
        (SampleType::F32, _) => |v| v as f32 as f64 == v,
        (SampleType::F64, _) => |_| true,
        _ => |_| false,
    };
    let int_own = r.mapping.is_identity().then(|| r.sample_type.int_range()).flatten();
    // Chunks of samples side by side, each with its samples off the lattice (`None`: an
    // index out of range, or more misses than allowed in the chunk alone); joined in order,
    // the same answer as one pass over the samples.
    const CHUNK: usize = 1 << 16;
    let offs: Option<Vec<Vec<usize>>> = out
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, o)| {
            let mut off = Vec::new();
            for (j, slot) in o.iter_mut().enumerate() {
                let i = c * CHUNK + j;
                if !r.is_valid(i) {
                    continue;
                }
                let v = r.data[i];
                if whole {
                    let k = v as i64;
                    let own = match int_own {
                        Some((lo, hi)) => v >= lo && v <= hi,
                        None => own_value(v),
                    };
                    if k as f64 == v && k.abs() <= MAX_UNITS && own {
                        *slot = k;
                        continue;
                    }
                }
                let k = d.index(v);
                if k.is_nan() || k.abs() > MAX_UNITS as f64 {
                    return None;
                }
                let k = k as i64;
                if finish(d.raw(k), r.sample_type, r.mapping) != v {
                    if off.len() == misses {
                        return None;
                    }
                    off.push(i);
                }
                *slot = k;
            }
            Some(off)
        })
        .collect();
    let off = offs?.concat();
    (off.len() <= misses).then_some((out, off))
}

/// Float data almost on whole numbers or a decimal step (DEMs whose voids were filled by
/// interpolation): at most 1/16 of the valid samples off it (each costs ~6 bytes stored verbatim,
/// against the many bits per sample a power-of-two step finer than the data would cost). Returns the lattice, the
/// indices (the nearest for the exceptions) and the exceptions, which a lossless encoder
/// stores verbatim.
pub fn with_exceptions(r: &Raster) -> Option<(Domain, Vec<i64>, Vec<usize>)> {
    if r.sample_type.is_integer() {
        return None;
    }
    let misses = r.valid_count() / 16;
    if misses == 0 {
        return None;
    }
    let (lo, hi) = r.valid_range()?;
    let amax = lo.abs().max(hi.abs());
    for digits in 0..=4 {
        let div = 10f64.powi(digits);
        if digits > 0 && 1.0 / div < 2.0 * float_spacing(r) * amax {
            break;
        }
        let d = Domain {
            mul: 1.0,
            div,
            offset: 0.0,
        };
        if let Some((k, off)) = near(r, d, misses) {
            return Some((d, k, off));
        }
    }
    None
}

/// The relative spacing of the sample type's floats.
fn float_spacing(r: &Raster) -> f64 {
    if r.sample_type == SampleType::F32 {
        2f64.powi(-23)
    } else {
        2f64.powi(-52)
    }
}

/// The data's own lattice, exactly: the source's codes (integer types), whole numbers, or a
/// decimal step coarser than float spacing. (The encoder's other choices, in order:
/// [`with_exceptions`] when lossless, [`pow2`], then [`approximate`] when lossy.)
pub fn stepped(r: &Raster) -> Option<(Domain, Vec<i64>)> {
    let m = r.mapping;
    if r.sample_type.is_integer() {
        let d = Domain {
            mul: m.scale,
            div: 1.0,
            offset: m.offset,
        };
        return exact(r, d).map(|k| (d, k));
    }
    let whole = Domain {
        mul: 1.0,
        div: 1.0,
        offset: 0.0,
    };
    if let Some(k) = exact(r, whole) {
        return Some((whole, k));
    }
    let (lo, hi) = r.valid_range()?;
    let amax = lo.abs().max(hi.abs());
    let eps = float_spacing(r);
    for digits in 1..=4 {
        let div = 10f64.powi(digits);
        // A decimal step finer than twice the float spacing is no lattice: every value
        // would trivially fit.
        if 1.0 / div < 2.0 * eps * amax {
            break;
        }
        let d = Domain {
            mul: 1.0,
            div,
            offset: 0.0,
        };
        if let Some(k) = exact(r, d) {
            return Some((d, k));
        }
    }
    None
}

/// The coarsest power of two dividing every valid value, when the indices fit.
pub fn pow2(r: &Raster) -> Option<(Domain, Vec<i64>)> {
    let mut e_min = i32::MAX;
    for (i, &v) in r.data.iter().enumerate() {
        if r.is_valid(i) && v != 0.0 {
            e_min = e_min.min(pow2_exponent(v));
        }
    }
    if e_min == i32::MAX {
        e_min = 0;
    }
    let d = Domain {
        mul: 2f64.powi(e_min),
        div: 1.0,
        offset: 0.0,
    };
    if !d.mul.is_normal() {
        return None;
    }
    exact(r, d).map(|k| (d, k))
}

/// The exponent of the lowest set bit of a finite non-zero f64's value.
fn pow2_exponent(v: f64) -> i32 {
    let bits = v.to_bits();
    let exp = ((bits >> 52) & 0x7ff) as i32;
    let mant = if exp == 0 {
        bits & ((1 << 52) - 1)
    } else {
        (bits & ((1 << 52) - 1)) | (1 << 52)
    };
    let e = if exp == 0 { -1074 } else { exp - 1075 };
    e + mant.trailing_zeros() as i32
}

/// A lattice for lossy coding of data without one of its own: a power-of-two step at most
/// `e / 64`, indices rounded (so they may be off by half a step).
pub fn approximate(r: &Raster, e: f64) -> Option<(Domain, Vec<i64>)> {
    let step = 2f64.powi((e / 64.0).log2().floor() as i32);
    if !step.is_normal() {
        return None;
    }
    let d = Domain {
        mul: step,
        div: 1.0,
        offset: 0.0,
    };
    let mut out = vec![0i64; r.len()];
    for (i, &v) in r.data.iter().enumerate() {
        if r.is_valid(i) {
            let k = d.index(v);
            if k.is_nan() || k.abs() > MAX_UNITS as f64 {
                return None;
            }
            out[i] = k as i64;
        }
    }
    Some((d, out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ValueMapping;
    use crate::testutil::Rng;

    /// `near` without its whole-number shortcut: the general test for every sample.
    fn near_reference(r: &Raster, d: Domain, misses: usize) -> Option<(Vec<i64>, Vec<usize>)> {
        let mut out = vec![0i64; r.len()];
        let mut off = Vec::new();
        for (i, &v) in r.data.iter().enumerate() {
            if !r.is_valid(i) {
                continue;
            }
            let k = d.index(v);
            if k.is_nan() || k.abs() > MAX_UNITS as f64 {
                return None;
            }
            let k = k as i64;
            if finish(d.raw(k), r.sample_type, r.mapping) != v {
                if off.len() == misses {
                    return None;
                }
                off.push(i);
            }
            out[i] = k;
        }
        Some((out, off))
    }

    /// Whole, fractional, signed-zero, out-of-range and off-f32 values on every sample
    /// type and mapping: the shortcut gives the general test's indices and misses.
    #[test]
    fn the_whole_number_shortcut_is_the_general_test() {
        let mut rng = Rng(5);
        let whole = Domain { mul: 1.0, div: 1.0, offset: 0.0 };
        let tenth = Domain { mul: 1.0, div: 10.0, offset: 0.0 };
        let specials = [-0.0, 0.0, 0.5, -1.5, 32767.0, 32768.0, -32769.0, 65535.0, 1e12, 3e11, 16777217.0, 0.1];
        for st in [SampleType::F32, SampleType::F64, SampleType::I16, SampleType::U16, SampleType::U8] {
            for mapping in [ValueMapping { scale: 1.0, offset: 0.0 }, ValueMapping { scale: 0.5, offset: -10.0 }] {
                for case in 0..20 {
                    let n = 200;
                    let data: Vec<f64> = (0..n)
                        .map(|_| {
                            if case % 4 == 0 && rng.below(10) == 0 {
                                specials[rng.below(specials.len() as u64) as usize]
                            } else {
                                rng.below(3000) as f64 - 1000.0
                            }
                        })
                        .collect();
                    let mut r = Raster::from_values(20, 10, data, None, SampleType::F64).unwrap();
                    (r.sample_type, r.mapping) = (st, mapping);
                    for d in [whole, tenth] {
                        for misses in [0, 3, 50] {
                            assert_eq!(near(&r, d, misses), near_reference(&r, d, misses), "{st:?} {mapping:?} case {case}");
                        }
                    }
                }
            }
        }
    }

    /// Over several chunks: misses spread over chunks count together, against a limit
    /// below, at and above their number.
    #[test]
    fn misses_in_several_chunks_count_together() {
        let mut rng = Rng(9);
        let (w, h) = (1000, 300);
        let data: Vec<f64> = (0..w * h)
            .map(|i| if i % 40_000 == 7 { 0.25 } else { rng.below(3000) as f64 })
            .collect();
        let misses = data.iter().filter(|&&v| v == 0.25).count();
        assert!(misses > 4 && w * h > 4 << 16);
        let r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
        let whole = Domain { mul: 1.0, div: 1.0, offset: 0.0 };
        for m in [0, misses - 1, misses, misses + 1] {
            let got = near(&r, whole, m);
            assert_eq!(got, near_reference(&r, whole, m), "limit {m}");
            assert_eq!(got.is_some(), m >= misses, "limit {m}");
        }
    }
}
