//! The FIS section: a fractal interpolation surface on rectangles (every k-th sample as
//! interpolation point, vertical scaling per rectangle), decoded by iterating the IFS.
//!
//! Construction (the fractal-interpolation paper, §3): the interpolation points are the
//! samples `(i·k, j·k)`, `i = 0..=M`, `j = 0..=N`; they cut the domain D into rectangles
//! `R_ij`. The affine map `L_ij : D → R_ij` sends the corner of D labelled `l` to the corner
//! of `R_ij` labelled `l`, where a subgrid vertex `(i, j)` has label `(i mod 2) + 2·(j mod 2)`
//! (D's corners are labelled like a 2×2 subgrid). So `L_ij` is a shrink by `1/M`, `1/N`,
//! mirrored in x when `i` is odd and in y when `j` is odd, and two rectangles sharing an
//! edge read the same edge of D (the join-up condition). With
//! `F_ij(x, y, z) = a x + b y + g x y + S_ij(x, y)·z + c` fixed by the four corners, the
//! attractor satisfies, at every point `t = L_ij(p)` of `R_ij`,
//!
//! ```text
//! f(t) = bilinear_ij(t) + S_ij(p) · (f(p) − bilinear_D(p))
//! ```
//!
//! where `bilinear_ij` interpolates the corner heights of `R_ij` and `bilinear_D` the corner
//! heights of D. The paper takes one constant `S = s`. Fitted per-rectangle constants would
//! tear the surface along shared edges (both sides read the same boundary of D but would
//! scale it differently), so vtz uses vertical scaling *functions*
//! `S_ij(p) = s0 + (s_ij − s0)·φ(p)` with `φ(u, v) = 16·u(1−u)·v(1−v)`, which is 0 on ∂D and
//! 1 at its centre: every rectangle scales D's boundary by the same `s0` (continuity), and
//! its interior by up to `s_ij`, fitted by least squares (collage). `|S| ≤ max(|s0|, |s_ij|)
//! < 1`, so Φ is a contraction.
//!
//! When `(W−1)` and `(H−1)` are multiples of k, `L_ij⁻¹` maps grid samples to grid samples
//! (it scales offsets by M and N), so the attractor is evaluated exactly on the grid by
//! iterating Φ on it. Other sizes are padded by repeating the last column and row up to
//! `M·k + 1` × `N·k + 1` and cropped after decoding.

mod method;
pub(crate) use method::Fis;
pub use method::FisOptions;

use crate::container::Header;
use crate::container::bytes::{ByteReader, PutLe};
use crate::entropy::range::{Decoder, Encoder, IntModel};
use crate::error::{Error, Result};
use crate::model::Raster;
use crate::quant::{Errors, code_of, finish_value, height_of};

/// Bit 0 of the flags byte: one scaling factor `s0` for every rectangle (no `s_ij` codes).
const FLAG_FIXED_S: u8 = 1;
/// Fitted interior scaling factors are stored as `code / S_DEN`.
const S_DEN: f64 = 32.0;
/// Largest |code| of a fitted factor: |s_ij| ≤ 0.5 keeps Φ well contractive (few
/// iterations); fitted factors on terrain are mostly below 0.1.
const S_MAX_CODE: i64 = 16;
/// Largest iteration count a decoder accepts.
const MAX_ITER: u16 = 1024;
/// Subgrid spacings the bound search tries, coarsest first.
const K_CANDIDATES: [usize; 14] = [256, 128, 96, 64, 48, 32, 24, 16, 12, 8, 6, 4, 3, 2];

/// Parameters of the FIS representation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FisParams {
    /// Meet this max error (data units): the encoder chooses k and the height step.
    pub max_error: Option<f64>,
    /// Use this subgrid spacing instead of searching.
    pub k: Option<usize>,
    /// One vertical scaling factor for every rectangle (the paper's s = 0.02) instead of
    /// fitted ones.
    pub fixed_s: Option<f64>,
    /// Give up (`Error::Unmet` with the methods' size-cap message) when the coarsest spacing
    /// that meets the bound codes to more than 4× this many bytes at the finest height
    /// step (`best`: the smallest candidate's payload; the coarser steps tried after it
    /// saved up to 2.5× on Big Tujunga at 10 % of the range, so 2× lost its winning file).
    pub size_cap: Option<usize>,
}

/// What the FIS encoder chose and achieved (on the valid samples).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FisStats {
    /// Subgrid spacing.
    pub k: usize,
    /// Interpolation points (subgrid vertices).
    pub points: usize,
    /// Max absolute error of the decoded surface.
    pub max_error: f64,
    /// RMSE of the decoded surface.
    pub rmse: f64,
    /// The boundary scaling factor.
    pub s0: f64,
    /// Mean |s_ij| over the rectangles.
    pub mean_abs_s: f64,
    /// Iterations of Φ the decoder runs.
    pub iterations: u16,
}

/// The subgrid geometry for a `w`×`h` raster and spacing `k`.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    w: usize,
    h: usize,
    k: usize,
    /// Rectangles across and down.
    m: usize,
    n: usize,
    /// Padded size `m·k + 1` × `n·k + 1`.
    wp: usize,
    hp: usize,
}

