//! The static-rANS codings of the residual layer: the fast coding (codings 2 and 3,
//! spec/FORMAT.md "Fast coding") and, in `lanes`, the lane coding built on its passes,
//! bands and tables (codings 4 and 5, "Lane coding"). The fast coding: multilevel cubic
//! interpolation with a least-squares stencil on the finest levels (points of coarser
//! levels and of the sample's own band), each bin a token (small values directly, large
//! ones as exponent + raw bits, as JPEG XL's hybrid integers) coded by static rANS under a
//! context of the level and a cheap "energy" (the support's curvature and four
//! neighbours' bins), the contexts clustered by the encoder. Every pass of every level is
//! cut into bands of rows, each its own stream: a sample reads only coarser samples and
//! its own band, so the bands of a pass decode (and encode) on as many cores as there are.

use super::plane::Plane;
use crate::container::bytes::ByteReader;
use crate::entropy::rans::{
    self, BitReader, BitWriter, DecTables, EncTable, StreamDecoder, StreamEncoder,
};
use crate::entropy::varint;
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::ops::Range;

mod band;
mod clusters;
mod fit;
mod lanes;
mod passes;

use band::{Global, run_pass};
use clusters::cluster;
use fit::fit;
pub use fit::resolve;
use passes::{ALPHABET, BAND_LOG2, GROUPS, FINE, Kind, NCTX, Pass, SymCoder, passes, token};
pub use passes::{Config, DEFAULT_BAND_LOG2, NW};

/// The encoder's first pass over a band: tokens, their contexts and the raw bits.
#[derive(Default)]
struct Recorder {
    tokens: Vec<u8>,
    ctxs: Vec<u8>,
    raw: BitWriter,
}

impl SymCoder for Recorder {
    const ENCODES: bool = true;
    #[inline(always)]
    fn code(&mut self, ctx: usize, bin: i64) -> Result<i64> {
        let (t, raw, n) = token(varint::zigzag(bin));
        self.tokens.push(t);
        self.ctxs.push(ctx as u8);
        if n > 0 {
            self.raw.put(raw, n);
        }
        Ok(bin)
    }
}

/// The decoder of one band's stream.
struct Reader<'a> {
    ans: StreamDecoder<'a>,
    raw: BitReader<'a>,
    /// Per context, the first slot of its cluster's table.
    base: &'a [usize],
    max_bin: u64,
}

impl SymCoder for Reader<'_> {
    const ENCODES: bool = false;
    #[inline(always)]
    fn code(&mut self, ctx: usize, _bin: i64) -> Result<i64> {
        let t = self.ans.symbol(self.base[ctx])? as u64;
        let v = if t < 16 {
            t
        } else {
            let e = (t - 16) / 2 + 4;
            let top = (t - 16) & 1;
            (1 << e) | (top << (e - 1)) | self.raw.get(e as u32 - 1)?
        };
        if v >> 1 > self.max_bin {
            return Err(Error::corrupt(
                "residual section: a bin lies outside the section's value range",
            ));
        }
        Ok(varint::unzigzag(v))
    }
}

/// A decoded plane: each value plus the offset is the sample's lattice index (the lane
/// coding's plane as it ran, in i32 where it fits, so no wider copy is made).
pub enum Rec {
    I32(Vec<i32>, i64),
    I64(Vec<i64>, i64),
}

impl Rec {
    /// The lattice indices.
    #[cfg(test)]
    pub fn indices(&self) -> Vec<i64> {
        match self {
            Rec::I32(v, o) => v.iter().map(|&k| k as i64 + o).collect(),
            Rec::I64(v, o) => v.iter().map(|&k| k + o).collect(),
        }
    }
}

/// What [`encode`] returns: stencil weights, the coding's bytes, the reconstruction.
pub type Encoded = (Vec<[i16; NW]>, Vec<u8>, Vec<i64>);

