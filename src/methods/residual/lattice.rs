//! The integer domain the residual layer codes in: every value is `offset + (k · mul) / div`
//! for an integer k, rounded to the sample type. Detected from the data (the source's own
//! codes for integer types; whole numbers, decimal steps 0.1 … 0.0001, any other step
//! (values converted from another unit, e.g. feet × 0.3048: [`general`]) or a power-of-two
//! step for floats), so that lossless means exact lattice indices and a bound below half a
//! step means lossless. A lossless request checks the bits (a −0 sample is off a lattice
//! that decodes +0, and is stored verbatim as an exception or the lattice is not taken).

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
        self.raw_f(k as f64)
    }

    /// [`Domain::raw`] of an index already in f64 (exactly `k as f64`).
    #[inline]
    pub fn raw_f(&self, k: f64) -> f64 {
        self.offset + (k * self.mul) / self.div
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
/// (the same bits when `bits`, else the same value: −0 = +0).
fn exact(r: &Raster, d: Domain, bits: bool) -> Option<Vec<i64>> {
    near(r, d, 0, bits).map(|(k, _)| k)
}

/// Whether the decoded value `got` gives back the sample `v`: the same bits when `bits`
/// (a lossless request), else the same value.
#[inline]
fn same(got: f64, v: f64, bits: bool) -> bool {
    if bits { got.to_bits() == v.to_bits() } else { got == v }
}

/// [`exact`] allowing up to `misses` samples off the lattice: their indices (sorted).
fn near(r: &Raster, d: Domain, misses: usize, bits: bool) -> Option<(Vec<i64>, Vec<usize>)> {
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
                    if same(k as f64, v, bits) && k.abs() <= MAX_UNITS && own {
                        *slot = k;
                        continue;
                    }
                }
                let k = d.index(v);
                if k.is_nan() || k.abs() > MAX_UNITS as f64 {
                    return None;
                }
                let k = k as i64;
                if !same(finish(d.raw(k), r.sample_type, r.mapping), v, bits) {
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
/// stores verbatim (so the bits are checked). After the decimal steps, any step
/// ([`general`]).
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
        if let Some((k, off)) = near(r, d, misses, true) {
            return Some((d, k, off));
        }
    }
    general(r, misses, true, 0.0)
}

/// The relative spacing of the sample type's floats.
fn float_spacing(r: &Raster) -> f64 {
    if r.sample_type == SampleType::F32 {
        2f64.powi(-23)
    } else {
        2f64.powi(-52)
    }
}

/// The data's own lattice, exactly: the source's codes (integer types), whole numbers, a
/// decimal step coarser than float spacing, or any other step ([`general`]); the same bits
/// when `bits` (a lossless request). (The encoder's other choices, in order:
/// [`with_exceptions`] when lossless, [`pow2`], then [`approximate`] when lossy.)
pub fn stepped(r: &Raster, bits: bool) -> Option<(Domain, Vec<i64>)> {
    let m = r.mapping;
    if r.sample_type.is_integer() {
        let d = Domain {
            mul: m.scale,
            div: 1.0,
            offset: m.offset,
        };
        // Integer types hold no −0: the same value is the same code.
        return exact(r, d, false).map(|k| (d, k));
    }
    let whole = Domain {
        mul: 1.0,
        div: 1.0,
        offset: 0.0,
    };
    if let Some(k) = exact(r, whole, bits) {
        return Some(coarser(r, bits, whole, k));
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
        if let Some(k) = exact(r, d, bits) {
            return Some(coarser(r, bits, d, k));
        }
    }
    general(r, 0, bits, 0.0).map(|(d, k, _)| (d, k))
}