impl Geometry {
    fn new(w: usize, h: usize, k: usize) -> Result<Geometry> {
        if w < 2 || h < 2 {
            return Err(Error::unsupported(format!(
                "FIS needs at least 2x2 samples, not {w}x{h}"
            )));
        }
        if k < 2 || k > (w - 1).max(h - 1) {
            return Err(Error::invalid(format!(
                "FIS spacing k = {k} must be between 2 and {}",
                (w - 1).max(h - 1).max(2)
            )));
        }
        let m = (w - 1).div_ceil(k);
        let n = (h - 1).div_ceil(k);
        Ok(Geometry {
            w,
            h,
            k,
            m,
            n,
            wp: m * k + 1,
            hp: n * k + 1,
        })
    }
    fn vertices(&self) -> usize {
        (self.m + 1) * (self.n + 1)
    }
    fn rects(&self) -> usize {
        self.m * self.n
    }
}

/// The bump φ at padded sample (x, y): 16·u(1−u)·v(1−v), 0 on ∂D.
#[inline]
fn phi(g: &Geometry, x: usize, y: usize) -> f64 {
    let u = x as f64 / (g.wp - 1) as f64;
    let v = y as f64 / (g.hp - 1) as f64;
    16.0 * u * (1.0 - u) * v * (1.0 - v)
}

/// Bilinear interpolation of the four corner values at fractions (u, v).
#[inline]
fn bilinear(z00: f64, z10: f64, z01: f64, z11: f64, u: f64, v: f64) -> f64 {
    let top = z00 + (z10 - z00) * u;
    let bottom = z01 + (z11 - z01) * u;
    top + (bottom - top) * v
}

/// Φ on the grid, as `f'(t) = a[t] + s[t] · f(src[t])` for every padded sample t.
struct Operator {
    a: Vec<f64>,
    s: Vec<f64>,
    src: Vec<u32>,
    /// `bilinear_ij(t)`: the starting surface (exact at the vertices).
    start: Vec<f64>,
    /// Heights at D's corners (0,0), (M,0), (0,N), (M,N).
    corners: [f64; 4],
}

impl Operator {
    /// `bilinear_D` at padded sample index `p`.
    fn bilinear_d(&self, p: usize, g: &Geometry) -> f64 {
        let [d00, d10, d01, d11] = self.corners;
        bilinear(
            d00,
            d10,
            d01,
            d11,
            (p % g.wp) as f64 / (g.wp - 1) as f64,
            (p / g.wp) as f64 / (g.hp - 1) as f64,
        )
    }
}

/// The rectangle owning padded sample (x, y) (samples on a shared edge belong to the
/// rectangle right of / below it) and the D sample `L_ij⁻¹` takes it from.
#[inline]
fn owner_and_source(g: &Geometry, x: usize, y: usize) -> (usize, usize, usize, usize) {
    let i = (x / g.k).min(g.m - 1);
    let j = (y / g.k).min(g.n - 1);
    let (px, py) = source_in(g, i, j, x, y);
    (i, j, px, py)
}

/// `L_ij⁻¹(x, y)` for a sample (x, y) of rectangle (i, j): offsets scaled by M and N, mirrored
/// in odd columns and rows.
#[inline]
fn source_in(g: &Geometry, i: usize, j: usize, x: usize, y: usize) -> (usize, usize) {
    let ox = x - i * g.k;
    let oy = y - j * g.k;
    let px = if i % 2 == 0 { ox } else { g.k - ox } * g.m;
    let py = if j % 2 == 0 { oy } else { g.k - oy } * g.n;
    (px, py)
}

/// Build Φ from the vertex heights `z` ((m+1)×(n+1), row-major), the boundary factor `s0`
/// and the interior factors `s` (one per rectangle; `None` = all `s0`).
fn operator(g: &Geometry, z: &[f64], s0: f64, s: Option<&[f64]>) -> Operator {
    let vw = g.m + 1;
    let zv = |i: usize, j: usize| z[j * vw + i];
    let (d00, d10, d01, d11) = (zv(0, 0), zv(g.m, 0), zv(0, g.n), zv(g.m, g.n));
    let np = g.wp * g.hp;
    let mut op = Operator {
        a: Vec::with_capacity(np),
        s: Vec::with_capacity(np),
        src: Vec::with_capacity(np),
        start: Vec::with_capacity(np),
        corners: [d00, d10, d01, d11],
    };
    let kf = g.k as f64;
    for y in 0..g.hp {
        for x in 0..g.wp {
            let (i, j, px, py) = owner_and_source(g, x, y);
            let u = (x - i * g.k) as f64 / kf;
            let v = (y - j * g.k) as f64 / kf;
            let b = bilinear(zv(i, j), zv(i + 1, j), zv(i, j + 1), zv(i + 1, j + 1), u, v);
            let bd = bilinear(
                d00,
                d10,
                d01,
                d11,
                px as f64 / (g.wp - 1) as f64,
                py as f64 / (g.hp - 1) as f64,
            );
            let sv = match s {
                None => s0,
                Some(s) => s0 + (s[j * g.m + i] - s0) * phi(g, px, py),
            };
            op.a.push(b - sv * bd);
            op.s.push(sv);
            op.src.push((py * g.wp + px) as u32);
            op.start.push(b);
        }
    }
    op
}

