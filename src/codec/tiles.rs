//! Tiled files (container version 2): a raster cut into tiles that encode on all cores and
//! are written in tile order as they finish, and decodes that read only the tiles a window
//! touches, band of tiles by band of tiles.

use super::decode::{self, check_output};
use super::encode::{EncodeReport, encode_parts};
use super::options::{DecodeOptions, EncodeOptions, SectionChoice};
use crate::container::tiled::{RasterReader, TileGrid, TiledWriter, tile_block, tile_name};
use crate::container::{ContainerReader, Header, SectionKind};
use crate::error::{Error, Result};
use crate::methods::Method;
use crate::model::{Raster, RowSource, Window};
use crate::quant::ErrorBound;
use crate::threads::{pool, with_threads};
use std::io::{Seek, Write};
use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The tile side an encode uses unless told (`--tile`), picked by measurement
/// (benches/README.md, "Tiles"): the bytes tiling costs against an untiled encode stay
/// small while a tile decodes in milliseconds.
pub const DEFAULT_TILE: u32 = 1024;

/// Unless a tile side is given, a raster of this many samples or fewer stays untiled,
/// whatever its shape: tiles of 1024² cost 3–9 % of the bytes at 0.3–1 % of the range and
/// 16–31 % at 10 % on 1201²–2400² rasters (each tile's framing, index entry, method header,
/// context learning and margins; benches/README.md, "Tiles"), and 6 % at 10 % on a
/// 4320 × 2161 raster, which buys a raster that fits in memory little a user would notice.
/// What tiling buys, memory bounded by the tiles in flight, depends on the sample count
/// alone (an untiled encode holds the raster and per-sample state), so the threshold is one
/// of samples, not of a side: 4096², the largest raster that stayed whole before.
pub const DEFAULT_UNTILED_MAX_SAMPLES: u64 = 4096 * 4096;

/// Samples each tile codes beyond its borders, across which a decoder blends neighbouring
/// tiles (spec/FORMAT.md, "Blending"): 8 makes the error change over 16 samples instead of
/// jumping at the border (benches/README.md, "Tiles: seams").
pub const MARGIN: u32 = 8;

/// Rows a band-by-band decode hands out at a time.
const SUB_BAND: usize = 64;

/// Options that are whole-file notions: a size target, comparison sections, a site count
/// or an RMSE target (a tile would meet each on its own).
fn whole_file_options(opts: &EncodeOptions) -> bool {
    opts.target_bytes.is_some()
        || opts.methods.len() > 1
        || opts.params.sibson.sites.is_some()
        || opts.params.sibson.rmse.is_some()
}

/// Whether an encode of a `w × h` raster with these options is tiled.
pub(crate) fn tiled(w: usize, h: usize, opts: &EncodeOptions) -> bool {
    let t = match opts.tile {
        Some(t) => t as usize,
        None if whole_file_options(opts) => return false,
        None if (w as u64).saturating_mul(h as u64) <= DEFAULT_UNTILED_MAX_SAMPLES => {
            return false;
        }
        None => DEFAULT_TILE as usize,
    };
    t > 0 && (w > t || h > t)
}

/// The tiles an encode of a `w × h` raster with these options makes (1 when untiled).
pub fn tile_count(w: usize, h: usize, opts: &EncodeOptions) -> u64 {
    if !tiled(w, h, opts) {
        return 1;
    }
    let t = opts.tile.unwrap_or(DEFAULT_TILE);
    let (Ok(w), Ok(h)) = (u32::try_from(w), u32::try_from(h)) else {
        return 1;
    };
    TileGrid::balanced(w, h, t, MARGIN).count()
}

