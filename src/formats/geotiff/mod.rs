//! GeoTIFF reading and writing: single-band elevation rasters with their georeferencing and nodata.
//!
//! One reader ([`Reader`]) over any `Read + Seek` source decodes a file band by band or whole:
//! [`read`] is that reader over bytes in memory, [`Reader::open`] over a file on disk. It goes
//! through the `tiff` crate's decoder, after a small pre-pass over the first image file
//! directory (IFD) of our own. The pre-pass checks that the tags the decoder will read point
//! inside the file, that the raster is of a layout we support (one sample per pixel; uint8,
//! int16, uint16, int32, float32 or float64; no compression, LZW, Deflate or PackBits;
//! predictor 1, 2 or 3) and that its size is within [`ReadOptions::max_samples`], so garbage
//! or hostile headers give an error instead of a large allocation.
//!
//! The GeoTIFF tags (ModelPixelScale, ModelTiepoint, ModelTransformation, the three GeoKey
//! tags and GDAL_NODATA) become a [`Georef`] with the GeoKeys kept verbatim, so a
//! GeoTIFF → raster → GeoTIFF round trip gives GDAL the same CRS. GDAL_METADATA (tag 42112,
//! XML) is kept verbatim in `Raster::gdal_metadata` and written back.
//!
//! Writing produces a striped, Deflate-compressed GeoTIFF of a raster held whole ([`write`]),
//! or a tiled one band by band ([`StreamWriter`]), in the raster's sample type, with the
//! horizontal predictor for integer samples. (The `tiff` 0.11 encoder has no floating-point
//! predictor, so float samples are written with Deflate alone.)
//!
//! A per-dataset mask band inside the file (GDAL's `GDAL_TIFF_INTERNAL_MASK`, as COGs carry
//! it) makes its masked samples invalid (`mask`).
//!
//! One file a concern: `ifd` (the TIFF header and directories walked over a source),
//! `precheck` (the pre-pass on the first directory), `reader` (decoding), `georef` (the
//! georeferencing tags both ways), `nodata` (GDAL_NODATA text both ways), `mask` (the internal
//! mask band), `write` (a whole raster, striped) and `writer` (band by band, tiled); the tag
//! numbers they share are below.
//!
//! [`ReadOptions::max_samples`]: crate::formats::ReadOptions::max_samples
//! [`Georef`]: crate::model::Georef

mod georef;
mod ifd;
mod mask;
mod nodata;
mod precheck;
mod reader;
mod tags;
mod write;
mod writer;

#[cfg(test)]
mod fixtures;

pub use reader::{Reader, read};
pub use write::write;
pub use writer::StreamWriter;

// Tag numbers shared by the pre-pass, the readers, the writers and the tests.
// TIFF baseline / extension tags the pre-pass looks at.
const TAG_IMAGE_WIDTH: u16 = 256;
const TAG_IMAGE_LENGTH: u16 = 257;
const TAG_BITS_PER_SAMPLE: u16 = 258;
const TAG_COMPRESSION: u16 = 259;
const TAG_PHOTOMETRIC: u16 = 262;
const TAG_STRIP_OFFSETS: u16 = 273;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_ROWS_PER_STRIP: u16 = 278;
const TAG_STRIP_BYTE_COUNTS: u16 = 279;
const TAG_PLANAR_CONFIG: u16 = 284;
const TAG_PREDICTOR: u16 = 317;
const TAG_TILE_WIDTH: u16 = 322;
const TAG_TILE_LENGTH: u16 = 323;
const TAG_TILE_OFFSETS: u16 = 324;
const TAG_TILE_BYTE_COUNTS: u16 = 325;
const TAG_EXTRA_SAMPLES: u16 = 338;
const TAG_SAMPLE_FORMAT: u16 = 339;
const TAG_JPEG_TABLES: u16 = 347;
const TAG_YCBCR_SUBSAMPLING: u16 = 530;
// GeoTIFF and GDAL tags.
const TAG_MODEL_PIXEL_SCALE: u16 = 33550;
const TAG_MODEL_TIEPOINT: u16 = 33922;
const TAG_MODEL_TRANSFORMATION: u16 = 34264;
const TAG_GEO_KEY_DIRECTORY: u16 = 34735;
const TAG_GEO_DOUBLE_PARAMS: u16 = 34736;
const TAG_GEO_ASCII_PARAMS: u16 = 34737;
/// GDAL_METADATA: GDAL's XML of band description, units, scale/offset and free items.
const TAG_GDAL_METADATA: u16 = 42112;
const TAG_GDAL_NODATA: u16 = 42113;
