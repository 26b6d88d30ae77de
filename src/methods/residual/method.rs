//! The residual layer as the registry sees it.

use super::{decode, describe, encode};
use crate::container::SectionKind;
use crate::error::Result;
use crate::model::Window;
use crate::methods::{
    DecodeJob, EncodeJob, Encoded, Identity, Method, Representation, StatValue, Stats,
};

/// Every sample predicted from decoded ones, quantized closed loop, context coded.
pub(crate) struct Residual;

impl Representation for Residual {
    fn uses_flat_values(&self) -> bool {
        true
    }
    fn id(&self) -> &'static Identity {
        &Identity {
            name: "residual",
            aliases: &["res"],
            section: SectionKind(6),
            section_name: "residual",
            bound_at: 32,
        }
    }
    fn lossless_default(&self) -> bool {
        true
    }
    fn encode(&self, job: &EncodeJob, progress: &mut dyn FnMut(f64)) -> Result<Encoded> {
        let (payload, bound) = encode(
            job.raster,
            job.header,
            job.max_error.unwrap_or(0.0),
            job.flat,
            job.effort,
            job.levels_first,
            progress,
        )?;
        Ok((payload, bound).into())
    }
    fn decode_full(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        let all = Window::full(job.header.width as usize, job.header.height as usize);
        decode(job.payload, job.header, job.mask, job.flat, all, 0)
    }
    /// The interpolation codings decode only the levels down to step 2^j.
    fn decode_decimated(&self, job: &DecodeJob, j: u32) -> Result<Vec<f64>> {
        let all = Window::full(job.header.width as usize, job.header.height as usize);
        decode(job.payload, job.header, job.mask, job.flat, all, j)
    }
    /// Where each level ends: the interpolation codings code coarse levels first.
    fn overview_prefixes(&self, job: &DecodeJob) -> Result<Vec<usize>> {
        super::overview_prefixes(job.payload, job.header, job.mask, job.flat)
    }
    /// The window alone: the fast coding decodes only the bands its rows need.
    fn decode(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        decode(job.payload, job.header, job.mask, job.flat, job.window, 0)
    }
    fn has_stats(&self) -> bool {
        true
    }
    fn describe(&self, job: &DecodeJob) -> Result<Option<Stats>> {
        let (predictor, levels, step, bin, bound) = describe(job.payload)?;
        let how = if levels > 0 {
            format!("{predictor} ({levels} levels, anchors every {})", 1u64 << levels)
        } else {
            predictor.to_string()
        };
        Ok(Some(Stats {
            method: Method::RESIDUAL,
            values: vec![
                ("predictor", StatValue::Count(u64::from(levels == 0))),
                ("levels", StatValue::Count(levels as u64)),
                ("lattice_step", StatValue::Number(step)),
                ("bin_width", StatValue::Count(bin)),
                ("max_error", StatValue::Number(bound)),
            ],
            lines: vec![format!(
                "residual      {how}, lattice step {}, bins of {bin} steps, max error {}",
                crate::metrics::num(step),
                crate::metrics::num(bound)
            )],
        }))
    }
}
