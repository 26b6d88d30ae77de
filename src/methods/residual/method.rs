//! The residual layer as the registry sees it.

use super::{decode, encode};
use crate::container::SectionKind;
use crate::error::Result;
use crate::methods::{DecodeJob, EncodeJob, Encoded, Identity, Representation};

/// Every sample predicted from decoded ones, quantized closed loop, context coded.
pub(crate) struct Residual;

impl Representation for Residual {
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
    fn encode(&self, job: &EncodeJob, _progress: &mut dyn FnMut(f64)) -> Result<Encoded> {
        let (payload, bound) = encode(
            job.raster,
            job.header,
            job.max_error.unwrap_or(0.0),
            job.flat,
            job.effort,
        )?;
        Ok((payload, bound).into())
    }
    fn decode_full(&self, job: &DecodeJob) -> Result<Vec<f64>> {
        decode(job.payload, job.header, job.mask, job.flat)
    }
}