/// Encode the plane: the stencil weights (per pass with a correction, coarsest first), the
/// fast coding's bytes (after the section's fixed fields, weights and exceptions) and the
/// reconstruction. `progress` gets the fraction done after the stencil fits, the passes
/// and the tables.
pub fn encode(p: &Plane, cfg: Config, progress: &mut dyn FnMut(f64)) -> Result<Encoded> {
    let (w, h) = (p.width, p.height);
    let n = w * h;
    let mut rec = vec![0i64; n];
    let mut mag = vec![0u8; n];
    let mut streams: Vec<Recorder> = Vec::new();
    // The stencils worth their bytes, fitted on the source before any pass runs; the
    // section stores the finest levels' sets down to the coarsest level using one (zeros
    // for a pass without).
    let mut all = passes(cfg, p.bin);
    let fits: Vec<Option<[i16; NW]>> = all
        .par_iter()
        .map(|&pass| {
            (pass.kind != Kind::Anchor && pass.level() <= cfg.ls_levels)
                .then(|| fit(p, pass, cfg.lanes))
                .flatten()
        })
        .collect();
    let ls_levels = all
        .iter()
        .zip(&fits)
        .filter(|(_, f)| f.is_some())
        .map(|(pass, _)| pass.level())
        .max()
        .unwrap_or(0);
    let mut weights = Vec::new();
    for (pass, f) in all.iter_mut().zip(fits) {
        if pass.kind != Kind::Anchor && pass.level() <= ls_levels {
            weights.push(f.unwrap_or([0; NW]));
            pass.weights = f;
        }
    }
    progress(0.35);
    if cfg.lanes {
        return encode_lanes(p, cfg, &all, weights, progress);
    }
    let g = Global::new(p);
    for pass in all {
        let bands = pass.bands(w, h, cfg.band_log2);
        streams.extend(run_pass(
            &g,
            pass,
            &bands,
            (&mut rec, &mut mag),
            |_| Ok(Recorder::default()),
            Ok,
        )?);
    }
    progress(0.75);
    // Tables from the counts of every stream.
    let mut counts = vec![[0u64; ALPHABET]; NCTX];
    for s in &streams {
        for (&t, &c) in s.tokens.iter().zip(&s.ctxs) {
            counts[c as usize][t as usize] += 1;
        }
    }
    let (map, tables, enc) = tables_of(&counts);
    let coded: Vec<(Vec<u8>, Vec<u8>)> = streams
        .into_par_iter()
        .map(|s| {
            let ans = StreamEncoder::encode(
                &enc,
                s.tokens
                    .iter()
                    .zip(&s.ctxs)
                    .map(|(&t, &c)| (map[c as usize] as usize, t)),
            );
            (ans, s.raw.finish())
        })
        .collect();
    Ok((weights, layout(cfg.band_log2, &tables, &coded), rec))
}

/// The tables from the contexts' token counts (groups of [`FINE`] classes): each context's
/// cluster, the bit block of the section's tables, and the clusters' encoder tables.
fn tables_of(counts: &[[u64; ALPHABET]]) -> (Vec<u16>, Vec<u8>, Vec<EncTable>) {
    let (map, clusters) = cluster(counts);
    let freqs: Vec<Vec<u32>> = clusters.iter().map(|c| rans::normalize(c)).collect();
    let enc: Vec<EncTable> = freqs.iter().map(|f| EncTable::new(f)).collect();
    let mut bits = BitWriter::default();
    for g in 0..counts.len() / FINE {
        for c in 1..FINE {
            let k = g * FINE + c;
            bits.put(u64::from(map[k] != map[k - 1]), 1);
        }
    }
    for f in &freqs {
        rans::write_table(&mut bits, f);
    }
    (map, bits.finish(), enc)
}

/// The coding's bytes after the exceptions: band size, tables, the stream directory, then
/// each band's rANS bytes and raw bits.
fn layout(band_log2: u8, tables: &[u8], coded: &[(Vec<u8>, Vec<u8>)]) -> Vec<u8> {
    let mut out = vec![band_log2];
    varint::put_u64(&mut out, tables.len() as u64);
    out.extend_from_slice(tables);
    for (a, r) in coded {
        varint::put_u64(&mut out, a.len() as u64);
        varint::put_u64(&mut out, r.len() as u64);
    }
    for (a, r) in coded {
        out.extend_from_slice(a);
        out.extend_from_slice(r);
    }
    out
}

