//! Encoding: pick the methods the request names (or `best`), run each through the
//! registry, and assemble the container (mask, sections, metadata).

use super::options::EncodeOptions;
use crate::container::{self, Header, SF_REQUIRED, Section, SectionKind};
use crate::error::{Error, Result};
use crate::methods::{EncodeJob, Encoded, Method, REGISTRY, Representation, Stats};
use crate::model::{Raster, Window};

/// What an encode produced besides the bytes.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct EncodeReport {
    /// Max error guaranteed on every valid sample (0 = lossless), in data units.
    pub max_error: f64,
    /// The method of the primary section.
    pub method: Method,
    /// The primary method's statistics, when it measures them while encoding (sibson).
    pub stats: Option<Stats>,
    /// Methods of a several-method request left out because they cannot meet it, each
    /// with the reason.
    pub skipped: Vec<(Method, String)>,
    /// The methods encoded in full (for `best`: those its probe could not rule out, less
    /// any its trial on sample tiles then dropped; every method `best` may try on tiny
    /// rasters).
    pub encoded: Vec<Method>,
    /// What the caller should print: `best` answering a lossy request with a lossless file
    /// because no method met the bound lossily says so here, with each method's reason.
    pub notes: Vec<String>,
}

/// One encoded representation, before it goes into the container.
struct Candidate {
    method: &'static dyn Representation,
    enc: Encoded,
}

/// Encode `raster` with one concrete method.
#[allow(clippy::too_many_arguments)]
fn encode_method(
    m: &'static dyn Representation,
    raster: &Raster,
    header: &Header,
    opts: &EncodeOptions,
    e: Option<f64>,
    flat: Option<&[f64]>,
    cap: Option<usize>,
    progress: &mut dyn FnMut(f64),
) -> Result<Candidate> {
    // Settings that belong to another method are a mistake, not something to ignore.
    for other in REGISTRY {
        if other.name() != m.name() {
            if let Some(msg) = other.own_options(&opts.params) {
                return Err(Error::invalid(msg));
            }
        }
    }
    let job = EncodeJob {
        raster,
        header,
        max_error: e,
        params: &opts.params,
        effort: opts.effort.unwrap_or(crate::methods::DEFAULT_EFFORT),
        flat,
        base: None,
        levels_first: opts.levels_first,
        size_cap: cap,
    };
    Ok(Candidate {
        method: m,
        enc: m.encode(&job, progress)?,
    })
}

/// Encode once (no size target): the request's methods, or the smallest of those `best`
/// may try, into a complete file.
pub(crate) fn encode_once(
    raster: &Raster,
    opts: &EncodeOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<u8>, EncodeReport)> {
    let (header, sections, report) = encode_parts(raster, opts, progress)?;
    Ok((container::write(&header, &sections), report))
}

