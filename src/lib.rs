//! vtz: a compression codec and file format for elevation data with a hard error bound.
//!
//! Pipeline: raster I/O ([`raster`]) → representation sections (e.g. [`grid`]) → entropy
//! coding ([`entropy`]) → the container ([`container`]), and back.
#![forbid(unsafe_code)]

pub mod error;
pub mod fsio;
pub mod raster;

pub use error::{Error, Result};
pub use raster::{Format, Georef, Raster, RasterType, SampleType};

/// Options for [`encode`].
#[derive(Clone, Debug, Default)]
pub struct EncodeOptions {}

/// Options for [`decode_with`].
#[derive(Clone, Debug, Default)]
pub struct DecodeOptions {}

/// Encode a raster into `.vtz` bytes.
pub fn encode(_raster: &Raster, _opts: &EncodeOptions) -> Result<Vec<u8>> {
    Err(Error::unsupported("encode is not written yet"))
}

/// Decode `.vtz` bytes into a raster.
pub fn decode_with(_bytes: &[u8], _opts: &DecodeOptions) -> Result<Raster> {
    Err(Error::unsupported("decode is not written yet"))
}
