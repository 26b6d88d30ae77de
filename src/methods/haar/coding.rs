//! Context modelling and range coding of the quantized bands (one walk for both directions).

use super::transform::{Band, Pyramid};
use crate::entropy::range::{Bit, Decoder, Encoder, IntModel, UIntModel};
use crate::error::{Error, Result};
use crate::predict::med::med;

/// Zero-flag contexts per band: neighbourhood class × parent class.
const ZERO_NB: usize = 6;
const ZERO_PARENT: usize = 4;
const ZERO_CTX: usize = ZERO_NB * ZERO_PARENT;
/// Magnitude contexts per band: bit length of |left| + |up| + |parent|, capped.
const MAG_CTX: usize = 8;
/// Sign contexts per band: signs (−, 0, +) of the left, upper and parent coefficients.
const SIGN_CTX: usize = 27;

/// The range coder seen from the coefficient walk: the encoder codes the value it is given
/// and returns it, the decoder ignores it and returns what it decodes.
pub(super) trait Io {
    fn bit(&mut self, ctx: &mut Bit, v: bool) -> bool;
    fn uint(&mut self, m: &mut UIntModel, v: u64) -> Result<u64>;
    fn int(&mut self, m: &mut IntModel, v: i64) -> Result<i64>;
    fn check(&self) -> Result<()>;
}

impl Io for Encoder {
    #[inline]
    fn bit(&mut self, ctx: &mut Bit, v: bool) -> bool {
        self.encode(ctx, v);
        v
    }
    #[inline]
    fn uint(&mut self, m: &mut UIntModel, v: u64) -> Result<u64> {
        m.encode(self, v);
        Ok(v)
    }
    #[inline]
    fn int(&mut self, m: &mut IntModel, v: i64) -> Result<i64> {
        m.encode(self, v);
        Ok(v)
    }
    fn check(&self) -> Result<()> {
        Ok(())
    }
}

impl Io for Decoder<'_> {
    #[inline]
    fn bit(&mut self, ctx: &mut Bit, _: bool) -> bool {
        self.decode(ctx)
    }
    #[inline]
    fn uint(&mut self, m: &mut UIntModel, _: u64) -> Result<u64> {
        m.decode(self)
    }
    #[inline]
    fn int(&mut self, m: &mut IntModel, _: i64) -> Result<i64> {
        m.decode(self)
    }
    fn check(&self) -> Result<()> {
        self.check_in_bounds()
    }
}

/// Adaptive models of one detail band.
struct BandModels {
    any: Bit,
    zero: [Bit; ZERO_CTX],
    sign: [Bit; SIGN_CTX],
    mag: Vec<UIntModel>,
}

impl BandModels {
    fn new() -> Self {
        BandModels {
            any: Bit::default(),
            zero: [Bit::default(); ZERO_CTX],
            sign: [Bit::default(); SIGN_CTX],
            mag: (0..MAG_CTX).map(|_| UIntModel::new()).collect(),
        }
    }
}

#[inline]
fn sign3(v: i64) -> usize {
    (v.signum() + 1) as usize
}

/// Neighbourhood class of the zero flag from a weighted magnitude sum.
#[inline]
fn zero_class(s: u64) -> usize {
    match s {
        0 => 0,
        1..=2 => 1,
        3..=4 => 2,
        5..=8 => 3,
        9..=20 => 4,
        _ => 5,
    }
}

