//! The Haar section: a 2-D integer Haar (S-transform) pyramid, dead-zone quantized, range
//! coded with per-subband contexts — the wavelet baseline of the Voronoi paper.

use crate::container::Header;
use crate::error::{Error, Result};
use crate::raster::Raster;

/// Parameters of the Haar representation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HaarParams {
    /// Max absolute error in data units; 0 means lossless (integer-valued data only).
    pub max_error: f64,
}

/// Encode `r` as a Haar-section payload meeting `p.max_error`. Returns the payload and the
/// max error it guarantees.
pub fn encode(_r: &Raster, _p: &HaarParams) -> Result<(Vec<u8>, f64)> {
    Err(Error::unsupported("the haar method is not implemented yet"))
}

/// Encode with a fixed coefficient quantization step (rate control by bisection). Returns the
/// payload and the max error it achieves.
pub fn encode_step(_r: &Raster, _step: f64) -> Result<(Vec<u8>, f64)> {
    Err(Error::unsupported("the haar method is not implemented yet"))
}

/// Decode a Haar-section payload (invalid samples get the nodata fill).
pub fn decode(_payload: &[u8], _header: &Header, _mask: Option<&[bool]>) -> Result<Vec<f64>> {
    Err(Error::unsupported("the haar method is not implemented yet"))
}
