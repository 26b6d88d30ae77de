//! The FIS section: a fractal interpolation surface on rectangles (every k-th sample as
//! interpolation point, vertical scaling factors per rectangle), decoded by iterating the IFS.

use crate::container::Header;
use crate::error::{Error, Result};
use crate::raster::Raster;

/// Parameters of the FIS representation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FisParams {
    /// Meet this max error (data units): the encoder chooses k and the quantization.
    pub max_error: Option<f64>,
    /// Use this subgrid spacing instead of searching.
    pub k: Option<usize>,
    /// One vertical scaling factor for every rectangle (the paper's s = 0.02) instead of
    /// fitted ones.
    pub fixed_s: Option<f64>,
}

/// What the FIS encoder chose and achieved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FisStats {
    pub k: usize,
    pub max_error: f64,
    pub rmse: f64,
}

pub fn encode(_r: &Raster, _p: &FisParams) -> Result<(Vec<u8>, FisStats)> {
    Err(Error::unsupported("the fis method is not implemented yet"))
}

pub fn decode(_payload: &[u8], _header: &Header, _mask: Option<&[bool]>) -> Result<Vec<f64>> {
    Err(Error::unsupported("the fis method is not implemented yet"))
}