/// `d` (whole numbers or a decimal step, holding every sample as `k`), or a coarser step of
/// [`general`] that holds every sample too: whole metres in steps of 5, quarters from
/// bilinear halves of whole metres (on the 0.01 step otherwise). A step q times coarser
/// saves about log₂ q bits a sample.
fn coarser(r: &Raster, bits: bool, d: Domain, k: Vec<i64>) -> (Domain, Vec<i64>) {
    match general(r, 0, bits, 1.5 * d.unit()) {
        Some((g, kg, _)) => (g, kg),
        None => (d, k),
    }
}

/// How many valid samples [`general`] looks at to find a step.
const GENERAL_SAMPLE: usize = 1 << 16;

/// A lattice of any step b (offset 0, div 1: value = k · b, rounded to the sample type) that
/// holds every valid sample but at most `misses` (returned, sorted; the same bits when
/// `bits`): values converted from another unit, e.g. whole feet × 0.3048 in f32, which no
/// decimal or power-of-two step holds (pcodec's "float mult" mode). Cheap: the step comes
/// from a sample of at most [`GENERAL_SAMPLE`] valid samples ([`find_step`]); exact: every
/// valid sample is then checked as the decoder computes it ([`near`]). Steps under 16
/// float spacings of the largest value are no lattice (every value would fit one); nor,
/// here, steps of at most `above` (a step already found: then only a coarser one is
/// worth the check).
pub fn general(
    r: &Raster,
    misses: usize,
    bits: bool,
    above: f64,
) -> Option<(Domain, Vec<i64>, Vec<usize>)> {
    if r.sample_type.is_integer() {
        return None;
    }
    let (lo, hi) = r.valid_range()?;
    let amax = lo.abs().max(hi.abs());
    if !(amax > 0.0 && amax.is_finite()) {
        return None;
    }
    // Every sample is within half of this of the exact k · b it was rounded from.
    let spacing = float_spacing(r) * amax;
    let n = r.len();
    let stride = (n / GENERAL_SAMPLE).max(1);
    // Zeros are on every such lattice, and subnormals (−0 too, when `bits`) on none that a
    // step of 16 spacings allows: [`near`] stores them as exceptions.
    let tiny = if r.sample_type == SampleType::F32 {
        f32::MIN_POSITIVE as f64
    } else {
        f64::MIN_POSITIVE
    };
    let mut sample: Vec<f64> = (0..n)
        .step_by(stride)
        .filter(|&i| r.is_valid(i) && r.data[i].abs() >= tiny)
        .map(|i| r.data[i])
        .collect();
    let valid = r.valid_count().max(1);
    // Sampled values off the lattice allowed, in proportion to `misses`.
    let budget = sample.len() * misses / valid;
    let mul = find_step(r, &mut sample, spacing, budget)?;
    if mul.abs() <= above {
        return None;
    }
    let d = Domain {
        mul,
        div: 1.0,
        offset: 0.0,
    };
    near(r, d, misses, bits).map(|(k, off)| (d, k, off))
}

