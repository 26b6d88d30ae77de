//! The encoder: lattice choice, band-step profiles and the closed-loop max-error search.

use super::coding::code_bands;
use super::decoder::decode;
use super::lattice::{Lattice, Output};
use super::quant::{dequant_detail, dequantize, quantize, reconstruct};
use super::transform::{HH, LL, Pyramid, choose_levels, forward, inv_block, inverse_down_to};
use super::{CODING_PYRAMID, HaarParams, MAX_STEP, STEP_UNIT};
use crate::container::Header;
use crate::container::bytes::PutLe;
use crate::entropy::range::Encoder;
use crate::entropy::varint;
use crate::error::{Error, Result};
use crate::model::Raster;
use crate::quant::Errors;

/// Largest |lattice code|: keeps every lifting step and quantizer product far from overflow.
const MAX_CODE: f64 = (1u64 << 50) as f64;
/// Non-integer float data gets a lattice of (bound or step) / this.
const LATTICE_DIV: f64 = 16.0;
/// Steps the max-error search tries above its bisection result (up to +25 %).
const SCAN: u64 = 6;

/// How the encoder derives per-band steps from one base step (informative: the steps are
/// stored, a decoder never needs this).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Profile {
    /// Step of level k+1 relative to level k (0.5 = equal steps in orthonormal terms).
    ratio: f64,
    /// Step of HH relative to HL/LH on the same level (2 = equal in orthonormal terms).
    hh: f64,
    /// Step of the LL band relative to the coarsest HL/LH step.
    ll: f64,
    /// Reconstruction bias in 1/256 (δ = bias/256).
    bias: u8,
    /// Band steps below this (in lattice steps) become 1 (lossless band).
    snap: f64,
    /// Quantizer rounding offset in 1/256 (0 = plain dead zone).
    round: u8,
    /// Finest-level repair radius for a max-error bound (0 = none): each 2×2 block with a
    /// sample over the bound tries its three detail codes within ± this.
    repair: i64,
}

/// The profile of [`encode_step`], tuned for RMSE at a given rate on crater: the same step
/// for every band in orthonormal terms (S-transform steps halve per level, HH doubles),
/// midpoint reconstruction.
const MSE_PROFILE: Profile = Profile {
    ratio: 0.5,
    hh: 2.0,
    ll: 1.0,
    bias: 128,
    snap: 1.5,
    round: 0,
    repair: 0,
};

/// All steps 1: lossless on the lattice.
const LOSSLESS_PROFILE: Profile = Profile {
    ratio: 1.0,
    hh: 1.0,
    ll: 1.0,
    bias: 0,
    snap: 1.0,
    round: 0,
    repair: 0,
};

/// The first of [`LINF_PROFILES`]; the others differ from it only in the fields they name.
const LINF_FIRST: Profile = Profile {
    ratio: 0.5,
    hh: 1.5,
    ll: 1.0,
    bias: 96,
    snap: 1.5,
    round: 32,
    repair: 1,
};

/// Profiles [`encode`] tries for a max-error bound; it keeps the smallest payload. The max
/// error is a noisy function of the steps, so a few spread-out profiles beat any one (on
/// crater each is best at some bound).
const LINF_PROFILES: &[Profile] = &[
    LINF_FIRST,
    Profile {
        ratio: 0.6,
        ..LINF_FIRST
    },
    Profile {
        ratio: 0.85,
        bias: 128,
        round: 0,
        ..LINF_FIRST
    },
];

/// Per-band steps (1/16 units) for base step `base` (1/16 units, the finest HL/LH step).
fn profile_steps(pyr: &Pyramid, base: u64, p: &Profile) -> Vec<u64> {
    let clamp = |s: f64| {
        if s < p.snap * STEP_UNIT as f64 {
            STEP_UNIT
        } else {
            (s.round() as u64).clamp(STEP_UNIT, MAX_STEP)
        }
    };
    pyr.bands
        .iter()
        .map(|b| {
            let f = p.ratio.powi(b.level.max(1) as i32 - 1);
            let f = match b.orient {
                LL => f * p.ll,
                HH => f * p.hh,
                _ => f,
            };
            clamp(base as f64 * f)
        })
        .collect()
}

/// Everything the encoder derives from the raster once: lattice codes and coefficients.
struct Prepared<'a> {
    r: &'a Raster,
    lattice: Lattice,
    pyr: Pyramid,
    coefs: Vec<i64>,
}