/// Iterate Φ `iters` times from the bilinear surface; the padded attractor.
fn iterate(op: &Operator, iters: u16) -> Vec<f64> {
    let mut f = op.start.clone();
    let mut next = vec![0.0; f.len()];
    for _ in 0..iters {
        for t in 0..f.len() {
            next[t] = op.a[t] + op.s[t] * f[op.src[t] as usize];
        }
        std::mem::swap(&mut f, &mut next);
    }
    f
}

/// Iterations so that `c^n · spread` is below `tol` (at least 1, at most [`MAX_ITER`]).
fn iterations_for(c: f64, spread: f64, tol: f64) -> u16 {
    if c <= 0.0 || spread <= tol {
        return 1;
    }
    let n = ((tol / spread).ln() / c.ln()).ceil();
    if n.is_finite() {
        n.clamp(1.0, MAX_ITER as f64) as u16
    } else {
        MAX_ITER
    }
}

/// The raster's samples padded to the geometry (last column and row repeated), nodata
/// filled, and which padded samples are valid samples of the raster.
fn padded(r: &Raster, filled: &[f64], g: &Geometry) -> (Vec<f64>, Vec<bool>) {
    let mut out = Vec::with_capacity(g.wp * g.hp);
    let mut valid = Vec::with_capacity(g.wp * g.hp);
    for y in 0..g.hp {
        let sy = y.min(g.h - 1);
        for x in 0..g.wp {
            let i = sy * g.w + x.min(g.w - 1);
            out.push(filled[i]);
            valid.push(x < g.w && y < g.h && r.is_valid(i));
        }
    }
    (out, valid)
}

/// Heights for vertices that are not valid samples (nodata, or padding beyond the raster):
/// a few Gauss–Seidel sweeps of least squares, each vertex fitted to the valid samples of
/// its (up to four) rectangles under bilinear interpolation, so the surface next to a void
/// follows the data instead of a crude fill.
fn fit_free_vertices(g: &Geometry, hpad: &[f64], valid: &[bool], z: &mut [f64]) {
    let vw = g.m + 1;
    let free: Vec<usize> = (0..g.vertices())
        .filter(|&v| !valid[(v / vw) * g.k * g.wp + (v % vw) * g.k])
        .collect();
    let kf = g.k as f64;
    for _ in 0..4 {
        for &v in &free {
            let (i, j) = (v % vw, v / vw);
            let (mut num, mut den) = (0.0, 0.0);
            for rj in j.saturating_sub(1)..=j.min(g.n - 1) {
                for ri in i.saturating_sub(1)..=i.min(g.m - 1) {
                    let zv =
                        |a: usize, b: usize| if (a, b) == (i, j) { 0.0 } else { z[b * vw + a] };
                    for y in rj * g.k..=(rj + 1) * g.k {
                        for x in ri * g.k..=(ri + 1) * g.k {
                            let t = y * g.wp + x;
                            if !valid[t] {
                                continue;
                            }
                            let u = (x - ri * g.k) as f64 / kf;
                            let w = (y - rj * g.k) as f64 / kf;
                            let wu = if i == ri { 1.0 - u } else { u };
                            let ww = if j == rj { 1.0 - w } else { w };
                            let wt = wu * ww;
                            if wt == 0.0 {
                                continue;
                            }
                            let others = bilinear(
                                zv(ri, rj),
                                zv(ri + 1, rj),
                                zv(ri, rj + 1),
                                zv(ri + 1, rj + 1),
                                u,
                                w,
                            );
                            num += wt * (hpad[t] - others);
                            den += wt * wt;
                        }
                    }
                }
            }
            if den > 0.0 {
                z[v] = num / den;
            }
        }
    }
}

/// Least-squares (collage) interior factors: for each rectangle, the `s_ij` minimising
/// Σ (H(t) − bilinear_ij(t) − s0·d(p) − (s_ij − s0)·φ(p)·d(p))² over its samples, with
/// `d = H − bilinear_D` taken from the original heights; clamped and quantized.
fn fit_factors(g: &Geometry, hpad: &[f64], valid: &[bool], op0: &Operator, s0: f64) -> Vec<i64> {
    let nr = g.rects();
    let mut num = vec![0.0; nr];
    let mut den = vec![0.0; nr];
    for y in 0..g.hp {
        for x in 0..g.wp {
            let t = y * g.wp + x;
            if !valid[t] {
                continue;
            }
            let (i, j, px, py) = owner_and_source(g, x, y);
            let ph = phi(g, px, py);
            if ph == 0.0 {
                continue;
            }
            let src = op0.src[t] as usize;
            let d = hpad[src] - op0.bilinear_d(src, g);
            let rres = hpad[t] - op0.start[t] - s0 * d;
            let xv = ph * d;
            num[j * g.m + i] += rres * xv;
            den[j * g.m + i] += xv * xv;
        }
    }
    (0..nr)
        .map(|r| {
            let s = if den[r] > 0.0 {
                s0 + num[r] / den[r]
            } else {
                s0
            };
            ((s * S_DEN).round() as i64).clamp(-S_MAX_CODE, S_MAX_CODE)
        })
        .collect()
}