/// The step of [`general`] from a sample of its non-zero values (sorted here): from the
/// most frequent value (surely on the lattice), candidate steps — the median and the
/// smallest gap between distinct values, each also halved and thirded — are refined over
/// ever wider spans (a value more than a quarter step, or than its rounding allows once the
/// step is known, off it is an outlier: at most `budget` of them); then the shortest
/// decimal near the refined step (0.3048, not the nearest double to a measured ratio), or a
/// step from the interval of steps that give every other value back when rounded, is
/// checked on the sample as the decoder computes it. Of the candidates that pass, the
/// coarsest (a step's divisors hold the data too).
fn find_step(r: &Raster, sample: &mut [f64], spacing: f64, budget: usize) -> Option<f64> {
    sample.sort_by(f64::total_cmp);
    // The most frequent value.
    let (mut anchor, mut top, mut run) = (*sample.first()?, 0usize, 0usize);
    for (i, &v) in sample.iter().enumerate() {
        run = if i > 0 && sample[i - 1] == v { run + 1 } else { 1 };
        if run > top {
            (anchor, top) = (v, run);
        }
    }
    let mut vals = sample.to_vec();
    vals.dedup();
    if vals.len() < 3 {
        return None;
    }
    let mut gaps: Vec<f64> = vals.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    // Values by their distance from the anchor, nearest first.
    let mut order = vals.clone();
    order.sort_by(|a, b| (a - anchor).abs().total_cmp(&(b - anchor).abs()));
    // Sampled values off the step `mul` as the decoder computes them.
    let off = |mul: f64| {
        let d = Domain {
            mul,
            div: 1.0,
            offset: 0.0,
        };
        vals.iter()
            .filter(|&&v| {
                let k = d.index(v);
                !(k.abs() <= MAX_UNITS as f64 && finish(d.raw(k as i64), r.sample_type, r.mapping) == v)
            })
            .count()
    };
    let mut tried: Vec<f64> = Vec::new();
    let mut best: Option<f64> = None;
    for g in [gaps[gaps.len() / 2], gaps[0]] {
        for q in 1..=3 {
            let b = g / q as f64;
            if b.is_nan() || b < 16.0 * spacing || tried.contains(&b) {
                continue;
            }
            tried.push(b);
            let Some((b, n_best)) = refine(&order, anchor, b, spacing, budget) else {
                continue;
            };
            // The shortest decimal near the step that gives the sample back (0.3048, also
            // where the interval below is narrower than f64 can tell), else one from the
            // interval of steps the sample allows.
            let found = (0..=17)
                .map(|digits| {
                    let p = 10f64.powi(digits);
                    (b * p).round() / p
                })
                .filter(|&m| m != 0.0 && (m - b).abs() <= 1e-3 * b.abs())
                .find(|&m| off(m) <= budget)
                .or_else(|| {
                    step_interval(r, &vals, b, spacing, n_best, budget).filter(|&m| off(m) <= budget)
                });
            // A step that holds the data, so does any divisor of it: the coarsest is kept.
            if let Some(m) = found {
                if best.is_none_or(|x: f64| m.abs() > x.abs()) {
                    best = Some(m);
                }
            }
        }
    }
    best
}

/// How far off its lattice point a value may lie once the step is known from a span of
/// `n_best` steps: its own rounding, plus the step's error over `n` steps.
fn slack(n: f64, spacing: f64, n_best: f64) -> f64 {
    2.0 * spacing * (1.0 + n.abs() / n_best.max(1.0))
}

/// The step `b` refined over `order` (distinct values, nearest the anchor first): each
/// value's span from the anchor, `n` steps of about `b`, gives b = span / n from the widest
/// span so far. A value whose n is 0 or that lies off by more than a quarter step (or, once
/// a span of 16 steps has pinned the step down, by more than [`slack`]) is an outlier; more
/// than `budget` of them: `None`. Returns the step and its widest span in steps.
fn refine(order: &[f64], anchor: f64, mut b: f64, spacing: f64, budget: usize) -> Option<(f64, f64)> {
    let (mut n_best, mut outliers) = (0.0f64, 0usize);
    for &v in order {
        let span = v - anchor;
        if span == 0.0 {
            continue;
        }
        let n = (span / b).round();
        let mut tol = 0.25 * b;
        if n_best >= 16.0 {
            tol = tol.min(slack(n, spacing, n_best));
        }
        if n == 0.0 || (span - n * b).abs() > tol {
            outliers += 1;
            if outliers > budget {
                return None;
            }
            continue;
        }
        if n.abs() > n_best {
            b = span / n;
            n_best = n.abs();
        }
    }
    Some((b, n_best))
}