/// Code (encoder) or decode (decoder) every quantized coefficient of `q` (Mallat layout;
/// all zero on entry when decoding). The walk, contexts and models are spec/FORMAT.md's
/// "Haar section"; sharing one walk keeps encoder and decoder in step by construction.
pub(super) fn code_bands<I: Io>(io: &mut I, q: &mut [i64], pyr: &Pyramid) -> Result<()> {
    let stride = pyr.width;
    // LL band: MED prediction from the left, upper and upper-left codes, one Int model.
    let ll = pyr.bands[0];
    let mut ll_model = IntModel::new();
    for y in 0..ll.h {
        for x in 0..ll.w {
            let i = y * stride + x;
            let p = match (x, y) {
                (0, 0) => 0,
                (_, 0) => q[i - 1],
                (0, _) => q[i - stride],
                _ => med(q[i - 1], q[i - stride], q[i - stride - 1]),
            };
            let r = io.int(&mut ll_model, q[i].wrapping_sub(p))?;
            q[i] = p.wrapping_add(r);
        }
        io.check()?;
    }
    for (k, b) in pyr.bands.iter().enumerate().skip(1) {
        if b.w == 0 || b.h == 0 {
            continue;
        }
        let mut m = BandModels::new();
        // The decoder's q is all zero here, so its `nonzero` is meaningless and ignored.
        let nonzero =
            (b.y0..b.y0 + b.h).any(|y| q[y * stride + b.x0..][..b.w].iter().any(|&v| v != 0));
        if !io.bit(&mut m.any, nonzero) {
            continue;
        }
        let parent = b
            .parent
            .map(|p| pyr.bands[p])
            .filter(|p| p.w > 0 && p.h > 0);
        // The other orientations of this level coded before this band (HL for LH; HL and
        // LH for HH).
        let cross: Vec<Band> = pyr.bands[k + 1 - b.orient..k]
            .iter()
            .copied()
            .filter(|c| c.w > 0 && c.h > 0)
            .collect();
        for y in 0..b.h {
            let row = (b.y0 + y) * stride + b.x0;
            for x in 0..b.w {
                let i = row + x;
                let left = if x > 0 { q[i - 1] } else { 0 };
                let (up, ul, ur) = if y > 0 {
                    let u = i - stride;
                    (
                        q[u],
                        if x > 0 { q[u - 1] } else { 0 },
                        if x + 1 < b.w { q[u + 1] } else { 0 },
                    )
                } else {
                    (0, 0, 0)
                };
                let par = match parent {
                    Some(p) => {
                        let px = (x / 2).min(p.w - 1);
                        let py = (y / 2).min(p.h - 1);
                        q[(p.y0 + py) * stride + p.x0 + px]
                    }
                    None => 0,
                };
                let mut nb = left.unsigned_abs().saturating_mul(2);
                nb = nb.saturating_add(up.unsigned_abs().saturating_mul(2));
                nb = nb.saturating_add(ul.unsigned_abs());
                nb = nb.saturating_add(ur.unsigned_abs());
                for c in &cross {
                    let (cx, cy) = (x.min(c.w - 1), y.min(c.h - 1));
                    nb = nb.saturating_add(q[(c.y0 + cy) * stride + c.x0 + cx].unsigned_abs());
                }
                let pa = par.unsigned_abs();
                let zc = zero_class(nb) * ZERO_PARENT + pa.min(ZERO_PARENT as u64 - 1) as usize;
                let v = q[i];
                if !io.bit(&mut m.zero[zc], v != 0) {
                    q[i] = 0;
                    continue;
                }
                let sc = (sign3(left) * 3 + sign3(up)) * 3 + sign3(par);
                let negative = io.bit(&mut m.sign[sc], v < 0);
                let act = left
                    .unsigned_abs()
                    .saturating_add(up.unsigned_abs())
                    .saturating_add(pa);
                let mc = ((64 - act.leading_zeros()) as usize).min(MAG_CTX - 1);
                let mag = io.uint(&mut m.mag[mc], v.unsigned_abs().wrapping_sub(1))?;
                let mag = i64::try_from(mag)
                    .ok()
                    .and_then(|m| m.checked_add(1))
                    .ok_or_else(|| Error::corrupt("haar section: coefficient out of range"))?;
                q[i] = if negative { -mag } else { mag };
            }
            io.check()?;
        }
    }
    Ok(())
}
