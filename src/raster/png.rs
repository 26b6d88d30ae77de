//! PLACEHOLDER being written by a helper.
use crate::error::{Error, Result};
use crate::raster::{Raster, ReadOptions};
use std::path::{Path, PathBuf};

/// Value mapping of a 16-bit PNG: value = offset + scale * code; `nodata_code` marks voids.
#[derive(Clone, Debug, PartialEq)]
pub struct PngMapping {
    pub scale: f64,
    pub offset: f64,
    pub nodata_code: Option<u16>,
}

pub fn sidecar_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".json");
    PathBuf::from(s)
}
pub fn read_sidecar(_path: &Path) -> Result<Option<PngMapping>> {
    Ok(None)
}
pub fn read(_bytes: &[u8], _m: Option<&PngMapping>, _trgb: bool, _opts: &ReadOptions) -> Result<Raster> {
    Err(Error::unsupported("png reading is not written yet"))
}
pub fn write(_r: &Raster, _m: Option<&PngMapping>) -> Result<(Vec<u8>, Option<Vec<u8>>)> {
    Err(Error::unsupported("png writing is not written yet"))
}
pub fn write_terrain_rgb(_r: &Raster) -> Result<Vec<u8>> {
    Err(Error::unsupported("terrain-rgb writing is not written yet"))
}
