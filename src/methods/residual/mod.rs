//! The residual layer: every valid sample coded to within the bound on the data's own
//! integer lattice — predicted from samples already decoded (multilevel interpolation or
//! the weighted scan predictor, whichever the encoder finds smaller), the prediction error
//! quantized into bins of odd width (closed loop: the encoder reconstructs exactly as the
//! decoder will), the bins range coded under adaptive contexts. All decoder arithmetic is
//! integer until the one lattice-to-value formula (spec/FORMAT.md, residual section).

mod coder;
mod fast;
mod interp;
mod lattice;
mod ls;
mod method;
mod plane;
mod weighted;

pub(crate) use method::Residual;

use crate::container::Header;
use crate::container::flat::Flat;
use crate::container::bytes::{ByteReader, PutLe};
use crate::entropy::range::{Decoder, Encoder};
use crate::error::{Error, Result};
use crate::model::{Raster, SampleType, Window};
use crate::quant::{Errors, finish_value};
use rayon::prelude::*;
use coder::{BinDecoder, BinEncoder, Models};
use lattice::{Domain, MAX_UNITS};
use plane::{CODED, FIXED, Plane, SKIPPED};

const CODING_LATTICE: u8 = 0;
/// As [`CODING_LATTICE`], with narrower bins on coarse interpolation levels.
const CODING_LATTICE_TIGHT: u8 = 1;
/// The fast coding: interpolation, static rANS tokens, streams per band of rows.
const CODING_FAST: u8 = 2;
/// As [`CODING_FAST`], with narrower bins on coarse levels.
const CODING_FAST_TIGHT: u8 = 3;
/// The lane coding: the fast coding's passes predicted from coarser passes only, four
/// interleaved rANS states (spec/FORMAT.md, "Lane coding").
const CODING_LANES: u8 = 4;
/// As [`CODING_LANES`], with narrower bins on coarse levels.
const CODING_LANES_TIGHT: u8 = 5;
const PRED_INTERP: u8 = 0;
const PRED_WEIGHTED: u8 = 1;
/// Bytes before the stencil weights.
const FIXED_LEN: usize = 72;
/// Largest anchor exponent (stride 2^12).
const MAX_LEVELS: u8 = 12;
/// Interpolation levels with a least-squares correction, finest first.
const LS_LEVELS: u32 = 3;
/// What the encoder reckons one exception costs, in bits (a gap and a float).
const EXCEPTION_BITS: f64 = 48.0;
/// Sub-lattice refinements the encoder considers (bins of (2·⌊d·E/q⌋+1)/d steps).
const MAX_SUBDIVISION: i64 = 16;

/// The encoder effort without `--effort`. What each effort does in the residual layer
/// (`codings`): 1–5 the lane coding (5 also sub-lattice bins on floating-point rasters),
/// except 2, the fast coding; 6 both range-coded predictors (the compact coding, with
/// sub-lattice bins and narrower coarse bins); 7–9 all of those, the smallest kept.
/// The lane coding is the default since issue 37: 5.8–8.2 % larger than the compact
/// coding (geomean per bound on the corpus) and 2–6× faster to decode (benches/README.md).
pub const DEFAULT_EFFORT: u8 = 5;
/// The effort that writes the compact (range-coded) coding alone: the smallest files of a
/// single coding, 2–6× slower to decode than the default.
pub const COMPACT_EFFORT: u8 = 6;

/// One way of coding the plane.
#[derive(Clone, Copy, Debug)]
enum Predictor {
    Interp(interp::Config),
    Weighted,
    /// The fast coding (codings 2 and 3).
    Fast(fast::Config),
}

/// What the encoder settled on, before coding.
struct Setup {
    domain: Domain,
    values: Vec<i64>,
    lo: i64,
    hi: i64,
    bin: i64,
    /// Samples off the lattice (lossless only), stored verbatim after the stencil weights.
    exceptions: Vec<usize>,
}

/// The kinds of every sample: fixed (a value in `fixed`, known to the decoder by other
/// means), skipped (invalid in `mask`) or coded.
fn kinds(n: usize, mask: Option<&[bool]>, fixed: Option<&[f64]>) -> Vec<u8> {
    (0..n)
        .map(|i| {
            if fixed.is_some_and(|f| !f[i].is_nan()) {
                FIXED
            } else if mask.is_some_and(|m| !m[i]) {
                SKIPPED
            } else {
                CODED
            }
        })
        .collect()
}

/// The interpolation levels for a raster: anchors every 64 samples, fewer on small rasters.
fn levels_for(w: usize, h: usize) -> u32 {
    let side = w.max(h).max(2);
    (usize::BITS - 1 - (side - 1).leading_zeros()).clamp(1, 6)
}