/// Map samples to lattice codes (nodata filled smoothly), then transform.
fn prepare(r: &Raster, step: f64, offset: f64, levels: usize) -> Result<Prepared<'_>> {
    let lattice = Lattice {
        step,
        offset,
        out: Output::new(r.sample_type, r.mapping),
    };
    let (w, h) = (r.width, r.height);
    let mut codes = vec![0i64; r.len()];
    for (i, &v) in r.data.iter().enumerate() {
        if r.is_valid(i) {
            let c = ((v - offset) / step).round();
            if c.is_nan() || c.abs() > MAX_CODE {
                return Err(Error::unmet(format!(
                    "haar: sample {v} is more than 2^50 lattice steps of {step} from {offset} \
                     (the bound is too small for this value range; use the grid method)"
                )));
            }
            codes[i] = c as i64;
        }
    }
    if let Some(m) = &r.mask {
        crate::model::fill_invalid(&mut codes, m, w, h, |a, b, i, len| {
            (a as i128 + (b as i128 - a as i128) * i as i128 / len as i128) as i64
        });
    }
    let pyr = Pyramid::new(w, h, levels);
    forward(&mut codes, &pyr);
    Ok(Prepared {
        r,
        lattice,
        pyr,
        coefs: codes,
    })
}

/// Scratch buffers of the closed loop.
struct Trial {
    q: Vec<i64>,
    rec: Vec<i64>,
    /// Level-1 blocks to repair (index by · w₁ + bx).
    bad: Vec<usize>,
}

