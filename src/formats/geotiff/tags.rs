//! TIFF tag access both directions share: the error mapping of the `tiff` crate, reading a
//! tag as text, writing one as text.

use crate::error::{Error, Result};
use std::io::{Read, Seek, Write};
use tiff::decoder::{Decoder, ifd::Value};
use tiff::encoder::{DirectoryEncoder, TiffKind};
use tiff::tags::{Tag, Type};
use tiff::{Directory, TiffError};

/// Map a `tiff` crate error to ours.
pub(super) fn tiff_err(e: TiffError) -> Error {
    match e {
        TiffError::UnsupportedError(u) => Error::unsupported(format!("GeoTIFF: {u}")),
        TiffError::LimitsExceeded => {
            Error::limit("GeoTIFF: the TIFF decoder's limits were exceeded")
        }
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::corrupt("GeoTIFF is truncated")
        }
        other => Error::corrupt(format!("GeoTIFF: {other}")),
    }
}

/// A tag's text; `None` when the tag is absent, an error when it is not ASCII.
pub(super) fn tag_string<R: Read + Seek>(dec: &mut Decoder<R>, tag: u16) -> Result<Option<String>> {
    match dec
        .find_tag(Tag::from_u16_exhaustive(tag))
        .map_err(tiff_err)?
    {
        None => Ok(None),
        Some(Value::Ascii(s)) => Ok(Some(s)),
        Some(_) => Err(Error::corrupt(format!(
            "GeoTIFF tag {tag} is not an ASCII string"
        ))),
    }
}

/// Map a `tiff` crate encoding error to ours.
pub(super) fn enc_err(e: TiffError) -> Error {
    Error::invalid(format!("GeoTIFF encoding failed: {e}"))
}

/// Write an ASCII tag with its trailing NUL. Unlike `write_tag(tag, &str)`, this accepts
/// non-ASCII UTF-8 text (which the reader gives back as it was), so verbatim GeoAsciiParams
/// with e.g. accented citations survive a round trip.
pub(super) fn write_ascii<W: Write + Seek, K: TiffKind>(
    e: &mut DirectoryEncoder<'_, W, K>,
    tag: Tag,
    s: &str,
) -> Result<()> {
    if s.contains('\0') {
        return Err(Error::invalid(format!(
            "text for TIFF tag {} contains a NUL character",
            tag.to_u16()
        )));
    }
    let mut b = Vec::with_capacity(s.len() + 1);
    b.extend_from_slice(s.as_bytes());
    b.push(0);
    let entry = e.write_entry_bytes(Type::ASCII, &b).map_err(enc_err)?;
    let mut dir = Directory::empty();
    dir.extend([(tag, entry)]);
    e.extend_from(&dir);
    Ok(())
}
