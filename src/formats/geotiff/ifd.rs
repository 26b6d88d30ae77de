//! The TIFF structure under the tags: the header, image directories (IFDs) and their entries,
//! walked over any seekable source (bytes in memory, an open file) with every position checked
//! against the source's length before anything is read or allocated. The pre-pass
//! (`precheck`) walks the first directory with it, the mask search (`mask`) the chain after it.

use crate::error::{Error, Result};
use std::io::{Read, Seek, SeekFrom};

/// What a [`Source`] reads from: anything readable and seekable.
pub(super) trait ReadSeek: Read + Seek {}
impl<T: Read + Seek> ReadSeek for T {}

/// A TIFF's bytes read at given positions, with the length they are checked against.
pub(super) struct Source<'a> {
    r: &'a mut dyn ReadSeek,
    len: u64,
}

impl<'a> Source<'a> {
    /// `r`, of `len` bytes from position 0.
    pub(super) fn new(r: &'a mut dyn ReadSeek, len: u64) -> Source<'a> {
        Source { r, len }
    }

    /// The source's length in bytes.
    pub(super) fn len(&self) -> u64 {
        self.len
    }

    /// The `n` bytes at `pos`; an error when they run past the end.
    pub(super) fn read_at(&mut self, pos: u64, n: usize) -> Result<Vec<u8>> {
        if pos.checked_add(n as u64).is_none_or(|end| end > self.len) {
            return Err(Error::corrupt("GeoTIFF is truncated"));
        }
        let io = |e| Error::io("reading GeoTIFF", e);
        self.r.seek(SeekFrom::Start(pos)).map_err(io)?;
        let mut b = vec![0u8; n];
        self.r.read_exact(&mut b).map_err(io)?;
        Ok(b)
    }

    /// The unsigned integer of `n` bytes at `pos` in the byte order `o`; `None` past the end.
    fn uint_at(&mut self, o: Order, pos: u64, n: usize) -> Result<Option<u64>> {
        if pos.checked_add(n as u64).is_none_or(|end| end > self.len) {
            return Ok(None);
        }
        Ok(Some(o.uint(&self.read_at(pos, n)?)))
    }
}

/// Byte order and kind (classic TIFF or BigTIFF) of a file.
#[derive(Clone, Copy, Debug)]
pub(super) struct Order {
    pub(super) le: bool,
    pub(super) big: bool,
}

impl Order {
    /// An unsigned integer of 1, 2, 4 or 8 bytes in this byte order.
    pub(super) fn uint(self, b: &[u8]) -> u64 {
        uint(b, self.le)
    }
    /// Bytes of a directory's entry count.
    fn count_len(self) -> u64 {
        if self.big { 8 } else { 2 }
    }
    /// Bytes of an entry.
    fn entry_len(self) -> u64 {
        if self.big { 20 } else { 12 }
    }
    /// Bytes of an offset: of the value field of an entry (values that fit are kept there),
    /// of the pointer to the next directory.
    pub(super) fn word(self) -> u64 {
        if self.big { 8 } else { 4 }
    }
}

/// An unsigned integer of 1, 2, 4 or 8 bytes in the given byte order.
pub(super) fn uint(b: &[u8], le: bool) -> u64 {
    let fold = |acc: u64, &x: &u8| (acc << 8) | u64::from(x);
    if le {
        b.iter().rev().fold(0, fold)
    } else {
        b.iter().fold(0, fold)
    }
}

/// Size in bytes of one value of a TIFF field type.
pub(super) fn type_size(typ: u16) -> Option<u64> {
    Some(match typ {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 | 16 | 17 | 18 => 8,
        _ => return None,
    })
}

/// The header: byte order, kind and the first directory's offset (checked to lie inside the
/// source). Errors name what is wrong: the byte-order mark, the version, the BigTIFF header,
/// the directory offset.
pub(super) fn header(src: &mut Source<'_>) -> Result<(Order, u64)> {
    let truncated = || Error::corrupt("GeoTIFF is truncated");
    let len = src.len();
    let le = match src.uint_at(
        Order {
            le: true,
            big: false,
        },
        0,
        2,
    )? {
        Some(0x4949) => true,  // "II"
        Some(0x4d4d) => false, // "MM"
        Some(_) => return Err(Error::corrupt("not a TIFF file (bad byte-order mark)")),
        None => return Err(truncated()),
    };
    let mut o = Order { le, big: false };
    let first = match src.uint_at(o, 2, 2)?.ok_or_else(truncated)? {
        42 => src.uint_at(o, 4, 4)?.ok_or_else(truncated)?,
        43 => {
            o.big = true;
            if src.uint_at(o, 4, 2)? != Some(8) || src.uint_at(o, 6, 2)? != Some(0) {
                return Err(Error::corrupt("BigTIFF header is invalid"));
            }
            src.uint_at(o, 8, 8)?.ok_or_else(truncated)?
        }
        v => return Err(Error::corrupt(format!("not a TIFF file (version {v})"))),
    };
    if first < 8 || first >= len {
        return Err(Error::corrupt(format!(
            "GeoTIFF image directory offset {first} is outside the file ({len} bytes)"
        )));
    }
    Ok((o, first))
}

/// An image directory: where its entries start and how many there are.
pub(super) struct Dir {
    pub(super) count: u64,
    first: u64,
}

/// One directory entry as stored.
pub(super) struct Entry {
    pub(super) tag: u16,
    pub(super) typ: u16,
    pub(super) count: u64,
    /// Where the entry's value field is in the file.
    field_pos: u64,
    /// The value field read as an offset.
    pointer: u64,
}

impl Entry {
    /// Where values of `len` bytes lie: in the entry itself when they fit, else where it points.
    pub(super) fn data_pos(&self, o: Order, len: u64) -> u64 {
        if len <= o.word() {
            self.field_pos
        } else {
            self.pointer
        }
    }
}

/// The directory at `pos`; `None` when its entry count runs past the end of the source.
pub(super) fn directory(src: &mut Source<'_>, o: Order, pos: u64) -> Result<Option<Dir>> {
    let Some(count) = src.uint_at(o, pos, o.count_len() as usize)? else {
        return Ok(None);
    };
    Ok(Some(Dir {
        count,
        first: pos + o.count_len(),
    }))
}

impl Dir {
    /// Where its entries end (and the next directory's offset starts); `None` on overflow.
    pub(super) fn end(&self, o: Order) -> Option<u64> {
        self.count
            .checked_mul(o.entry_len())
            .and_then(|n| n.checked_add(self.first))
    }

    /// Each entry in order, given to `f`, read a block at a time (a directory of millions of
    /// entries is never held whole). The caller has checked that [`Dir::end`] lies inside the
    /// source.
    pub(super) fn entries(
        &self,
        src: &mut Source<'_>,
        o: Order,
        mut f: impl FnMut(&Entry) -> Result<()>,
    ) -> Result<()> {
        const BLOCK: u64 = 4096;
        let size = o.entry_len();
        let mut k = 0;
        while k < self.count {
            let n = (self.count - k).min(BLOCK);
            let block = src.read_at(self.first + k * size, (n * size) as usize)?;
            for (j, e) in block.chunks_exact(size as usize).enumerate() {
                let pos = self.first + (k + j as u64) * size;
                let (count, field) = if o.big {
                    (o.uint(&e[4..12]), 12)
                } else {
                    (o.uint(&e[4..8]), 8)
                };
                f(&Entry {
                    tag: o.uint(&e[..2]) as u16,
                    typ: o.uint(&e[2..4]) as u16,
                    count,
                    field_pos: pos + field,
                    pointer: o.uint(&e[field as usize..]),
                })?;
            }
            k += n;
        }
        Ok(())
    }
}