/// Encode a raster read band by band into a version-2 file written to `out`: tiles go to
/// the workers a few rows of tiles at a time and are written in tile order, so memory holds
/// the tiles in flight, not the raster. `progress` gets the fraction of tiles done.
pub fn encode_tiled<W: Write + Seek>(
    src: &mut dyn RowSource,
    opts: &EncodeOptions,
    out: W,
    progress: &mut dyn FnMut(f64),
) -> Result<(W, EncodeReport)> {
    let tile = opts.tile.unwrap_or(DEFAULT_TILE);
    if tile < crate::container::tiled::MIN_TILE {
        return Err(Error::invalid(format!(
            "a tile of {tile} samples is below the smallest, {}",
            crate::container::tiled::MIN_TILE
        )));
    }
    if whole_file_options(opts) {
        return Err(Error::invalid(
            "a size target, several methods, --sites and --rmse are whole-file requests: \
             leave --tile out, or give --tile 0",
        ));
    }
    if let Some(k) = opts.effort.filter(|k| !(1..=9).contains(k)) {
        return Err(Error::invalid(format!("effort {k} is not in 1..=9")));
    }
    if let Some(meta) = &opts.metadata {
        serde_json::from_str::<serde_json::Value>(meta)
            .map_err(|e| Error::invalid(format!("metadata is not JSON: {e}")))?;
    }
    let (w, h) = (src.width(), src.height());
    if w == 0 || h == 0 {
        return Err(Error::invalid("the raster is empty"));
    }
    let (wu, hu) = (
        u32::try_from(w).map_err(|_| Error::limit("raster wider than 2^32"))?,
        u32::try_from(h).map_err(|_| Error::limit("raster taller than 2^32"))?,
    );
    if wu > i32::MAX as u32 || hu > i32::MAX as u32 {
        return Err(Error::limit("raster dimension over 2^31 - 1"));
    }
    let grid = TileGrid::balanced(wu, hu, tile, MARGIN);
    let m = grid.margin as usize;
    let th = grid.tile_h as usize;
    let first = src.band(0, 1)?;
    let header = Header {
        width: wu,
        height: hu,
        sample_type: first.sample_type,
        primary: 0,
        mapping: first.mapping,
        nodata: first.nodata,
        range: None,
        georef: first.georef.clone(),
    };
    // A bound in % of the range needs the whole raster's range first: one pass of bands.
    let e = match opts.max_error {
        Some(ErrorBound::PercentOfRange(_)) => {
            let mut range: Option<(f64, f64)> = None;
            for y in (0..h).step_by(th) {
                let b = src.band(y, th.min(h - y))?;
                if let Some((lo, hi)) = b.valid_range() {
                    range = Some(range.map_or((lo, hi), |(a, c)| (a.min(lo), c.max(hi))));
                }
            }
            opts.max_error.map(|b| b.absolute(range))
        }
        b => b.map(|b| b.absolute(None)),
    };
    let mut topts = opts.clone();
    topts.max_error = e.map(ErrorBound::Abs);
    topts.metadata = None;
    topts.tile = Some(0);
    topts.levels_first = true;
    let mut global = Vec::new();
    if let Some(meta) = &opts.metadata {
        global.push(crate::container::Section {
            kind: SectionKind::METADATA,
            flags: 0,
            payload: meta.as_bytes().to_vec(),
        });
    }
    if let Some(xml) = &first.gdal_metadata {
        global.push(crate::container::Section {
            kind: SectionKind::GDAL_METADATA,
            flags: 0,
            payload: xml.as_bytes().to_vec(),
        });
    }
    drop(first);
    let mut writer = TiledWriter::new(out, &header, grid, &global)?;
    let pool = pool(opts.threads)?;
    let cols = grid.cols() as usize;
    let rows = grid.rows() as usize;
    let total = grid.count() as usize;
    // Rows of tiles in flight: enough tiles that workers rarely wait for the slowest of a
    // group (tiles of sea and of mountains differ tenfold in time), within a memory budget
    // of about 64 M samples of source bands.
    let want = (8 * pool.current_num_threads()).div_ceil(cols).max(1);
    let budget = (64usize << 20) / (w * th).max(1);
    let group = want.min(budget.saturating_sub(2)).max(1);
    let mut report = EncodeReport {
        max_error: 0.0,
        method: Method::GRID,
        stats: None,
        skipped: Vec::new(),
        encoded: Vec::new(),
        notes: Vec::new(),
    };
    let mut counts: Vec<(Method, usize)> = Vec::new();
    // Progress counts two steps per tile, its encode and its write, and one for the index
    // that `finish` writes: each is reported as it happens (the encodes from the workers as
    // they finish, in any order; the writes in tile order as soon as a tile's turn comes).
    let steps = (2 * total + 1) as f64;
    let mut done = 0usize;
    progress(0.0);
    for r0 in (0..rows).step_by(group) {
        let mut tiles: Vec<(usize, Raster)> = Vec::new();
        for r in r0..(r0 + group).min(rows) {
            // The tile row's coded rows: its core and the margins.
            let y0 = (r * th).saturating_sub(m);
            let y1 = ((r + 1) * th + m).min(h);
            let band = src.band(y0, y1 - y0)?;
            for c in 0..cols {
                let k = r * cols + c;
                let win = grid.ext(k);
                let mut t = band.crop(Window {
                    y: win.y - y0,
                    ..win
                });
                t.georef = header.georef.as_ref().map(|g| g.window(win.x, win.y));
                tiles.push((k, t));
            }
        }
        let n = tiles.len();
        let mut ready: Vec<Option<Result<_>>> = (0..n).map(|_| None).collect();
        let mut next = 0usize;
        let (tx, rx) = std::sync::mpsc::channel();
        let (pool, tiles, topts, grid) = (&pool, &tiles, &topts, &grid);
        let outcome: Result<()> = std::thread::scope(|scope| {
            let workers = scope.spawn(move || {
                pool.install(|| {
                    use rayon::prelude::*;
                    tiles
                        .par_iter()
                        .enumerate()
                        .for_each_with(tx, |tx, (i, (k, t))| {
                            let r = with_threads(1, || encode_parts(t, topts, &mut |_| {}))
                                .map_err(|e| e.context(tile_name(grid, *k)));
                            let r = r.and_then(|(hd, sections, rep)| {
                                let kind = sections[hd.primary as usize].kind;
                                let block = tile_block(hd.primary, &sections);
                                // Where overviews of the tile end (version 4's chunks):
                                // read back from the block as a decoder reads it.
                                let prefixes = {
                                    let len = block.len() as u64;
                                    let mut rd = ContainerReader::tile(
                                        std::io::Cursor::new(&block[..]),
                                        hd.clone(),
                                        len,
                                        crate::container::Limits::default(),
                                        decode::kind_names,
                                        "tile",
                                    )?;
                                    decode::overview_prefixes(&mut rd)
                                        .map_err(|e| e.context(tile_name(grid, *k)))?
                                };
                                Ok((block, kind, t.valid_count() as u64, hd.range, rep, prefixes))
                            });
                            // The receiver has gone only when a tile before failed.
                            let _ = tx.send((i, r));
                        });
                })
            });
            let mut outcome = Ok(());
            'tiles: for (i, r) in rx.iter() {
                done += 1;
                progress(done as f64 / steps);
                ready[i] = Some(r);
                // Write every tile whose turn has come, in tile order.
                while let Some(r) = ready.get_mut(next).and_then(Option::take) {
                    next += 1;
                    let written = r.and_then(|(block, kind, valid, range, rep, prefixes)| {
                        writer.push(&block, kind, valid, range, rep.max_error, &prefixes)?;
                        Ok(rep)
                    });
                    let rep = match written {
                        Ok(rep) => rep,
                        Err(e) => {
                            outcome = Err(e);
                            break 'tiles;
                        }
                    };
                    done += 1;
                    progress(done as f64 / steps);
                    report.max_error = report.max_error.max(rep.max_error);
                    match counts.iter_mut().find(|(m, _)| *m == rep.method) {
                        Some(c) => c.1 += 1,
                        None => counts.push((rep.method, 1)),
                    }
                    for m in rep.encoded {
                        if !report.encoded.contains(&m) {
                            report.encoded.push(m);
                        }
                    }
                    // The first tile's note says why (the others' differ in their numbers only).
                    if report.notes.is_empty() {
                        report.notes = rep.notes;
                    }
                }
            }
            // Leaving the loop early drops the receiver: the workers' last sends fail
            // quietly and they finish the group's remaining tiles.
            drop(rx);
            if let Err(panic) = workers.join() {
                std::panic::resume_unwind(panic);
            }
            outcome
        });
        outcome?;
        debug_assert_eq!(next, n, "every tile of the group written");
        debug_assert_eq!(writer.written(), done / 2, "tiles written so far");
    }
    // The method most tiles chose (the first such in tile order on a tie).
    if let Some(&(m, _)) = counts.iter().max_by_key(|(_, n)| *n) {
        report.method = counts
            .iter()
            .find(|(_, n)| *n == counts.iter().map(|c| c.1).max().unwrap_or(0))
            .map_or(m, |c| c.0);
    }
    let out = writer.finish()?;
    progress(1.0);
    Ok((out, report))
}