/// Encode `r` within `e` (0 = lossless). `fixed` holds the values the decoder gets
/// elsewhere (flat regions; NaN elsewhere), samples `r` marks invalid.
pub(crate) fn encode(
    r: &Raster,
    header: &Header,
    e: f64,
    fixed: Option<&[f64]>,
    effort: u8,
    levels_first: bool,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, f64)> {
    if !(e >= 0.0 && e.is_finite()) {
        return Err(Error::invalid(format!(
            "max error {e} must be a finite number ≥ 0"
        )));
    }
    if !(1..=9).contains(&effort) {
        return Err(Error::invalid(format!(
            "effort {} is not in 1..=9",
            effort
        )));
    }
    let kinds = kinds(r.len(), r.mask.as_deref(), fixed);
    let (w, h) = (r.width, r.height);
    let levels = levels_for(w, h);
    let preds = {
        let cfg = interp::Config {
            levels,
            ls_levels: LS_LEVELS.min(levels),
            tighten: false,
        };
        move |bin: i64| codings(cfg, bin, effort)
    };
    // Lossy coding may need a safety margin for the final rounding to the sample type;
    // try without first, and the encoder checks the bound on the decoder's values.
    let mut last = None;
    for margin in [false, true] {
        let Some(mut setup) = setup(r, e, margin, effort)? else {
            break;
        };
        if let Some(f) = fixed {
            for (i, &v) in f.iter().enumerate() {
                if !v.is_nan() {
                    setup.values[i] = setup.domain.index(v).clamp(
                        -MAX_UNITS as f64,
                        MAX_UNITS as f64,
                    ) as i64;
                }
            }
        }
        let mut best: Option<Vec<u8>> = None;
        let tries = preds(setup.bin);
        let n = tries.len();
        for (t, pred) in tries.into_iter().enumerate() {
            let p = Plane {
                width: w,
                height: h,
                kinds: &kinds,
                values: &setup.values,
                lo: setup.lo,
                hi: setup.hi,
                bin: setup.bin,
            };
            // Within a coding's share, the stages it reports (the fast codings').
            let mut within = |f: f64| progress((t as f64 + f.clamp(0.0, 1.0)) / n as f64);
            let exc = exceptions_bytes(r, &setup.exceptions);
            let (payload, rec) = match code(&p, pred, &setup, &exc, &mut within) {
                Ok(x) => x,
                // The weighted predictor cannot code every plane: its mean prediction must
                // stay within ±2^45 eighths of a step (`weighted::MAX_P`, what keeps its
                // arithmetic in i64). Interpolation, tried before it, codes any plane, so it
                // is left out.
                Err(_) if matches!(pred, Predictor::Weighted) => continue,
                Err(e) => return Err(e),
            };
            let mut errs = Errors::default();
            let mut next_exc = setup.exceptions.iter().peekable();
            for (i, &k) in rec.iter().enumerate() {
                if r.is_valid(i) {
                    // An exception decodes to its stored value, the others to the lattice's.
                    let v = if next_exc.next_if_eq(&&i).is_some() {
                        finish_value(r.data[i], header)
                    } else {
                        finish_value(setup.domain.raw(k), header)
                    };
                    errs.add(v, r.data[i]);
                }
            }
            if errs.max > e {
                last = Some(errs.max);
                best = None;
                break;
            }
            // Each predictor is one full coding pass: the progress counts them (a second,
            // margin pass is rare and starts over within the last share).
            progress((t + 1) as f64 / n as f64);
            let mut payload = payload;
            payload[32..40].copy_from_slice(&errs.max.to_le_bytes());
            // The smallest wins; with `levels_first` a coding without coarse levels (the
            // weighted scan) only by more than LEVELS_FIRST_MARGIN.
            let keep = if levels_first && matches!(pred, Predictor::Weighted) {
                1.0 - crate::methods::LEVELS_FIRST_MARGIN
            } else {
                1.0
            };
            if best
                .as_ref()
                .is_none_or(|b| (payload.len() as f64) < keep * b.len() as f64)
            {
                best = Some(payload);
            }
        }
        if let Some(b) = best {
            let bound = f64::from_le_bytes(b[32..40].try_into().expect("8 bytes"));
            return Ok((b, bound));
        }
        if e == 0.0 {
            break;
        }
    }
    Err(Error::unmet(match last {
        Some(m) => format!(
            "the residual layer cannot keep this raster within {} (it reached {})",
            crate::metrics::num(e),
            crate::metrics::num(m)
        ),
        None => "the residual layer has no integer lattice for these values within its range"
            .to_string(),
    }))
}

/// Which codings to try. Efforts 1 and 3–5: the lane coding alone (coding 4 or 5);
/// effort 2: the fast coding alone (2 or 3); each with narrower coarse-level bins where
/// bins are wide against the finest level's prediction error ([`fast::resolve`]) and
/// stencil corrections where the encoder reckons they pay. Effort 6: the two range-coded
/// predictors (multilevel interpolation, the weighted scan), and interpolation with
/// narrower coarse bins when bins are ≥ 3 steps (SZ3's α/β: it gains at wide bins and
/// loses at narrow ones). Efforts 7–9: all of those, the lane coding and both bin layouts
/// of the fast coding. The smallest wins.
fn codings(cfg: interp::Config, bin: i64, effort: u8) -> Vec<Predictor> {
    let fast = |tighten, tighten_auto, lanes| {
        Predictor::Fast(fast::Config {
            levels: cfg.levels,
            ls_levels: cfg.ls_levels,
            tighten,
            tighten_auto,
            band_log2: fast::DEFAULT_BAND_LOG2,
            lanes,
        })
    };
    if effort == 2 {
        return vec![fast(false, true, false)];
    }
    if effort <= DEFAULT_EFFORT {
        return vec![fast(false, true, true)];
    }
    let mut v = vec![Predictor::Interp(cfg)];
    if bin >= 3 {
        v.push(Predictor::Interp(interp::Config {
            tighten: true,
            ..cfg
        }));
    }
    v.push(Predictor::Weighted);
    if effort > COMPACT_EFFORT {
        v.extend([
            fast(false, true, true),
            fast(false, false, false),
            fast(true, false, false),
        ]);
    }
    v
}