/// [`encode_once`] before framing: the header (its `primary` set) and the sections.
pub(crate) fn encode_parts(
    raster: &Raster,
    opts: &EncodeOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Header, Vec<Section>, EncodeReport)> {
    raster.validate()?;
    if let Some(k) = opts.effort.filter(|k| !(1..=9).contains(k)) {
        return Err(Error::invalid(format!("effort {k} is not in 1..=9")));
    }
    let mut header = Header::of(raster)?;
    let e = opts.max_error.map(|b| b.absolute(header.range));
    // An integer raster's values are its codes' values (value = offset + scale · code, the
    // code in the type's range). A value farther from its nearest one than the bound allows
    // (any off the lattice when lossless; one beyond the codes' range by more than the
    // bound) cannot be stored as its type within the request: it is refused here, naming
    // the sample, instead of a method's vaguer "cannot meet" (or, before, f64 bit keys a
    // decoder of an integer file rejects: spec/FORMAT.md, "a value of the sample type").
    if raster.sample_type.is_integer() {
        let (st, m, tol) = (raster.sample_type, raster.mapping, e.unwrap_or(0.0));
        let off = |i: usize| {
            let v = raster.data[i];
            raster.is_valid(i) && !st.holds(v, m) && (st.nearest_value(v, m) - v).abs() > tol
        };
        if let Some(i) = (0..raster.len()).find(|&i| off(i)) {
            let why = st
                .check_holds("the value", raster.data[i], m)
                .expect_err("not a value of the type");
            let beyond = if tol > 0.0 {
                format!(", and its nearest one is farther than the max error {tol}")
            } else {
                String::new()
            };
            return Err(Error::invalid(format!(
                "sample {i} (row {}, column {}): {why}{beyond}",
                i / raster.width,
                i % raster.width
            )));
        }
    }
    // Flat regions decode exactly whatever the method: they get a section of their own,
    // and the methods see them as samples they need not represent. At every bound,
    // lossless included: a method would code each of their samples (a constant 3601²
    // tile: 2 980 bytes of the residual layer's zero bins losslessly, against a flat
    // section of a few dozen bytes).
    let flat = crate::model::flat::find(raster);
    // A flat region's value is stored as every one of its samples' value, and a decoder
    // rejects one that is not a value of the sample type (spec/FORMAT.md). The samples of
    // a raster read from a file are; a region of other values (a raster built with them)
    // is left to the method, which rounds its values to the type as every other sample's.
    let flat = flat.and_then(|mut f| {
        let (st, m) = (raster.sample_type, raster.mapping);
        f.iter_mut()
            .filter(|v| !v.is_nan() && !st.holds(**v, m))
            .for_each(|v| *v = f64::NAN);
        f.iter().any(|v| !v.is_nan()).then_some(f)
    });
    let masked;
    let (source, raster) = match &flat {
        Some(f) => {
            masked = raster.without_flat(f);
            (raster, &masked)
        }
        None => (raster, raster),
    };
    let flat_payload = flat
        .as_deref()
        .map(|f| container::flat::encode(f, source.width, source.mask.as_deref()));
    // Per-sample values only for a method that reads them (8 bytes per sample).
    let keep = opts.methods.is_empty() || opts.methods.iter().any(|m| m.0.uses_flat_values());
    let flat = flat.filter(|_| keep);
    let flat = flat.as_deref();
    let mut cands: Vec<Candidate> = Vec::new();
    let mut skipped: Vec<(Method, String)> = Vec::new();
    let mut encoded: Vec<Method> = Vec::new();
    let mut notes: Vec<String> = Vec::new();
    if opts.methods.is_empty() {
        let (chosen, tried, said) = encode_best(raster, &header, opts, e, flat, progress)?;
        cands.push(chosen);
        encoded = tried;
        notes.extend(said);
    } else {
        let n = opts.methods.len();
        let mut first_err = None;
        for (k, m) in opts.methods.iter().enumerate() {
            if cands.iter().any(|c| c.method.name() == m.name()) {
                continue;
            }
            // The first method takes every setting; the comparison sections get only their
            // own (a site count does not stop a Haar section).
            let mut o = opts.clone();
            if k > 0 {
                o.params = Default::default();
                m.0.keep_own(&opts.params, &mut o.params);
            }
            let mut p = slot(progress, k, n);
            encoded.push(*m);
            match encode_method(m.0, raster, &header, &o, e, flat, None, &mut p) {
                Ok(c) => cands.push(c),
                // Of several methods, one that cannot meet the request is left out with a
                // note; the others still make the file.
                Err(err @ Error::Unmet { .. }) if n > 1 => {
                    skipped.push((*m, err.to_string()));
                    first_err.get_or_insert(err);
                }
                Err(err) => return Err(err),
            }
        }
        if cands.is_empty() {
            return Err(first_err.expect("every method failed, so one error was kept"));
        }
    }
    let primary = (0..cands.len())
        .min_by_key(|&i| cands[i].enc.payload.len())
        .expect("non-empty");
    let mut sections = Vec::new();
    if let Some(m) = &source.mask {
        if m.iter().any(|&b| !b) {
            sections.push(Section {
                kind: SectionKind::MASK,
                flags: SF_REQUIRED,
                payload: container::mask::encode(m, source.width),
            });
        }
    }
    if let Some(payload) = flat_payload {
        sections.push(Section {
            kind: SectionKind::FLAT,
            flags: SF_REQUIRED,
            payload,
        });
    }
    header.primary = (sections.len() + primary) as u16;
    let report = EncodeReport {
        max_error: cands[primary].enc.bound,
        method: Method(cands[primary].method),
        stats: cands[primary].enc.stats.clone(),
        skipped,
        encoded,
        notes,
    };
    for (i, c) in cands.into_iter().enumerate() {
        sections.push(Section {
            kind: c.method.section(),
            // Comparison sections are optional: a decoder that lacks their method skips them.
            flags: if i == primary { SF_REQUIRED } else { 0 },
            payload: c.enc.payload,
        });
    }
    if let Some(meta) = &opts.metadata {
        serde_json::from_str::<serde_json::Value>(meta)
            .map_err(|e| Error::invalid(format!("metadata is not JSON: {e}")))?;
        sections.push(Section {
            kind: SectionKind::METADATA,
            flags: 0,
            payload: meta.as_bytes().to_vec(),
        });
    }
    if let Some(xml) = &source.gdal_metadata {
        // Optional (flags clear): samples decode without it, and older decoders skip it.
        sections.push(Section {
            kind: SectionKind::GDAL_METADATA,
            flags: 0,
            payload: xml.as_bytes().to_vec(),
        });
    }
    Ok((header, sections, report))
}