impl Prepared<'_> {
    /// For every sample, the codes whose output is within `e` of it (an interval, since a
    /// code's output value is monotone in the code); everything for invalid samples.
    /// Conservative: never wider than `e` / lattice step + 2 codes each way. Err when the
    /// lattice itself cannot meet `e`.
    fn intervals(&self, e: f64) -> Result<Vec<(i64, i64)>> {
        let (lat, r) = (&self.lattice, self.r);
        let reach = ((e / lat.step).ceil() + 2.0).min(MAX_CODE) as i64;
        let mut iv = vec![(i64::MIN, i64::MAX); r.len()];
        for (i, (&v, slot)) in r.data.iter().zip(iv.iter_mut()).enumerate() {
            if !r.is_valid(i) {
                continue;
            }
            let ok = |k: i64| lat.value(k).is_some_and(|x| (x - v).abs() <= e);
            let k0 = ((v - lat.offset) / lat.step).round() as i64;
            let Some(k) = [k0, k0 - 1, k0 + 1].into_iter().find(|&k| ok(k)) else {
                return Err(Error::unmet(format!(
                    "haar: the value lattice (step {}) alone breaks the max error {e}",
                    lat.step
                )));
            };
            // Start from the exact-arithmetic ends and step to the true ones (a step or two).
            // Both ends stay within ±MAX_CODE, where the estimates are clamped: a bound far
            // above the data's range (1e30 on values of ±2^38) would otherwise walk from the
            // clamped estimate towards k ± reach one code at a time (2^38 steps). A
            // narrower interval only constrains the encoder more; the bound still holds.
            let est = |x: f64| ((x - lat.offset) / lat.step).clamp(-MAX_CODE, MAX_CODE);
            let min_k = (k - reach).max(-MAX_CODE as i64).min(k);
            let max_k = (k + reach).min(MAX_CODE as i64).max(k);
            let mut lo = (est(v - e).ceil() as i64).clamp(min_k, k);
            let mut hi = (est(v + e).floor() as i64).clamp(k, max_k);
            while lo < k && !ok(lo) {
                lo += 1;
            }
            while lo > min_k && ok(lo - 1) {
                lo -= 1;
            }
            while hi > k && !ok(hi) {
                hi -= 1;
            }
            while hi < max_k && ok(hi + 1) {
                hi += 1;
            }
            *slot = (lo, hi);
        }
        Ok(iv)
    }

    /// Quantize with `steps` into `t.q`, rebuild into `t.rec` as the decoder will, and say
    /// whether every code lies in its interval; if not and the profile says so, repair the
    /// finest level where it failed, rebuild and check again.
    fn trial(&self, steps: &[u64], prof: &Profile, iv: &[(i64, i64)], t: &mut Trial) -> bool {
        self.rebuild(steps, prof, t);
        let inside = |(&c, &(lo, hi)): (&i64, &(i64, i64))| lo <= c && c <= hi;
        if t.rec.iter().zip(iv).all(inside) {
            return true;
        }
        if prof.repair == 0 || self.pyr.levels == 0 {
            return false;
        }
        // The level-1 blocks (2×2 samples) holding a sample outside its interval.
        let (w, w1) = (self.pyr.width, self.pyr.sizes[1].0);
        t.bad.clear();
        for (i, p) in t.rec.iter().zip(iv).enumerate() {
            if !inside(p) {
                t.bad.push((i / w / 2) * w1 + (i % w) / 2);
            }
        }
        t.bad.dedup();
        t.bad.sort_unstable();
        t.bad.dedup();
        self.repair(steps, prof, iv, t);
        t.rec.clone_from(&t.q);
        reconstruct(&mut t.rec, &self.pyr, steps, prof.bias);
        t.rec.iter().zip(iv).all(inside)
    }

    /// Quantize and reconstruct (no check, no repair).
    fn rebuild(&self, steps: &[u64], prof: &Profile, t: &mut Trial) {
        quantize(&self.coefs, &self.pyr, steps, prof.round, &mut t.q);
        t.rec.clone_from(&t.q);
        reconstruct(&mut t.rec, &self.pyr, steps, prof.bias);
    }

    /// Max error of the reconstruction `rec` over the valid samples (None if a value is
    /// not finite).
    fn max_error(&self, rec: &[i64]) -> Option<f64> {
        Errors::of(self.r, rec.iter().map(|&c| self.lattice.value(c))).map(|e| e.max)
    }

    /// Change the finest-level codes of every block listed in `t.bad` (blocks with a sample
    /// outside its interval) to the nearby codes (± `prof.repair`) with the smallest magnitudes that bring all its
    /// samples inside, if any. The finest inverse is local to a block, so this is exact
    /// given the coarser levels; [`Self::trial`] still checks the full reconstruction.
    fn repair(&self, steps: &[u64], prof: &Profile, iv: &[(i64, i64)], t: &mut Trial) {
        let pyr = &self.pyr;
        let stride = pyr.width;
        // The coarser levels as the decoder rebuilds them: the level-1 LL values.
        t.rec.clone_from(&t.q);
        dequantize(&mut t.rec, pyr, steps, prof.bias);
        inverse_down_to(&mut t.rec, pyr, 1);
        let (w, h) = pyr.sizes[0];
        let (w1, h1) = pyr.sizes[1];
        let nb = steps.len();
        let (n_hl, n_lh, n_hh) = (steps[nb - 3], steps[nb - 2], steps[nb - 1]);
        let bias = prof.bias;
        // Whether a block's samples are all inside their intervals for given detail codes.
        let block_ok = |bx: usize, by: usize, s: i64, c: [Option<i64>; 3]| -> bool {
            let deq = |q: Option<i64>, n: u64| q.map(|q| dequant_detail(q, n, bias));
            let codes = inv_block(s, deq(c[0], n_hl), deq(c[1], n_lh), deq(c[2], n_hh));
            codes.iter().enumerate().all(|(dy, row)| {
                row.iter().enumerate().all(|(dx, &code)| {
                    code.is_none_or(|code| {
                        let (lo, hi) = iv[(2 * by + dy) * stride + 2 * bx + dx];
                        lo <= code && code <= hi
                    })
                })
            })
        };
        let rad = prof.repair;
        for &blk in &t.bad {
            let (by, bx) = (blk / w1, blk % w1);
            let (has_h, has_v) = (bx < w / 2, by < h / 2);
            let idx = [
                has_h.then_some(by * stride + w1 + bx),
                has_v.then_some((h1 + by) * stride + bx),
                (has_h && has_v).then_some((h1 + by) * stride + w1 + bx),
            ];
            let cur = idx.map(|i| i.map(|i| t.q[i]));
            let s = t.rec[by * stride + bx];
            if block_ok(bx, by, s, cur) {
                continue;
            }
            let range = |c: Option<i64>| match c {
                Some(c) => (c - rad, c + rad),
                None => (0, 0),
            };
            let ((a0, a1), (b0, b1), (c0, c1)) = (range(cur[0]), range(cur[1]), range(cur[2]));
            // Smallest total magnitude; among equals, the first in this order.
            let mut best: Option<(u64, [Option<i64>; 3])> = None;
            for a in a0..=a1 {
                for b in b0..=b1 {
                    for c in c0..=c1 {
                        let cand = [cur[0].map(|_| a), cur[1].map(|_| b), cur[2].map(|_| c)];
                        let cost: u64 = cand.iter().flatten().map(|v| v.unsigned_abs()).sum();
                        if best.is_none_or(|b| cost < b.0) && block_ok(bx, by, s, cand) {
                            best = Some((cost, cand));
                        }
                    }
                }
            }
            if let Some((_, cand)) = best {
                for (i, c) in idx.iter().zip(cand) {
                    if let (Some(i), Some(c)) = (i, c) {
                        t.q[*i] = c;
                    }
                }
            }
        }
    }

    /// The payload for quantized coefficients `q` (the closed loop's last trial).
    fn payload(&self, q: &[i64], steps: &[u64], bias: u8, bound: f64) -> Vec<u8> {
        let mut out = Vec::new();
        out.put_u8(CODING_PYRAMID);
        out.put_u8(0);
        out.put_u8(self.pyr.levels as u8);
        out.put_u8(bias);
        out.put_f64(self.lattice.step);
        out.put_f64(self.lattice.offset);
        out.put_f64(bound);
        for &s in steps {
            varint::put_u64(&mut out, s);
        }
        let mut enc = Encoder::with_capacity(q.len() / 8);
        let mut q = q.to_vec();
        code_bands(&mut enc, &mut q, &self.pyr).expect("encoding cannot fail");
        out.extend_from_slice(&enc.finish());
        out
    }

    /// Check in debug builds that [`decode`] gives exactly what the closed loop measured.
    fn debug_check(&self, payload: &[u8], rec: &[i64]) {
        if cfg!(debug_assertions) {
            let r = self.r;
            let header = Header::of(r).expect("the raster being encoded");
            let back = decode(payload, &header, r.mask.as_deref()).expect("own payload decodes");
            for (i, (&b, &c)) in back.iter().zip(rec).enumerate() {
                if r.is_valid(i) {
                    assert_eq!(b.to_bits(), self.lattice.value(c).unwrap().to_bits());
                }
            }
        }
    }
}