/// The steps m that give each value of `vals` on step `b` back as `k · m` rounded to the
/// sample type (k its nearest index) form an interval (values off by more than [`slack`]
/// are outliers, at most `budget`): the shortest decimal strictly inside it (else its
/// midpoint); `None` when it is empty.
fn step_interval(r: &Raster, vals: &[f64], b: f64, spacing: f64, n_best: f64, budget: usize) -> Option<f64> {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut outliers = 0usize;
    for &v in vals {
        let k = (v / b).round();
        if k == 0.0 || (v - k * b).abs() > slack(k, spacing, n_best) {
            outliers += 1;
            if outliers > budget {
                return None;
            }
            continue;
        }
        // The values that round to v: half-way to the neighbouring floats of its type.
        let (below, above) = neighbours(v, r.sample_type == SampleType::F32);
        let (a, z) = ((v + below) / 2.0 / k, (v + above) / 2.0 / k);
        let (a, z) = if k > 0.0 { (a, z) } else { (z, a) };
        lo = lo.max(a);
        hi = hi.min(z);
    }
    if lo.is_nan() || hi.is_nan() || lo >= hi {
        return None;
    }
    let mid = lo + (hi - lo) / 2.0;
    for digits in 0..=17 {
        let p = 10f64.powi(digits);
        let m = (mid * p).round() / p;
        if m > lo && m < hi {
            return Some(m);
        }
    }
    Some(mid)
}

/// The floats of the sample type (f32 when `f32_type`, else f64) just below and above `v`
/// (finite and non-zero).
fn neighbours(v: f64, f32_type: bool) -> (f64, f64) {
    // One unit of the bits down is towards zero, one up away from it.
    let (inward, outward) = if f32_type {
        let b = (v as f32).to_bits();
        (f32::from_bits(b - 1) as f64, f32::from_bits(b + 1) as f64)
    } else {
        let b = v.to_bits();
        (f64::from_bits(b - 1), f64::from_bits(b + 1))
    };
    if v > 0.0 { (inward, outward) } else { (outward, inward) }
}