/// The lattice, units and bin width for bound `e`; `None` when there is nothing to try.
fn setup(r: &Raster, e: f64, margin: bool, effort: u8) -> Result<Option<Setup>> {
    let float_out = matches!(r.sample_type, SampleType::F32 | SampleType::F64);
    // The data's step; else, when the bound makes it lossless on it, the step with the
    // few samples off it stored verbatim; else a power-of-two step; else (lossy) an
    // approximate one.
    let mut exceptions = Vec::new();
    // Only for a lossless request: below half a step a lossy code on a finer step can be
    // smaller (measured: Vinschgau at 0.01 % of its range, 48 795 against 50 527 bytes).
    // Lossless means the same bits (a −0 sample is no sample of a lattice decoding +0).
    let bits = e == 0.0;
    let stepped = lattice::stepped(r, bits);
    // A coarser step with exceptions beats a finer exact one (or a power of two) when the
    // exceptions (~48 bits each) cost less than the finer step's extra bits per sample.
    // (Not looked for at all when lossy: that saves its passes over the data.)
    let coarser = (e == 0.0)
        .then(|| lattice::with_exceptions(r))
        .flatten()
        .filter(|(d, _, x)| {
            stepped.as_ref().is_none_or(|(s, _)| {
                d.unit() > s.unit()
                    && (x.len() as f64) * EXCEPTION_BITS
                        < r.valid_count() as f64 * (d.unit() / s.unit()).log2()
            })
        });
    let found = match (stepped, coarser) {
        (_, Some((d, k, x))) => {
            exceptions = x;
            Some((d, k))
        }
        (Some(x), None) => Some(x),
        (None, None) => lattice::pow2(r, bits),
    };
    let (domain, values, exact) = match found {
        Some((d, k)) => (d, k, true),
        None if e > 0.0 => match lattice::approximate(r, e) {
            Some((d, k)) => (d, k, false),
            None => return Ok(None),
        },
        None => return Ok(None),
    };
    let (mut lo, mut hi) = (i64::MAX, i64::MIN);
    for (i, &k) in values.iter().enumerate() {
        if r.is_valid(i) {
            lo = lo.min(k);
            hi = hi.max(k);
        }
    }
    if lo > hi {
        (lo, hi) = (0, 0);
    }
    let unit = domain.unit();
    let mut budget = e;
    if !exact {
        budget -= unit / 2.0;
    }
    if margin {
        let amax = r.valid_range().map_or(0.0, |(a, b)| a.abs().max(b.abs())) + e;
        budget -= amax
            * if r.sample_type == SampleType::F64 {
                2f64.powi(-51)
            } else {
                2f64.powi(-22)
            };
    }
    let eu = (budget / unit).max(0.0);
    // Sub-lattice bins: units of 1/d step, the d giving the widest bin per step.
    let mut d = 1i64;
    if float_out && eu >= 0.5 && effort >= 5 && eu < 1e6 {
        let width = |d: i64| (2.0 * (d as f64 * eu).floor() + 1.0) / d as f64;
        for c in 2..=MAX_SUBDIVISION {
            if width(c) > width(d) {
                d = c;
            }
        }
    }
    // Sub-lattice units multiply the indices by d: on a lattice already near ±2^38 steps
    // they would leave the range a section may hold, so it is coded on its own steps.
    if lo.abs().max(hi.abs()) > MAX_UNITS / d {
        d = 1;
    }
    let bin = 2.0 * (d as f64 * eu).floor() + 1.0;
    // Odd and at most 2^38 (2^38 − 1 is the widest odd bin a decoder takes).
    let bin = bin.min((MAX_UNITS - 1) as f64) as i64;
    let (lo, hi) = (lo * d, hi * d);
    if lo < -MAX_UNITS || hi > MAX_UNITS {
        return Ok(None);
    }
    let values = if d > 1 {
        values.into_iter().map(|k| k * d).collect()
    } else {
        values
    };
    Ok(Some(Setup {
        domain: Domain {
            div: domain.div * d as f64,
            ..domain
        },
        values,
        lo,
        hi,
        bin,
        exceptions,
    }))
}