/// The lattice for `r`: (step, offset), exact for integer types and integer-valued floats;
/// `fine` (the step for non-integer float data) when given, else an error.
fn choose_lattice(r: &Raster, fine: Option<f64>) -> Result<(f64, f64)> {
    if r.sample_type.is_integer() {
        return Ok((r.mapping.scale.abs(), r.mapping.offset));
    }
    let integral = r
        .data
        .iter()
        .enumerate()
        .all(|(i, &v)| !r.is_valid(i) || (v.round() == v && v.abs() <= MAX_CODE));
    if integral {
        return Ok((1.0, 0.0));
    }
    match fine {
        Some(u) if u > 0.0 && u.is_finite() => Ok((u, r.valid_range().map_or(0.0, |(lo, _)| lo))),
        _ => Err(Error::unmet(
            "the haar method is lossless only on integer-valued data; give a max error \
             or use the grid method for lossless float data",
        )),
    }
}

/// Encode `r` as a Haar-section payload meeting `p.max_error`. Returns the payload and the
/// max error it guarantees (measured over every valid sample, ≤ `p.max_error`).
#[cfg(test)]
pub fn encode(r: &Raster, p: &HaarParams) -> Result<(Vec<u8>, f64)> {
    encode_progress(r, p, &mut |_| {})
}

/// Encode `r` meeting `p.max_error` (the payload and the max error it guarantees, measured
/// over every valid sample), reporting progress as the fraction of step profiles searched.
pub(crate) fn encode_progress(
    r: &Raster,
    p: &HaarParams,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, f64)> {
    let e = p.max_error;
    if !(e >= 0.0 && e.is_finite()) {
        return Err(Error::invalid(format!(
            "max error {e} must be a finite number ≥ 0"
        )));
    }
    let (u, off) = choose_lattice(r, (e > 0.0).then_some(e / LATTICE_DIV))?;
    let prep = prepare(r, u, off, choose_levels(r.width, r.height))?;
    let (payload, err, rec) = encode_bound(&prep, e, LINF_PROFILES, progress)?;
    prep.debug_check(&payload, &rec);
    Ok((payload, err))
}

