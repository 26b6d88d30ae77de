//! The Haar representation as the registry sees it.

use super::{HaarParams, decode, describe, encode_progress, encode_step};
use crate::container::SectionKind;
use crate::error::Result;
use crate::methods::{
    DecodeJob, EncodeJob, Encoded, Identity, Knob, Method, MethodParams, Representation, StatValue, Stats,
};

/// Settings only the Haar method reads.
#[derive(Clone, Debug, Default, PartialEq)]
#[non_exhaustive]
pub struct HaarOptions {
    /// A fixed coefficient quantizer step instead of a bound (what size targets bisect, as
    /// the RMSE-optimal rate control for a wavelet).
    pub step: Option<f64>,
}
/// The 2-D integer Haar pyramid, dead-zone quantized (the Voronoi paper's baseline).
pub(crate) struct Haar;

impl Representation for Haar {
    fn id(&self) -> &'static Identity {
        &Identity {
            name: "haar",
            aliases: &["wavelet"],
            section: SectionKind(5),
            section_name: "haar",
            bound_at: 20,
        }
    }
    fn own_options(&self, p: &MethodParams) -> Option<&'static str> {
        p.haar
            .step
            .is_some()
            .then_some("a Haar step needs the haar method")
    }
    fn keep_own(&self, from: &MethodParams, to: &mut MethodParams) {
        to.haar = from.haar.clone();
    }
    fn rate_knob(&self) -> Option<Knob> {
        // The wavelet's own rate control: the smallest coefficient step (data units) whose
        // file fits.
        Some(Knob {
            what: "the coarsest Haar step",
            span: (1e-6, 4.0),
            steps: 24,
            set: |p, q| p.haar.step = Some(q),
        })
    }
    fn relative_cost(&self) -> f64 {
        // Kauai 1201², one thread, 1 m / 1 %: 1.39 / 1.90 s (whole
        // processes) against the residual layer's lane coding (the default effort) 0.18 / 0.15 s.
        10.0
    }
    fn encode(&self, job: &EncodeJob, progress: &mut dyn FnMut(f64)) -> Result<Encoded> {
        let (payload, bound) = match job.params.haar.step {
            Some(step) => encode_step(job.raster, step)?,
            None => encode_progress(
                job.raster,
                &HaarParams {
                    max_error: job.max_error.unwrap_or(0.0),
                },
                progress,
            )?,
        };
        Ok((payload, bound).into())
    }
    fn decode_full(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        decode(job.payload, job.header, job.mask)
    }
    fn has_stats(&self) -> bool {
        true
    }
    fn describe(&self, job: &DecodeJob) -> Result<Option<Stats>> {
        let (levels, step) = describe(job.payload)?;
        Ok(Some(Stats {
            method: Method::HAAR,
            values: vec![
                ("levels", StatValue::Count(levels as u64)),
                ("lattice_step", StatValue::Number(step)),
            ],
            lines: vec![format!(
                "haar          {levels} levels, value lattice step {step}"
            )],
        }))
    }
}