/// The coarsest power of two dividing every valid value, when the indices fit (the same
/// bits when `bits`).
pub fn pow2(r: &Raster, bits: bool) -> Option<(Domain, Vec<i64>)> {
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
    exact(r, d, bits).map(|k| (d, k))
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
    fn near_reference(r: &Raster, d: Domain, misses: usize, bits: bool) -> Option<(Vec<i64>, Vec<usize>)> {
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
            if !same(finish(d.raw(k), r.sample_type, r.mapping), v, bits) {
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
                            for bits in [false, true] {
                                assert_eq!(
                                    near(&r, d, misses, bits),
                                    near_reference(&r, d, misses, bits),
                                    "{st:?} {mapping:?} case {case} bits {bits}"
                                );
                            }
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
            let got = near(&r, whole, m, false);
            assert_eq!(got, near_reference(&r, whole, m, false), "limit {m}");
            assert_eq!(got.is_some(), m >= misses, "limit {m}");
        }
    }

    /// Smooth integer "terrain" of `w`×`h` (a few hundred to a few thousand units) with noise.
    fn ints(w: usize, h: usize, seed: u64) -> Vec<i64> {
        let mut rng = Rng(seed);
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                (3000.0 + 2500.0 * (x / 37.0).sin() * (y / 23.0).cos() + rng.below(7) as f64) as i64
            })
            .collect()
    }

    /// Whole feet × 0.3048 in f32 and f64, and whole units × √2: the step is found (the
    /// shortest decimal for 0.3048), every index is the source's integer, every bit kept.
    #[test]
    fn any_step_is_found_exactly() {
        let (w, h) = (300, 250);
        let k = ints(w, h, 3);
        for (st, step) in [
            (SampleType::F32, 0.3048),
            (SampleType::F64, 0.3048),
            (SampleType::F32, std::f64::consts::SQRT_2),
            (SampleType::F32, -0.3048),
        ] {
            let data: Vec<f64> = k
                .iter()
                .map(|&k| {
                    let v = k as f64 * step;
                    if st == SampleType::F32 { v as f32 as f64 } else { v }
                })
                .collect();
            let r = Raster::from_values(w, h, data, None, st).unwrap();
            let (d, got, off) = general(&r, 0, true, 0.0).unwrap_or_else(|| panic!("{st:?} {step}"));
            assert!(off.is_empty());
            if step.abs() == 0.3048 {
                assert_eq!(d.mul.abs(), 0.3048, "{st:?}");
            }
            for i in 0..r.len() {
                assert_eq!(got[i].abs(), k[i], "{st:?} {step} sample {i}");
                assert_eq!(finish(d.raw(got[i]), st, r.mapping).to_bits(), r.data[i].to_bits());
            }
            // The encoder's order finds it too (in f32 no decimal step holds these values).
            let found = stepped(&r, true).map(|(d, _)| d);
            if st == SampleType::F32 {
                assert_eq!(found, Some(d), "{step}");
            } else {
                assert!(found.is_some(), "{step}");
            }
        }
    }

    /// Whole numbers in steps of 5 and quarters (bilinear halves of whole numbers, which the
    /// 0.01 step also holds): the coarser step is taken; plain whole numbers stay on 1.
    #[test]
    fn a_coarser_step_than_whole_or_decimal_is_taken() {
        let (w, h) = (300, 250);
        let k = ints(w, h, 9);
        for (step, want) in [(5.0, 5.0), (0.25, 0.25), (1.0, 1.0)] {
            let data: Vec<f64> = k.iter().map(|&k| k as f64 * step).collect();
            let r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
            let (d, got) = stepped(&r, true).unwrap();
            assert_eq!(d.unit(), want, "step {step}");
            for (&g, &v) in got.iter().zip(&r.data) {
                assert_eq!(finish(d.raw(g), r.sample_type, r.mapping), v);
            }
        }
    }

    /// Floats with full mantissas and no lattice: none is found (and the search is cheap to
    /// rule out); nor for a lattice with an offset it does not look for.
    #[test]
    fn no_step_without_a_lattice() {
        let (w, h) = (200, 150);
        let mut rng = Rng(11);
        let noise: Vec<f64> = (0..w * h)
            .map(|_| (100.0 + rng.below(1 << 30) as f64 / (1 << 20) as f64) as f32 as f64)
            .collect();
        let r = Raster::from_values(w, h, noise, None, SampleType::F32).unwrap();
        assert!(general(&r, 0, true, 0.0).is_none());
        assert!(general(&r, r.len() / 16, true, 0.0).is_none());
        let shifted: Vec<f64> =
            ints(w, h, 5).iter().map(|&k| (0.1 + k as f64 * 0.3048) as f32 as f64).collect();
        let r = Raster::from_values(w, h, shifted, None, SampleType::F32).unwrap();
        assert!(general(&r, 0, true, 0.0).is_none());
    }

    /// A few samples off the lattice (a value between two steps, −0 when the bits count,
    /// subnormals): no lattice without misses; with them, exactly those samples are the
    /// misses. −0 is a sample of the lattice when only the value counts.
    #[test]
    fn off_lattice_samples_are_the_misses() {
        let (w, h) = (300, 250);
        let mut data: Vec<f64> =
            ints(w, h, 7).iter().map(|&k| (k as f64 * 0.3048) as f32 as f64).collect();
        let odd = [
            (17, -0.0),
            (400, f32::from_bits(1) as f64),
            (401, -(f32::from_bits(0x0040_0000) as f64)),
            (9000, 1234.567_f32 as f64),
        ];
        for &(i, v) in &odd {
            data[i] = v;
        }
        let r = Raster::from_values(w, h, data, None, SampleType::F32).unwrap();
        assert!(general(&r, 0, true, 0.0).is_none());
        let (d, _, off) = general(&r, 100, true, 0.0).expect("a lattice with misses");
        assert_eq!(d.mul, 0.3048);
        assert_eq!(off, vec![17, 400, 401, 9000]);
        let (_, _, off) = general(&r, 100, false, 0.0).unwrap();
        assert_eq!(off, vec![400, 401, 9000]);
    }
}
