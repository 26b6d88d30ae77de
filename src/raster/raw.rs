//! PLACEHOLDER being written by a helper.
use crate::error::{Error, Result};
use crate::raster::{Raster, ReadOptions};

pub fn read(_bytes: &[u8], _json: &[u8], _opts: &ReadOptions) -> Result<Raster> {
    Err(Error::unsupported("raw reading is not written yet"))
}
pub fn write(_r: &Raster) -> Result<(Vec<u8>, Vec<u8>)> {
    Err(Error::unsupported("raw writing is not written yet"))
}
