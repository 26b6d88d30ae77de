//! Decoding: open the container, pick the section, check every size the options derive
//! against the limits, and run the section's method from the registry.

use super::options::{DecodeOptions, Scale, SectionChoice};
use super::resample::{nearest, resample, scaled_georef, scaled_size};
use crate::container::flat::Flat;
use crate::container::{ContainerReader, Header, Limits, SectionKind};
use crate::error::{Error, Result};
use crate::methods::{self, DecodeJob, Scaled};
use crate::model::{Georef, Raster, Window};
use std::io::{Read, Seek};

/// The registry's names for the container (which knows no method).
pub(crate) fn kind_names(k: SectionKind) -> Option<&'static str> {
    methods::by_section(k).map(|m| m.section_name())
}

/// The directory index `choice` names in an opened file.
pub(crate) fn section_index<R: Read + Seek>(
    rd: &ContainerReader<R>,
    choice: SectionChoice,
) -> Result<usize> {
    Ok(match choice {
        SectionChoice::Primary => rd.header().primary as usize,
        SectionChoice::Index(i) => i,
        SectionChoice::Method(m) => rd
            .find(m.0.section())
            .ok_or_else(|| Error::invalid(format!("the file has no {} section", m.name())))?,
    })
}

/// Check that `n` samples (a derived output size) are within the limits before anything
/// of that size is allocated.
pub(crate) fn check_output(
    what: impl FnOnce() -> String,
    n: Option<u64>,
    limits: &Limits,
) -> Result<()> {
    match n {
        Some(n) if n <= limits.max_samples => Ok(()),
        Some(n) => Err(Error::limit(format!(
            "{} = {n} samples, over the limit of {}",
            what(),
            limits.max_samples
        ))),
        None => Err(Error::limit(format!("{} overflows", what()))),
    }
}

/// The window a decode of a `w × h` raster asks for (all of it without one), checked to lie
/// inside the raster.
pub(crate) fn window(opts: &DecodeOptions, w: usize, h: usize) -> Result<Window> {
    let win = opts.window.unwrap_or(Window::full(w, h));
    if !inside(win, w, h) {
        return Err(Error::invalid(format!(
            "window {},{},{},{} is not inside the {w}x{h} raster",
            win.x, win.y, win.width, win.height
        )));
    }
    Ok(win)
}

/// Whether `win` holds a sample and lies inside a `w × h` raster.
pub(crate) fn inside(win: Window, w: usize, h: usize) -> bool {
    win.width > 0
        && win.height > 0
        && win.x.checked_add(win.width).is_some_and(|e| e <= w)
        && win.y.checked_add(win.height).is_some_and(|e| e <= h)
}

// ---------------------------------------------------------------- overviews
// (`DecodeOptions::overview`, `vtz decode --overview K`, GDAL's overview bands: every 2^K-th
// sample, from what the format already holds; a tiled file's: `tiles::decode_overview`.)

/// An overview request, checked: its level K, its size, and the window of it wanted.
pub(crate) struct Overview {
    pub k: u32,
    pub width: usize,
    pub height: usize,
    pub window: Window,
}

