//! Where a `.vtz` file's bytes come from: a small trait that reads byte ranges
//! ([`RangeSource`]), with a local file, bytes in memory and any `Read + Seek` behind it
//! (and remote objects over HTTP or S3 behind the `remote` feature). The container reads
//! every file through it, so a reader fetches only the ranges it needs: the header and
//! index first (one read of [`HEAD_BYTES`]), then the blocks of the tiles a window touches,
//! all of them in one call that a remote source issues concurrently.

#[cfg(feature = "remote")]
pub mod remote;

use crate::error::{Error, Result};
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Bytes read from the start of a file when it is opened: the header, the tile index of a
/// version-4 or -5 file and its global sections fit here for a few hundred tiles
/// (spec/FORMAT.md, "Version 4"), so opening costs one request. Matches the 16–64 KB
/// GDAL reads first from a Cloud Optimized GeoTIFF.
pub const HEAD_BYTES: u64 = 64 * 1024;

/// Ranges closer than this are fetched as one (the bytes between are read and dropped).
/// Small on purpose: the blocks of a window's tiles in one row of tiles lie back to back
/// (gap 0) and merge whatever the gap, while an overview reads a prefix of each block, and
/// merging across the rest of a block (tens of KB) would fetch the whole file; the ranges
/// left apart are fetched concurrently.
pub const COALESCE_GAP: u64 = 4 * 1024;

/// Whether `s` is a URL a remote source reads (`http://`, `https://` or `s3://`, in any
/// case) rather than a local path. The CLI opens such inputs with `remote::open_url`
/// (feature `remote`).
pub fn is_url(s: &str) -> bool {
    s.split_once("://").is_some_and(|(scheme, _)| {
        ["http", "https", "s3"]
            .iter()
            .any(|k| scheme.eq_ignore_ascii_case(k))
    })
}

/// A source of bytes that reads ranges: a local file, memory, an object on a server.
///
/// Implementations read every range exactly (a range past the end is an error, never a
/// short read), may read them in any order or at once, and must return the same bytes for
/// the same range for as long as the source is open (a remote source checks the object's
/// ETag and fails when it changed).
// `len` is fallible (a remote length may need a request): an `is_empty` would only repeat it.
#[allow(clippy::len_without_is_empty)]
pub trait RangeSource: Send + Sync {
    /// The object's length in bytes.
    fn len(&self) -> Result<u64>;
    /// Whether the object is empty.
    fn is_empty(&self) -> Result<bool> {
        Ok(self.len()? == 0)
    }
    /// The bytes of each range, in the order asked. Ranges may overlap or be empty.
    ///
    /// # Errors
    /// [`Error::Io`] when the source fails; [`Error::Corrupt`] when a range lies past the
    /// end of the object (the file is truncated).
    fn read_ranges(&self, ranges: &[Range<u64>]) -> Result<Vec<Vec<u8>>>;
    /// The path or URL, for messages.
    fn name(&self) -> String;
}

/// Merge sorted-or-not ranges that lie within `gap` bytes of each other. Gives the merged
/// ranges (ascending) and, for each input range, the merged range holding it.
pub fn coalesce(ranges: &[Range<u64>], gap: u64) -> (Vec<Range<u64>>, Vec<usize>) {
    merge_by(ranges, |r, m| r.start <= m.end.saturating_add(gap))
}

/// Ranges that overlap merged, adjacent ones kept apart (ascending): for a reader with a
/// cache of its own whose transport merges consecutive ranges itself (GDAL's /vsicurl/),
/// so each tile block stays an entry of its own. Same shape as [`coalesce`].
pub fn disjoint(ranges: &[Range<u64>]) -> (Vec<Range<u64>>, Vec<usize>) {
    merge_by(ranges, |r, m| r.start < m.end || *m == *r)
}

