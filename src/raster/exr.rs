//! PLACEHOLDER being written by a helper.
use crate::error::{Error, Result};
use crate::raster::{Raster, ReadOptions};

pub fn read(_bytes: &[u8], _opts: &ReadOptions) -> Result<Raster> {
    Err(Error::unsupported("exr reading is not written yet"))
}
pub fn write(_r: &Raster) -> Result<Vec<u8>> {
    Err(Error::unsupported("exr writing is not written yet"))
}
