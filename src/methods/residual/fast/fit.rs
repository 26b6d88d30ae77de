//! What the encoder fits on the source before coding: each pass's stencil weights and
//! whether coarse bins are narrowed.

use super::passes::{Config, FIT_SAMPLES_LOG2, Kind, NCOARSE, NW, Pass};
use super::super::plane::CODED;
use super::super::plane::{Plane, SKIPPED};

/// Fit a pass's stencil weights on the source (encoder): the samples whose stencil lies
/// inside on pass rows spread to about 2^[`FIT_SAMPLES_LOG2`] samples. `None` when they are not worth their 20
/// bytes: the bits they save are estimated from the squared errors before and after, each
/// plus W²/4 (wide bins hide small improvements).
/// With `lanes` (the lane coding) the pass's own two points are left out and the weights
/// kept within ±[`super::lanes::MAX_WEIGHT`].
pub(super) fn fit(p: &Plane, pass: Pass, lanes: bool) -> Option<[i16; NW]> {
    if lanes {
        // The eight coarser points alone: a smaller system to fit.
        fit_n::<NCOARSE>(p, pass, true)
    } else {
        fit_n::<NW>(p, pass, false)
    }
}

/// [`fit`] on the stencil's first `N` points (the rest of the weights 0).
fn fit_n<const N: usize>(p: &Plane, pass: Pass, lanes: bool) -> Option<[i16; NW]> {
    let (w, h) = (p.width, p.height);
    let s = pass.s;
    let offs = pass.offsets(w);
    let along = if pass.kind == Kind::Vertical { (w * s) as isize } else { s as isize };
    // Rows evenly spread to about 2^FIT_SAMPLES_LOG2 samples. 2^15 fits most rasters as
    // well for a fifth less encode time, but Half Dome at 1 m loses 1.6 % (benches/README.md).
    let step = ((pass.rows(h) * pass.cols(w)) >> FIT_SAMPLES_LOG2).max(1);
    // Without skipped samples no stencil point needs its kind looked up.
    let skips = p.kinds.contains(&SKIPPED);
    // Calls `f(features, target)` for every sample the fit uses.
    let each = |f: &mut dyn FnMut(&[i64; N], i64)| {
        for k in (0..pass.rows(h)).step_by(step) {
            let y = pass.r0 + k * pass.rs;
            let rows_in = match pass.kind {
                Kind::Vertical => y >= 3 * s && y + 3 * s < h,
                _ => y >= 2 * s && y + s < h,
            };
            if !rows_in {
                continue;
            }
            for col in 0..pass.cols(w) {
                let x = pass.c0 + col * pass.cs;
                let inside = match pass.kind {
                    Kind::Vertical => x >= 2 * s && x + 2 * s < w,
                    _ => x >= 3 * s && x + 3 * s < w,
                };
                let i = y * w + x;
                if !inside || (skips && p.kinds[i] == SKIPPED) {
                    continue;
                }
                let at = |d: isize| p.values[(i as isize + d * along) as usize];
                let base = (-at(-3) + 9 * (at(-1) + at(1)) - at(3) + 8) >> 4;
                let mut fs = [0i64; N];
                let mut ok = true;
                for (fk, o) in fs.iter_mut().zip(offs) {
                    let j = (i as isize + o) as usize;
                    ok &= !skips || p.kinds[j] != SKIPPED;
                    *fk = p.values[j] - base;
                }
                if ok {
                    f(&fs, p.values[i] - base);
                }
            }
        }
    };
    let mut n = super::super::ls::Normal::<N>::new();
    each(&mut |fs, t| n.add(fs, t as f64));
    let mut wt = n.solve();
    if lanes {
        let m = super::lanes::MAX_WEIGHT;
        wt = wt.map(|v| v.clamp(-m, m));
    }
    if wt == [0; N] {
        return None;
    }
    // Squared errors in f64: lattice values reach ±2^38 (`lattice::MAX_UNITS`), so a
    // residual t reaches ~2^39 and t² leaves i64. The correction itself is the decoder's
    // integer arithmetic (|f·w| ≤ 2^39.4 · 2^15, ten of them: < 2^58).
    let (mut e0, mut e1, mut m) = (0f64, 0f64, 0f64);
    each(&mut |fs, t| {
        let acc: i64 = fs.iter().zip(&wt).map(|(f, w)| f * *w as i64).sum();
        let c = (acc + 512) >> 10;
        e0 += (t as f64).powi(2);
        e1 += ((t - c) as f64).powi(2);
        m += 1.0;
    });
    // W ≤ 2^38: W² in f64 too.
    let q = (pass.bin as f64).powi(2) / 4.0;
    let per = 0.5 * ((e0 / m + q) / (e1 / m + q)).log2();
    let samples = (pass.rows(h) * pass.cols(w)) as f64;
    let mut all = [0i16; NW];
    all[..N].copy_from_slice(&wt);
    (per * samples > 2.0 * 8.0 * 2.0 * NW as f64).then_some(all)
}

/// Narrower coarse bins pay when bins are wide against the finest level's prediction
/// error: from W ≥ 4σ, σ the RMS of the cubic prediction error of level 1's horizontal
/// pass on the source (where its support is not flat water). (Measured, W/σ: White Mountains 1.5 loses, 5.5 and 17.6 win; Half
/// Dome 0.8 loses, 5.7 and 19 win; Crater Lake 2.8 loses, 10.5 ties, 31 wins.)
const TIGHT_FROM_SIGMAS: f64 = 4.0;
/// … and never below bins of 7 lattice steps, where narrowing rounds coarse bins down to
/// (nearly) lossless ones (Istria at 1 m, W = 3, σ < 0.75: 423 169 bytes plain, 507 837
/// narrowed; Crater Lake at 0.3 %, W = 5: 14 447 against 15 849; Istria at 0.3 %, W = 7:
/// narrowed wins, 188 575 against 194 890).
const TIGHT_FROM_BIN: i64 = 7;

/// `cfg` with `tighten` decided when it is left to the data.
pub fn resolve(p: &Plane, cfg: Config) -> Config {
    if !cfg.tighten_auto {
        return cfg;
    }
    let (w, h) = (p.width, p.height);
    // The horizontal pass of level 1 on rows spread to about 2^15 samples.
    let step = ((h * (w / 2)) >> FIT_SAMPLES_LOG2).max(1);
    let (mut e, mut n) = (0f64, 0f64);
    for y in (0..h).step_by(step) {
        for x in (3..w.saturating_sub(3)).step_by(2) {
            let i = y * w + x;
            // Coded samples only: flat regions (fixed) would make σ small.
            let ok = |j: usize| p.kinds.get(j).is_none_or(|&k| k == CODED);
            if !(ok(i) && ok(i - 3) && ok(i - 1) && ok(i + 1) && ok(i + 3)) {
                continue;
            }
            let v = p.values;
            if v[i - 3] == v[i - 1] && v[i - 1] == v[i + 1] && v[i + 1] == v[i + 3] {
                // Flat water the flat section did not take: it says nothing of the terrain.
                continue;
            }
            let base = (-v[i - 3] + 9 * (v[i - 1] + v[i + 1]) - v[i + 3] + 8) >> 4;
            e += ((v[i] - base) as f64).powi(2);
            n += 1.0;
        }
    }
    let sigma = if n > 0.0 { (e / n).sqrt() } else { 0.0 };
    Config {
        tighten: p.bin as f64 >= TIGHT_FROM_SIGMAS * sigma && p.bin >= TIGHT_FROM_BIN,
        tighten_auto: false,
        ..cfg
    }
}