/// Ranges in ascending order, each merged into the last merged one when `joins(range,
/// last)`; gives the merged ranges and, for each input range, the one holding it.
fn merge_by(
    ranges: &[Range<u64>],
    joins: impl Fn(&Range<u64>, &Range<u64>) -> bool,
) -> (Vec<Range<u64>>, Vec<usize>) {
    let mut order: Vec<usize> = (0..ranges.len()).collect();
    order.sort_by_key(|&i| (ranges[i].start, ranges[i].end));
    let mut merged: Vec<Range<u64>> = Vec::new();
    let mut owner = vec![0usize; ranges.len()];
    for i in order {
        let r = &ranges[i];
        match merged.last_mut() {
            Some(m) if joins(r, m) => m.end = m.end.max(r.end),
            _ => merged.push(r.clone()),
        }
        owner[i] = merged.len() - 1;
    }
    (merged, owner)
}

/// The bytes of `ranges` cut out of the merged reads `got` (as [`coalesce`] planned them).
pub fn split(
    ranges: &[Range<u64>],
    merged: &[Range<u64>],
    owner: &[usize],
    got: &[Vec<u8>],
) -> Vec<Vec<u8>> {
    ranges
        .iter()
        .zip(owner)
        .map(|(r, &o)| {
            let base = merged[o].start;
            got[o][(r.start - base) as usize..(r.end - base) as usize].to_vec()
        })
        .collect()
}

fn past_end(name: &str, r: &Range<u64>, len: u64) -> Error {
    Error::corrupt(format!(
        "{name} is truncated: bytes {}..{} asked of a {len}-byte file",
        r.start, r.end
    ))
}

/// A local file, read with positioned reads (one handle, shared by every thread).
pub struct FileSource {
    file: Mutex<std::fs::File>,
    path: PathBuf,
    len: u64,
}

impl FileSource {
    /// Open `path` for reading.
    ///
    /// # Errors
    /// [`Error::Io`] naming the path when it cannot be opened or measured.
    pub fn open(path: &Path) -> Result<FileSource> {
        let file = std::fs::File::open(path)
            .map_err(|e| Error::io(format!("opening {}", path.display()), e))?;
        let len = file
            .metadata()
            .map_err(|e| Error::io(format!("reading {}", path.display()), e))?
            .len();
        Ok(FileSource {
            file: Mutex::new(file),
            path: path.to_path_buf(),
            len,
        })
    }
}

impl RangeSource for FileSource {
    fn len(&self) -> Result<u64> {
        Ok(self.len)
    }
    fn read_ranges(&self, ranges: &[Range<u64>]) -> Result<Vec<Vec<u8>>> {
        let mut f = self.file.lock().unwrap_or_else(|p| p.into_inner());
        let name = self.name();
        ranges
            .iter()
            .map(|r| {
                if r.end > self.len || r.start > r.end {
                    return Err(past_end(&name, r, self.len));
                }
                let mut buf = vec![0u8; (r.end - r.start) as usize];
                f.seek(SeekFrom::Start(r.start))
                    .and_then(|_| f.read_exact(&mut buf))
                    .map_err(|e| Error::io(format!("reading {name}"), e))?;
                Ok(buf)
            })
            .collect()
    }
    fn name(&self) -> String {
        self.path.display().to_string()
    }
}

/// Bytes in memory.
pub struct MemorySource {
    bytes: Arc<[u8]>,
}

impl MemorySource {
    /// A source over `bytes`.
    pub fn new(bytes: impl Into<Arc<[u8]>>) -> MemorySource {
        MemorySource {
            bytes: bytes.into(),
        }
    }
}

impl RangeSource for MemorySource {
    fn len(&self) -> Result<u64> {
        Ok(self.bytes.len() as u64)
    }
    fn read_ranges(&self, ranges: &[Range<u64>]) -> Result<Vec<Vec<u8>>> {
        let len = self.bytes.len() as u64;
        ranges
            .iter()
            .map(|r| {
                if r.end > len || r.start > r.end {
                    return Err(past_end("the file", r, len));
                }
                Ok(self.bytes[r.start as usize..r.end as usize].to_vec())
            })
            .collect()
    }
    fn name(&self) -> String {
        "bytes in memory".into()
    }
}

/// Any `Read + Seek` (a file, a cursor, a reader of your own), one range at a time.
pub struct ReadSeekSource<R> {
    inner: Mutex<R>,
    len: u64,
}