/// Code the plane with one predictor: the payload (max error still 0) and the
/// reconstruction in units.
fn code(
    p: &Plane,
    pred: Predictor,
    s: &Setup,
    exceptions: &[u8],
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, Vec<i64>)> {
    let mut c = BinEncoder {
        m: Models::new(),
        enc: Encoder::with_capacity(p.kinds.len() / 4),
    };
    if let Predictor::Fast(cfg) = pred {
        let cfg = fast::resolve(p, cfg);
        let (weights, body, rec) = fast::encode(p, cfg, progress)?;
        let mut out = fixed_fields(
            match (cfg.lanes, cfg.tighten) {
                (false, false) => CODING_FAST,
                (false, true) => CODING_FAST_TIGHT,
                (true, false) => CODING_LANES,
                (true, true) => CODING_LANES_TIGHT,
            },
            PRED_INTERP,
            cfg.levels as u8,
            weights.len() as u8,
            p,
            s,
        );
        for w in weights.iter().flatten() {
            out.extend_from_slice(&w.to_le_bytes());
        }
        out.extend_from_slice(exceptions);
        out.extend_from_slice(&body);
        return Ok((out, rec));
    }
    let (code, levels, weights, st) = match pred {
        Predictor::Fast(_) => unreachable!("coded above"),
        Predictor::Interp(cfg) => {
            let mut wts = Vec::new();
            let st = interp::run(p, cfg, &mut wts, &mut c, 0)?;
            let flat: Vec<i16> = wts.iter().flatten().copied().collect();
            (PRED_INTERP, cfg.levels as u8, (wts.len(), flat), st)
        }
        Predictor::Weighted => {
            let wts = weighted::fit(p);
            let st = weighted::run(p, &wts, &mut c)?;
            let flat: Vec<i16> = wts.iter().flatten().copied().collect();
            (PRED_WEIGHTED, 0, (wts.len(), flat), st)
        }
    };
    let tight = matches!(pred, Predictor::Interp(c) if c.tighten);
    let coding = if tight {
        CODING_LATTICE_TIGHT
    } else {
        CODING_LATTICE
    };
    let mut out = fixed_fields(coding, code, levels, weights.0 as u8, p, s);
    for w in &weights.1 {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out.extend_from_slice(exceptions);
    out.extend_from_slice(&c.enc.finish());
    Ok((out, st.rec))
}

/// The section's first [`FIXED_LEN`] bytes (max error 0: the encoder sets it once checked).
fn fixed_fields(coding: u8, pred: u8, levels: u8, weight_sets: u8, p: &Plane, s: &Setup) -> Vec<u8> {
    let coded = p.kinds.iter().filter(|&&k| k == CODED).count() as u64;
    let mut out = Vec::new();
    out.put_u8(coding);
    out.put_u8(pred);
    out.put_u8(levels);
    out.put_u8(weight_sets);
    out.put_u32(s.exceptions.len() as u32);
    out.put_f64(s.domain.mul);
    out.put_f64(s.domain.div);
    out.put_f64(s.domain.offset);
    out.put_f64(0.0);
    out.put_u64(p.bin as u64);
    out.put_u64(p.lo as u64);
    out.put_u64(p.hi as u64);
    out.put_u64(coded);
    debug_assert_eq!(out.len(), FIXED_LEN);
    out
}

/// The fixed fields of a residual payload, checked.
struct Head {
    cfg: Predictor,
    weight_sets: usize,
    domain: Domain,
    bound: f64,
    bin: u64,
    lo: i64,
    hi: i64,
    coded: u64,
    exceptions: u32,
}

/// Read and check the fixed fields (the reader is left at the stencil weights).
fn read_head(rd: &mut ByteReader) -> Result<Head> {
    let coding = rd.u8("coding")?;
    if coding > CODING_LANES_TIGHT {
        return Err(rd.corrupt(format!("coding {coding} is not defined")));
    }
    let fast = coding >= CODING_FAST;
    let pred = rd.u8("predictor")?;
    let levels = rd.u8("levels")?;
    let weight_sets = rd.u8("weight sets")? as usize;
    let cfg = match pred {
        PRED_INTERP => {
            if !(1..=MAX_LEVELS).contains(&levels) {
                return Err(rd.corrupt(format!("{levels} interpolation levels (1 ..= 12)")));
            }
            if weight_sets % 2 != 0 || weight_sets > 2 * levels.min(4) as usize {
                return Err(rd.corrupt(format!("{weight_sets} weight sets for {levels} levels")));
            }
            if fast {
                Predictor::Fast(fast::Config {
                    levels: levels as u32,
                    ls_levels: weight_sets as u32 / 2,
                    tighten: coding == CODING_FAST_TIGHT || coding == CODING_LANES_TIGHT,
                    tighten_auto: false,
                    // Read with the streams.
                    band_log2: 0,
                    lanes: coding >= CODING_LANES,
                })
            } else {
            Predictor::Interp(interp::Config {
                levels: levels as u32,
                ls_levels: weight_sets as u32 / 2,
                tighten: coding == CODING_LATTICE_TIGHT,
            })
            }
        }
        PRED_WEIGHTED => {
            if coding != CODING_LATTICE {
                return Err(rd.corrupt("the weighted predictor has no coarse levels to tighten"));
            }
            if levels != 0 || weight_sets != weighted::CLASSES {
                return Err(rd.corrupt("weighted predictor: levels must be 0 and weight sets 8"));
            }
            Predictor::Weighted
        }
        _ => return Err(rd.corrupt(format!("predictor {pred} is not defined"))),
    };
    let exceptions = rd.u32("exception count")?;
    let mul = rd.finite_f64("mul")?;
    let div = rd.finite_f64("div")?;
    let offset = rd.finite_f64("offset")?;
    if mul == 0.0 || div <= 0.0 {
        return Err(rd.corrupt("mul must be ≠ 0 and div > 0"));
    }
    let bound = rd.finite_f64("max error")?;
    if bound < 0.0 {
        return Err(rd.corrupt("max error is negative"));
    }
    let bin = rd.u64("bin width")?;
    if bin % 2 == 0 || bin > MAX_UNITS as u64 {
        return Err(rd.corrupt(format!("bin width {bin} is not odd in 1 ..= 2^38")));
    }
    let lo = rd.u64("lo")? as i64;
    let hi = rd.u64("hi")? as i64;
    if !(-MAX_UNITS <= lo && lo <= hi && hi <= MAX_UNITS) {
        return Err(rd.corrupt(format!("range {lo} ..= {hi} is outside ±2^38")));
    }
    let coded = rd.u64("coded count")?;
    Ok(Head {
        cfg,
        weight_sets,
        domain: Domain { mul, div, offset },
        bound,
        bin,
        lo,
        hi,
        coded,
        exceptions,
    })
}

/// The exceptions as stored: per sample, in sample order, the varint gap from the previous
/// one (the index itself for the first; index − previous − 1 after) and its value's bits
/// (f32 for f32 data, f64 otherwise), little-endian.
fn exceptions_bytes(r: &Raster, idx: &[usize]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut next = 0usize;
    for &i in idx {
        crate::entropy::varint::put_u64(&mut out, (i - next) as u64);
        next = i + 1;
        if r.sample_type == SampleType::F32 {
            out.extend_from_slice(&(r.data[i] as f32).to_le_bytes());
        } else {
            out.put_f64(r.data[i]);
        }
    }
    out
}

/// A varint (LEB128, at most 10 bytes).
fn read_varint(rd: &mut ByteReader) -> Result<u64> {
    let mut v = 0u64;
    for k in 0..10 {
        let b = rd.u8("exception gap")?;
        if k == 9 && b > 1 {
            break;
        }
        v |= ((b & 0x7f) as u64) << (7 * k);
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(rd.corrupt("an exception gap is not a varint"))
}

/// Decode the window `win` of a residual payload. `flat` holds the samples known by other
/// means (flat regions). The whole payload is read and checked; the fast coding decodes
/// only the bands the window's rows need, the range-coded ones (one stream) everything.
/// With `stop` above 0 the result is instead the samples at every 2^stop-th row and column
/// of the whole raster (`win` is then the whole raster), and the interpolation codings
/// decode only the levels that reach them.
pub(crate) fn decode(
    payload: &[u8],
    header: &Header,
    mask: Option<&[bool]>,
    flat: Option<&Flat>,
    win: Window,
    stop: u32,
) -> Result<Vec<f64>> {
    decode_marked(payload, header, mask, flat, win, stop, None)
}

/// For an overview decode (`stop` = K ≥ 1), the bytes of the payload it reads: element K − 1
/// for K = 1 ..= L (coarser overviews read what K = L reads, the anchors'), empty for the
/// weighted scan (it has no coarse levels: every overview reads it whole). The interpolation
/// codings' range-coded stream is decoded through level 2 to find where each level ends
/// (the coder reads one byte per renormalisation, so a decode that stops after a level
/// reads exactly the bytes it had read there); the fast coding's streams are located from
/// its stream directory alone. What version 4's progressive tiles are cut at
/// (spec/FORMAT.md, "Version 4").
pub(crate) fn overview_prefixes(
    payload: &[u8],
    header: &Header,
    mask: Option<&[bool]>,
    flat: Option<&Flat>,
) -> Result<Vec<usize>> {
    let (levels, weighted) = {
        let mut rd = ByteReader::new(payload, "residual section");
        let h = read_head(&mut rd)?;
        match h.cfg {
            Predictor::Interp(c) => (c.levels, false),
            Predictor::Fast(f) => (f.levels, false),
            Predictor::Weighted => (0, true),
        }
    };
    if weighted || levels == 0 {
        return Ok(Vec::new());
    }
    let all = Window::full(header.width as usize, header.height as usize);
    let mut marks = Vec::new();
    decode_marked(payload, header, mask, flat, all, 1, Some(&mut marks))?;
    // marks: the anchors', then level L's, L − 1's, …: overview K reads through level K + 1
    // (level L + 1 = the anchors).
    let at = |l: u32| marks.get((levels + 1 - l) as usize).copied();
    (1..=levels)
        .map(|k| {
            at(k + 1)
                .map(|e| e.min(payload.len()))
                .ok_or_else(|| Error::corrupt("residual section: a level's end is missing"))
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn decode_marked(
    payload: &[u8],
    header: &Header,
    mask: Option<&[bool]>,
    flat: Option<&Flat>,
    win: Window,
    stop: u32,
    marks: Option<&mut Vec<usize>>,
) -> Result<Vec<f64>> {
    let mut rd = ByteReader::new(payload, "residual section");
    let Head {
        cfg,
        weight_sets: nweights,
        domain,
        bound: _,
        bin,
        lo,
        hi,
        coded,
        exceptions,
    } = read_head(&mut rd)?;
    let n = header.samples() as usize;
    let (w, h) = (header.width as usize, header.height as usize);
    if mask.is_some_and(|m| m.len() != n) {
        return Err(Error::corrupt("residual section: mask and raster sizes differ"));
    }
    // The samples the header says the section codes are counted without allocating
    // anything sized by the header: a header that claims more than the section codes is
    // rejected before the planes are built.
    let mut want = mask.map_or(n, crate::model::count_true) as u64;
    for (s, l, _) in flat.into_iter().flat_map(Flat::runs) {
        // (A run past the raster counts nothing here and is refused below.)
        let valid = match mask {
            None => l,
            Some(m) => m.get(s..s + l).map_or(0, crate::model::count_true),
        };
        want = want.saturating_sub(valid as u64);
    }
    if coded != want {
        return Err(rd.corrupt(format!("codes {coded} samples, the raster has {want}")));
    }
    let flat = flat.filter(|f| f.runs().next().is_some());
    if flat.is_some_and(|f| f.runs().last().is_some_and(|(s, l, _)| s + l > n)) {
        return Err(Error::corrupt("residual section: mask and raster sizes differ"));
    }
    // The fast coding reads no kinds when every sample is coded (an empty plane).
    let every_coded = mask.is_none() && flat.is_none();
    let kinds = if every_coded && matches!(cfg, Predictor::Fast(_)) {
        Vec::new()
    } else {
        let mut k: Vec<u8> = match mask {
            Some(m) => m.iter().map(|&v| if v { CODED } else { SKIPPED }).collect(),
            None => vec![CODED; n],
        };
        for (s, l, _) in flat.into_iter().flat_map(Flat::runs) {
            k[s..s + l].fill(FIXED);
        }
        k
    };
    let nf = match cfg {
        Predictor::Interp(_) => interp::NF,
        Predictor::Weighted => weighted::NF,
        Predictor::Fast(_) => fast::NW,
    };
    let mut flat_w = Vec::with_capacity(nweights * nf);
    for _ in 0..nweights * nf {
        flat_w.push(rd.u16("stencil weight")? as i16);
    }
    // Exceptions: coded samples whose value is stored verbatim (only float data has them).
    if exceptions as u64 > coded
        || (exceptions > 0 && !matches!(header.sample_type, SampleType::F32 | SampleType::F64))
    {
        return Err(rd.corrupt(format!("{exceptions} exceptions do not fit this raster")));
    }
    let mut exc: Vec<(usize, f64)> = Vec::new();
    let mut next = 0u64;
    for _ in 0..exceptions {
        let i = next.saturating_add(read_varint(&mut rd)?);
        let v = if header.sample_type == SampleType::F32 {
            f32::from_bits(rd.u32("exception value")?) as f64
        } else {
            rd.f64("exception value")?
        };
        let coded_at = |i: usize| kinds.get(i).is_none_or(|&k| k == CODED);
        if i >= n as u64 || !coded_at(i as usize) || !v.is_finite() {
            return Err(rd.corrupt(format!("exception at sample {i} is not a coded sample with a finite value")));
        }
        exc.push((i as usize, v));
        next = i + 1;
    }
    // The fixed samples' values: runs for the lane coding (it writes them into its plane),
    // a plane of them for the others (only they are read).
    let lanes = matches!(cfg, Predictor::Fast(f) if f.lanes);
    let index_of = |v: f64| domain.index(v).clamp(-MAX_UNITS as f64, MAX_UNITS as f64) as i64;
    let fixed_runs: Vec<(usize, usize, i64)> = if lanes {
        flat.into_iter().flat_map(Flat::runs).map(|(s, l, v)| (s, l, index_of(v))).collect()
    } else {
        Vec::new()
    };
    let mut values = if flat.is_some() && !lanes { vec![0i64; n] } else { Vec::new() };
    if !lanes {
        for (s, l, v) in flat.into_iter().flat_map(Flat::runs) {
            values[s..s + l].fill(index_of(v));
        }
    }
    let p = Plane {
        width: w,
        height: h,
        kinds: &kinds,
        values: &values,
        lo,
        hi,
        bin: bin as i64,
    };
    // The narrowest bins (tightened coarse levels) allow the largest bins.
    let max_bin = ((hi - lo) as u64) / narrowest(cfg, bin as i64) as u64 + 1;
    let rec: fast::Rec = if let Predictor::Fast(f) = cfg {
        let wts: Vec<[i16; fast::NW]> = flat_w
            .chunks_exact(fast::NW)
            .map(|c| c.try_into().expect("NW weights"))
            .collect();
        fast::decode(&mut rd, &p, &fixed_runs, f.levels, f.tighten, f.lanes, &wts, max_bin, win.y..win.y + win.height, stop, marks)?
    } else {
    // Codings 0 and 1 are one range-coded stream: every sample is decoded, whatever the
    // window.
    let stream_at = rd.position();
    let stream = rd.take(rd.remaining(), "bins")?;
    let mut c = BinDecoder {
        m: Models::new(),
        dec: Decoder::new(stream)?,
        max_bin,
        marks: Vec::new(),
    };
    let st = match cfg {
        Predictor::Fast(_) => unreachable!("decoded above"),
        Predictor::Interp(cfg) => {
            let mut wts: Vec<[i16; interp::NF]> = flat_w
                .chunks_exact(interp::NF)
                .map(|c| c.try_into().expect("NF weights"))
                .collect();
            interp::run(&p, cfg, &mut wts, &mut c, stop)?
        }
        Predictor::Weighted => {
            let wts: Vec<[i16; weighted::NF]> = flat_w
                .chunks_exact(weighted::NF)
                .map(|c| c.try_into().expect("NF weights"))
                .collect();
            weighted::run(&p, &wts, &mut c)?
        }
    };
    if stop == 0 || matches!(cfg, Predictor::Weighted) {
        c.dec.finish()?;
    } else {
        // A decode that stopped after a coarse level has not reached the stream's end, but
        // read nothing past the end of what it was given (a version-4 tile's prefix).
        c.dec.check_in_bounds()?;
    }
    if let Some(m) = marks {
        m.extend(c.marks.iter().map(|&e| stream_at + e));
    }
    fast::Rec::I64(st.rec, 0)
    };
    let fill = header.nodata.unwrap_or(f64::NAN);
    if stop > 0 {
        // Every 2^stop-th sample of every 2^stop-th row, as the full decode has them.
        let s = 1usize << stop;
        let (ow, oh) = (w.div_ceil(s), h.div_ceil(s));
        let rec = match &rec {
            fast::Rec::I32(v, o) => fast::Rec::I32(crate::methods::decimate(v, w, h, stop), *o),
            fast::Rec::I64(v, o) => fast::Rec::I64(crate::methods::decimate(v, w, h, stop), *o),
        };
        let kinds = if kinds.is_empty() { kinds } else { crate::methods::decimate(&kinds, w, h, stop) };
        let mut out = lattice_values(&rec, &kinds, fill, domain, header, ow, Window::full(ow, oh), (lo, hi));
        if let Some(f) = flat {
            for (j, o) in out.iter_mut().enumerate() {
                if let Some(v) = f.value_at((j / ow) * s * w + (j % ow) * s) {
                    *o = v;
                }
            }
        }
        for (i, v) in exc {
            let (x, y) = (i % w, i / w);
            if x % s == 0 && y % s == 0 {
                out[(y / s) * ow + x / s] = v;
            }
        }
        return Ok(out);
    }
    let mut out = lattice_values(&rec, &kinds, fill, domain, header, w, win, (lo, hi));
    if let Some(f) = flat {
        f.overwrite(&mut out, w, (win.x, win.y, win.width, win.height));
    }
    for (i, v) in exc {
        let (x, y) = (i % w, i / w);
        if (win.x..win.x + win.width).contains(&x) && (win.y..win.y + win.height).contains(&y) {
            out[(y - win.y) * win.width + x - win.x] = v;
        }
    }
    Ok(out)
}

/// The values of the window `win`'s coded samples from their lattice indices (planes `w`
/// wide; `kinds` empty: all coded; a skipped sample gets `fill`): `finish_value(domain.raw(k))`, without the
/// multiplication, division and rounding where the lattice is the integers and the sample
/// type's codes are the values (the same result: every step is exact). The case is chosen
/// once, so the loop over the samples holds no branch but the kinds'.
#[allow(clippy::too_many_arguments)]
fn lattice_values(
    rec: &fast::Rec,
    kinds: &[u8],
    fill: f64,
    domain: Domain,
    header: &Header,
    w: usize,
    win: Window,
    range: (i64, i64),
) -> Vec<f64> {
    // The section's own range lies inside the type's: the clamp to it is a no-op, and
    // leaving it out keeps the loop a plain conversion (the same values).
    let within = header
        .sample_type
        .int_range()
        .is_some_and(|(a, b)| a <= range.0 as f64 && range.1 as f64 <= b);
    match rec {
        // (k + o in f64 is the index exactly: |k| < 2^31, |o| ≤ 2^38; and it vectorises.)
        fast::Rec::I32(v, o) => {
            let of = *o as f64;
            lattice_values_of(v, move |k| k as f64 + of, kinds, fill, domain, header, w, win, within)
        }
        fast::Rec::I64(v, o) => {
            let o = *o;
            lattice_values_of(v, move |k| (k + o) as f64, kinds, fill, domain, header, w, win, within)
        }
    }
}

/// [`lattice_values`] of a plane of `V`, `index_f` its lattice index as f64 (exactly).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn lattice_values_of<V: Copy + Sync>(
    rec: &[V],
    index_f: impl Fn(V) -> f64 + Sync + Copy,
    kinds: &[u8],
    fill: f64,
    domain: Domain,
    header: &Header,
    w: usize,
    win: Window,
    within: bool,
) -> Vec<f64> {
    let at = (w, win);
    let ident = domain.mul == 1.0 && domain.div == 1.0 && domain.offset == 0.0;
    let int_codes = (header.mapping.scale == 1.0 && header.mapping.offset == 0.0)
        .then(|| header.sample_type.int_range())
        .flatten();
    match (ident, int_codes) {
        (true, Some(_)) if within => map_values(rec, kinds, fill, at, index_f),
        (true, Some((lo, hi))) => map_values(rec, kinds, fill, at, move |k| index_f(k).clamp(lo, hi)),
        (true, None) => map_values(rec, kinds, fill, at, |k| crate::quant::finish_value(index_f(k), header)),
        // From the f64 index (the same value as the i64's: its conversion vectorises, the
        // i64's does not), float32 samples rounded in the loop without the sample type's
        // match per sample: the same values, a 512² web tile's mapping in less time.
        _ if header.sample_type == SampleType::F32 => {
            map_values(rec, kinds, fill, at, |k| domain.raw_f(index_f(k)) as f32 as f64)
        }
        _ => map_values(rec, kinds, fill, at, |k| finish_value(domain.raw_f(index_f(k)), header)),
    }
}

/// [`lattice_values`] with the value function chosen, in chunks of whole window rows
/// (about 2^16 samples) on all threads; `w` is the raster's width.
fn map_values<V: Copy + Sync>(
    rec: &[V],
    kinds: &[u8],
    fill: f64,
    (w, win): (usize, Window),
    value: impl Fn(V) -> f64 + Sync,
) -> Vec<f64> {
    const CHUNK: usize = 1 << 16;
    let ww = win.width;
    let mut out = vec![0f64; ww * win.height];
    if out.is_empty() {
        return out;
    }
    let rows = (CHUNK / ww).max(1);
    let arch = pulp::Arch::new();
    out.par_chunks_mut(rows * ww).enumerate().for_each(|(c, o)| {
        for (r, o) in o.chunks_mut(ww).enumerate() {
            let at = (win.y + c * rows + r) * w + win.x;
            let rr = &rec[at..at + ww];
            let kd = (!kinds.is_empty()).then(|| &kinds[at..at + ww]);
            arch.dispatch(ValueRow { out: o, rec: rr, kinds: kd, fill, value: &value });
        }
    });
    out
}

/// One row of [`map_values`] as a `pulp` operation (compiled for the processor's vector
/// instructions: the conversion to f64 and the clamp vectorise).
struct ValueRow<'a, V, F> {
    out: &'a mut [f64],
    rec: &'a [V],
    kinds: Option<&'a [u8]>,
    fill: f64,
    value: &'a F,
}

impl<V: Copy, F: Fn(V) -> f64> pulp::WithSimd for ValueRow<'_, V, F> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let value = self.value;
        match self.kinds {
            None => {
                for (o, &k) in self.out.iter_mut().zip(self.rec) {
                    *o = value(k);
                }
            }
            Some(kd) => {
                let fill = self.fill;
                for ((o, &k), &kind) in self.out.iter_mut().zip(self.rec).zip(kd) {
                    // A select, not a branch: the loop vectorises.
                    let v = value(k);
                    *o = if kind == SKIPPED { fill } else { v };
                }
            }
        }
    }
}

/// The narrowest bin width of an interpolation coding with `levels` levels.
#[cfg(test)]
fn narrowest_bin(bin: i64, levels: u32, tighten: bool) -> i64 {
    narrowest(
        Predictor::Interp(interp::Config {
            levels,
            ls_levels: 0,
            tighten,
        }),
        bin,
    )
}

/// The narrowest bin width any sample of the section uses.
fn narrowest(cfg: Predictor, bin: i64) -> i64 {
    match cfg {
        Predictor::Interp(interp::Config {
            levels,
            tighten: true,
            ..
        })
        | Predictor::Fast(fast::Config {
            levels,
            tighten: true,
            ..
        }) => (1..=levels + 1)
            .map(|l| interp::level_bin(bin, l))
            .min()
            .unwrap_or(bin),
        _ => bin,
    }
}

/// What `vtz info --stats` shows of a residual payload: the predictor, its levels, the
/// lattice step and the bin width.
pub(crate) fn describe(payload: &[u8]) -> Result<(&'static str, u32, f64, u64, f64)> {
    let mut rd = ByteReader::new(payload, "residual section");
    let h = read_head(&mut rd)?;
    let (name, levels) = match h.cfg {
        Predictor::Interp(c) => ("interpolation", c.levels),
        Predictor::Weighted => ("weighted", 0),
        Predictor::Fast(c) if c.lanes => ("lane interpolation", c.levels),
        Predictor::Fast(c) => ("fast interpolation", c.levels),
    };
    Ok((name, levels, h.domain.unit(), h.bin, h.bound))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::Rng;

    /// The widest lattice a section may hold: every value and reconstruction in ±2^38.
    const M: i64 = MAX_UNITS;

    fn header(w: usize, h: usize) -> Header {
        Header {
            width: w as u32,
            height: h as u32,
            sample_type: SampleType::F64,
            primary: 0,
            mapping: Default::default(),
            nodata: None,
            range: None,
            georef: None,
        }
    }

    /// Planes whose values span the whole range the format allows, in the patterns that
    /// make predictions, residuals, stencil sums and contexts largest: samples alternating
    /// between −2^38 and 2^38 (along rows, columns, both), random extremes, uniform noise
    /// over the range, a ramp, lone spikes.
    /// The identity lattice over ±M with bin `bin`: the coder's setup and its plane.
    fn extreme_setup<'a>(
        w: usize,
        h: usize,
        kinds: &'a [u8],
        values: &'a [i64],
        bin: i64,
    ) -> (Setup, Plane<'a>) {
        let setup = Setup {
            domain: Domain { mul: 1.0, div: 1.0, offset: 0.0 },
            values: values.to_vec(),
            lo: -M,
            hi: M,
            bin,
            exceptions: Vec::new(),
        };
        let plane = Plane { width: w, height: h, kinds, values, lo: -M, hi: M, bin };
        (setup, plane)
    }

    fn extreme_planes(w: usize, h: usize) -> Vec<(&'static str, Vec<i64>)> {
        let mut rng = Rng(35);
        let n = w * h;
        let pm = |b: bool| if b { M } else { -M };
        let mut out: Vec<(&'static str, Vec<i64>)> = vec![
            ("alternating", (0..n).map(|i| pm(i % 2 == 0)).collect()),
            ("checkerboard", (0..n).map(|i| pm((i % w + i / w) % 2 == 0)).collect()),
            ("rows", (0..n).map(|i| pm((i / w) % 2 == 0)).collect()),
            ("ramp", (0..n).map(|i| -M + (2 * M / (n as i64 - 1).max(1)) * i as i64).collect()),
            ("spikes", (0..n).map(|i| if i % 7 == 3 { M } else { -M }).collect()),
        ];
        let ext = [-M, M, 0, M / 3, -M / 3, M - 1, -M + 1];
        out.push(("extremes", (0..n).map(|_| ext[rng.below(ext.len() as u64) as usize]).collect()));
        out.push(("noise", (0..n).map(|_| rng.below(2 * M as u64 + 1) as i64 - M).collect()));
        out
    }

    /// Every coding the encoder may choose: efforts 9 and 1's lists, at bin width `bin`.
    fn every_coding(w: usize, h: usize, bin: i64) -> Vec<Predictor> {
        let levels = levels_for(w, h);
        let cfg = interp::Config {
            levels,
            ls_levels: LS_LEVELS.min(levels),
            tighten: false,
        };
        let mut v = codings(cfg, bin, 9);
        v.extend(codings(cfg, bin, 1));
        v
    }

    /// Every coding codes and decodes planes spanning ±2^38 with bins of 1, 3, 1001 and the
    /// widest, with and without skipped samples: within half a bin of the source (exact at
    /// bin 1), the decoder's values the encoder's reconstruction. Under overflow checks
    /// (the ci profile) this is the proof that no product, sum or shift leaves i64; only the
    /// weighted predictor may decline a plane (its mean leaving ±2^45 eighths).
    #[test]
    fn planes_spanning_the_whole_lattice_range_round_trip_in_every_coding() {
        let (w, h) = (37, 29);
        let mut declined = 0;
        let mut coded = 0;
        for (name, values) in extreme_planes(w, h) {
            for holes in [false, true] {
                let kinds: Vec<u8> =
                    (0..w * h).map(|i| if holes && i % 11 == 5 { SKIPPED } else { CODED }).collect();
                let mask: Option<Vec<bool>> = holes.then(|| kinds.iter().map(|&k| k == CODED).collect());
                for bin in [1, 3, 1001, MAX_UNITS - 1] {
                    let (setup, p) = extreme_setup(w, h, &kinds, &values, bin);
                    for pred in every_coding(w, h, bin) {
                        let what = format!("{name}, holes {holes}, bin {bin}, {pred:?}");
                        let (payload, rec) = match code(&p, pred, &setup, &[], &mut |_| {}) {
                            Ok(x) => x,
                            Err(e) => {
                                assert!(matches!(pred, Predictor::Weighted), "{what}: {e}");
                                declined += 1;
                                continue;
                            }
                        };
                        coded += 1;
                        let back = decode(&payload, &header(w, h), mask.as_deref(), None, Window::full(w, h), 0)
                            .unwrap_or_else(|e| panic!("{what}: {e}"));
                        for i in 0..w * h {
                            if kinds[i] == CODED {
                                assert!((rec[i] - values[i]).abs() <= bin / 2, "{what}: sample {i}");
                                assert_eq!(back[i], rec[i] as f64, "{what}: sample {i}");
                            }
                        }
                    }
                }
            }
        }
        assert!(coded > 10 * declined, "{coded} coded, {declined} declined");
    }

    /// Hostile sections on the widest lattice: each coding's section of an extreme plane
    /// with its stencil weights set to ±2^15 and bits of its body flipped decodes to an
    /// error or to samples, never a panic (an overflow under the ci profile's checks).
    #[test]
    fn hostile_sections_on_the_widest_lattice_never_panic() {
        let (w, h) = (37, 29);
        let kinds = vec![CODED; w * h];
        let mut rng = Rng(7);
        for (_, values) in extreme_planes(w, h) {
            for bin in [1, MAX_UNITS - 1] {
                let (setup, p) = extreme_setup(w, h, &kinds, &values, bin);
                for pred in every_coding(w, h, bin) {
                    let Ok((payload, _)) = code(&p, pred, &setup, &[], &mut |_| {}) else { continue };
                    let sets = payload[3] as usize;
                    let nf = match pred {
                        Predictor::Weighted => weighted::NF,
                        Predictor::Interp(_) => interp::NF,
                        Predictor::Fast(_) => fast::NW,
                    };
                    let wend = FIXED_LEN + 2 * nf * sets;
                    for trial in 0..24 {
                        let mut bad = payload.clone();
                        for k in (FIXED_LEN..wend).step_by(2) {
                            let v: i16 = match trial % 3 {
                                0 => i16::MAX,
                                1 => i16::MIN,
                                _ => if rng.below(2) == 0 { i16::MAX } else { i16::MIN },
                            };
                            bad[k..k + 2].copy_from_slice(&v.to_le_bytes());
                        }
                        if trial >= 3 && bad.len() > wend {
                            for _ in 0..1 + trial % 4 {
                                let k = wend + rng.below((bad.len() - wend) as u64) as usize;
                                bad[k] ^= 1 << rng.below(8);
                            }
                        }
                        let _ = decode(&bad, &header(w, h), None, None, Window::full(w, h), 0);
                    }
                }
            }
        }
    }
}