/// Open a raster file (any version; an untiled one as a one-tile grid) with the registry's
/// section names.
pub(crate) fn open(
    inner: crate::source::Source,
    limits: crate::container::Limits,
) -> Result<RasterReader> {
    RasterReader::new(inner, limits, decode::kind_names)
}

/// Decode a window (or all) of a file band by band, top to bottom, each band handed to
/// `sink`: the one decode path. An untiled file is the one-tile case: its one tile is the
/// raster, decoded (the window of it, at the scale or overview asked, on every thread) as
/// one band with nothing to blend. A tiled file's tiles go through [`decode_tiles`] (bands
/// blended from them), an overview of them through [`decode_overview`] (one band, each
/// sample from the tile whose core holds it); both read and decode their tiles in the one
/// tile loop, [`decode_tile_rows`]. Gives back the tiles skipped as corrupt
/// (`opts.skip_corrupt`).
pub(crate) fn decode_bands(
    rd: &mut RasterReader,
    opts: &DecodeOptions,
    sink: &mut dyn FnMut(Raster) -> Result<()>,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Vec<String>> {
    if let Some(whole) = rd.whole() {
        sink(decode::decode_reader(whole, opts, progress)?)?;
        return Ok(Vec::new());
    }
    check_tiled_options(opts)?;
    if opts.overview.is_some() {
        // An overview is one band: its window is checked against the limits whole.
        let (r, skipped) = decode_overview(rd, opts, progress)?;
        sink(r)?;
        return Ok(skipped);
    }
    decode_tiles(rd, opts, sink, progress)
}

/// Decoded tiles as [`decode_tile_rows`] hands them out: each tile's index, what the caller
/// keeps of it and its decode.
type DecodedTiles<T> = Vec<(usize, T, Result<Raster>)>;

/// The overview's columns and rows (ranges of its window) that one tile's core holds.
type OverviewPart = (Range<usize>, Range<usize>);

/// The tiles a tiled decode reads, by row of tiles, and how: each tile with what the
/// caller keeps of it (`T`); at overview `level` (0: whole blocks; k: the prefix of each
/// block that overview k needs); at most `read_rows` rows of tiles in one read and, past the
/// first row, at most `read_bytes` bytes of blocks (`None`: no byte limit); decoded
/// `decode_rows` (at least 1) rows at a time.
struct TileRows<T> {
    rows: Vec<Vec<(usize, T)>>,
    level: u32,
    read_rows: usize,
    read_bytes: Option<u64>,
    decode_rows: usize,
}

/// The one tile loop of a tiled decode, at full resolution or of an overview. The rows of
/// tiles of `plan` are read in batches, one read per batch: a remote source fetches a
/// batch's blocks at once, and version 5's heads as one range. Each batch is decoded on
/// `pool`, every tile on one thread with the options `tile_opts` gives it, its errors naming
/// it. The decoded tiles go to `place` one decode group at a time, in row order, with the
/// count of rows of tiles decoded so far. A tile that fails as corrupt under
/// `opts.skip_corrupt` goes to `place` as its error and is named in the list given back. Any
/// other error ends the decode. Progress counts tiles.
fn decode_tile_rows<T: Send>(
    rd: &mut RasterReader,
    mut plan: TileRows<T>,
    opts: &DecodeOptions,
    pool: &crate::threads::Pool,
    tile_opts: &(dyn Fn(usize, &T) -> DecodeOptions + Sync),
    progress: &(dyn Fn(f64) + Sync),
    place: &mut dyn FnMut(DecodedTiles<T>, usize) -> Result<()>,
) -> Result<Vec<String>> {
    use rayon::prelude::*;
    let total = plan.rows.iter().map(Vec::len).sum::<usize>().max(1);
    let done = AtomicUsize::new(0);
    let grid = rd.grid();
    let mut skipped = Vec::new();
    let n = plan.rows.len();
    let step = plan.decode_rows.max(1);
    let mut i = 0;
    while i < n {
        // The batch: rows i..j.
        let (mut j, mut bytes) = (i, 0u64);
        while j < n && j - i < plan.read_rows {
            if let Some(limit) = plan.read_bytes {
                let b: u64 = plan.rows[j]
                    .iter()
                    .map(|(t, _)| rd.tiles()[*t].prefix(plan.level))
                    .sum();
                if j > i && bytes + b > limit {
                    break;
                }
                bytes += b;
            }
            j += 1;
        }
        let ks: Vec<usize> = plan.rows[i..j]
            .iter()
            .flat_map(|r| r.iter().map(|(k, _)| *k))
            .collect();
        let got = rd.tile_blocks(&ks, plan.level)?;
        if got.len() != ks.len() {
            return Err(Error::invalid("a batch of tiles was not read whole"));
        }
        let mut got = got.into_iter();
        let opener = rd.opener();
        for g in (i..j).step_by(step) {
            let g1 = (g + step).min(j);
            let blocks: Vec<(usize, T, Result<Vec<u8>>)> = plan.rows[g..g1]
                .iter_mut()
                .flat_map(std::mem::take)
                .zip(got.by_ref())
                .map(|((k, t), b)| (k, t, b))
                .collect();
            let out: DecodedTiles<T> = pool.install(|| {
                blocks
                    .into_par_iter()
                    .map(|(k, t, block)| {
                        let r = block.and_then(|b| {
                            let mut trd = opener.open(k, b)?;
                            let o = tile_opts(k, &t);
                            with_threads(1, || decode::decode_reader(&mut trd, &o, &|_| {}))
                                .map_err(|e| e.context(tile_name(&grid, k)))
                        });
                        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                        progress(d as f64 / total as f64);
                        (k, t, r)
                    })
                    .collect()
            });
            let mut placed = Vec::with_capacity(out.len());
            for (k, t, r) in out {
                let r = match r {
                    Err(e) if opts.skip_corrupt && matches!(e, Error::Corrupt { .. }) => {
                        skipped.push(e.to_string());
                        Err(e)
                    }
                    Err(e) => return Err(e),
                    ok => ok,
                };
                placed.push((k, t, r));
            }
            place(placed, g1)?;
        }
        i = j;
    }
    Ok(skipped)
}

/// A decoded tile: the part of its coded samples inside the window (raster coordinates),
/// its decode, and its column weights over that part.
struct Decoded {
    sub: Window,
    raster: Result<Raster>,
    wx: Vec<u64>,
}

/// What a tiled file's decode cannot do: a sites prefix, a section by index.
pub(crate) fn check_tiled_options(opts: &DecodeOptions) -> Result<()> {
    if opts.sites.is_some() || opts.levels.is_some() {
        return Err(Error::invalid(
            "--sites and --level need an untiled file (each tile has its own sites)",
        ));
    }
    if let SectionChoice::Index(_) = opts.section {
        return Err(Error::invalid(
            "a tiled file's tiles have their own directories: choose a section by method name",
        ));
    }
    Ok(())
}

/// Decode a window of a tiled file band by band: a few rows of tiles at a time are read
/// (one reader) and decoded (every thread), and each band of the window is blended from
/// them, its rows side by side.
fn decode_tiles(
    rd: &mut RasterReader,
    opts: &DecodeOptions,
    sink: &mut dyn FnMut(Raster) -> Result<()>,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Vec<String>> {
    let header = rd.header().clone();
    let grid = rd.grid();
    let (w, h) = (header.width as usize, header.height as usize);
    let win = decode::window(opts, w, h)?;
    let th = grid.tile_h as usize;
    check_output(
        || format!("a band of {} x {} samples", win.width, th.min(win.height)),
        (win.width as u64).checked_mul(th.min(win.height) as u64),
        rd.limits(),
    )?;
    let gdal = rd.gdal_metadata()?;
    let lossy = rd.tiles().iter().any(|t| t.max_error != 0.0);
    let gdal = if lossy || (win.width, win.height) != (w, h) {
        gdal.map(|x| crate::formats::without_statistics(&x).into_owned())
    } else {
        gdal
    };
    let pool = pool(opts.threads)?;
    let touched = grid.touching_ext(win);
    let cols = grid.cols() as usize;
    let (r0, r1) = (win.y / th, (win.y + win.height - 1) / th);
    let (first_row, last_row) = (
        touched.first().map_or(r0, |k| k / cols),
        touched.last().map_or(r1, |k| k / cols),
    );
    // Rows of tiles decoded at once: enough tiles that every thread has a few (tiles of sea
    // and of mountains differ tenfold in time, and a row of tiles may hold fewer tiles than
    // there are threads), within about 64 M samples of decoded tiles held (a batch and the
    // two rows of tiles a band also blends), never fewer than one row at a time.
    let per_row = touched.len().div_ceil(last_row + 1 - first_row).max(1);
    let m2 = 2 * grid.margin as usize;
    let tile_samples = (grid.tile_w as usize + m2) * (th + m2);
    let want = (4 * pool.current_num_threads()).div_ceil(per_row);
    let budget = (64usize << 20) / (per_row * tile_samples).max(1);
    let group = want.min(budget.saturating_sub(2)).max(1);
    // Each tile with its coded samples inside the window, in raster coordinates.
    let rows: Vec<Vec<(usize, Window)>> = (first_row..=last_row)
        .map(|row| {
            touched
                .iter()
                .copied()
                .filter(|k| k / cols == row)
                .map(|k| {
                    let e = grid.ext(k);
                    let x0 = win.x.max(e.x);
                    let x1 = (win.x + win.width).min(e.x + e.width);
                    let y0 = win.y.max(e.y);
                    let y1 = (win.y + win.height).min(e.y + e.height);
                    let sub = Window {
                        x: x0,
                        y: y0,
                        width: x1 - x0,
                        height: y1 - y0,
                    };
                    (k, sub)
                })
                .collect()
        })
        .collect();
    let plan = TileRows {
        rows,
        level: 0,
        read_rows: group,
        read_bytes: None,
        decode_rows: group,
    };
    let tile_opts = |k: usize, sub: &Window| {
        let e = grid.ext(k);
        DecodeOptions {
            window: Some(Window {
                x: sub.x - e.x,
                y: sub.y - e.y,
                ..*sub
            }),
            threads: 1,
            scale: None,
            ..opts.clone()
        }
    };
    // Decoded tiles, kept while a band they contribute to is still to come.
    let mut decoded: std::collections::BTreeMap<usize, Decoded> = std::collections::BTreeMap::new();
    let fill = header.nodata.unwrap_or(f64::NAN);
    // The next band of tiles to hand out: band r blends tiles of rows r − 1 ..= r + 1, so it
    // goes out once the rows of tiles up to r + 1 are decoded.
    let mut r = r0;
    let mut place = |out: DecodedTiles<Window>, rows_done: usize| -> Result<()> {
        for (k, sub, raster) in out {
            let wx = (sub.x..sub.x + sub.width)
                .map(|x| grid.weight_x(k, x))
                .collect();
            decoded.insert(k, Decoded { sub, raster, wx });
        }
        let next_row = first_row.saturating_add(rows_done);
        while r <= r1 && (r + 1).min(last_row) < next_row {
            // Band r: the window's rows in core row r, handed out SUB_BAND rows at a time to
            // keep the buffers small.
            let band_y0 = (r * th).max(win.y);
            let band_y1 = ((r + 1) * th).min(win.y + win.height);
            for sy0 in (band_y0..band_y1).step_by(SUB_BAND) {
                let sy1 = (sy0 + SUB_BAND).min(band_y1);
                let mut band = blend(&grid, &decoded, win, (sy0, sy1), fill, &header, &pool);
                band.georef = header.georef.as_ref().map(|g| g.window(win.x, sy0));
                band.gdal_metadata = gdal.clone();
                sink(band)?;
                // Tiles that code no later row are done with.
                decoded.retain(|_, d| d.sub.y + d.sub.height > sy1);
            }
            r += 1;
        }
        Ok(())
    };
    let skipped = decode_tile_rows(rd, plan, opts, &pool, &tile_opts, progress, &mut place)?;
    // Bands no row of tiles reaches (none when the window touches a tile).
    place(Vec::new(), usize::MAX)?;
    Ok(skipped)
}

/// Rows `sy0..sy1` of the window, each sample the weighted blend of the tiles that code it
/// (spec/FORMAT.md, "Blending"), rows side by side. A sample one tile alone codes (with a
/// weight above 0, valid) is that tile's value as it is: the blend of one value, `finish(w·v / w)`
/// clamped to `v ..= v`, is `v`. Samples several tiles code are blended in tile order, so
/// the sums are the same on every run and thread count.
fn blend(
    grid: &TileGrid,
    decoded: &std::collections::BTreeMap<usize, Decoded>,
    win: Window,
    (sy0, sy1): (usize, usize),
    fill: f64,
    header: &Header,
    pool: &crate::threads::Pool,
) -> Raster {
    use rayon::prelude::*;
    let bh = sy1 - sy0;
    let n = win.width * bh;
    // The tiles with a decode that code some row of the band, in tile order.
    let tiles: Vec<(usize, &Decoded, &Raster)> = decoded
        .iter()
        .filter_map(|(&k, d)| d.raster.as_ref().ok().map(|r| (k, d, r)))
        .filter(|(_, d, _)| d.sub.y < sy1 && d.sub.y + d.sub.height > sy0)
        .collect();
    let mut data = vec![fill; n];
    let mut mask = vec![false; n];
    pool.install(|| {
        data.par_chunks_mut(win.width)
            .zip(mask.par_chunks_mut(win.width))
            .enumerate()
            .for_each_init(
                || vec![0u8; win.width],
                |cover, (dy, (drow, mrow))| {
                    let y = sy0 + dy;
                    // (tile, its row's weight, its row's first sample, its first column in
                    // the window) of the tiles that code row y.
                    let here: Vec<(&Decoded, &Raster, u64, usize, usize)> = tiles
                        .iter()
                        .filter(|(_, d, _)| (d.sub.y..d.sub.y + d.sub.height).contains(&y))
                        .map(|&(k, d, r)| {
                            (
                                d,
                                r,
                                grid.weight_y(k, y),
                                (y - d.sub.y) * d.sub.width,
                                d.sub.x - win.x,
                            )
                        })
                        .filter(|h| h.2 > 0)
                        .collect();
                    cover.fill(0);
                    for &(d, r, _, t0, o0) in &here {
                        for (i, &wx) in d.wx.iter().enumerate() {
                            if wx > 0 && r.is_valid(t0 + i) {
                                cover[o0 + i] += 1;
                            }
                        }
                    }
                    for &(d, r, _, t0, o0) in &here {
                        for (i, &wx) in d.wx.iter().enumerate() {
                            if wx > 0 && cover[o0 + i] == 1 && r.is_valid(t0 + i) {
                                drow[o0 + i] = r.data[t0 + i];
                                mrow[o0 + i] = true;
                            }
                        }
                    }
                    for (o, &c) in cover.iter().enumerate() {
                        if c < 2 {
                            continue;
                        }
                        let x = win.x + o;
                        let (mut acc, mut wsum) = (0.0f64, 0u64);
                        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                        for &(d, r, wy, t0, _) in &here {
                            if !(d.sub.x..d.sub.x + d.sub.width).contains(&x) {
                                continue;
                            }
                            let i = x - d.sub.x;
                            let ww = d.wx[i] * wy;
                            if ww == 0 || !r.is_valid(t0 + i) {
                                continue;
                            }
                            let v = r.data[t0 + i];
                            acc += ww as f64 * v;
                            wsum += ww;
                            lo = lo.min(v);
                            hi = hi.max(v);
                        }
                        let v = crate::quant::finish(
                            acc / wsum as f64,
                            header.sample_type,
                            header.mapping,
                        );
                        drow[o] = v.clamp(lo, hi);
                        mrow[o] = true;
                    }
                },
            );
    });
    let any_invalid = mask.contains(&false);
    Raster {
        width: win.width,
        height: bh,
        data,
        mask: any_invalid.then_some(mask),
        nodata: header.nodata,
        sample_type: header.sample_type,
        mapping: header.mapping,
        georef: None,
        gdal_metadata: None,
    }
}

/// Bytes of tile blocks an overview decode reads at once (compressed: a few % of the
/// samples' memory).
const OVERVIEW_READ_BYTES: u64 = 64 << 20;

/// Overview `req.k` of a tiled file (the window `req.window` of it): each tile whose core
/// holds an overview sample decodes at its own 2^k lattice (a row of tiles at a time, on
/// every thread), and the sample takes the tile's value at the lattice point nearest it
/// (ties to the lower; within the tile). Gives back the tiles skipped as corrupt.
fn decode_overview(
    rd: &mut RasterReader,
    opts: &DecodeOptions,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<(Raster, Vec<String>)> {
    let header: Header = rd.header().clone();
    let grid = rd.grid();
    let (w, h) = (header.width as usize, header.height as usize);
    let req = decode::check_overview(opts, w, h, rd.limits())?
        .ok_or_else(|| Error::invalid("no overview asked for"))?;
    let (k, win) = (req.k, req.window);
    let s = 1usize << k;
    let (tw, th) = (grid.tile_w as usize, grid.tile_h as usize);
    let cols = grid.cols() as usize;
    // The overview's columns and rows by the tile column / row whose core holds them.
    let xs: Vec<usize> = (win.x..win.x + win.width).map(|i| i * s).collect();
    let ys: Vec<usize> = (win.y..win.y + win.height).map(|i| i * s).collect();
    let span = |v: &[usize], t: usize| -> Vec<(usize, std::ops::Range<usize>)> {
        let mut out: Vec<(usize, std::ops::Range<usize>)> = Vec::new();
        for (i, &p) in v.iter().enumerate() {
            match out.last_mut() {
                Some((c, r)) if *c == p / t => r.end = i + 1,
                _ => out.push((p / t, i..i + 1)),
            }
        }
        out
    };
    let (tcols, trows) = (span(&xs, tw), span(&ys, th));
    let fill = header.nodata.unwrap_or(f64::NAN);
    let n = win.width * win.height;
    let mut data = vec![fill; n];
    let mut mask = vec![false; n];
    let pool = pool(opts.threads)?;
    // Each tile with the overview's columns and rows its core holds. Blocks are read for as
    // many rows of tiles as fit in OVERVIEW_READ_BYTES (at least one row), of each block the
    // prefix this overview needs (version 4 and 5: its first chunks; in version 5 at the
    // file's split or coarser those lie together in the heads, and the whole overview is one
    // range); they are decoded a row of tiles at a time.
    let rows: Vec<Vec<(usize, OverviewPart)>> = trows
        .iter()
        .map(|(tr, yr)| {
            tcols
                .iter()
                .map(|(tc, cr)| (tr * cols + tc, (cr.clone(), yr.clone())))
                .collect()
        })
        .collect();
    let plan = TileRows {
        rows,
        level: k,
        read_rows: usize::MAX,
        read_bytes: Some(OVERVIEW_READ_BYTES),
        decode_rows: 1,
    };
    let tile_opts = |_: usize, _: &OverviewPart| DecodeOptions {
        window: None,
        threads: 1,
        ..opts.clone()
    };
    let mut place = |out: DecodedTiles<OverviewPart>, _| {
        // A tile skipped as corrupt leaves its samples invalid.
        for (t, (cr, yr), r) in out {
            let Ok(r) = r else { continue };
            let e = grid.ext(t);
            // The nearest point of the tile's lattice (ties to the lower), inside the tile.
            let near =
                |p: usize, origin: usize, n: usize| ((p - origin + (s - 1) / 2) / s).min(n - 1);
            let mx: Vec<usize> = xs[cr.clone()]
                .iter()
                .map(|&x| near(x, e.x, r.width))
                .collect();
            for yi in yr {
                let my = near(ys[yi], e.y, r.height);
                for (xi, &m) in cr.clone().zip(&mx) {
                    let i = my * r.width + m;
                    if r.is_valid(i) {
                        data[yi * win.width + xi] = r.data[i];
                        mask[yi * win.width + xi] = true;
                    }
                }
            }
        }
        Ok(())
    };
    let skipped = decode_tile_rows(rd, plan, opts, &pool, &tile_opts, progress, &mut place)?;
    let gdal = rd
        .gdal_metadata()?
        .map(|x| crate::formats::without_statistics(&x).into_owned());
    let mut r = Raster {
        width: win.width,
        height: win.height,
        data,
        mask: Some(mask),
        nodata: header.nodata,
        sample_type: header.sample_type,
        mapping: header.mapping,
        georef: header
            .georef
            .as_ref()
            .map(|g| decode::overview_georef(g, k).window(win.x, win.y)),
        gdal_metadata: gdal,
    };
    r.normalize_mask();
    Ok((r, skipped))
}

/// Decode a window (or all) of a file into memory: its bands ([`decode_bands`]) joined. An
/// untiled file's one band is its one tile's decode, with `opts.scale` the method's own
/// surface where it has one; a tiled file's scale is its joined bands' samples interpolated
/// as every method's are (`codec::resample`: continuous across tile borders by
/// construction).
pub(crate) fn decode_all(
    rd: &mut RasterReader,
    opts: &DecodeOptions,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<(Raster, Vec<String>)> {
    // A tiled file's scale is applied here, to the joined bands (an overview has none).
    let resampled = rd.tiled() && opts.overview.is_none();
    let mut scale = None;
    if resampled {
        let header = rd.header();
        let (w, h) = (header.width as usize, header.height as usize);
        let limits = *rd.limits();
        scale = decode::check_scale(opts, w, h, &limits)?;
        let win = decode::window(opts, w, h)?;
        check_output(
            || format!("a decode of {} x {} samples", win.width, win.height),
            (win.width as u64).checked_mul(win.height as u64),
            &limits,
        )?;
    }
    let mut parts: Vec<Raster> = Vec::new();
    let o = DecodeOptions {
        scale: if resampled { None } else { opts.scale },
        ..opts.clone()
    };
    // With a scale, the bands are the first half of the work, the resampling the second.
    let share = if scale.is_some() { 0.5 } else { 1.0 };
    let skipped = decode_bands(
        rd,
        &o,
        &mut |b| {
            parts.push(b);
            Ok(())
        },
        &|f| progress(share * f),
    )?;
    let mut it = parts.into_iter();
    let mut r = it.next().ok_or_else(|| Error::invalid("empty window"))?;
    let rest: Vec<Raster> = it.collect();
    let rows: usize = r.height + rest.iter().map(|b| b.height).sum::<usize>();
    r.data.reserve(r.width * rows - r.data.len());
    for b in rest {
        r.height += b.height;
        let had = r.mask.is_some() || b.mask.is_some();
        if had {
            let n = r.data.len();
            let m = r.mask.get_or_insert_with(|| vec![true; n]);
            match &b.mask {
                Some(bm) => m.extend_from_slice(bm),
                None => m.extend(std::iter::repeat_n(true, b.data.len())),
            }
        }
        r.data.extend_from_slice(&b.data);
    }
    r.normalize_mask();
    if let Some((s, ow, oh)) = scale {
        r = super::resample::resample(&r, s, ow, oh, opts.threads, &|f| {
            progress(share + (1.0 - share) * f)
        })?;
    }
    Ok((r, skipped))
}