/// The overview a decode asks for, checked against the raster (at least one sample each
/// way; K ≤ 30) and the limits; its window (in the overview's samples) inside it. `None`
/// without one.
pub(crate) fn check_overview(
    opts: &DecodeOptions,
    w: usize,
    h: usize,
    limits: &Limits,
) -> Result<Option<Overview>> {
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
    if !inside(win, ow, oh) {
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
    Ok(Some(Overview {
        k,
        width: ow,
        height: oh,
        window: win,
    }))
}

/// The georeferencing of overview `k`: the same origin (the corner of pixel (0, 0), or its
/// centre for pixel-is-point, whose sample the overview keeps), pixels 2^k times larger.
pub(crate) fn overview_georef(g: &Georef, k: u32) -> Georef {
    let mut out = g.clone();
    let f = (1u64 << k) as f64;
    out.pixel_size = [g.pixel_size[0] * f, g.pixel_size[1] * f];
    out
}

/// The part `win` of an overview raster (`r` the whole overview).
pub(crate) fn crop_overview(mut r: Raster, win: Window) -> Raster {
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

/// For a tile's block (read whole), the bytes of it an overview K = 1, 2, … decode reads
/// (element K − 1): the primary section must be the block's last, and its method must code
/// coarse levels first ([`methods::Representation::overview_prefixes`]); otherwise empty.
pub(crate) fn overview_prefixes<R: Read + Seek>(rd: &mut ContainerReader<R>) -> Result<Vec<u64>> {
    let idx = rd.header().primary as usize;
    if idx + 1 != rd.entries().len() {
        return Ok(Vec::new());
    }
    let entry = rd.entries()[idx].clone();
    let Some(method) = methods::by_section(entry.kind) else {
        return Ok(Vec::new());
    };
    let mask = rd.read_mask()?;
    let prefixes = whole_job(rd, idx, mask.as_deref(), |job| {
        method.overview_prefixes(job)
    })?;
    Ok(prefixes
        .into_iter()
        .map(|e| entry.offset + e as u64)
        .collect())
}

/// Run `f` on the one-thread, whole-raster decode job of section `idx` (its payload read,
/// the flat regions read, `mask` the file's validity mask).
pub(crate) fn whole_job<R: Read + Seek, T>(
    rd: &mut ContainerReader<R>,
    idx: usize,
    mask: Option<&[bool]>,
    f: impl FnOnce(&DecodeJob) -> Result<T>,
) -> Result<T> {
    let header = rd.header().clone();
    let flat = rd.read_flat(mask)?;
    let method_mask = method_mask(mask, flat.as_ref(), header.samples() as usize);
    let payload = rd.read_section(idx)?;
    let job = DecodeJob {
        payload: &payload,
        header: &header,
        mask: method_mask.as_deref().or(mask),
        window: Window::full(header.width as usize, header.height as usize),
        sites: None,
        levels: None,
        threads: 1,
        flat: flat.as_ref(),
        base: None,
        progress: &|_| {},
    };
    f(&job)
}

/// Decode one container (an untiled file, or one tile's block) with options into a raster:
/// the window of it that `opts` asks for, on `opts.threads` threads.
pub(crate) fn decode_reader<R: Read + Seek>(
    rd: &mut ContainerReader<R>,
    opts: &DecodeOptions,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Raster> {
    let header = rd.header().clone();
    let mask = rd.read_mask()?;
    let flat = rd.read_flat(mask.as_deref())?;
    let method_mask = method_mask(
        mask.as_deref(),
        flat.as_ref(),
        rd.header().samples() as usize,
    );
    let mut gdal_metadata = rd.read_gdal_metadata()?;
    let idx = section_index(rd, opts.section)?;
    let entry = rd
        .entries()
        .get(idx)
        .ok_or_else(|| Error::invalid(format!("the file has no section {idx}")))?
        .clone();
    let (w, h) = (header.width as usize, header.height as usize);
    let overview = check_overview(opts, w, h, rd.limits())?;
    // An overview's window is in its own samples; the method decodes the whole raster.
    let win = if overview.is_some() {
        Window::full(w, h)
    } else {
        window(opts, w, h)?
    };
    if !entry.kind.may_be_primary() && methods::by_section(entry.kind).is_none() {
        let methods: Vec<String> = rd
            .entries()
            .iter()
            .enumerate()
            .filter(|(_, e)| methods::by_section(e.kind).is_some())
            .map(|(i, e)| format!("{i} ({})", e.name))
            .collect();
        return Err(Error::invalid(format!(
            "section {idx} is the {} section, not a surface; choose one of: {}",
            entry.name,
            methods.join(", ")
        )));
    }
    let Some(method) = methods::by_section(entry.kind) else {
        return Err(Error::unsupported(format!(
            "decoding a {} section is not implemented by this version",
            entry.name
        )));
    };
    if !method.progressive() && (opts.sites.is_some() || opts.levels.is_some()) {
        return Err(Error::invalid(format!(
            "--sites and --level need a sites section (this one is {})",
            method.name()
        )));
    }
    let scale = check_scale(opts, w, h, rd.limits())?;
    let payload = rd.read_section(idx)?;
    // A part, a resampling, a prefix or a lossy section of the raster has other statistics
    // than the source's whole.
    let off = method.id().bound_at;
    let lossy = payload
        .get(off..off + 8)
        .is_some_and(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) != 0.0);
    if lossy
        || scale.is_some()
        || opts.sites.is_some()
        || opts.levels.is_some()
        || overview.is_some()
        || (win.width, win.height) != (w, h)
    {
        gdal_metadata = gdal_metadata.map(|x| crate::formats::without_statistics(&x).into_owned());
    }
    let job = DecodeJob {
        payload: &payload,
        header: &header,
        mask: method_mask.as_deref().or(mask.as_deref()),
        window: win,
        sites: opts.sites,
        levels: opts.levels,
        threads: opts.threads,
        flat: flat.as_ref(),
        base: None,
        progress,
    };
    // Progress as each stage finishes: the method's decode (with its own reports where it
    // makes any), then, for a scale that the method's surface does not evaluate itself,
    // the resampling row by row, the second half. The caller reports 1.
    if let Some(req) = overview {
        let k = req.k;
        let mut data = method.decode_decimated(&job, k)?;
        progress(1.0);
        if let Some(f) = &flat {
            let (st, ow) = (1usize << k, req.width);
            for (j, o) in data.iter_mut().enumerate() {
                if let Some(v) = f.value_at((j / ow) * st * w + (j % ow) * st) {
                    *o = v;
                }
            }
        }
        let mut r = Raster {
            width: req.width,
            height: req.height,
            data,
            mask: mask.map(|m| methods::decimate(&m, w, h, k)),
            nodata: header.nodata,
            sample_type: header.sample_type,
            mapping: header.mapping,
            georef: header.georef.as_ref().map(|g| overview_georef(g, k)),
            gdal_metadata,
        };
        r.normalize_mask();
        return Ok(crop_overview(r, req.window));
    }
    if let Some((s, ow, oh)) = scale {
        if let Some(r) = method.decode_scaled(&job, s.num, s.den, (ow, oh))? {
            return Ok(scaled_raster(r, &header, flat.as_ref(), s, gdal_metadata));
        }
    }
    // The method's decode is most of the work: 95 % of it (half with a scale); the flat
    // regions and the mask, then the caller's end, the rest.
    let share = if scale.is_some() { 0.5 } else { 0.95 };
    let first = |f: f64| progress(share * f.clamp(0.0, 1.0));
    let job = DecodeJob {
        progress: &first,
        ..job
    };
    let mut data = method.decode(&job)?;
    progress(share);
    if let Some(f) = &flat {
        // Flat regions hold their exact value whatever the method made of them.
        f.overwrite(&mut data, w, (win.x, win.y, win.width, win.height));
    }
    let mut r = Raster {
        width: win.width,
        height: win.height,
        data,
        mask: mask.map(|m| methods::crop(&m, w, win)),
        nodata: header.nodata,
        sample_type: header.sample_type,
        mapping: header.mapping,
        georef: header.georef.as_ref().map(|g| g.window(win.x, win.y)),
        gdal_metadata,
    };
    if let Some((s, ow, oh)) = scale {
        // A method without a surface of its own: its decoded samples interpolated, the
        // flat regions then exact by the nearest-sample rule.
        let out = resample(&r, s, ow, oh, opts.threads, &|f| {
            progress(share + (1.0 - share) * f)
        })?;
        let (data, mask) = (out.data, out.mask.unwrap_or_else(|| vec![true; ow * oh]));
        return Ok(scaled_raster(
            (data, mask, ow, oh),
            &header,
            flat.as_ref(),
            s,
            out.gdal_metadata,
        ));
    }
    r.normalize_mask();
    Ok(r)
}

/// The scale a decode asks for, reduced, with its output size checked (at least one sample
/// each way, within the limits); `None` without one or for a scale of 1, which is the
/// plain decode.
pub(crate) fn check_scale(
    opts: &DecodeOptions,
    w: usize,
    h: usize,
    limits: &Limits,
) -> Result<Option<(Scale, usize, usize)>> {
    let Some(s) = opts.scale else {
        return Ok(None);
    };
    if opts.window.is_some() {
        return Err(Error::invalid("--scale and --window cannot be combined"));
    }
    let s = s.reduced();
    let (ow, oh) = scaled_size(w, h, s);
    check_output(
        || format!("a scale of {}/{} makes a {ow}x{oh} raster", s.num, s.den),
        ow.checked_mul(oh),
        limits,
    )?;
    if ow == 0 || oh == 0 {
        return Err(Error::invalid(format!(
            "a scale of {s} makes a {ow}x{oh} raster of this {w}x{h} one; the smallest scale for it is 1/{}",
            w.min(h)
        )));
    }
    Ok((s.num != s.den).then_some((s, ow as usize, oh as usize)))
}

/// The mask a method decodes with: the file's, with the flat regions' samples also
/// invalid (the method need not represent them); `None` without flat regions.
pub(crate) fn method_mask(
    mask: Option<&[bool]>,
    flat: Option<&Flat>,
    n: usize,
) -> Option<Vec<bool>> {
    let f = flat?;
    let mut m = mask.map_or_else(|| vec![true; n], <[bool]>::to_vec);
    for (s, l, _) in f.runs() {
        m[s..s + l].fill(false);
    }
    Some(m)
}

/// A decode at scale `s` as a raster: the flat regions' samples exact (each output sample
/// whose nearest source sample is flat takes its value, and is valid as that sample is),
/// the georeferencing scaled (same corner, pixel size / s).
fn scaled_raster(
    (mut data, mut mask, ow, oh): Scaled,
    header: &Header,
    flat: Option<&Flat>,
    s: Scale,
    gdal_metadata: Option<String>,
) -> Raster {
    let (w, h) = (header.width as usize, header.height as usize);
    if let Some(f) = flat {
        let xs: Vec<usize> = (0..ow).map(|x| nearest(x, w, s)).collect();
        for y in 0..oh {
            let row = nearest(y, h, s) * w;
            for (x, &sx) in xs.iter().enumerate() {
                if let Some(v) = f.value_at(row + sx) {
                    data[y * ow + x] = v;
                    mask[y * ow + x] = true;
                }
            }
        }
    }
    let mut r = Raster {
        width: ow,
        height: oh,
        data,
        mask: Some(mask),
        nodata: header.nodata,
        sample_type: header.sample_type,
        mapping: header.mapping,
        georef: header.georef.as_ref().map(|g| scaled_georef(g, s)),
        gdal_metadata,
    };
    r.normalize_mask();
    r
}

#[cfg(feature = "internals")]
/// Parse a whole file held in memory (every checksum verified), with the registry's names.
pub fn read_all(bytes: &[u8], limits: Limits) -> Result<crate::container::Container> {
    crate::container::read(bytes, limits, kind_names)
}
