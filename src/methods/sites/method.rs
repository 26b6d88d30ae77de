//! The sites representation as the registry sees it: options, encode, decode, stats.

use super::{SitesParams, SitesStats, decode_sites, render, render_scaled, stats};
use crate::threads::default_threads;
use crate::container::{Header, SectionKind};
use crate::error::{Error, Result};
use crate::methods::{
    DecodeJob, EncodeJob, Encoded, Identity, Method, MethodParams, Representation, Scaled, Site,
    StatValue, Stats,
};
use crate::quant::ErrorBound;

use super::select::Norm;

/// Settings only the Sibson method reads.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct SibsonOptions {
    /// Stop when the RMSE is at most this.
    pub rmse: Option<ErrorBound>,
    /// Stop at this many sites.
    pub sites: Option<usize>,
    /// Refinement norm.
    pub norm: Norm,
    /// Height step as a multiple of the error target (default 1; tuning).
    pub step_factor: Option<f64>,
}
/// Greedy Voronoi/Sibson sites in progressive levels.
pub(crate) struct Sibson;

impl Representation for Sibson {
    fn id(&self) -> &'static Identity {
        &Identity {
            name: "sibson",
            aliases: &[],
            section: SectionKind(3),
            section_name: "sites",
            bound_at: 20,
        }
    }
    fn own_options(&self, p: &MethodParams) -> Option<&'static str> {
        (p.sibson.sites.is_some() || p.sibson.rmse.is_some())
            .then_some("--sites and --rmse need the sibson method")
    }
    fn stops_by_itself(&self, p: &MethodParams) -> bool {
        self.own_options(p).is_some()
    }
    fn keep_own(&self, from: &MethodParams, to: &mut MethodParams) {
        to.sibson = from.sibson.clone();
    }
    fn relative_cost(&self) -> f64 {
        // Kauai 1201², one thread, 1 m / 1 %: 2.48 / 1.05 s (whole
        // processes) against the residual layer's lane coding (the default effort) 0.18 / 0.15 s.
        10.0
    }
    fn encode(&self, job: &EncodeJob, progress: &mut dyn FnMut(f64)) -> Result<Encoded> {
        let o = &job.params.sibson;
        if job.max_error == Some(0.0) && self.own_options(job.params).is_none() {
            // A bound was given but resolves to 0 (a percent of a constant or empty raster's
            // range, or 0 itself): sites approximate, they do not store every sample.
            return Err(Error::unmet(
                "the sibson method needs a bound above 0, and the bound given is 0 here (a percent of the range of a raster whose valid samples are all equal, or none); use --lossless",
            ));
        }
        if job.lossless() && self.own_options(job.params).is_none() {
            return Err(Error::invalid(
                "the sibson method needs --max-error, --rmse or --sites",
            ));
        }
        if o.sites.is_some() && (job.max_error.is_some() || o.rmse.is_some()) {
            // A site count stops the refinement wherever the error is; a bound keeps going
            // until it holds. Together one would silently override the other.
            return Err(Error::invalid(
                "--sites stops at N sites whatever the error: it excludes --max-error and --rmse",
            ));
        }
        let sp = SitesParams {
            max_error: job.max_error,
            rmse: o.rmse.map(|b| b.absolute(job.header.range)),
            max_sites: o.sites,
            norm: o.norm,
            step_factor: o.step_factor,
            size_cap: job.size_cap,
        };
        let (payload, st) = super::encode(job.raster, job.header, &sp, progress)?;
        Ok(Encoded {
            payload,
            bound: st.max_error,
            stats: Some(to_stats(&st, job.header)),
        })
    }
    fn decode_full(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        let full = DecodeJob {
            window: crate::model::Window::full(
                job.header.width as usize,
                job.header.height as usize,
            ),
            ..*job
        };
        self.decode(&full)
    }
    fn decode(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        let d = decode_sites(job.payload, job.header, job.mask, job.levels, job.sites)?;
        let w = job.window;
        render(
            &d,
            job.header,
            job.mask,
            (w.x, w.y, w.width, w.height),
            if job.threads == 0 {
                default_threads()
            } else {
                job.threads
            },
            job.progress,
        )
    }
    fn progressive(&self) -> bool {
        true
    }
    fn decode_scaled(
        &self,
        job: &DecodeJob,
        num: u32,
        den: u32,
        size: (usize, usize),
    ) -> Result<Option<Scaled>> {
        let d = decode_sites(job.payload, job.header, job.mask, job.levels, job.sites)?;
        let threads = if job.threads == 0 {
            default_threads()
        } else {
            job.threads
        };
        render_scaled(&d, job.header, job.mask, num, den, size, threads).map(Some)
    }
    fn describe(&self, job: &DecodeJob) -> Result<Option<Stats>> {
        Ok(Some(to_stats(
            &stats(job.payload, job.header, job.mask)?,
            job.header,
        )))
    }
    fn has_stats(&self) -> bool {
        true
    }
    fn stores_sites(&self) -> bool {
        true
    }
    fn sites(&self, job: &DecodeJob) -> Result<Option<Vec<Site>>> {
        let d = decode_sites(job.payload, job.header, job.mask, None, None)?;
        let w = job.header.width as usize;
        let mut out = Vec::with_capacity(d.sites.len());
        for (level, &n) in d.levels.iter().enumerate() {
            for &(idx, height) in &d.sites[out.len()..out.len() + n] {
                out.push(Site {
                    rank: out.len(),
                    level,
                    col: idx as usize % w,
                    row: idx as usize / w,
                    height,
                });
            }
        }
        Ok(Some(out))
    }
}

/// The statistics as the registry reports them.
fn to_stats(s: &SitesStats, header: &Header) -> Stats {
    let range = header.range.map_or(0.0, |(lo, hi)| hi - lo);
    let pct = |v: f64| if range > 0.0 { 100.0 * v / range } else { 0.0 };
    let n = s.sites.max(1) as f64;
    Stats {
        method: Method::SIBSON,
        values: vec![
            ("sites", StatValue::Count(s.sites as u64)),
            ("hull", StatValue::Count(s.hull as u64)),
            (
                "levels",
                StatValue::Counts(s.levels.iter().map(|&l| l as u64).collect()),
            ),
            (
                "position_bits_per_site",
                StatValue::Number(s.position_bits / n),
            ),
            ("height_bits_per_site", StatValue::Number(s.height_bits / n)),
            ("max_error", StatValue::Number(s.max_error)),
            ("max_error_pct", StatValue::Number(pct(s.max_error))),
            ("rmse", StatValue::Number(s.rmse)),
            ("rmse_pct", StatValue::Number(pct(s.rmse))),
        ],
        lines: vec![
            format!(
                "sites         {} in {} levels {:?}",
                s.sites,
                s.levels.len(),
                s.levels
            ),
            format!(
                "bits/site     {:.2} positions + {:.2} heights = {:.2}",
                s.position_bits / n,
                s.height_bits / n,
                (s.position_bits + s.height_bits) / n
            ),
            format!(
                "achieved      max error {} ({:.4} % of range), rmse {:.4} ({:.4} %)",
                s.max_error,
                pct(s.max_error),
                s.rmse,
                pct(s.rmse)
            ),
        ],
    }
}