/// Rasters up to this many samples get every method `best` may try in full; larger ones a
/// trial on sample tiles first ([`shortlist`]).
const EXHAUSTIVE_MAX_SAMPLES: usize = 512 * 512;
/// Side of a sample tile, and how many of them ([`shortlist`]).
const TRIAL_TILE: usize = 128;
const TRIAL_TILES: [usize; 2] = [4, 3];
/// A method whose trial total is within this factor of the smallest is encoded in full.
const TRIAL_MARGIN: f64 = 1.15;
/// A method and the max error it is asked for.
type Run = (&'static dyn Representation, Option<f64>);
/// Below this many bits per sample on the tiles a method is encoded in full whatever the
/// others' trial: there each tile's fixed cost (a sites encoder's hull corners, a header)
/// outweighs its content, so the trial misjudges, and a full encode is quick (few sites).
/// Measured: Monterey Bay at 10 % of the range, where the tiles put FIS (722 bytes) ahead
/// of the sites (467 bytes in full).
const TRIAL_LOW_RATE: f64 = 0.25;

/// `best`: the methods that can meet the request, narrowed by a probe on a sample of rows
/// ([`contenders`]) and (large rasters only) a trial on sample tiles ([`shortlist`]), each
/// encoded in full (the residual layer first, each later one capped by the smallest payload
/// so far); the smallest wins. Returns it, the methods encoded, and notes for the report.
fn encode_best(
    raster: &Raster,
    header: &Header,
    opts: &EncodeOptions,
    e: Option<f64>,
    flat: Option<&[f64]>,
    progress: &mut dyn FnMut(f64),
) -> Result<(Candidate, Vec<Method>, Vec<String>)> {
    let mut cands: Vec<Candidate> = Vec::new();
    let mut encoded: Vec<Method> = Vec::new();
    let mut notes: Vec<String> = Vec::new();
    let runs = best_runs(raster, opts, e);
    // The probe: the residual layer (the usual winner) and the grid on a sample of rows;
    // only the methods it cannot rule out are tried. Its share of the bar: the probe and
    // its first half (1.5/16 of the rows) through the residual layer and the grid, against
    // one full encode of the residual layer.
    let cost = |k: Method| k.0.relative_cost();
    let probe = 1.5 / PROBE_SHARE as f64 * (cost(Method::RESIDUAL) + cost(Method::GRID));
    let ps = probe / (probe + cost(Method::RESIDUAL));
    let (runs, grid_estimate) = contenders(&runs, raster, opts, &mut |f| progress(ps * f))?;
    let mut after = |f: f64| progress(ps + (1.0 - ps) * f);
    let progress: &mut dyn FnMut(f64) = &mut after;
    // The bar's shares follow each stage's expected time (`relative_cost`): the trial
    // against at least the cheapest full encode, then the full encodes.
    // The probe has compared the residual layer and the grid; the trial is for the
    // methods it could not rule out beside them.
    let trial = raster.len() > EXHAUSTIVE_MAX_SAMPLES && runs.len() > 2;
    let share = if trial {
        let tiles = (TRIAL_TILE * TRIAL_TILE * TRIAL_TILES[0] * TRIAL_TILES[1]) as f64;
        let t: f64 = runs.iter().map(|(m, _)| m.relative_cost()).sum::<f64>() * tiles;
        let cheapest = runs
            .iter()
            .map(|(m, _)| m.relative_cost())
            .fold(f64::INFINITY, f64::min);
        t / (t + cheapest * raster.len() as f64)
    } else {
        0.0
    };
    // Why each method left out could not meet the request (for the note below).
    let mut why: Vec<(&'static str, String)> = Vec::new();
    let mut short = if trial {
        shortlist(&runs, raster, opts, &mut why, &mut |f| progress(share * f))?
    } else {
        runs
    };
    // The residual layer first (the usual winner, and among the cheapest), then the
    // others by cost: each later one is told the smallest payload so far, and the sites
    // and FIS encoders stop once they would be larger.
    let rank = |m: &dyn Representation| {
        if m.name() == Method::RESIDUAL.name() {
            0.0
        } else {
            m.relative_cost()
        }
    };
    short.sort_by(|a, b| rank(a.0).total_cmp(&rank(b.0)));
    let costs: Vec<f64> = short.iter().map(|(m, _)| m.relative_cost()).collect();
    let total: f64 = costs.iter().sum();
    let mut last_err = None;
    for (i, &(m, e)) in short.iter().enumerate() {
        let cap = cands.iter().map(|c| c.enc.payload.len()).min();
        let before: f64 = costs[..i].iter().sum();
        let mut p = |f: f64| {
            let f = f.clamp(0.0, 1.0);
            progress(share + (1.0 - share) * (before + costs[i] * f) / total)
        };
        // On a large raster the grid, kept by the probe's two estimates, is left out when
        // its estimate is above the residual layer's actual payload by GRID_ACTUAL_MARGIN
        // (on a small one the probe's fixed costs skew the estimate: a 300 × 200 window,
        // mostly sea, had the grid's 263 bytes against the residual layer's 442).
        if let (Some(g), Some(c)) = (grid_estimate, cap) {
            if m.name() == Method::GRID.name()
                && raster.len() > EXHAUSTIVE_MAX_SAMPLES
                && g > c as f64 * GRID_ACTUAL_MARGIN
            {
                p(1.0);
                continue;
            }
        }
        if !encoded.iter().any(|x| x.name() == m.name()) {
            encoded.push(Method(m));
        }
        match encode_method(m, raster, header, opts, e, flat, cap, &mut p) {
            Ok(c) => cands.push(c),
            // Stopped because it would be larger than a candidate: not a failure.
            Err(Error::Unmet { what }) if what == crate::methods::SIZE_CAP_MESSAGE => p(1.0),
            Err(err) => {
                why.push((m.name(), err.to_string()));
                last_err = Some(err);
            }
        }
    }
    if cands.is_empty() {
        return Err(last_err.unwrap_or_else(|| {
            Error::unsupported("no method of this build can meet the request")
        }));
    }
    // In a version-4 tile (`levels_first`) a method without coarse levels (every one
    // but the residual layer) must save more than LEVELS_FIRST_MARGIN: an overview reads
    // its whole block.
    let weight = |c: &Candidate| {
        let no_levels = opts.levels_first && c.method.name() != Method::RESIDUAL.name();
        c.enc.payload.len() as f64
            / if no_levels {
                1.0 - crate::methods::LEVELS_FIRST_MARGIN
            } else {
                1.0
            }
    };
    let i = (0..cands.len())
        .min_by(|&a, &b| weight(&cands[a]).total_cmp(&weight(&cands[b])))
        .expect("non-empty");
    // A lossy request that only lossless coding answered: never silently (the file may
    // be many times the size a lossy file would have).
    let lossy = e.is_some_and(|b| b > 0.0 && raster.value_step().is_none_or(|q| b >= q / 2.0));
    if lossy && cands.iter().all(|c| c.enc.bound == 0.0) {
        let reasons: Vec<String> = why
            .iter()
            .map(|(m, r)| format!("{m}: {}", r.trim_start_matches("cannot meet the request: ")))
            .collect();
        notes.push(format!(
            "no method met max error {} lossily on this raster, so it is stored losslessly \
             ({} bytes){}",
            crate::metrics::num(e.unwrap_or(0.0)),
            cands[i].enc.payload.len(),
            if reasons.is_empty() {
                String::new()
            } else {
                format!(": {}", reasons.join("; "))
            }
        ));
    }
    Ok((cands.swap_remove(i), encoded, notes))
}

/// What `best` may try: (method, the bound it is asked for). Settings only one method reads
/// (a site count, an RMSE) name that method alone; a lossless request, the lossless
/// methods; a bound below half the data's own value step too (only the exact values meet
/// it, so it is a lossless request: no trial of the lossy methods, which would only find
/// the exact values at many times the cost); otherwise every method.
fn best_runs(
    raster: &Raster,
    opts: &EncodeOptions,
    e: Option<f64>,
) -> Vec<(&'static dyn Representation, Option<f64>)> {
    let owners: Vec<_> = REGISTRY
        .iter()
        .copied()
        .filter(|m| m.own_options(&opts.params).is_some())
        .map(|m| (m, e))
        .collect();
    if !owners.is_empty() {
        return owners;
    }
    let lossless_methods = REGISTRY.iter().copied().filter(|m| m.lossless_default());
    match e {
        None | Some(0.0) => lossless_methods.map(|m| (m, e)).collect(),
        Some(b) if raster.value_step().is_some_and(|q| b < q / 2.0) => {
            lossless_methods.map(|m| (m, Some(0.0))).collect()
        }
        Some(_) => REGISTRY.iter().map(|&m| (m, e)).collect(),
    }
}

/// Estimate before encoding in full: run every candidate on a few sample tiles (a 4×3
/// lattice of 128² windows spread over the raster, about 200 000 samples, as SZ3 samples
/// blocks to choose its predictor) and keep those whose total payload comes within
/// [`TRIAL_MARGIN`] of the smallest. A method that cannot meet the request on a tile drops
/// out, and a method cheap enough on the tiles ([`TRIAL_LOW_RATE`]) stays in. The
/// encoders' cost grows with size (the sites encoder about N^1.5), so the trial
/// costs a small part of one full encode; `benches/best_choice.sh` checks that the choice
/// equals the exhaustive one.
/// A method that fails on a tile gives its reason to `why`.
fn shortlist(
    runs: &[(&'static dyn Representation, Option<f64>)],
    raster: &Raster,
    opts: &EncodeOptions,
    why: &mut Vec<(&'static str, String)>,
    progress: &mut dyn FnMut(f64),
) -> Result<Vec<Run>> {
    let tiles = sample_tiles(raster, TRIAL_TILE);
    if tiles.is_empty() {
        return Ok(runs.to_vec());
    }
    let total = runs.iter().map(|(m, _)| m.relative_cost()).sum::<f64>() * tiles.len() as f64;
    let mut done = 0.0;
    let mut sizes: Vec<Option<usize>> = Vec::with_capacity(runs.len());
    for &(m, e) in runs {
        let mut sum = Some(0usize);
        for (k, t) in tiles.iter().enumerate() {
            let h = Header::of(t)?;
            let r = encode_method(m, t, &h, opts, e, None, None, &mut |_| {});
            progress((done + m.relative_cost() * (k + 1) as f64) / total);
            match r {
                Ok(c) => *sum.as_mut().expect("still a candidate") += c.enc.payload.len(),
                Err(err) => {
                    why.push((m.name(), err.to_string()));
                    sum = None;
                    break;
                }
            }
        }
        done += m.relative_cost() * tiles.len() as f64;
        progress(done / total);
        sizes.push(sum);
    }
    let Some(min) = sizes.iter().flatten().copied().min() else {
        // No method met the request on the tiles: let the full encodes say why.
        return Ok(runs.to_vec());
    };
    let tile_samples: usize = tiles.iter().map(Raster::len).sum();
    // The residual layer stays whenever it met the request: its static tables cost more on
    // a 128² tile than on a whole raster (the trial under-rates it: Istria 2400² at 1 %,
    // 55 405 bytes against the sites' 77 548, was ruled out), and it is the cheapest
    // full encode, which then caps the sites encoder.
    Ok(runs
        .iter()
        .zip(&sizes)
        .filter(|((m, _), s)| {
            s.is_some_and(|s| {
                s as f64 <= min as f64 * TRIAL_MARGIN
                    || (s * 8) as f64 / (tile_samples as f64) < TRIAL_LOW_RATE
                    || m.name() == Method::RESIDUAL.name()
            })
        })
        .map(|(r, _)| *r)
        .collect())
}

/// A 4 × 3 lattice of `side`² windows spread over the raster (tile centres at the centres
/// of a 4 × 3 partition), those with a valid sample.
fn sample_tiles(raster: &Raster, side: usize) -> Vec<Raster> {
    let (tw, th) = (side.min(raster.width), side.min(raster.height));
    let [nx, ny] = TRIAL_TILES;
    let mut tiles = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            // Tile centres at the centres of an nx × ny partition of the raster.
            let x = ((2 * i + 1) * raster.width / (2 * nx)).saturating_sub(tw / 2);
            let y = ((2 * j + 1) * raster.height / (2 * ny)).saturating_sub(th / 2);
            let w = Window {
                x: x.min(raster.width - tw),
                y: y.min(raster.height - th),
                width: tw,
                height: th,
            };
            let t = raster.crop(w);
            if t.valid_count() > 0 {
                tiles.push(t);
            }
        }
    }
    tiles
}

/// The probe: about 1 / `PROBE_SHARE` of the rows (at least `PROBE_MIN_ROWS`), in bands of at
/// least `PROBE_BAND_ROWS` rows, at most `PROBE_BANDS` of them.
const PROBE_SHARE: usize = 16;
const PROBE_MIN_ROWS: usize = 24;
const PROBE_BAND_ROWS: usize = 8;
const PROBE_BANDS: usize = 8;
/// The grid is tried in full when its estimate is at most this factor of the residual
/// layer's. The probe alone favours the grid (the residual layer's adaptive models learn on
/// fewer samples: on the corpus the probe's ratio is up to 40 % below the full files'); the
/// estimates from the probe and its first half ([`contenders`]) are closer, and every
/// corpus cell the grid wins has an estimated ratio of at most 1.000.
const PROBE_GRID_MARGIN: f64 = 1.03;
/// On rasters over [`EXHAUSTIVE_MAX_SAMPLES`], the grid is encoded in full only when its
/// probe estimate is within this factor of the
/// residual layer's actual payload. Measured (10 corpus rasters × 1 m, 0.1 %, 1 %, 3 %):
/// where the grid won, its estimate was 0.90–1.11× the residual layer's payload (Aleutians
/// at 1 m 1.110, the Delft DSM at 3 % 1.084); where the residual layer won, 1.02–5.5×.
const GRID_ACTUAL_MARGIN: f64 = 1.15;
/// Below this many bits per sample of the residual layer on the probe, the methods that win
/// at low rates (sibson's sites, FIS) are tried too.
const PROBE_LOW_RATE: f64 = 0.5;

/// Rasters of fewer samples get every method in full (a few milliseconds each), as do those
/// whose probe would hold more than a quarter of the rows.
const PROBE_MIN_SAMPLES: usize = 128 * 128;

/// Bands of whole rows spread evenly over the raster (band centres at the centres of an
/// equal partition), stacked into one raster of about `1 / PROBE_SHARE` of the rows; `None`
/// for a raster too small to sample ([`PROBE_MIN_SAMPLES`]).
fn sample_bands(raster: &Raster) -> Option<Raster> {
    let want = (raster.height / PROBE_SHARE).max(PROBE_MIN_ROWS);
    let rows = (want / PROBE_BANDS).max(PROBE_BAND_ROWS);
    let bands = (want / rows).clamp(1, PROBE_BANDS);
    if raster.len() < PROBE_MIN_SAMPLES || 4 * rows * bands > raster.height {
        return None;
    }
    let w = raster.width;
    let mut data = Vec::with_capacity(rows * bands * w);
    let mut mask = raster
        .mask
        .as_ref()
        .map(|_| Vec::with_capacity(rows * bands * w));
    for b in 0..bands {
        let y = ((2 * b + 1) * raster.height / (2 * bands)).saturating_sub(rows / 2);
        let y = y.min(raster.height - rows);
        data.extend_from_slice(&raster.data[y * w..(y + rows) * w]);
        if let (Some(m), Some(src)) = (mask.as_mut(), raster.mask.as_ref()) {
            m.extend_from_slice(&src[y * w..(y + rows) * w]);
        }
    }
    Some(Raster {
        mapping: raster.mapping,
        ..Raster::from_parts(
            w,
            rows * bands,
            data,
            mask,
            raster.nodata,
            raster.sample_type,
        )
    })
}

/// The methods of `runs` worth a full encode, from a probe: the residual layer and the grid
/// encode a sample of rows ([`sample_bands`]) and its first half, and a line through the
/// two sizes estimates each one's full size. The grid stays when its estimate comes within
/// [`PROBE_GRID_MARGIN`] of the residual layer's (edges, some float data), unless the
/// request is lossy and the residual layer's probe rate is below [`PROBE_LOW_RATE`] (the
/// grid codes every sample, and won no corpus cell there); sibson's sites and FIS only at
/// such a low rate (a smooth raster at a loose bound, where a few sites or FIS maps can
/// undercut the residual layer).
/// Haar never won a cell of the corpus table, and is not tried. Everything is tried when
/// the request names one method's own settings, when the residual layer is not among
/// `runs`, when the raster is too small to sample, or when the residual layer cannot meet
/// the request on the probe. Also returns the grid's estimate (payload bytes), which `best`
/// holds against the residual layer's actual payload before it encodes the grid.
fn contenders(
    runs: &[(&'static dyn Representation, Option<f64>)],
    raster: &Raster,
    opts: &EncodeOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(Vec<Run>, Option<f64>)> {
    let progress = std::cell::RefCell::new(progress);
    let done = || (progress.borrow_mut())(1.0);
    let all = || {
        done();
        Ok((runs.to_vec(), None))
    };
    let is = |m: &dyn Representation, k: Method| m.name() == k.name();
    let Some(&(res, res_e)) = runs.iter().find(|(m, _)| is(*m, Method::RESIDUAL)) else {
        return all();
    };
    if runs.len() < 2
        || REGISTRY
            .iter()
            .any(|m| m.own_options(&opts.params).is_some())
    {
        return all();
    }
    // Nothing left to code (every sample nodata or in a flat region, as a chunk of open
    // sea): every method writes a few bytes, and the slow ones (FIS, Haar: seconds on a
    // 900² chunk) cannot gain more than that.
    if raster.valid_count() == 0 {
        done();
        return Ok((
            runs.iter()
                .copied()
                .filter(|(m, _)| is(*m, Method::RESIDUAL) || is(*m, Method::GRID))
                .collect(),
            None,
        ));
    }
    let Some(probe) = sample_bands(raster) else {
        return all();
    };
    let n = probe.valid_count();
    if n == 0 {
        return all();
    }
    // The probe's first half too: a line through the two sizes gives the size at the
    // raster's count, less skewed by the cost of adaptation than the probe's own.
    let half = probe.crop(Window {
        x: 0,
        y: 0,
        width: probe.width,
        height: probe.height / 2,
    });
    let nh = half.valid_count();
    let (header, half_header) = (Header::of(&probe)?, Header::of(&half)?);
    // Each of the (at most four) probe encodes moves the bar a quarter of its share.
    let steps = std::cell::Cell::new(0u32);
    let len = |r: &Raster, h: &Header, m: &'static dyn Representation, e: Option<f64>| {
        let out = encode_method(m, r, h, opts, e, None, None, &mut |_| {})
            .ok()
            .map(|c| c.enc.payload.len() as f64);
        steps.set(steps.get() + 1);
        (progress.borrow_mut())(f64::from(steps.get().min(4)) / 4.0);
        out
    };
    let full = raster.valid_count() as f64;
    // The full size from the probe's size `s` and the size of its first half.
    let estimate = |s: f64, m: &'static dyn Representation, e: Option<f64>| {
        let sh = len(&half, &half_header, m, e)?;
        Some(if nh > 0 && nh < n {
            s + (s - sh) * (full - n as f64) / (n - nh) as f64
        } else {
            s * full / n as f64
        })
    };
    let lossy = res_e.is_some_and(|b| b > 0.0);
    let Some(r) = len(&probe, &header, res, res_e) else {
        return all();
    };
    let rate = r * 8.0 / n as f64;
    let grid_too = !lossy || rate >= PROBE_LOW_RATE;
    let mut keep = Vec::new();
    let mut grid_estimate = None;
    for &(m, e) in runs {
        let k = if is(m, Method::RESIDUAL) {
            true
        } else if is(m, Method::GRID) {
            // Left out when it cannot meet the request on the probe; kept when an estimate
            // fails.
            grid_too
                && len(&probe, &header, m, e).is_some_and(|g| {
                    match (estimate(r, res, res_e), estimate(g, m, e)) {
                        (Some(r), Some(g)) => {
                            grid_estimate = Some(g);
                            g <= r * PROBE_GRID_MARGIN
                        }
                        _ => true,
                    }
                })
        } else if is(m, Method::HAAR) {
            false
        } else {
            lossy && rate < PROBE_LOW_RATE
        };
        if k {
            keep.push((m, e));
        }
    }
    done();
    Ok((keep, grid_estimate))
}

/// The progress of the `i`-th of `n` encodes as its slice of the whole, so that several
/// methods in a row never move the caller's bar backwards.
fn slot(progress: &mut dyn FnMut(f64), i: usize, n: usize) -> impl FnMut(f64) + '_ {
    move |f| progress((i as f64 + f.clamp(0.0, 1.0)) / n.max(1) as f64)
}