/// Global least-squares boundary factor (φ ≡ 1), clamped to the fitted range.
fn fit_s0(g: &Geometry, hpad: &[f64], valid: &[bool], op0: &Operator) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..hpad.len() {
        if !valid[t] {
            continue;
        }
        let src = op0.src[t] as usize;
        let d = hpad[src] - op0.bilinear_d(src, g);
        num += (hpad[t] - op0.start[t]) * d;
        den += d * d;
    }
    let s = if den > 0.0 { num / den } else { 0.0 };
    ((s * S_DEN).round() as i64).clamp(-S_MAX_CODE, S_MAX_CODE) as f64 / S_DEN
}

/// Everything a payload says, decoded.
struct Model {
    g: Geometry,
    fixed: bool,
    iters: u16,
    step: f64,
    offset: f64,
    s0: f64,
    codes: Vec<i64>,
    s_codes: Vec<i64>,
}

impl Model {
    fn heights(&self) -> Vec<f64> {
        self.codes
            .iter()
            .map(|&c| height_of(c, self.step, self.offset))
            .collect()
    }

    fn factors(&self) -> Option<Vec<f64>> {
        (!self.fixed).then(|| self.s_codes.iter().map(|&c| c as f64 / S_DEN).collect())
    }

    /// The decoded samples (unpadded, before the nodata fill), finished to the sample type.
    fn render(&self, header: &Header) -> Vec<f64> {
        let z = self.heights();
        let s = self.factors();
        let op = operator(&self.g, &z, self.s0, s.as_deref());
        let f = iterate(&op, self.iters);
        let g = &self.g;
        let mut out = Vec::with_capacity(g.w * g.h);
        for y in 0..g.h {
            for x in 0..g.w {
                out.push(finish_value(f[y * g.wp + x], header));
            }
        }
        out
    }

    fn write(&self, bound: f64) -> Vec<u8> {
        let mut enc = Encoder::new();
        crate::predict::med::encode_lattice(&mut enc, &self.codes, self.g.m + 1);
        if !self.fixed {
            let mut models = [IntModel::new(), IntModel::new()];
            for (r, &c) in self.s_codes.iter().enumerate() {
                let ctx = usize::from(r % self.g.m > 0 && self.s_codes[r - 1] != 0);
                models[ctx].encode(&mut enc, c);
            }
        }
        let body = enc.finish();
        let mut out = Vec::with_capacity(body.len() + 48);
        out.put_u8(if self.fixed { FLAG_FIXED_S } else { 0 });
        out.put_u8(0);
        out.put_u16(self.iters);
        out.put_u32(self.g.k as u32);
        out.put_f64(self.step);
        out.put_f64(self.offset);
        out.put_f64(self.s0);
        out.put_f64(bound);
        out.extend_from_slice(&body);
        out
    }

    fn read(payload: &[u8], header: &Header) -> Result<Model> {
        let mut r = ByteReader::new(payload, "fis section");
        let flags = r.u8("flags")?;
        if flags & !FLAG_FIXED_S != 0 {
            return Err(r.corrupt(format!("undefined flags {flags:#04x}")));
        }
        if r.u8("reserved")? != 0 {
            return Err(r.corrupt("reserved byte is not zero"));
        }
        let iters = r.u16("iterations")?;
        if iters == 0 || iters > MAX_ITER {
            return Err(r.corrupt(format!("{iters} iterations (1..={MAX_ITER})")));
        }
        let k = r.u32("k")? as usize;
        let g = Geometry::new(header.width as usize, header.height as usize, k)
            .map_err(|e| r.corrupt(format!("spacing {k}: {e}")))?;
        let step = r.finite_f64("step")?;
        if step <= 0.0 {
            return Err(r.corrupt("height step is not positive"));
        }
        let offset = r.finite_f64("offset")?;
        let s0 = r.finite_f64("s0")?;
        if s0.abs() >= 1.0 {
            return Err(r.corrupt(format!("scaling factor {s0} is not in (-1, 1)")));
        }
        let bound = r.finite_f64("max error")?;
        if bound < 0.0 {
            return Err(r.corrupt("max error is negative"));
        }
        let fixed = flags & FLAG_FIXED_S != 0;
        let body = r.take(r.remaining(), "coded heights")?;
        let mut dec = Decoder::new(body)?;
        let codes = crate::predict::med::decode_lattice(&mut dec, g.m + 1, g.vertices())?;
        let mut s_codes = Vec::new();
        if !fixed {
            let mut models = [IntModel::new(), IntModel::new()];
            s_codes.reserve(g.rects());
            for r_ in 0..g.rects() {
                let ctx = usize::from(r_ % g.m > 0 && s_codes[r_ - 1] != 0);
                let c = models[ctx].decode(&mut dec)?;
                if c.abs() > S_MAX_CODE {
                    return Err(Error::corrupt(format!(
                        "fis section: scaling code {c} is out of range"
                    )));
                }
                s_codes.push(c);
            }
        }
        dec.finish()?;
        for &c in &codes {
            if !height_of(c, step, offset).is_finite() || c.unsigned_abs() > 1 << 52 {
                return Err(Error::corrupt("fis section: a height code is out of range"));
            }
        }
        Ok(Model {
            g,
            fixed,
            iters,
            step,
            offset,
            s0,
            codes,
            s_codes,
        })
    }
}

