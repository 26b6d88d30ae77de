//! Decoding at another resolution (`--scale`), GDAL's way (`gdal_translate -outsize`): an
//! output of ⌊w·s⌋ × ⌊h·s⌋ pixels over the source's extent from the same corner, pixel is
//! area: output pixel i's centre sits at source sample coordinate (i + ½)/s − ½.
//!
//! A sites section evaluates its Sibson surface there (`methods::sites::render_scaled`);
//! every other section, and a tiled file, interpolates its decoded samples here: Keys'
//! bicubic (a = −½, GDAL's `cubic`) over the 4 × 4 samples around the position (indices
//! clamped to the raster, so the edges are extended), the result clamped to the range of
//! the 2 × 2 samples around it (no overshoot: a constant neighbourhood, a flat region's
//! inside, comes out exact), then rounded to the sample type ([`crate::quant::finish`]).
//! Validity follows the nearest source sample (round half up); a valid output whose 4 × 4
//! stencil touches an invalid sample uses bilinear over the 2 × 2 when those are valid, else
//! the nearest sample's value. Each output sample is computed alone in a fixed order, so
//! the result is the same for any thread count.

use super::options::Scale;
use crate::error::Result;
use crate::model::{Georef, Raster, RasterType};

/// The output size of a `w × h` raster scaled by `s`: ⌊w·s⌋ × ⌊h·s⌋ (GDAL truncates
/// `-outsize N%` the same way), saturating.
pub(crate) fn scaled_size(w: usize, h: usize, s: Scale) -> (u64, u64) {
    let s = s.reduced();
    let f = |n: usize| {
        let v = n as u128 * s.num as u128 / s.den as u128;
        u64::try_from(v).unwrap_or(u64::MAX)
    };
    (f(w), f(h))
}

/// Where output index `i` samples a source axis of `n` samples, in units of 1/(2·num) of a
/// source sample: (2i + 1)·den − num.
fn position(i: usize, s: Scale) -> i128 {
    (2 * i as i128 + 1) * s.den as i128 - s.num as i128
}

/// The source sample nearest output index `i` (round half up, within the axis).
pub(crate) fn nearest(i: usize, n: usize, s: Scale) -> usize {
    let p = (2 * i as u128 + 1) * s.den as u128 / (2 * s.num as u128);
    (p.min(n as u128 - 1)) as usize
}

/// One output index's view of a source axis.
#[derive(Clone, Copy)]
struct Axis {
    /// The 4 stencil indices (clamped) and their bicubic weights.
    idx: [usize; 4],
    wt: [f64; 4],
    /// The two samples around the position (clamped) and the fraction between them.
    lin: [usize; 2],
    t: f64,
    near: usize,
}

fn axis(i: usize, n: usize, s: Scale) -> Axis {
    let q = 2 * s.num as i128;
    let p = position(i, s);
    let x0 = p.div_euclid(q);
    let t = p.rem_euclid(q) as f64 / q as f64;
    let at = |k: i128| (x0 + k).clamp(0, n as i128 - 1) as usize;
    // Keys' cubic convolution kernel with a = −1/2 at distances 1 + t, t, 1 − t, 2 − t.
    let wt = [
        ((-0.5 * t + 1.0) * t - 0.5) * t,
        (1.5 * t - 2.5) * t * t + 1.0,
        ((-1.5 * t + 2.0) * t + 0.5) * t,
        (0.5 * t - 0.5) * t * t,
    ];
    Axis {
        idx: [at(-1), at(0), at(1), at(2)],
        wt,
        lin: [at(0), at(1)],
        t,
        near: nearest(i, n, s),
    }
}

