//! LEB128 varints and zig-zag mapping of signed integers.

use crate::error::{Error, Result};

/// Append `v` as an unsigned LEB128 varint (7 bits a byte, low first).
pub fn put_u64(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Zig-zag map a signed integer to an unsigned one (0, -1, 1, -2, … → 0, 1, 2, 3, …).
#[inline]
pub fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

#[inline]
pub fn unzigzag(u: u64) -> i64 {
    ((u >> 1) as i64) ^ -((u & 1) as i64)
}

pub fn put_i64(out: &mut Vec<u8>, v: i64) {
    put_u64(out, zigzag(v));
}

/// Reads varints from a byte slice, with errors naming the stream.
pub struct VarintReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    what: &'static str,
}

impl<'a> VarintReader<'a> {
    pub fn new(bytes: &'a [u8], what: &'static str) -> Self {
        VarintReader {
            bytes,
            pos: 0,
            what,
        }
    }

    pub fn u64(&mut self) -> Result<u64> {
        let mut v: u64 = 0;
        let mut shift = 0u32;
        loop {
            let b = *self
                .bytes
                .get(self.pos)
                .ok_or_else(|| Error::corrupt(format!("{}: stream ends early", self.what)))?;
            self.pos += 1;
            if shift == 63 && b > 1 {
                return Err(Error::corrupt(format!("{}: varint overflows", self.what)));
            }
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
            shift += 7;
            if shift > 63 {
                return Err(Error::corrupt(format!("{}: varint too long", self.what)));
            }
        }
    }

    pub fn i64(&mut self) -> Result<i64> {
        Ok(unzigzag(self.u64()?))
    }

    /// Fail unless every byte was consumed.
    pub fn finish(&self) -> Result<()> {
        if self.pos != self.bytes.len() {
            return Err(Error::corrupt(format!(
                "{}: {} unused bytes after the last value",
                self.what,
                self.bytes.len() - self.pos
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(crate::testutil::proptest_config(256))]
        #[test]
        fn varints_round_trip(vals in proptest::collection::vec(any::<i64>(), 0..200)) {
            let mut buf = Vec::new();
            for &v in &vals { put_i64(&mut buf, v); }
            let mut r = VarintReader::new(&buf, "test");
            for &v in &vals { prop_assert_eq!(r.i64().unwrap(), v); }
            r.finish().unwrap();
        }
    }

    #[test]
    fn overlong_varints_are_rejected() {
        let bytes = [0xffu8; 11];
        assert!(VarintReader::new(&bytes, "t").u64().is_err());
        let bytes = [0xffu8, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02];
        assert!(VarintReader::new(&bytes, "t").u64().is_err());
        let max = [0xffu8, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01];
        assert_eq!(VarintReader::new(&max, "t").u64().unwrap(), u64::MAX);
    }
}