/// Max error and RMSE of `dec` against the valid samples of `r`.
fn errors(r: &Raster, dec: &[f64]) -> (f64, f64) {
    let e = Errors::of(r, dec.iter().map(|&v| Some(v))).expect("a value per sample");
    (e.max, e.rmse())
}

/// Build the model for spacing `k` and height step `step`, and what it decodes to.
fn build(
    header: &Header,
    (hpad, valid): (&[f64], &[bool]),
    g: Geometry,
    step: f64,
    fixed_s: Option<f64>,
) -> (Model, Vec<f64>) {
    let offset = header.range.map_or(0.0, |(lo, _)| lo);
    let vw = g.m + 1;
    let mut z: Vec<f64> = (0..g.vertices())
        .map(|v| hpad[(v / vw) * g.k * g.wp + (v % vw) * g.k])
        .collect();
    fit_free_vertices(&g, hpad, valid, &mut z);
    let codes: Vec<i64> = z
        .iter()
        .map(|&h| code_of(h, step, offset))
        .collect();
    let mut model = Model {
        g,
        fixed: fixed_s.is_some(),
        iters: 1,
        step,
        offset,
        s0: fixed_s.unwrap_or(0.0),
        codes,
        s_codes: Vec::new(),
    };
    if fixed_s.is_none() {
        let z = model.heights();
        let op0 = operator(&g, &z, 0.0, None);
        model.s0 = fit_s0(&g, hpad, valid, &op0);
        model.s_codes = fit_factors(&g, hpad, valid, &op0, model.s0);
    }
    let c = model
        .s_codes
        .iter()
        .map(|&c| (c as f64 / S_DEN).abs())
        .fold(model.s0.abs(), f64::max);
    let spread = header.range.map_or(1.0, |(lo, hi)| (hi - lo).max(step));
    model.iters = iterations_for(c, spread, step * 1e-3);
    let dec = model.render(header);
    (model, dec)
}

fn stats_of(model: &Model, r: &Raster, dec: &[f64]) -> FisStats {
    let (max_error, rmse) = errors(r, dec);
    let mean_abs_s = if model.fixed {
        model.s0.abs()
    } else {
        model
            .s_codes
            .iter()
            .map(|&c| (c as f64 / S_DEN).abs())
            .sum::<f64>()
            / model.s_codes.len().max(1) as f64
    };
    FisStats {
        k: model.g.k,
        points: model.g.vertices(),
        max_error,
        rmse,
        s0: model.s0,
        mean_abs_s,
        iterations: model.iters,
    }
}

/// The height step for a target error `e`: a fraction of it, on the source's code lattice
/// for integer samples.
fn height_step(header: &Header, e: f64) -> f64 {
    if header.sample_type.is_integer() {
        let sc = header.mapping.scale.abs();
        ((e / sc).floor().max(1.0)) * sc
    } else {
        e
    }
}

/// Encode `r` as an FIS payload. With `max_error`, the coarsest spacing k (and height step)
/// whose decoded surface meets it — or an error saying FIS cannot meet it at any k ≥ 2.
/// With `k` alone, that spacing with near-exact heights (the paper's setting).
#[cfg(any(test, feature = "internals"))]
pub fn encode(r: &Raster, p: &FisParams) -> Result<(Vec<u8>, FisStats)> {
    encode_with(r, &Header::of(r)?, p, &mut |_| {})
}

