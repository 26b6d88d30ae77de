//! Overviews (`DecodeOptions::overview`, `vtz decode --overview K`, GDAL's overview
//! bands): the decoded samples at every 2^K-th row and column, from what the format
//! already holds. The residual layer's interpolation codings reach those samples after
//! their coarse levels and stop there (`Representation::decode_decimated`); a tiled file's
//! tiles each decode their own coarse levels, and each overview sample comes from the tile
//! whose core holds it.

use std::io::{Read, Seek};
use std::sync::atomic::{AtomicUsize, Ordering};

use super::decode::{self, check_output};
use super::options::DecodeOptions;
use super::tiles;
use crate::container::tiled::{TiledReader, tile_name};
use crate::container::{Header, Limits};
use crate::error::{Error, Result};
use crate::methods;
use crate::model::{Georef, Raster, Window};

/// An overview request, checked: its level K, its size, and the window of it wanted.
pub(crate) struct Request {
    pub k: u32,
    pub width: usize,
    pub height: usize,
    pub window: Window,
}

/// The overview a decode asks for, checked against the raster (at least one sample each
/// way; K ≤ 30) and the limits; its window (in the overview's samples) inside it. `None`
/// without one.
pub(crate) fn check(
    opts: &DecodeOptions,
    w: usize,
    h: usize,
    limits: &Limits,
) -> Result<Option<Request>> {
    let Some(k) = opts.overview else {
        return Ok(None);
    };
    if !(1..=30).contains(&k) {
        return Err(Error::invalid(format!(
            "overview level {k} is not in 1..=30 (level K has every 2^K-th sample)"
        )));
    }
    if opts.scale.is_some() {
        return Err(Error::invalid("--overview and --scale cannot be combined"));
    }
    let s = 1usize << k;
    let (ow, oh) = (w.div_ceil(s), h.div_ceil(s));
    let win = match opts.window {
        Some(win) => win,
        None => Window::full(ow, oh),
    };
    if win.width == 0
        || win.height == 0
        || win.x.checked_add(win.width).is_none_or(|e| e > ow)
        || win.y.checked_add(win.height).is_none_or(|e| e > oh)
    {
        return Err(Error::invalid(format!(
            "window {},{},{},{} is not inside overview {k} ({ow}x{oh} of the {w}x{h} raster)",
            win.x, win.y, win.width, win.height
        )));
    }
    check_output(
        || {
            format!(
                "overview {k}'s window of {} x {} samples",
                win.width, win.height
            )
        },
        (win.width as u64).checked_mul(win.height as u64),
        limits,
    )?;
    Ok(Some(Request {
        k,
        width: ow,
        height: oh,
        window: win,
    }))
}

/// The georeferencing of overview `k`: the same origin (the corner of pixel (0, 0), or its
/// centre for pixel-is-point, whose sample the overview keeps), pixels 2^k times larger.
pub(crate) fn georef(g: &Georef, k: u32) -> Georef {
    let mut out = g.clone();
    let f = (1u64 << k) as f64;
    out.pixel_size = [g.pixel_size[0] * f, g.pixel_size[1] * f];
    out
}

/// The part `win` of an overview raster (`r` the whole overview).
pub(crate) fn crop(mut r: Raster, win: Window) -> Raster {
    if (win.x, win.y, win.width, win.height) == (0, 0, r.width, r.height) {
        return r;
    }
    let w = r.width;
    r.data = methods::crop(&r.data, w, win);
    r.mask = r.mask.map(|m| methods::crop(&m, w, win));
    r.georef = r.georef.map(|g| g.window(win.x, win.y));
    r.width = win.width;
    r.height = win.height;
    r.normalize_mask();
    r
}

/// Overview `req.k` of a tiled file (the window `req.window` of it): each tile whose core
/// holds an overview sample decodes at its own 2^k lattice (a row of tiles at a time, on
/// every thread), and the sample takes the tile's value at the lattice point nearest it
/// (ties to the lower; within the tile). Gives back the tiles skipped as corrupt.
pub(crate) fn decode_tiled<R: Read + Seek>(
    rd: &mut TiledReader<R>,
    opts: &DecodeOptions,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<(Raster, Vec<String>)> {
    tiles::check_tiled_options(opts)?;
    let header: Header = rd.header().clone();
    let grid = rd.grid();
    let (w, h) = (header.width as usize, header.height as usize);
    let req =
        check(opts, w, h, rd.limits())?.ok_or_else(|| Error::invalid("no overview asked for"))?;
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
    let total = (tcols.len() * trows.len()).max(1);
    let fill = header.nodata.unwrap_or(f64::NAN);
    let n = win.width * win.height;
    let mut data = vec![fill; n];
    let mut mask = vec![false; n];
    let mut skipped = Vec::new();
    let pool = tiles::pool(opts.threads)?;
    let done = AtomicUsize::new(0);
    for (tr, rows) in &trows {
        let mut blocks = Vec::with_capacity(tcols.len());
        for (tc, cols_here) in &tcols {
            let t = tr * cols + tc;
            blocks.push((t, cols_here.clone(), rd.tile_block(t)));
        }
        let opener = rd.opener();
        let decoded: Vec<(usize, std::ops::Range<usize>, Result<Raster>)> = pool.install(|| {
            use rayon::prelude::*;
            blocks
                .into_par_iter()
                .map(|(t, cr, block)| {
                    let r = block.and_then(|b| {
                        let mut trd = opener.open(t, b)?;
                        let o = DecodeOptions {
                            window: None,
                            threads: 1,
                            ..opts.clone()
                        };
                        methods::with_threads(1, || decode::decode_reader(&mut trd, &o, &|_| {}))
                            .map_err(|e| e.context(tile_name(&grid, t)))
                    });
                    let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                    progress(d as f64 / total as f64);
                    (t, cr, r)
                })
                .collect()
        });
        for (t, cr, r) in decoded {
            let r = match r {
                Ok(r) => r,
                Err(e) if opts.skip_corrupt && matches!(e, Error::Corrupt { .. }) => {
                    skipped.push(e.to_string());
                    continue;
                }
                Err(e) => return Err(e),
            };
            let e = grid.ext(t);
            // The nearest point of the tile's lattice (ties to the lower), inside the tile.
            let near =
                |p: usize, origin: usize, n: usize| ((p - origin + (s - 1) / 2) / s).min(n - 1);
            let mx: Vec<usize> = xs[cr.clone()]
                .iter()
                .map(|&x| near(x, e.x, r.width))
                .collect();
            for yi in rows.clone() {
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
    }
    let gdal = rd
        .global_section(crate::container::SectionKind::GDAL_METADATA)?
        .map(|b| {
            String::from_utf8(b).map_err(|_| Error::corrupt("gdal-metadata section is not UTF-8"))
        })
        .transpose()?
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
            .map(|g| georef(g, k).window(win.x, win.y)),
        gdal_metadata: gdal,
    };
    r.normalize_mask();
    Ok((r, skipped))
}