impl<R: Read + Seek + Send> ReadSeekSource<R> {
    /// A source over `inner` (measured by seeking to its end).
    ///
    /// # Errors
    /// [`Error::Io`] when the reader cannot seek.
    pub fn new(mut inner: R) -> Result<ReadSeekSource<R>> {
        let len = inner
            .seek(SeekFrom::End(0))
            .map_err(|e| Error::io("measuring the file", e))?;
        Ok(ReadSeekSource {
            inner: Mutex::new(inner),
            len,
        })
    }
}

impl<R: Read + Seek + Send> RangeSource for ReadSeekSource<R> {
    fn len(&self) -> Result<u64> {
        Ok(self.len)
    }
    fn read_ranges(&self, ranges: &[Range<u64>]) -> Result<Vec<Vec<u8>>> {
        let mut f = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        ranges
            .iter()
            .map(|r| {
                if r.end > self.len || r.start > r.end {
                    return Err(past_end("the file", r, self.len));
                }
                let mut buf = vec![0u8; (r.end - r.start) as usize];
                f.seek(SeekFrom::Start(r.start))
                    .and_then(|_| f.read_exact(&mut buf))
                    .map_err(|e| Error::io("reading the file", e))?;
                Ok(buf)
            })
            .collect()
    }
    fn name(&self) -> String {
        "the file".into()
    }
}

/// An opened source as the container reads it: its length, the first [`HEAD_BYTES`]
/// (read once on opening), and a position, so the framing code reads it as `Read + Seek`
/// (reads inside the head are free; any other read is one range) while tile blocks are
/// fetched many at once ([`Source::read_ranges`]).
#[derive(Clone)]
pub struct Source {
    shared: Arc<Shared>,
    pos: u64,
}

struct Shared {
    src: Arc<dyn RangeSource>,
    len: u64,
    head: Vec<u8>,
}

impl Source {
    /// Measure `src` and read its first [`HEAD_BYTES`] (one request).
    ///
    /// # Errors
    /// What the source gives.
    pub fn open(src: Arc<dyn RangeSource>) -> Result<Source> {
        let len = src.len()?;
        let n = len.min(HEAD_BYTES);
        let head = src
            .read_ranges(std::slice::from_ref(&(0..n)))?
            .pop()
            .unwrap_or_default();
        if head.len() as u64 != n {
            return Err(Error::corrupt(format!(
                "{}: a read of {n} bytes gave {}",
                src.name(),
                head.len()
            )));
        }
        Ok(Source {
            shared: Arc::new(Shared { src, len, head }),
            pos: 0,
        })
    }
    /// The file's length.
    pub fn len(&self) -> u64 {
        self.shared.len
    }
    /// Whether the file is empty.
    pub fn is_empty(&self) -> bool {
        self.shared.len == 0
    }
    /// The path or URL.
    pub fn name(&self) -> String {
        self.shared.src.name()
    }
    /// The bytes of each range (what of them the head holds from memory, the rest in one
    /// call to the source, which may coalesce and fetch them concurrently).
    pub fn read_ranges(&self, ranges: &[Range<u64>]) -> Result<Vec<Vec<u8>>> {
        let head = &self.shared.head;
        let hl = head.len() as u64;
        // What the head does not hold: a range reaching past it is fetched from its end.
        let far: Vec<Range<u64>> = ranges
            .iter()
            .filter(|r| r.end > hl)
            .map(|r| r.start.max(hl)..r.end)
            .collect();
        let mut got = if far.is_empty() {
            Vec::new()
        } else {
            self.shared.src.read_ranges(&far)?
        }
        .into_iter();
        ranges
            .iter()
            .map(|r| {
                if r.end <= hl {
                    Ok(head[r.start as usize..r.end as usize].to_vec())
                } else {
                    let tail = got
                        .next()
                        .ok_or_else(|| Error::corrupt("a range read gave too few ranges"))?;
                    let b = if r.start < hl {
                        let mut b = head[r.start as usize..].to_vec();
                        b.extend_from_slice(&tail);
                        b
                    } else {
                        tail
                    };
                    if b.len() as u64 != r.end - r.start {
                        return Err(Error::corrupt(format!(
                            "{}: a read of bytes {}..{} gave {} bytes",
                            self.name(),
                            r.start,
                            r.end,
                            b.len()
                        )));
                    }
                    Ok(b)
                }
            })
            .collect()
    }
    /// The bytes `start..end`.
    pub fn read_at(&self, r: Range<u64>) -> Result<Vec<u8>> {
        Ok(self
            .read_ranges(std::slice::from_ref(&r))?
            .pop()
            .unwrap_or_default())
    }
}