/// [`encode`] with the raster's header (as the container will store it) and a progress
/// callback (fraction of the trials done).
pub(crate) fn encode_with(
    r: &Raster,
    header: &Header,
    p: &FisParams,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, FisStats)> {
    r.validate()?;
    if let Some(s) = p.fixed_s {
        if !(s.is_finite() && s.abs() < 1.0) {
            return Err(Error::invalid(format!(
                "FIS scaling factor {s} must be in (-1, 1)"
            )));
        }
    }
    let range = header.range.map_or(0.0, |(lo, hi)| hi - lo);
    // Nodata filled once; every trial pads it to its own geometry.
    let filled = r.filled();
    let one_with = |k: usize, step: f64, fixed: Option<f64>| -> Result<(Model, Vec<f64>)> {
        let g = Geometry::new(r.width, r.height, k)?;
        let (hpad, valid) = padded(r, &filled, &g);
        Ok(build(header, (&hpad, &valid), g, step, fixed))
    };
    let one = |k: usize, step: f64| one_with(k, step, p.fixed_s);
    let finish = |model: Model, dec: Vec<f64>| -> (Vec<u8>, FisStats) {
        let st = stats_of(&model, r, &dec);
        (model.write(st.max_error), st)
    };
    let Some(e) = p.max_error else {
        let k =
            p.k.ok_or_else(|| Error::invalid("FIS needs a max error or a spacing k"))?;
        // Near-exact vertices: the source lattice for integers, 2⁻¹⁶ of the range otherwise.
        let step = if r.sample_type.is_integer() {
            r.mapping.scale.abs()
        } else if range > 0.0 {
            range / 65536.0
        } else {
            1.0
        };
        let (model, dec) = one(k, step)?;
        return Ok(finish(model, dec));
    };
    if !(e.is_finite() && e > 0.0) {
        return Err(Error::invalid(format!(
            "FIS max error {e} must be a positive number"
        )));
    }
    let ks: Vec<usize> = match p.k {
        Some(k) => vec![k],
        None => K_CANDIDATES
            .iter()
            .copied()
            .filter(|&k| k <= (r.width - 1).max(r.height - 1))
            .collect(),
    };
    let mut best: Option<(Vec<u8>, FisStats)> = None;
    let mut closest = f64::INFINITY;
    let consider = |model: Model, dec: Vec<f64>, best: &mut Option<(Vec<u8>, FisStats)>| {
        let c = finish(model, dec);
        if best.as_ref().is_none_or(|b| c.0.len() < b.0.len()) {
            *best = Some(c);
        }
    };
    // Progress: the bisection's trials, then at most 2 spacings × 3 steps × 2 factor kinds.
    let total = (usize::BITS - ks.len().leading_zeros()) as f64 + 12.0;
    let mut done = 0.0;
    let mut tick = |progress: &mut dyn FnMut(f64)| {
        done += 1.0;
        progress((done / total).min(1.0));
    };
    // Does spacing ks[idx] meet the bound with the finest height step? (Errors grow with k,
    // so bisect for the coarsest spacing that does.)
    // The payload size of each spacing that met the bound (at the finest step).
    let mut sizes = vec![None; ks.len()];
    let mut meets = |idx: usize| -> Result<bool> {
        let (model, dec) = one(ks[idx], height_step(header, e * 0.25))?;
        let maxe = errors(r, &dec).0;
        closest = closest.min(maxe);
        if maxe <= e && p.size_cap.is_some() {
            sizes[idx] = Some(model.write(maxe).len());
        }
        Ok(maxe <= e)
    };
    let (mut lo, mut hi) = (0usize, ks.len());
    while lo < hi {
        let mid = (lo + hi) / 2;
        tick(progress);
        if meets(mid)? {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    if let (Some(cap), Some(Some(size))) = (p.size_cap, sizes.get(lo)) {
        if *size > 4 * cap {
            return Err(Error::unmet(crate::methods::SIZE_CAP_MESSAGE));
        }
    }
    // The coarsest spacing that met the bound and one finer (it may code smaller), each
    // with three height steps, fitted factors and the boundary factor alone.
    for &k in ks.iter().skip(lo).take(2) {
        for frac in [0.25, 0.5, 1.0] {
            let step = height_step(header, e * frac);
            tick(progress);
            let (model, dec) = one(k, step)?;
            if errors(r, &dec).0 > e {
                break;
            }
            let s0 = model.s0;
            consider(model, dec, &mut best);
            if p.fixed_s.is_none() {
                tick(progress);
                let (model, dec) = one_with(k, step, Some(s0))?;
                if errors(r, &dec).0 <= e {
                    consider(model, dec, &mut best);
                }
            }
        }
    }
    best.ok_or_else(|| {
        let e = crate::metrics::num(e);
        if closest.is_finite() {
            Error::unmet(format!(
                "FIS cannot meet a max error of {e} at any spacing k ≥ 2 (the closest reached {})",
                crate::metrics::num(closest)
            ))
        } else {
            Error::unmet(format!(
                "FIS cannot meet a max error of {e}: no spacing k ≥ 2 fits a {}x{} raster",
                r.width, r.height
            ))
        }
    })
}

/// Decode an FIS payload (invalid samples get the nodata fill).
pub fn decode(payload: &[u8], header: &Header, mask: Option<&[bool]>) -> Result<Vec<f64>> {
    let model = Model::read(payload, header)?;
    let mut out = model.render(header);
    if let Some(m) = mask {
        let fill = header.nodata.unwrap_or(f64::NAN);
        for (v, &ok) in out.iter_mut().zip(m) {
            if !ok {
                *v = fill;
            }
        }
    }
    Ok(out)
}

/// Decode an FIS payload and report its spacing, factors and iteration count (for `info`).
pub fn describe(payload: &[u8], header: &Header) -> Result<(usize, usize, f64, u16)> {
    let m = Model::read(payload, header)?;
    Ok((m.g.k, m.g.vertices(), m.s0, m.iters))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SampleType;
    use proptest::prelude::*;

    /// A rough test surface: sums of sines plus a hashed jitter.
    fn surface(w: usize, h: usize, seed: u64) -> Vec<f64> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let mut z = 100.0 * (x * 0.05 + seed as f64).sin() + 60.0 * (y * 0.08).cos();
                z += 20.0 * ((x + 2.0 * y) * 0.31).sin();
                let hsh = (i as u64 ^ seed).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
                z + (hsh % 1000) as f64 / 100.0
            })
            .collect()
    }

    fn header_of(r: &Raster) -> Header {
        Header::of(r).expect("small raster")
    }

    /// [`encode`] at spacing `k` alone (near-exact heights); panics on an error.
    fn encode_at_k(r: &Raster, k: usize) -> (Vec<u8>, FisStats) {
        encode(
            r,
            &FisParams {
                k: Some(k),
                ..Default::default()
            },
        )
        .unwrap()
    }

    /// [`encode`] for a max error `e` alone.
    fn encode_for_bound(r: &Raster, e: f64) -> Result<(Vec<u8>, FisStats)> {
        encode(
            r,
            &FisParams {
                max_error: Some(e),
                ..Default::default()
            },
        )
    }

    /// Φ applied at padded sample (x, y) through rectangle (i, j), with per-rectangle
    /// scaling `scale(i, j, px, py)`.
    fn phi_through(
        g: &Geometry,
        z: &[f64],
        f: &[f64],
        (i, j): (usize, usize),
        (x, y): (usize, usize),
        scale: &dyn Fn(usize, usize, usize, usize) -> f64,
    ) -> f64 {
        let vw = g.m + 1;
        let zv = |a: usize, b: usize| z[b * vw + a];
        let (px, py) = source_in(g, i, j, x, y);
        let b = bilinear(
            zv(i, j),
            zv(i + 1, j),
            zv(i, j + 1),
            zv(i + 1, j + 1),
            (x - i * g.k) as f64 / g.k as f64,
            (y - j * g.k) as f64 / g.k as f64,
        );
        let bd = bilinear(
            zv(0, 0),
            zv(g.m, 0),
            zv(0, g.n),
            zv(g.m, g.n),
            px as f64 / (g.wp - 1) as f64,
            py as f64 / (g.hp - 1) as f64,
        );
        b + scale(i, j, px, py) * (f[py * g.wp + px] - bd)
    }

    /// Largest disagreement of Φf along shared rectangle edges, computed from both sides.
    fn max_tear(
        g: &Geometry,
        z: &[f64],
        f: &[f64],
        scale: &dyn Fn(usize, usize, usize, usize) -> f64,
    ) -> f64 {
        let mut tear = 0.0f64;
        for j in 0..g.n {
            for i in 0..g.m {
                for o in 0..=g.k {
                    if i + 1 < g.m {
                        let (x, y) = ((i + 1) * g.k, j * g.k + o);
                        let a = phi_through(g, z, f, (i, j), (x, y), scale);
                        let b = phi_through(g, z, f, (i + 1, j), (x, y), scale);
                        tear = tear.max((a - b).abs());
                    }
                    if j + 1 < g.n {
                        let (x, y) = (i * g.k + o, (j + 1) * g.k);
                        let a = phi_through(g, z, f, (i, j), (x, y), scale);
                        let b = phi_through(g, z, f, (i, j + 1), (x, y), scale);
                        tear = tear.max((a - b).abs());
                    }
                }
            }
        }
        tear
    }

    #[test]
    fn fitted_scaling_functions_keep_the_surface_continuous_across_every_edge() {
        let (w, h, k) = (97, 81, 8);
        let r = Raster::from_values(w, h, surface(w, h, 3), None, SampleType::F32).unwrap();
        let (payload, st) = encode_at_k(&r, k);
        let header = header_of(&r);
        let model = Model::read(&payload, &header).unwrap();
        let g = model.g;
        let z = model.heights();
        let s = model.factors().unwrap();
        assert!(
            s.iter().any(|&v| v != s[0]),
            "the fit should give differing factors"
        );
        // The attractor itself, on the padded grid.
        let op = operator(&g, &z, model.s0, Some(&s));
        let f = iterate(&op, model.iters);
        let s0 = model.s0;
        let with_phi =
            |i: usize, j: usize, px: usize, py: usize| s0 + (s[j * g.m + i] - s0) * phi(&g, px, py);
        let tear = max_tear(&g, &z, &f, &with_phi);
        assert!(
            tear <= 1e-9 * 200.0,
            "tear {tear} with vertical scaling functions"
        );
        // The attractor is Φ's fixed point: applying Φ again changes nothing (edges included).
        for y in 0..g.hp {
            for x in 0..g.wp {
                let (i, j, _, _) = owner_and_source(&g, x, y);
                let v = phi_through(&g, &z, &f, (i, j), (x, y), &with_phi);
                assert!(
                    (v - f[y * g.wp + x]).abs() < 1e-6,
                    "not converged at {x},{y}"
                );
            }
        }
        // Negative control: plain per-rectangle constants tear the surface apart.
        let constant = |i: usize, j: usize, _: usize, _: usize| 0.3 * ((i + 2 * j) % 3) as f64;
        assert!(max_tear(&g, &z, &f, &constant) > 1.0);
        assert!(st.max_error.is_finite());
    }

    #[test]
    fn vertices_decode_exactly_and_zero_scaling_is_bilinear() {
        let (w, h, k) = (65, 49, 16);
        let data: Vec<f64> = surface(w, h, 1).iter().map(|v| v.round()).collect();
        let r = Raster::from_values(w, h, data, None, SampleType::I16).unwrap();
        let header = header_of(&r);
        let (payload, _) = encode(
            &r,
            &FisParams {
                k: Some(k),
                fixed_s: Some(0.0),
                ..Default::default()
            },
        )
        .unwrap();
        let dec = decode(&payload, &header, None).unwrap();
        for y in 0..h {
            for x in 0..w {
                let v = dec[y * w + x];
                if x % k == 0 && y % k == 0 {
                    assert_eq!(v, r.data[y * w + x], "vertex {x},{y}");
                }
                let (i, j) = ((x / k).min(w / k - 1), (y / k).min(h / k - 1));
                let c = |a: usize, b: usize| r.data[b * k * w + a * k];
                let b = bilinear(
                    c(i, j),
                    c(i + 1, j),
                    c(i, j + 1),
                    c(i + 1, j + 1),
                    (x - i * k) as f64 / k as f64,
                    (y - j * k) as f64 / k as f64,
                );
                assert_eq!(v, b.round(), "bilinear at {x},{y}");
            }
        }
    }

    #[test]
    fn padding_handles_sizes_that_are_not_multiples_of_k() {
        let (w, h) = (50, 37);
        let r = Raster::from_values(w, h, surface(w, h, 9), None, SampleType::F64).unwrap();
        let header = header_of(&r);
        for k in [2, 3, 7, 16, 49] {
            let (payload, st) = encode_at_k(&r, k);
            let dec = decode(&payload, &header, None).unwrap();
            assert_eq!(dec.len(), w * h);
            assert_eq!(errors(&r, &dec).0, st.max_error);
            // Vertices inside the raster are (nearly) exact.
            for y in (0..h).step_by(k) {
                for x in (0..w).step_by(k) {
                    assert!((dec[y * w + x] - r.data[y * w + x]).abs() <= st_step(&r));
                }
            }
        }
    }

    fn st_step(r: &Raster) -> f64 {
        let (lo, hi) = r.valid_range().unwrap();
        (hi - lo) / 65536.0
    }

    #[test]
    fn too_tight_a_bound_is_reported_not_faked() {
        let (w, h) = (40, 40);
        let r = Raster::from_values(w, h, surface(w, h, 5), None, SampleType::F32).unwrap();
        let err = encode_for_bound(&r, 1e-3).unwrap_err();
        assert!(err.to_string().contains("cannot meet"), "{err}");
    }

    #[test]
    fn nodata_samples_come_back_as_nodata_and_are_not_counted() {
        let (w, h) = (60, 45);
        let mut data = surface(w, h, 2);
        for (i, v) in data.iter_mut().enumerate() {
            if (i % w) < 10 && (i / w) > 20 {
                *v = -9999.0;
            }
        }
        let mut r = Raster::from_values(w, h, data, Some(-9999.0), SampleType::F32).unwrap();
        r.normalize_mask();
        let header = header_of(&r);
        let (payload, st) = encode_for_bound(&r, 40.0).unwrap();
        let dec = decode(&payload, &header, r.mask.as_deref()).unwrap();
        for (i, &d) in dec.iter().enumerate() {
            if r.is_valid(i) {
                assert!((d - r.data[i]).abs() <= st.max_error);
            } else {
                assert_eq!(d, -9999.0);
            }
        }
        assert!(st.max_error <= 40.0);
    }

    #[test]
    fn corrupt_payloads_are_rejected() {
        let (w, h) = (33, 33);
        let r = Raster::from_values(w, h, surface(w, h, 4), None, SampleType::F32).unwrap();
        let header = header_of(&r);
        let (payload, _) = encode_at_k(&r, 8);
        assert!(decode(&payload, &header, None).is_ok());
        for cut in 0..payload.len() {
            assert!(decode(&payload[..cut], &header, None).is_err(), "cut {cut}");
        }
        let mut bad = payload.clone();
        bad[0] = 0x80; // undefined flag
        assert!(decode(&bad, &header, None).is_err());
        let mut bad = payload.clone();
        bad[2..4].copy_from_slice(&0u16.to_le_bytes()); // zero iterations
        assert!(decode(&bad, &header, None).is_err());
        let mut bad = payload.clone();
        bad[4..8].copy_from_slice(&1u32.to_le_bytes()); // k = 1
        assert!(decode(&bad, &header, None).is_err());
        let mut bad = payload.clone();
        bad[24..32].copy_from_slice(&1.0f64.to_le_bytes()); // s0 = 1: not contractive
        assert!(decode(&bad, &header, None).is_err());
    }

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(24))]

        /// Any size, any bound: the decoded surface meets the bound the encoder reports, or
        /// the encoder says FIS cannot meet it.
        #[test]
        fn round_trip_meets_the_reported_bound(
            w in 3usize..70, h in 3usize..70, seed in 0u64..1000, pct in 1.0f64..60.0,
            int in any::<bool>(),
        ) {
            let mut data = surface(w, h, seed);
            if int {
                data.iter_mut().for_each(|v| *v = v.round());
            }
            let st_ty = if int { SampleType::I16 } else { SampleType::F32 };
            let r = Raster::from_values(w, h, data, None, st_ty).unwrap();
            let header = header_of(&r);
            let (lo, hi) = r.valid_range().unwrap();
            let e = (hi - lo) * pct / 100.0;
            match encode_for_bound(&r, e) {
                Ok((payload, st)) => {
                    prop_assert!(st.max_error <= e);
                    let dec = decode(&payload, &header, None).unwrap();
                    let again = decode(&payload, &header, None).unwrap();
                    prop_assert_eq!(&dec, &again);
                    for (d, v) in dec.iter().zip(&r.data) {
                        prop_assert!((d - v).abs() <= e);
                    }
                }
                Err(err) => prop_assert!(err.to_string().contains("cannot meet"), "{}", err),
            }
        }
    }
}