/// The closed loop of [`encode`]: for each profile, the largest base step whose
/// reconstruction meets `e` on every valid sample; the smallest payload wins. Returns the
/// payload, its max error and its reconstructed lattice codes.
fn encode_bound(
    prep: &Prepared,
    e: f64,
    profiles: &[Profile],
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, f64, Vec<i64>)> {
    let iv = prep.intervals(e)?;
    let mut t = Trial {
        q: vec![0; prep.coefs.len()],
        rec: vec![0; prep.coefs.len()],
        bad: Vec::new(),
    };
    let mut best: Option<(Vec<u8>, Vec<i64>)> = None;
    let mut prev: Option<u64> = None;
    if e > 0.0 {
        for (i, prof) in profiles.iter().enumerate() {
            progress(i as f64 / profiles.len() as f64);
            // Largest base step that passes: double, then bisect to 1/128.
            let pass = |n: u64, t: &mut Trial| {
                prep.trial(&profile_steps(&prep.pyr, n, prof), prof, &iv, t)
            };
            // Start near the previous profile's step (they land within 2× of each other).
            let start = match prev {
                Some(p) if p / 2 > STEP_UNIT && pass(p / 2, &mut t) => p / 2,
                _ if pass(STEP_UNIT, &mut t) => STEP_UNIT,
                _ => continue,
            };
            let (mut lo, mut hi) = (start, 2 * start);
            while hi < MAX_STEP && pass(hi, &mut t) {
                lo = hi;
                hi *= 2;
            }
            while hi - lo > (lo / 128).max(1) {
                let mid = lo + (hi - lo) / 2;
                if pass(mid, &mut t) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            // The max error is not monotone in the step: look a little further up.
            let top = lo + lo / 4;
            for k in 1..=SCAN {
                let n = lo + (top - lo) * k / SCAN;
                if n > lo && pass(n, &mut t) {
                    lo = n;
                }
            }
            prev = Some(lo);
            let steps = profile_steps(&prep.pyr, lo, prof);
            let passed = pass(lo, &mut t); // rebuild the winner into `t`
            debug_assert!(passed);
            let err = prep.max_error(&t.rec).unwrap_or(f64::INFINITY);
            let payload = prep.payload(&t.q, &steps, prof.bias, err);
            if best.as_ref().is_none_or(|b| payload.len() < b.0.len()) {
                best = Some((payload, t.rec.clone()));
            }
        }
    }
    let (payload, rec) = match best {
        Some(b) => b,
        None => {
            // Every step 1: lossless on the lattice, within `e` (the intervals say so).
            let lossless = vec![STEP_UNIT; prep.pyr.bands.len()];
            let passed = prep.trial(&lossless, &LOSSLESS_PROFILE, &iv, &mut t);
            debug_assert!(passed);
            let err = prep.max_error(&t.rec).unwrap_or(f64::INFINITY);
            (prep.payload(&t.q, &lossless, 0, err), t.rec.clone())
        }
    };
    let err = prep.max_error(&rec).unwrap_or(f64::INFINITY);
    if err.is_nan() || err > e {
        // Cannot happen: every code was checked against its interval.
        return Err(Error::unmet(format!(
            "haar: the closed loop measured {err} over the bound {e}"
        )));
    }
    Ok((payload, err, rec))
}

/// Encode with a fixed coefficient quantization step (rate control by bisection). Returns the
/// payload and the max error it achieves.
///
/// `step` is in data units: the dead-zone step of the finest HL/LH bands (the step of an
/// orthonormal Haar transform's coefficients, all bands alike); coarser bands get the
/// matching S-transform steps, never below one lattice step.
pub fn encode_step(r: &Raster, step: f64) -> Result<(Vec<u8>, f64)> {
    if !(step > 0.0 && step.is_finite()) {
        return Err(Error::invalid(format!(
            "haar quantizer step {step} must be a finite number > 0"
        )));
    }
    encode_step_with(r, step, &MSE_PROFILE)
}

fn encode_step_with(r: &Raster, step: f64, prof: &Profile) -> Result<(Vec<u8>, f64)> {
    let (u, off) = choose_lattice(r, Some(step / LATTICE_DIV))?;
    let prep = prepare(r, u, off, choose_levels(r.width, r.height))?;
    let mut t = Trial {
        q: vec![0; r.len()],
        rec: vec![0; r.len()],
        bad: Vec::new(),
    };
    let base = (step / u * STEP_UNIT as f64).clamp(STEP_UNIT as f64, MAX_STEP as f64) as u64;
    let steps = profile_steps(&prep.pyr, base, prof);
    prep.rebuild(&steps, prof, &mut t);
    let err = prep
        .max_error(&t.rec)
        .ok_or_else(|| Error::invalid("haar: a reconstruction is not finite"))?;
    let payload = prep.payload(&t.q, &steps, prof.bias, err);
    prep.debug_check(&payload, &t.rec);
    Ok((payload, err))
}