impl Read for Source {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let len = self.shared.len;
        if self.pos >= len || buf.is_empty() {
            return Ok(0);
        }
        let end = (self.pos + buf.len() as u64).min(len);
        let bytes = self
            .read_at(self.pos..end)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        buf[..bytes.len()].copy_from_slice(&bytes);
        self.pos = end;
        Ok(bytes.len())
    }
}

impl Seek for Source {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let p = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.shared.len.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = p.ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
        })?;
        Ok(self.pos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coalescing_merges_near_ranges_and_splits_them_back() {
        let rs = [100..200, 0..10, 205..300, 5000..5010, 150..160];
        let (m, o) = coalesce(&rs, 10);
        assert_eq!(m, vec![0..10, 100..300, 5000..5010]);
        let bytes: Vec<u8> = (0..6000u32).map(|i| (i % 251) as u8).collect();
        let got: Vec<Vec<u8>> = m
            .iter()
            .map(|r| bytes[r.start as usize..r.end as usize].to_vec())
            .collect();
        let parts = split(&rs, &m, &o, &got);
        for (r, p) in rs.iter().zip(parts) {
            assert_eq!(p, &bytes[r.start as usize..r.end as usize]);
        }
    }

    #[test]
    fn urls_are_told_from_paths() {
        for u in ["https://h/a.vtz", "HTTP://h/a.vtz", "s3://b/k.vtz"] {
            assert!(is_url(u), "{u}");
        }
        for p in [
            "a.vtz",
            "/tmp/s3/a.vtz",
            "C:\\a.vtz",
            "file://a.vtz",
            "s3:/b/k",
        ] {
            assert!(!is_url(p), "{p}");
        }
    }

    /// A source that records the ranges asked of it.
    struct Logged(MemorySource, Mutex<Vec<Range<u64>>>);
    impl RangeSource for Logged {
        fn len(&self) -> Result<u64> {
            self.0.len()
        }
        fn read_ranges(&self, r: &[Range<u64>]) -> Result<Vec<Vec<u8>>> {
            self.1.lock().unwrap().extend_from_slice(r);
            self.0.read_ranges(r)
        }
        fn name(&self) -> String {
            "logged".into()
        }
    }

    #[test]
    fn ranges_the_head_holds_are_not_fetched_again() {
        let n = HEAD_BYTES as usize + 1000;
        let bytes: Vec<u8> = (0..n).map(|i| (i % 253) as u8).collect();
        let src = Arc::new(Logged(
            MemorySource::new(bytes.clone()),
            Mutex::new(Vec::new()),
        ));
        let s = Source::open(src.clone()).unwrap();
        let h = HEAD_BYTES;
        let got = s
            .read_ranges(&[10..20, h - 100..h + 50, h + 10..h + 20])
            .unwrap();
        assert_eq!(got[0], &bytes[10..20]);
        assert_eq!(got[1], &bytes[(h - 100) as usize..(h + 50) as usize]);
        assert_eq!(got[2], &bytes[(h + 10) as usize..(h + 20) as usize]);
        // The open, then only what lies past the head.
        assert_eq!(
            *src.1.lock().unwrap(),
            vec![0..h, h..h + 50, h + 10..h + 20]
        );
    }

    #[test]
    fn a_range_past_the_end_is_a_truncated_file_not_a_short_read() {
        let s = MemorySource::new(vec![1u8; 10]);
        assert!(matches!(
            s.read_ranges(std::slice::from_ref(&(5..11))),
            Err(Error::Corrupt { .. })
        ));
        let src = Source::open(Arc::new(s)).unwrap();
        assert_eq!(src.read_at(2..4).unwrap(), vec![1, 1]);
    }
}
