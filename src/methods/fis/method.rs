//! The FIS representation as the registry sees it.

use super::{FisParams, decode, describe, encode_with};
use crate::container::SectionKind;
use crate::error::{Error, Result};
use crate::methods::{
    DecodeJob, EncodeJob, Encoded, Identity, Method, MethodParams, Representation, StatValue, Stats,
};

/// Settings only the FIS method reads.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct FisOptions {
    /// Subgrid spacing k (default: the cheapest k that meets the bound).
    pub k: Option<usize>,
    /// One fixed vertical scaling factor (the paper's 0.02) instead of fitted ones.
    pub s: Option<f64>,
}
/// A fractal interpolation surface on every k-th sample.
pub(crate) struct Fis;

impl Representation for Fis {
    fn id(&self) -> &'static Identity {
        &Identity {
            name: "fis",
            aliases: &["fractal"],
            section: SectionKind(4),
            section_name: "fis",
            bound_at: 32,
        }
    }
    fn own_options(&self, p: &MethodParams) -> Option<&'static str> {
        (p.fis.k.is_some() || p.fis.s.is_some()).then_some("the FIS options need the fis method")
    }
    fn keep_own(&self, from: &MethodParams, to: &mut MethodParams) {
        to.fis = from.fis.clone();
    }
    fn relative_cost(&self) -> f64 {
        // Kauai 1201², one thread, 1 m / 1 %: 0.73 / 0.60 s (failing) (whole
        // processes) against the residual layer's lane coding (the default effort) 0.18 / 0.15 s.
        4.0
    }
    fn encode(&self, job: &EncodeJob, progress: &mut dyn FnMut(f64)) -> Result<Encoded> {
        let o = &job.params.fis;
        if job.max_error == Some(0.0) && o.k.is_none() {
            return Err(Error::unmet(
                "the fis method needs a bound above 0, and the bound given is 0 here (a percent of the range of a raster whose valid samples are all equal, or none); use --lossless",
            ));
        }
        if job.lossless() && o.k.is_none() {
            return Err(Error::invalid(
                "the fis method needs --max-error or --fis-k",
            ));
        }
        let (payload, st) = encode_with(
            job.raster,
            job.header,
            &FisParams {
                max_error: job.max_error.filter(|&e| e > 0.0),
                k: o.k,
                fixed_s: o.s,
                size_cap: job.size_cap,
            },
            progress,
        )?;
        Ok((payload, st.max_error).into())
    }
    fn decode_full(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        decode(job.payload, job.header, job.mask)
    }
    fn has_stats(&self) -> bool {
        true
    }
    fn describe(&self, job: &DecodeJob) -> Result<Option<Stats>> {
        let (k, points, s0, iterations) = describe(job.payload, job.header)?;
        Ok(Some(Stats {
            method: Method::FIS,
            values: vec![
                ("k", StatValue::Count(k as u64)),
                ("points", StatValue::Count(points as u64)),
                ("s0", StatValue::Number(s0)),
                ("iterations", StatValue::Count(iterations as u64)),
            ],
            lines: vec![format!(
                "fis           spacing k = {k}: {points} interpolation points, s0 {s0}, {iterations} iterations"
            )],
        }))
    }
}
