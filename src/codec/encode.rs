//! Encoding: pick the methods the request names (or `best`), run each through the
//! registry, and assemble the container (mask, sections, metadata).

use super::options::EncodeOptions;
use crate::container::{self, Header, SF_REQUIRED, Section, SectionKind};
use crate::error::{Error, Result};
use crate::methods::{EncodeJob, Encoded, Method, REGISTRY, Representation, Stats};
use crate::model::Raster;

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
}

/// One encoded representation, before it goes into the container.
struct Candidate {
    method: &'static dyn Representation,
    enc: Encoded,
}

/// Encode `raster` with one concrete method.
fn encode_method(
    m: &'static dyn Representation,
    raster: &Raster,
    header: &Header,
    opts: &EncodeOptions,
    e: Option<f64>,
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
        base: None,
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
    raster.validate()?;
    let mut header = Header::of(raster)?;
    let e = opts.max_error.map(|b| b.absolute(header.range));
    let mut cands: Vec<Candidate> = Vec::new();
    if opts.methods.is_empty() {
        // `best`: every method that can meet the request; the smallest wins. A method that
        // cannot (e.g. FIS at a bound no subgrid reaches) simply drops out. Settings that
        // only one method reads (a site count, an RMSE) name that method alone.
        let owners: Vec<&'static dyn Representation> = REGISTRY
            .iter()
            .copied()
            .filter(|m| m.own_options(&opts.params).is_some())
            .collect();
        let lossless = e.is_none_or(|e| e == 0.0);
        let tries: Vec<&'static dyn Representation> = if !owners.is_empty() {
            owners
        } else if lossless {
            REGISTRY
                .iter()
                .copied()
                .filter(|m| m.lossless_default())
                .collect()
        } else {
            REGISTRY.to_vec()
        };
        let mut last_err = None;
        let n = tries.len();
        for (i, m) in tries.into_iter().enumerate() {
            match encode_method(m, raster, &header, opts, e, &mut slot(progress, i, n)) {
                Ok(c) => cands.push(c),
                Err(err) => last_err = Some(err),
            }
        }
        if cands.is_empty() {
            return Err(last_err.unwrap_or_else(|| {
                Error::unsupported("no method of this build can meet the request")
            }));
        }
        let i = (0..cands.len())
            .min_by_key(|&i| cands[i].enc.payload.len())
            .expect("non-empty");
        cands = vec![cands.swap_remove(i)];
    } else {
        let n = opts.methods.len();
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
            cands.push(encode_method(m.0, raster, &header, &o, e, &mut p)?);
        }
    }
    let primary = (0..cands.len())
        .min_by_key(|&i| cands[i].enc.payload.len())
        .expect("non-empty");
    let mut sections = Vec::new();
    if let Some(m) = &raster.mask {
        if m.iter().any(|&b| !b) {
            sections.push(Section {
                kind: SectionKind::MASK,
                flags: SF_REQUIRED,
                payload: container::mask::encode(m),
            });
        }
    }
    header.primary = (sections.len() + primary) as u16;
    let report = EncodeReport {
        max_error: cands[primary].enc.bound,
        method: Method(cands[primary].method),
        stats: cands[primary].enc.stats.clone(),
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
    if let Some(xml) = &raster.gdal_metadata {
        // Optional (flags clear): samples decode without it, and older decoders skip it.
        sections.push(Section {
            kind: SectionKind::GDAL_METADATA,
            flags: 0,
            payload: xml.as_bytes().to_vec(),
        });
    }
    Ok((container::write(&header, &sections), report))
}

/// The progress of the `i`-th of `n` encodes as its slice of the whole, so that several
/// methods in a row never move the caller's bar backwards.
fn slot(progress: &mut dyn FnMut(f64), i: usize, n: usize) -> impl FnMut(f64) + '_ {
    move |f| progress((i as f64 + f.clamp(0.0, 1.0)) / n.max(1) as f64)
}
