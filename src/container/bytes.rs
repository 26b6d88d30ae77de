//! Bounds-checked little-endian reading of container fields, with errors naming the field.

use crate::error::{Error, Result};
use byteorder::{ByteOrder, LittleEndian as LE};

/// A cursor over untrusted bytes: every read is checked against the end.
pub struct ByteReader<'a> {
    data: &'a [u8],
    pos: usize,
    what: &'a str,
}

impl<'a> ByteReader<'a> {
    pub fn new(data: &'a [u8], what: &'a str) -> Self {
        ByteReader { data, pos: 0, what }
    }
    /// Bytes read so far.
    pub fn position(&self) -> usize {
        self.pos
    }
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }
    pub fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(Error::corrupt(format!(
                "{}: truncated at {field} (needs {n} bytes, {} left)",
                self.what,
                self.remaining()
            )));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    pub fn u8(&mut self, field: &str) -> Result<u8> {
        Ok(self.take(1, field)?[0])
    }
    pub fn u16(&mut self, field: &str) -> Result<u16> {
        Ok(LE::read_u16(self.take(2, field)?))
    }
    pub fn u32(&mut self, field: &str) -> Result<u32> {
        Ok(LE::read_u32(self.take(4, field)?))
    }
    pub fn u64(&mut self, field: &str) -> Result<u64> {
        Ok(LE::read_u64(self.take(8, field)?))
    }
    pub fn f64(&mut self, field: &str) -> Result<f64> {
        Ok(LE::read_f64(self.take(8, field)?))
    }
    /// A finite f64 (NaN and infinities are rejected).
    pub fn finite_f64(&mut self, field: &str) -> Result<f64> {
        let v = self.f64(field)?;
        if !v.is_finite() {
            return Err(Error::corrupt(format!(
                "{}: {field} is not finite",
                self.what
            )));
        }
        Ok(v)
    }
    /// A u32 count of `elem_size`-byte items that must fit in the remaining bytes.
    pub fn count(&mut self, elem_size: usize, field: &str) -> Result<usize> {
        let n = self.u32(field)? as usize;
        if n.saturating_mul(elem_size) > self.remaining() {
            return Err(Error::corrupt(format!(
                "{}: {field} = {n} does not fit in the {} bytes left",
                self.what,
                self.remaining()
            )));
        }
        Ok(n)
    }
    /// Fail unless every byte was consumed.
    pub fn finish(&self) -> Result<()> {
        if self.remaining() != 0 {
            return Err(Error::corrupt(format!(
                "{}: {} unexpected bytes at the end",
                self.what,
                self.remaining()
            )));
        }
        Ok(())
    }
    pub fn corrupt(&self, msg: impl std::fmt::Display) -> Error {
        Error::corrupt(format!("{}: {msg}", self.what))
    }
}

/// Little-endian writing helpers for `Vec<u8>`.
pub trait PutLe {
    fn put_u8(&mut self, v: u8);
    fn put_u16(&mut self, v: u16);
    fn put_u32(&mut self, v: u32);
    fn put_u64(&mut self, v: u64);
    fn put_f64(&mut self, v: f64);
}

impl PutLe for Vec<u8> {
    fn put_u8(&mut self, v: u8) {
        self.push(v);
    }
    fn put_u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_u64(&mut self, v: u64) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_f64(&mut self, v: f64) {
        self.extend_from_slice(&v.to_le_bytes());
    }
}