/// The decoded raster `r` resampled to `ow × oh` by `s` (see the module's note); the
/// georeferencing scaled with it ([`scaled_georef`]), statistics in the GDAL metadata
/// dropped.
pub(crate) fn resample(
    r: &Raster,
    s: Scale,
    ow: usize,
    oh: usize,
    threads: usize,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Raster> {
    let s = s.reduced();
    let xs: Vec<Axis> = (0..ow).map(|i| axis(i, r.width, s)).collect();
    let ys: Vec<Axis> = (0..oh).map(|j| axis(j, r.height, s)).collect();
    let fill = r.nodata.unwrap_or(f64::NAN);
    let (st, mapping, w) = (r.sample_type, r.mapping, r.width);
    let valid = |i: usize| r.is_valid(i);
    let row = |ay: &Axis, data: &mut [f64], mask: &mut [bool]| {
        for ((ax, d), m) in xs.iter().zip(data.iter_mut()).zip(mask.iter_mut()) {
            if !valid(ay.near * w + ax.near) {
                *d = fill;
                *m = false;
                continue;
            }
            let at = |y: usize, x: usize| r.data[y * w + x];
            let v = if ay
                .idx
                .iter()
                .all(|&y| ax.idx.iter().all(|&x| valid(y * w + x)))
            {
                let mut acc = 0.0;
                for (&y, &wy) in ay.idx.iter().zip(&ay.wt) {
                    let mut racc = 0.0;
                    for (&x, &wx) in ax.idx.iter().zip(&ax.wt) {
                        racc += wx * at(y, x);
                    }
                    acc += wy * racc;
                }
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for &y in &ay.lin {
                    for &x in &ax.lin {
                        lo = lo.min(at(y, x));
                        hi = hi.max(at(y, x));
                    }
                }
                acc.clamp(lo, hi)
            } else if ay
                .lin
                .iter()
                .all(|&y| ax.lin.iter().all(|&x| valid(y * w + x)))
            {
                let [y0, y1] = ay.lin;
                let [x0, x1] = ax.lin;
                let top = at(y0, x0) + (at(y0, x1) - at(y0, x0)) * ax.t;
                let bottom = at(y1, x0) + (at(y1, x1) - at(y1, x0)) * ax.t;
                top + (bottom - top) * ay.t
            } else {
                at(ay.near, ax.near)
            };
            *d = crate::quant::finish(v, st, mapping);
            *m = true;
        }
    };
    // `progress` gets the fraction of output rows done, about every 1/256 of them, under a
    // lock so that the fractions never decrease whichever thread reports.
    let rows_done = std::sync::Mutex::new(0usize);
    let every = (oh / 256).max(1);
    let row = |ay: &Axis, data: &mut [f64], mask: &mut [bool]| {
        row(ay, data, mask);
        let mut n = rows_done
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        *n += 1;
        if *n % every == 0 || *n == oh {
            progress(*n as f64 / oh as f64);
        }
    };
    let mut data = vec![0.0; ow * oh];
    let mut mask = vec![true; ow * oh];
    let threads = if threads == 0 {
        crate::threads::default_threads()
    } else {
        threads
    };
    if threads <= 1 || ow * oh < 1 << 16 {
        for ((ay, d), m) in ys.iter().zip(data.chunks_mut(ow)).zip(mask.chunks_mut(ow)) {
            row(ay, d, m);
        }
    } else {
        use rayon::prelude::*;
        let pool = crate::threads::thread_pool(threads)?;
        pool.install(|| {
            ys.par_iter()
                .zip(data.par_chunks_mut(ow))
                .zip(mask.par_chunks_mut(ow))
                .for_each(|((ay, d), m)| row(ay, d, m));
        });
    }
    let mut out = Raster {
        width: ow,
        height: oh,
        data,
        mask: Some(mask),
        georef: r.georef.as_ref().map(|g| scaled_georef(g, s)),
        gdal_metadata: r
            .gdal_metadata
            .as_ref()
            .map(|x| crate::formats::without_statistics(x).into_owned()),
        ..r.clone_meta()
    };
    out.normalize_mask();
    Ok(out)
}

/// The georeferencing of a raster scaled by `s`: the same upper-left corner, the pixel size
/// divided by s. (A pixel-is-point raster keeps its type; its origin, the first sample's
/// centre, moves to the new first sample's centre, half a new pixel from the same corner.)
pub(crate) fn scaled_georef(g: &Georef, s: Scale) -> Georef {
    let f = |v: f64| v * s.den as f64 / s.num as f64;
    let mut out = g.clone();
    out.pixel_size = [f(g.pixel_size[0]), f(g.pixel_size[1])];
    if g.raster_type == RasterType::Point {
        let gt = g.geotransform();
        out.origin[0] = gt[0] + 0.5 * out.pixel_size[0];
        out.origin[1] = gt[3] - 0.5 * out.pixel_size[1];
    }
    out
}