/// A varint (LEB128, at most 10 bytes) from the section.
fn read_varint(rd: &mut ByteReader, what: &str) -> Result<u64> {
    let mut v = 0u64;
    for k in 0..10 {
        let b = rd.u8(what)?;
        if k == 9 && b > 1 {
            break;
        }
        v |= ((b & 0x7f) as u64) << (7 * k);
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(rd.corrupt(format!("{what} is not a varint")))
}

/// The bands of each pass (ranges of band indices) a decode of the raster rows `rows` runs.
/// From the finest pass back to the anchors: a pass must reconstruct the rows of `rows`
/// and every row the bands run by finer passes read of it ([`Pass::reach`] around each of
/// their rows: a band runs whole, from its first row, so all its rows count); it runs
/// the bands that hold any of them.
fn needed(passes: &[Pass], bands: &[Vec<(usize, usize)>], h: usize, rows: Range<usize>) -> Vec<Range<usize>> {
    let (mut lo, mut hi) = (rows.start, rows.end.min(h));
    let mut out = vec![0..0; passes.len()];
    for (k, (pass, bands)) in passes.iter().zip(bands).enumerate().rev() {
        let (Some(&(per0, per1)), Some(&(_, end))) = (bands.first(), bands.last()) else {
            continue;
        };
        // The pass rows r0 + j·rs in lo..hi.
        let j0 = lo.saturating_sub(pass.r0).div_ceil(pass.rs);
        let j1 = if hi > pass.r0 { ((hi - 1 - pass.r0) / pass.rs + 1).min(end) } else { 0 };
        if j0 >= j1 {
            continue;
        }
        // Every band but the last holds `per` pass rows.
        let per = per1 - per0;
        let (b0, b1) = (j0 / per, (j1 - 1) / per + 1);
        out[k] = b0..b1;
        let first = pass.r0 + bands[b0].0 * pass.rs;
        let last = pass.r0 + (bands[b1 - 1].1 - 1) * pass.rs;
        lo = lo.min(first.saturating_sub(pass.reach()));
        hi = hi.max((last + pass.reach() + 1).min(h));
    }
    out
}

/// Decode the plane from the rest of the section (`rd` just after the exceptions).
/// `values` holds the fixed samples' values; `max_bin` bounds a bin's magnitude. Only the
/// raster rows `rows` are sure to be reconstructed: the bands they do not need are
/// length-checked, not decoded ([`needed`]; the others' samples are left 0). With `stop`
/// above 0 only the passes of steps ≥ 2^stop run: the samples at every 2^stop-th row and
/// column are reconstructed, no other.
#[allow(clippy::too_many_arguments)]
pub fn decode(
    rd: &mut ByteReader,
    p: &Plane,
    fixed: &[(usize, usize, i64)],
    levels: u32,
    tighten: bool,
    lanes: bool,
    weights: &[[i16; NW]],
    max_bin: u64,
    rows: Range<usize>,
    stop: u32,
    marks: Option<&mut Vec<usize>>,
) -> Result<Rec> {
    let (w, h) = (p.width, p.height);
    let band_log2 = rd.u8("band size")?;
    if !BAND_LOG2.contains(&band_log2) {
        return Err(rd.corrupt(format!("band size 2^{band_log2} (2^10 ..= 2^30)")));
    }
    let cfg = Config {
        levels,
        ls_levels: weights.len() as u32 / 2,
        tighten,
        tighten_auto: false,
        band_log2,
        lanes,
    };
    if lanes && !weights.iter().all(lanes::weights_ok) {
        return Err(rd.corrupt("a lane coding's stencil weighs the pass's own points or exceeds ±4096"));
    }
    let tlen = read_varint(rd, "tables length")?;
    let tbytes = rd.take(usize::try_from(tlen).unwrap_or(usize::MAX), "tables")?;
    let mut br = BitReader::new(tbytes, "tables");
    let groups = GROUPS;
    let mut map = vec![0usize; groups * FINE];
    let mut clusters = 0usize;
    for g in 0..groups {
        if g > 0 {
            clusters += 1;
        }
        map[g * FINE] = clusters;
        for c in 1..FINE {
            clusters += br.get(1)? as usize;
            map[g * FINE + c] = clusters;
        }
    }
    let clusters = clusters + 1;
    let mut tables = Vec::with_capacity(clusters);
    for _ in 0..clusters {
        tables.push(rans::read_table(&mut br, ALPHABET)?);
    }
    br.finish()?;
    let dec = DecTables::new(&tables);
    let base: Vec<usize> = map.iter().map(|c| c * rans::TOTAL as usize).collect();
    // The streams: lengths first, then the bytes.
    let passes = passes(cfg, p.bin);
    let bands: Vec<Vec<(usize, usize)>> = passes.iter().map(|pass| pass.bands(w, h, band_log2)).collect();
    let mut lens = Vec::new();
    for b in &bands {
        for _ in 0..b.len() {
            let a = read_varint(rd, "stream length")?;
            let r = read_varint(rd, "stream length")?;
            lens.push((a, r));
        }
    }
    // Where each level's streams end (the anchors' first): a decode that stops after a
    // level needs the payload up to there (the progressive tiles of version 4), and with
    // `stop` above 0 the payload may be such a prefix: the finer passes' streams are then
    // neither read nor required.
    let mut end = rd.position() as u64;
    let mut level_end: Vec<(u32, u64)> = Vec::new();
    let mut k = 0;
    for (pass, b) in passes.iter().zip(&bands) {
        for &(a, r) in &lens[k..k + b.len()] {
            end = end.saturating_add(a).saturating_add(r);
        }
        k += b.len();
        let lvl = if pass.kind == Kind::Anchor { levels + 1 } else { pass.level() };
        match level_end.last_mut() {
            Some((l, e)) if *l == lvl => *e = end,
            _ => level_end.push((lvl, end)),
        }
    }
    if let Some(m) = marks {
        m.extend(level_end.iter().map(|&(_, e)| usize::try_from(e).unwrap_or(usize::MAX)));
    }
    let wanted = |pass: &Pass| pass.kind == Kind::Anchor || stop == 0 || pass.s >= 1 << stop;
    let mut slices = Vec::with_capacity(lens.len());
    let mut k = 0;
    for (pass, b) in passes.iter().zip(&bands) {
        for &(a, r) in &lens[k..k + b.len()] {
            if !wanted(pass) {
                slices.push((&[][..], &[][..]));
                continue;
            }
            let a = rd.take(usize::try_from(a).unwrap_or(usize::MAX), "entropy stream")?;
            let r = rd.take(usize::try_from(r).unwrap_or(usize::MAX), "raw bits")?;
            slices.push((a, r));
        }
        k += b.len();
    }
    if stop == 0 {
        rd.finish()?;
    }
    let pick = needed(&passes, &bands, h, rows);
    if lanes {
        let mut tabs = [dec.table(0); 256];
        for (o, &c) in tabs.iter_mut().zip(&map) {
            *o = dec.table(c);
        }
        let mut next_w = weights.iter();
        let mut passes = passes;
        for pass in &mut passes {
            if pass.kind != Kind::Anchor && pass.level() <= cfg.ls_levels {
                pass.weights = next_w.next().copied().filter(|w| *w != [0; NW]);
            }
        }
        let mut firsts = Vec::with_capacity(bands.len());
        let mut next = 0;
        for b in &bands {
            firsts.push(next);
            next += b.len();
        }
        let chosen: Vec<Range<usize>> = passes
            .iter()
            .zip(pick)
            .map(|(pass, pick)| if pass.kind != Kind::Anchor && pass.s < 1 << stop { 0..0 } else { pick })
            .collect();
        let make = |k: usize, b: usize| -> Result<lanes::Reader> {
            let (a, r) = slices[firsts[k] + chosen[k].start + b];
            Ok(lanes::Reader {
                ans: rans::LanesDecoder::new(a, lanes::state_mask(&passes[k], w) + 1)?,
                raw: BitReader::new(r, "raw bits"),
                tables: &tabs,
                max_bin,
                mask: lanes::state_mask(&passes[k], w),
            })
        };
        let done = |rdr: lanes::Reader| -> Result<()> {
            rdr.ans.finish()?;
            let mut raw = rdr.raw;
            raw.finish()
        };
        return if lanes::fits_i32(p.hi - p.lo, p.bin) {
            run_lanes::<i32, _, _>(p, Some(fixed), &passes, &bands, &chosen, make, done).map(|x| Rec::I32(x.0, p.lo))
        } else {
            run_lanes::<i64, _, _>(p, Some(fixed), &passes, &bands, &chosen, make, done).map(|x| Rec::I64(x.0, p.lo))
        };
    }
    let n = w * h;
    let mut rec = vec![0i64; n];
    let mut mag = vec![0u8; n];
    let g = Global::new(p);
    let mut next = 0;
    let mut next_w = weights.iter();
    for ((mut pass, bands), pick) in passes.into_iter().zip(&bands).zip(pick) {
        if pass.kind != Kind::Anchor && pass.level() <= cfg.ls_levels {
            // All-zero weights correct nothing: the plain prediction (the same values).
            pass.weights = next_w.next().copied().filter(|w| *w != [0; NW]);
        }
        let pick = if pass.kind != Kind::Anchor && pass.s < 1 << stop { 0..0 } else { pick };
        let mine = &slices[next + pick.start..next + pick.end];
        next += bands.len();
        run_pass(
            &g,
            pass,
            &bands[pick],
            (&mut rec, &mut mag),
            |b| {
                let (a, r) = mine[b];
                Ok(Reader {
                    ans: StreamDecoder::new(a, &dec)?,
                    raw: BitReader::new(r, "raw bits"),
                    base: &base,
                    max_bin,
                })
            },
            |mut rdr| {
                rdr.ans.finish()?;
                rdr.raw.finish()
            },
        )?;
    }
    Ok(Rec::I64(rec, 0))
}

/// The lane coding's encode (after the stencils are fitted): tokens of every band, tables
/// from their counts, then each band's interleaved stream.
fn encode_lanes(
    p: &Plane,
    cfg: Config,
    all: &[Pass],
    weights: Vec<[i16; NW]>,
    progress: &mut dyn FnMut(f64),
) -> Result<Encoded> {
    let (w, h) = (p.width, p.height);
    let bands: Vec<Vec<(usize, usize)>> = all.iter().map(|pass| pass.bands(w, h, cfg.band_log2)).collect();
    let chosen: Vec<Range<usize>> = bands.iter().map(|b| 0..b.len()).collect();
    let make = |k: usize, _: usize| {
        Ok(lanes::Recorder {
            mask: lanes::state_mask(&all[k], w),
            ..Default::default()
        })
    };
    let lo = p.lo;
    let (rec, streams): (Vec<i64>, _) = if lanes::fits_i32(p.hi - p.lo, p.bin) {
        let (r, s) = run_lanes::<i32, _, _>(p, None, all, &bands, &chosen, make, Ok)?;
        (r.par_iter().map(|&v| v as i64 + lo).collect(), s)
    } else {
        let (r, s) = run_lanes::<i64, _, _>(p, None, all, &bands, &chosen, make, Ok)?;
        (r.par_iter().map(|&v| v + lo).collect(), s)
    };
    progress(0.75);
    let mut counts = vec![[0u64; ALPHABET]; lanes::LNCTX];
    for s in &streams {
        for &(c, t, _) in &s.syms {
            counts[c as usize][t as usize] += 1;
        }
    }
    let (map, tables, enc) = tables_of(&counts);
    let coded: Vec<(Vec<u8>, Vec<u8>)> = streams
        .into_par_iter()
        .map(|s| {
            let syms: Vec<(u16, u8, u8)> = s.syms.iter().map(|&(c, t, l)| (map[c as usize], t, l)).collect();
            (rans::LanesEncoder::encode(&enc, &syms, s.mask + 1), s.raw.finish())
        })
        .collect();
    Ok((weights, layout(cfg.band_log2, &tables, &coded), rec))
}

/// Run the lane coding's passes on the bands `chosen[k]` of each pass k (`make(k, b)` gives
/// the coder of the b-th chosen band of pass k, `done` takes it back): each band into
/// buffers of its own (side by side on as many threads as there are), then written into the
/// planes. Returns the reconstruction (lattice units less `p.lo`) and what `done`
/// returned, in band order.
#[allow(clippy::too_many_arguments)]
fn run_lanes<T, C, X>(
    p: &Plane,
    fixed: Option<&[(usize, usize, i64)]>,
    passes: &[Pass],
    bands: &[Vec<(usize, usize)>],
    chosen: &[Range<usize>],
    make: impl Fn(usize, usize) -> Result<C> + Sync,
    done: impl Fn(C) -> Result<X> + Sync,
) -> Result<(Vec<T>, Vec<X>)>
where
    T: lanes::Lane,
    C: lanes::Tokens<T> + lanes::AnchorTokens + Send,
    X: Send,
{
    let (w, h) = (p.width, p.height);
    let mut plane = vec![T::of(0); w * h];
    let mut mag = vec![0u8; w * h];
    // The fixed samples' values go into the plane first: their pass takes them from there
    // (each position is written once, by its own pass). `fixed`: the decoder's runs of
    // (start, length, lattice index); else (the encoder) the plane's values at fixed kinds.
    let put = |k: i64| T::of((k - p.lo).clamp(0, p.hi - p.lo));
    match fixed {
        Some(runs) => {
            for &(s, l, k) in runs {
                plane[s..s + l].fill(put(k));
            }
        }
        None => {
            for (i, _) in p.kinds.iter().enumerate().filter(|(_, k)| **k == super::plane::FIXED) {
                plane[i] = put(p.values[i]);
            }
        }
    }
    let row_coded = lanes::row_flags(p.kinds, w, h);
    let all_coded = p.kinds.is_empty() || row_coded.iter().all(|&c| c);
    let mut out = Vec::new();
    for (k, pass) in passes.iter().enumerate() {
        let picked = &bands[k][chosen[k].clone()];
        if picked.is_empty() {
            continue;
        }
        let g = lanes::Global {
            w,
            h,
            r: T::of(p.hi - p.lo),
            lo: p.lo,
            kinds: if all_coded { &[] } else { p.kinds },
            row_coded: if all_coded { &[] } else { &row_coded },
            values: p.values,
        };
        let arch = pulp::Arch::new();
        if pass.kind == Kind::Anchor || picked.len() == 1 || rayon::current_num_threads() == 1 {
            // One band at a time, straight into the planes.
            for (b, &band) in picked.iter().enumerate() {
                let mut c = make(k, b)?;
                if pass.kind == Kind::Anchor {
                    let bufs = [lanes::run_anchors(&g, &plane, pass, &mut c)?];
                    passes::scatter(w, pass, picked, &bufs, &mut plane, &mut mag);
                } else {
                    let mut planes = lanes::Planes::Own(&mut plane, &mut mag);
                    // The band's loops compiled for the best instruction set this processor has.
                    arch.dispatch(lanes::Band { g: &g, planes: &mut planes, pass, band, coder: &mut c })?;
                }
                out.push(done(c)?);
            }
            continue;
        }
        let bufs: Vec<(passes::BandBuf<T>, X)> = picked
            .par_iter()
            .enumerate()
            .map(|(b, &band)| {
                let mut c = make(k, b)?;
                let mut planes = lanes::Planes::Shared(&plane, &mag);
                let buf = arch.dispatch(lanes::Band { g: &g, planes: &mut planes, pass, band, coder: &mut c })?;
                Ok((buf, done(c)?))
            })
            .collect::<Result<_>>()?;
        let (bufs, xs): (Vec<_>, Vec<_>) = bufs.into_iter().unzip();
        passes::scatter(w, pass, picked, &bufs, &mut plane, &mut mag);
        out.extend(xs);
    }
    Ok((plane, out))
}

/// `round_div` is the same rounding the interior fast paths write as `(n + 8) >> 4`.
#[cfg(test)]
mod tests {
    use super::super::coder::round_div;
    use super::super::plane::{CODED, FIXED};
    use super::*;

    #[test]
    fn the_interior_rounding_is_round_div() {
        for n in -1000..1000 {
            assert_eq!((n + 8) >> 4, round_div(n, 16));
        }
    }

    /// The fixed samples of a test plane as the decoder's runs.
    fn fixed_of(p: &Plane) -> Vec<(usize, usize, i64)> {
        (0..p.kinds.len()).filter(|&i| p.kinds[i] == FIXED).map(|i| (i, 1, p.values[i])).collect()
    }

    /// A smooth surface with noise, a hole (skipped) and a fixed patch, on a lattice.
    fn plane_data(w: usize, h: usize) -> (Vec<u8>, Vec<i64>) {
        let mut rng = crate::testutil::Rng(7);
        let mut kinds = vec![CODED; w * h];
        let mut values = vec![0i64; w * h];
        for y in 0..h {
            for x in 0..w {
                let s = rng.next();
                let i = y * w + x;
                let (fx, fy) = (x as f64 / 7.0, y as f64 / 5.0);
                values[i] = (400.0 * fx.sin() * fy.cos() + 30.0 * (fx * fy).sqrt()) as i64
                    + ((s >> 60) as i64 - 8);
                if (x as isize - 20).pow(2) + (y as isize - 15).pow(2) < 40 {
                    kinds[i] = super::super::plane::SKIPPED;
                }
                if (50..58).contains(&x) && (30..40).contains(&y) {
                    kinds[i] = FIXED;
                    values[i] = 77;
                }
            }
        }
        (kinds, values)
    }

    /// A plane of `kinds` and `values` with their range as lo ..= hi.
    fn test_plane<'a>(w: usize, h: usize, kinds: &'a [u8], values: &'a [i64], bin: i64) -> Plane<'a> {
        Plane {
            width: w,
            height: h,
            kinds,
            values,
            lo: *values.iter().min().unwrap(),
            hi: *values.iter().max().unwrap(),
            bin,
        }
    }

    /// Four levels, bands of 2^10 samples.
    fn test_config(ls_levels: u32, tighten: bool, lanes: bool) -> Config {
        Config {
            levels: 4,
            ls_levels,
            tighten,
            tighten_auto: false,
            band_log2: 10,
            lanes,
        }
    }

    #[test]
    fn bands_round_trip_on_any_thread_count_and_every_prefix_fails() {
        let (w, h) = (97, 83);
        let (kinds, values) = plane_data(w, h);
        for (bin, tighten, ls, lanes) in [
            (1, false, 3, false),
            (5, false, 2, false),
            (41, true, 3, false),
            (301, true, 0, false),
            (1, false, 3, true),
            (5, false, 2, true),
            (41, true, 3, true),
            (301, true, 0, true),
        ] {
            let p = test_plane(w, h, &kinds, &values, bin);
            let cfg = test_config(ls, tighten, lanes);
            let (wts, bytes, rec) = encode(&p, cfg, &mut |_| {}).unwrap();
            assert!(wts.len() <= 2 * ls as usize);
            for (i, (&r, &k)) in rec.iter().zip(&kinds).enumerate() {
                if k == CODED {
                    assert!((r - values[i]).abs() <= bin / 2, "bin {bin}: sample {i}");
                } else if k == FIXED {
                    assert_eq!(r, 77);
                }
            }
            let max_bin = (p.hi - p.lo) as u64 / super::super::narrowest_bin(bin, 4, tighten) as u64 + 1;
            for threads in [1, 2, 3] {
                let back = crate::threads::with_threads(threads, || {
                    decode(&mut ByteReader::new(&bytes, "t"), &p, &fixed_of(&p), 4, tighten, lanes, &wts, max_bin, 0..h, 0, None)
                })
                .unwrap()
                .indices();
                assert_eq!(back, rec, "bin {bin}, {threads} threads");
            }
            for cut in (0..bytes.len()).step_by(7) {
                let r = decode(&mut ByteReader::new(&bytes[..cut], "t"), &p, &fixed_of(&p), 4, tighten, lanes, &wts, max_bin, 0..h, 0, None);
                assert!(r.is_err(), "bin {bin}: a prefix of {cut} bytes decoded");
            }
            // One flipped bit in the streams decodes to an error or other samples, never a
            // panic.
            for k in (bytes.len() / 2..bytes.len()).step_by(13) {
                let mut bad = bytes.clone();
                bad[k] ^= 0x10;
                let _ = decode(&mut ByteReader::new(&bad, "t"), &p, &fixed_of(&p), 4, tighten, lanes, &wts, max_bin, 0..h, 0, None);
            }
        }
    }

    /// A tall plane (several bands in every pass of levels 1 to 3 at bands of 2^10) of a
    /// rough surface, with a skipped disc and a fixed patch unless `all_coded`.
    fn tall_plane(w: usize, h: usize, all_coded: bool) -> (Vec<u8>, Vec<i64>) {
        let mut rng = crate::testutil::Rng(11);
        let mut kinds = vec![CODED; w * h];
        let mut values = vec![0i64; w * h];
        for y in 0..h {
            for x in 0..w {
                let s = rng.next();
                let i = y * w + x;
                let (fx, fy) = (x as f64 / 9.0, y as f64 / 13.0);
                values[i] = (300.0 * fx.sin() * fy.cos() + 2.0 * y as f64) as i64 + ((s >> 58) as i64 - 32);
                if all_coded {
                    continue;
                }
                if (x as isize - w as isize / 3).pow(2) + (y as isize - h as isize / 4).pow(2) < 60 {
                    kinds[i] = super::super::plane::SKIPPED;
                }
                if (w / 2..w / 2 + 9).contains(&x) && (h / 2..h / 2 + 23).contains(&y) {
                    kinds[i] = FIXED;
                    values[i] = 77;
                }
            }
        }
        (if all_coded { Vec::new() } else { kinds }, values)
    }

    /// A decode of any rows reconstructs them as the full decode does (the bands it skips
    /// are none that they need), on one thread and two, while skipping bands.
    #[test]
    fn a_window_decodes_its_rows_as_the_full_decode_does() {
        let cases = [
            (131, 517, false, 1, false, 3),
            (131, 517, true, 5, true, 2),
            (37, 1903, false, 3, false, 3),
            (64, 1500, false, 41, true, 0),
        ];
        for ((w, h, all_coded, bin, tighten, ls), lanes) in cases.into_iter().flat_map(|c| [(c, false), (c, true)]) {
            let (kinds, values) = tall_plane(w, h, all_coded);
            let p = test_plane(w, h, &kinds, &values, bin);
            let cfg = test_config(ls, tighten, lanes);
            let what = format!("{w}x{h}, bin {bin}, {ls} stencil levels, lanes {lanes}");
            let (wts, bytes, rec) = encode(&p, cfg, &mut |_| {}).unwrap();
            assert_eq!(wts.len(), 2 * ls as usize, "{what}: a stencil on every level it may");
            let all = passes(cfg, bin);
            let bands: Vec<_> = all.iter().map(|pass| pass.bands(w, h, 10)).collect();
            for (pass, b) in all.iter().zip(&bands) {
                if pass.kind != Kind::Anchor && pass.level() <= 3 {
                    assert!(b.len() >= 2, "{what}: {pass:?} has {} bands", b.len());
                }
            }
            let max_bin = (p.hi - p.lo) as u64 / super::super::narrowest_bin(bin, 4, tighten) as u64 + 1;
            let dec = |rows: Range<usize>| decode(&mut ByteReader::new(&bytes, "t"), &p, &fixed_of(&p), 4, tighten, lanes, &wts, max_bin, rows, 0, None).map(|r| r.indices());
            assert_eq!(dec(0..h).unwrap(), rec, "{what}: the full decode");
            // Every single row, the first and last few, and random ranges.
            let mut windows: Vec<Range<usize>> = (0..h).map(|y| y..y + 1).collect();
            windows.extend([0..2, 0..h, h - 3..h, 1..h - 1]);
            let mut rng = crate::testutil::Rng(5);
            for _ in 0..120 {
                let r = rng.next();
                let y0 = (r >> 33) as usize % h;
                let len = 1 + (r >> 13) as usize % (h - y0).min(if r & 1 == 0 { 8 } else { h });
                windows.push(y0..y0 + len);
            }
            for threads in [1, 2] {
                let pool = crate::threads::thread_pool(threads).unwrap();
                for rows in &windows {
                    let back = pool.install(|| dec(rows.clone())).unwrap_or_else(|e| panic!("{what}: rows {rows:?}: {e}"));
                    let span = rows.start * w..rows.end * w;
                    assert!(back[span.clone()] == rec[span], "{what}, {threads} threads: rows {rows:?} differ");
                }
            }
            // A row in the middle skips most bands.
            let pick = needed(&all, &bands, h, h / 2..h / 2 + 1);
            let (run, of): (usize, usize) = (pick.iter().map(|r| r.len()).sum(), bands.iter().map(Vec::len).sum());
            assert!(run * 2 < of, "{what}: a row runs {run} of {of} bands");
        }
    }

    #[test]
    fn tokens_cover_every_bin() {
        for v in [0u64, 1, 15, 16, 17, 31, 32, 1000, (1 << 41) - 1] {
            let (t, raw, n) = token(v);
            assert!((t as usize) < ALPHABET);
            let back = if t < 16 {
                t as u64
            } else {
                let e = (t as u64 - 16) / 2 + 4;
                (1 << e) | (((t as u64 - 16) & 1) << (e - 1)) | raw
            };
            assert_eq!(back, v);
            assert!(n < 41);
        }
    }
}
