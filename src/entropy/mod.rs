//! Turns integer symbol streams into bytes and back (the only module that knows bit layouts).
//!
//! Version 1 of the format uses zig-zag LEB128 varints compressed with raw DEFLATE; the
//! adaptive arithmetic coder of the sites section will live here too.

pub mod range;
pub mod rans;
pub mod varint;

use crate::error::{Error, Result};
use std::io::{Read, Write};

/// Compress bytes with raw DEFLATE (RFC 1951), best compression.
pub fn deflate(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
    // Writing to a Vec cannot fail.
    enc.write_all(bytes).expect("in-memory deflate");
    enc.finish().expect("in-memory deflate")
}

/// Decompress a raw DEFLATE stream that must inflate to at most `max_len` bytes; `what`
/// names the stream in errors. Never allocates more than `max_len` (+1) bytes.
pub fn inflate(bytes: &[u8], max_len: usize, what: &str) -> Result<Vec<u8>> {
    let dec = flate2::read::DeflateDecoder::new(bytes);
    let mut out = Vec::new();
    dec.take(max_len as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| Error::corrupt(format!("{what}: bad DEFLATE stream ({e})")))?;
    if out.len() > max_len {
        return Err(Error::corrupt(format!(
            "{what}: DEFLATE stream inflates to more than the {max_len} bytes it may hold"
        )));
    }
    Ok(out)
}
