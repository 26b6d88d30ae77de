//! The dead-zone (detail) and uniform (LL) quantizers of the pyramid coefficients.

use super::STEP_UNIT;
use super::transform::{LL, Pyramid, inverse};

/// Dead-zone quantizer of a detail coefficient with step n/16: sign(c)·⌊16|c|/n⌋.
#[inline]
fn quant_detail(c: i64, n: u64) -> i64 {
    // |c| ≤ 2^53 in the encoder, so 16|c| fits.
    let m = (c.unsigned_abs() * STEP_UNIT / n) as i64;
    if c < 0 { -m } else { m }
}

/// [`quant_detail`] with a rounding offset: sign(c)·⌊16|c|/n + round/256⌋ (encoder only).
#[inline]
fn quant_detail_round(c: i64, n: u64, round: u8) -> i64 {
    // |c| ≤ 2^53, so 4096|c| fits; the rest only overflows for absurd steps.
    let m = match (round as u64)
        .checked_mul(n)
        .and_then(|r| r.checked_add(c.unsigned_abs() << 12))
    {
        Some(num) if n < 1 << 56 => (num / (n << 8)) as i64,
        _ => {
            let num = c.unsigned_abs() as u128 * 4096 + round as u128 * n as u128;
            (num / (256 * n as u128)) as i64
        }
    };
    if c < 0 { -m } else { m }
}

/// Reconstruction of a detail coefficient: sign(q)·⌊(|q| + b/256)·n/16⌋ (0 for q = 0).
#[inline]
pub(super) fn dequant_detail(q: i64, n: u64, bias: u8) -> i64 {
    if q == 0 {
        return 0;
    }
    let m = match (q.unsigned_abs().checked_mul(256)).and_then(|x| (x + bias as u64).checked_mul(n))
    {
        Some(x) => (x / 4096).min(i64::MAX as u64) as i64,
        None => {
            let num = q.unsigned_abs() as u128 * 256 + bias as u128;
            (num * n as u128 / 4096).min(i64::MAX as u128) as i64
        }
    };
    if q < 0 { -m } else { m }
}

/// Uniform (mid-tread) quantizer of an LL coefficient: ⌊(32c + n) / 2n⌋.
#[inline]
fn quant_ll(c: i64, n: u64) -> i64 {
    (32 * c as i128 + n as i128).div_euclid(2 * n as i128) as i64
}

/// Reconstruction of an LL coefficient: ⌊(2qn + 16) / 32⌋, saturated to i64.
#[inline]
fn dequant_ll(q: i64, n: u64) -> i64 {
    (2 * q as i128 * n as i128 + 16)
        .div_euclid(32)
        .clamp(i64::MIN as i128, i64::MAX as i128) as i64
}

/// Quantize every band of `coefs` into `q` (same layout); `round` (in 1/256) shrinks the
/// dead zone and moves every decision threshold down (encoder only).
pub(super) fn quantize(coefs: &[i64], pyr: &Pyramid, steps: &[u64], round: u8, q: &mut [i64]) {
    for (b, &n) in pyr.bands.iter().zip(steps) {
        for y in b.y0..b.y0 + b.h {
            let row = y * pyr.width + b.x0..y * pyr.width + b.x0 + b.w;
            let (src, dst) = (&coefs[row.clone()], &mut q[row]);
            if b.orient == LL {
                dst.iter_mut()
                    .zip(src)
                    .for_each(|(d, &c)| *d = quant_ll(c, n));
            } else if n == STEP_UNIT {
                dst.copy_from_slice(src);
            } else if round == 0 {
                dst.iter_mut()
                    .zip(src)
                    .for_each(|(d, &c)| *d = quant_detail(c, n));
            } else {
                dst.iter_mut()
                    .zip(src)
                    .for_each(|(d, &c)| *d = quant_detail_round(c, n, round));
            }
        }
    }
}

/// Dequantize `q` in place and run the inverse pyramid: the lattice codes the decoder
/// outputs. Shared by the encoder's closed loop and [`decode`](super::decode).
pub(super) fn reconstruct(q: &mut [i64], pyr: &Pyramid, steps: &[u64], bias: u8) {
    dequantize(q, pyr, steps, bias);
    inverse(q, pyr);
}

/// Replace every quantized coefficient by its reconstruction.
pub(super) fn dequantize(q: &mut [i64], pyr: &Pyramid, steps: &[u64], bias: u8) {
    for (b, &n) in pyr.bands.iter().zip(steps) {
        for y in b.y0..b.y0 + b.h {
            let row = &mut q[y * pyr.width + b.x0..][..b.w];
            if b.orient == LL {
                row.iter_mut().for_each(|v| *v = dequant_ll(*v, n));
            } else {
                row.iter_mut()
                    .for_each(|v| *v = dequant_detail(*v, n, bias));
            }
        }
    }
}
