//! PLACEHOLDER being written by a helper.
use crate::error::{Error, Result};
use crate::raster::{Raster, ReadOptions};

pub fn read(_bytes: &[u8], _name: &str, _opts: &ReadOptions) -> Result<Raster> {
    Err(Error::unsupported("hgt reading is not written yet"))
}
pub fn write(_r: &Raster) -> Result<Vec<u8>> {
    Err(Error::unsupported("hgt writing is not written yet"))
}
