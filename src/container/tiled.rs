//! Tiled files' framing (versions 2, 4 and 5): the tile grid, the global and tile blocks,
//! and the tile index that a reader finds from the header (spec/FORMAT.md, "Version 2:
//! tiled files", "Version 4", "Version 5"); and the one reader of raster files
//! ([`RasterReader`]), to which an untiled file (version 1) is a one-tile grid.

use super::bytes::{ByteReader, PutLe};
use super::{
    ContainerReader, DIR_ENTRY_LEN, FileStart, Header, KindNames, Limits, Section, SectionEntry,
    SectionKind, VERSION_CLOUD, VERSION_HEADS, VERSION_TILED, checksum_ok, directory_bytes,
};
use crate::error::{Error, Result};
use crate::model::Window;
use crate::source::Source;
use std::io::{Cursor, Read, Seek, SeekFrom, Write};

/// Bytes of a version-4 index entry before its chunk table.
pub const CLOUD_ENTRY_LEN: usize = 40;
/// Most chunks a version-4 tile block has (the anchors and up to 12 levels).
pub const MAX_CHUNKS: usize = 13;
/// Bytes of the tile fields at the end of a version-4 header body.
const CLOUD_FIELDS_LEN: usize = 16;
/// Bytes of the tile fields at the end of a version-5 header body (version 4's and the split).
const HEADS_FIELDS_LEN: usize = 20;
/// The side (in samples) of the coarsest overview whose chunks a version-5 writer puts in the
/// heads: the overview a screen-sized view of the whole raster reads (a 1024² request of
/// the 20 000² mosaic reads overview 4, 1250²) and everything coarser is one range.
pub const HEADS_OVERVIEW_SIDE: u64 = 1024;

/// The split a version-5 writer uses for a `width × height` raster: the largest overview K
/// (1 ..= MAX_CHUNKS − 1) whose longer side is still at least [`HEADS_OVERVIEW_SIDE`]
/// (overview K has ⌈side / 2^K⌉ samples a side), else 1.
pub fn heads_split(width: u32, height: u32) -> u32 {
    let side = width.max(height) as u64;
    (1..MAX_CHUNKS as u32)
        .rev()
        .find(|&k| side.div_ceil(1 << k) >= HEADS_OVERVIEW_SIDE)
        .unwrap_or(1)
}
/// Bytes of one tile index entry.
pub const INDEX_ENTRY_LEN: usize = 56;
/// Smallest tile side a file may declare (unless the raster itself is smaller).
pub const MIN_TILE: u32 = 16;
/// Bytes of the tile fields at the end of a version-2 header body.
const TILE_FIELDS_LEN: usize = 28;
/// Index entry flag: the tile has valid samples, and its minimum and maximum are set.
const TF_RANGE: u16 = 1;

/// How a raster is cut into tiles: row-major, each `tile_w × tile_h` but the last column
/// and row, which hold what is left.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileGrid {
    /// Raster width.
    pub width: u32,
    /// Raster height.
    pub height: u32,
    /// Tile width (the last column may be narrower).
    pub tile_w: u32,
    /// Tile height (the last row may be shorter).
    pub tile_h: u32,
    /// Samples each tile codes beyond its core on every side that has a neighbour; a
    /// decoder blends neighbours across this band (spec/FORMAT.md, "Blending").
    pub margin: u32,
}

impl TileGrid {
    /// The grid an encoder picks for tiles of side at most `tile`: as many tiles per axis
    /// as that side needs, of equal size but for the last (no sliver of a few samples), and
    /// a margin of `margin` (less where a tile is too small for it).
    pub fn balanced(width: u32, height: u32, tile: u32, margin: u32) -> TileGrid {
        let side = |n: u32| {
            let t = tile.max(1);
            // Never below the smallest tile a decoder accepts.
            let count = n.div_ceil(t).min((n / MIN_TILE).max(1));
            n.div_ceil(count)
        };
        let mut g = TileGrid {
            width,
            height,
            tile_w: side(width),
            tile_h: side(height),
            margin: 0,
        };
        g.margin = margin.min(g.max_margin());
        g
    }
    /// The largest margin this grid allows: half the smallest core along an axis that has
    /// more than one tile.
    fn max_margin(&self) -> u32 {
        let mut m = u32::MAX;
        for (n, t) in [(self.width, self.tile_w), (self.height, self.tile_h)] {
            if n > t {
                let last = n - (n.div_ceil(t) - 1) * t;
                m = m.min(t.min(last) / 2);
            }
        }
        if m == u32::MAX { 0 } else { m }
    }
    /// Tiles per row.
    pub fn cols(&self) -> u32 {
        self.width.div_ceil(self.tile_w)
    }
    /// Rows of tiles.
    pub fn rows(&self) -> u32 {
        self.height.div_ceil(self.tile_h)
    }
    /// Number of tiles.
    pub fn count(&self) -> u64 {
        self.cols() as u64 * self.rows() as u64
    }
    /// The samples tile `k` covers.
    pub fn rect(&self, k: usize) -> Window {
        let (c, r) = (k as u32 % self.cols(), k as u32 / self.cols());
        let (x, y) = (c * self.tile_w, r * self.tile_h);
        Window {
            x: x as usize,
            y: y as usize,
            width: self.tile_w.min(self.width - x) as usize,
            height: self.tile_h.min(self.height - y) as usize,
        }
    }
    /// The samples tile `k` codes: its core and the margin on every side that has a
    /// neighbour.
    pub fn ext(&self, k: usize) -> Window {
        let r = self.rect(k);
        let m = self.margin as usize;
        let x0 = r.x.saturating_sub(m);
        let y0 = r.y.saturating_sub(m);
        let x1 = (r.x + r.width + m).min(self.width as usize);
        let y1 = (r.y + r.height + m).min(self.height as usize);
        Window {
            x: x0,
            y: y0,
            width: x1 - x0,
            height: y1 - y0,
        }
    }
    /// The weight, out of [`TileGrid::weight_den`], of tile `k` at sample `(x, y)` (0
    /// outside its coded samples): 1 in its core away from its neighbours, ramping linearly
    /// across the `2 · margin` samples around a border, so neighbours' weights sum to the
    /// denominator everywhere.
    #[cfg(test)]
    pub fn weight(&self, k: usize, x: usize, y: usize) -> u64 {
        self.weight_x(k, x) * self.weight_y(k, y)
    }
    /// The column factor of [`TileGrid::weight`].
    pub fn weight_x(&self, k: usize, x: usize) -> u64 {
        let r = self.rect(k);
        ramp(
            x,
            r.x,
            r.x + r.width,
            self.width as usize,
            self.margin as usize,
        )
    }
    /// The row factor of [`TileGrid::weight`].
    pub fn weight_y(&self, k: usize, y: usize) -> u64 {
        let r = self.rect(k);
        ramp(
            y,
            r.y,
            r.y + r.height,
            self.height as usize,
            self.margin as usize,
        )
    }
    /// The sum of the weights at any sample.
    #[cfg(test)]
    pub fn weight_den(&self) -> u64 {
        let d = if self.margin == 0 {
            1
        } else {
            4 * self.margin as u64
        };
        d * d
    }
    /// The tiles whose coded samples (core and margin) a window touches, row-major.
    pub fn touching_ext(&self, w: Window) -> Vec<usize> {
        let m = self.margin as usize;
        let x0 = w.x.saturating_sub(m);
        let y0 = w.y.saturating_sub(m);
        let x1 = (w.x + w.width + m).min(self.width as usize);
        let y1 = (w.y + w.height + m).min(self.height as usize);
        self.touching(Window {
            x: x0,
            y: y0,
            width: x1 - x0,
            height: y1 - y0,
        })
    }
    /// The tiles whose cores a window touches, row-major.
    pub fn touching(&self, w: Window) -> Vec<usize> {
        if w.width == 0 || w.height == 0 {
            return Vec::new();
        }
        let (tw, th) = (self.tile_w as usize, self.tile_h as usize);
        let (c0, c1) = (w.x / tw, (w.x + w.width - 1) / tw);
        let (r0, r1) = (w.y / th, (w.y + w.height - 1) / th);
        let cols = self.cols() as usize;
        (r0..=r1)
            .flat_map(|r| (c0..=c1).map(move |c| r * cols + c))
            .collect()
    }
    fn check(&self) -> Result<()> {
        let ok = |t: u32, n: u32| t >= 1 && t <= n && (t >= MIN_TILE || t == n);
        if !ok(self.tile_w, self.width) || !ok(self.tile_h, self.height) {
            return Err(Error::corrupt(format!(
                "header: tile size {}x{} is out of range for a {}x{} raster",
                self.tile_w, self.tile_h, self.width, self.height
            )));
        }
        if self.margin > self.max_margin() {
            return Err(Error::corrupt(format!(
                "header: a margin of {} is over half the smallest tile ({})",
                self.margin,
                self.max_margin()
            )));
        }
        Ok(())
    }
}

/// A tile's weight along one axis at `p`, out of `4m` (1 for m = 0): its core is `[a, b)`
/// of `[0, n)`; across a border with a neighbour it ramps over `[border − m, border + m)`
/// by odd steps (1, 3, …, 4m − 1), so two neighbours' weights sum to `4m`.
fn ramp(p: usize, a: usize, b: usize, n: usize, m: usize) -> u64 {
    if m == 0 {
        return (a <= p && p < b) as u64;
    }
    let full = 4 * m as u64;
    let left = if a == 0 || p >= a + m {
        full
    } else if p + m < a {
        0
    } else {
        (2 * (p + m - a) + 1) as u64
    };
    let right = if b == n || p + m < b {
        full
    } else if p >= b + m {
        0
    } else {
        (2 * (b + m - p) - 1) as u64
    };
    left.min(right)
}

/// One tile's entry in the index: where its block is and what it holds.
#[derive(Clone, Debug, PartialEq)]
pub struct TileEntry {
    /// Byte offset of the tile's block in the file (version 5: of its head).
    pub offset: u64,
    /// Bytes of the block.
    pub length: u64,
    /// Bytes of the block at `offset`: version 5's head (the chunks overview `split` reads),
    /// else the whole block.
    pub head: u64,
    /// Where the rest of the block (`length − head` bytes) lies: version 5's tail.
    pub tail_offset: u64,
    /// CRC-32 of the block.
    pub crc: u32,
    /// The type of the tile's primary section (its method).
    pub kind: SectionKind,
    /// Valid samples in the tile.
    pub valid: u64,
    /// (min, max) of the tile's valid source samples; `None` when it has none.
    pub range: Option<(f64, f64)>,
    /// The max error the tile's encoder achieved (0 = lossless).
    pub max_error: f64,
    /// Version 4: the block's chunks, coarse to fine, each `(end, crc)`: it ends `end` bytes
    /// into the block (the last at `length`) and its bytes have CRC-32 `crc`. An overview K
    /// ≥ 1 reads chunks `0 ..= max(0, n − 1 − K)` of n. Empty in version 2 (`crc` covers
    /// the block).
    pub chunks: Vec<(u32, u32)>,
}

impl TileEntry {
    /// The bytes of the block an overview-`k` decode reads (0 = a full decode): a prefix of
    /// the block in version 4, the block in version 2.
    pub fn prefix(&self, k: u32) -> u64 {
        let n = self.chunks.len();
        if k == 0 || n == 0 {
            return self.length;
        }
        let j = (n - 1).saturating_sub(k as usize);
        self.chunks[j].0 as u64
    }
    /// The file's byte ranges holding the block's first `p` bytes: its head's part, then
    /// (version 5, when `p` reaches past the head) its tail's.
    pub fn ranges(&self, p: u64) -> (std::ops::Range<u64>, Option<std::ops::Range<u64>>) {
        let h = p.min(self.head);
        let tail = (p > self.head).then(|| self.tail_offset..self.tail_offset + (p - self.head));
        (self.offset..self.offset + h, tail)
    }
}

/// A tile's block: its primary section index, a reserved zero, then its directory and
/// sections.
pub fn tile_block(primary: u16, sections: &[Section]) -> Vec<u8> {
    let payload: usize = sections.iter().map(|s| s.payload.len()).sum();
    let mut out = Vec::with_capacity(8 + sections.len() * DIR_ENTRY_LEN + 4 + payload);
    out.put_u16(primary);
    out.put_u16(0);
    directory_bytes(&mut out, sections);
    out
}

/// The fixed part and header of a version-5 file. `header.primary` must be 0 and
/// `header.range` is not stored (the index holds each tile's).
fn cloud_head_bytes(header: &Header, grid: &TileGrid, index_len: u32, split: u32) -> Vec<u8> {
    let mut h = header.clone();
    h.primary = 0;
    h.range = None;
    let mut body = h.to_bytes();
    body.put_u32(grid.tile_w);
    body.put_u32(grid.tile_h);
    body.put_u32(grid.margin);
    body.put_u32(index_len);
    body.put_u32(split);
    let mut out = Vec::with_capacity(20 + body.len());
    FileStart::write(&mut out, VERSION_HEADS, &body);
    out
}

/// Where tile blocks wait until the index is known: a version-5 file puts its index before
/// them. Up to [`SPOOL_MEMORY`] bytes in memory, beyond that an unnamed temporary file
/// (removed by the system however the process ends), so a large mosaic's encode stays
/// within its memory budget.
enum Spool {
    Memory(Vec<u8>),
    File(std::fs::File),
}

/// Bytes of tile blocks a writer keeps in memory before it spools them to a temporary file.
const SPOOL_MEMORY: usize = 64 << 20;

/// Writes a tiled file (version 5) to any seekable sink, in two passes: tile blocks as
/// they come (in tile order) into a spool, then at [`TiledWriter::finish`] the header, the
/// index, the global sections, every block's head (the chunks overview `split` reads) and
/// every block's tail, copied from the spool.
pub struct TiledWriter<W: Write + Seek> {
    out: W,
    header: Header,
    grid: TileGrid,
    split: u32,
    global: Vec<u8>,
    entries: Vec<TileEntry>,
    spool: Spool,
    pos: u64,
}

impl<W: Write + Seek> TiledWriter<W> {
    /// Start a file with its global sections (metadata, GDAL metadata); nothing is written
    /// to `out` before [`TiledWriter::finish`]. The split is [`heads_split`] of the raster.
    pub fn new(out: W, header: &Header, grid: TileGrid, global: &[Section]) -> Result<Self> {
        let mut block = Vec::new();
        directory_bytes(&mut block, global);
        Ok(TiledWriter {
            out,
            header: header.clone(),
            grid,
            split: heads_split(grid.width, grid.height),
            global: block,
            entries: Vec::with_capacity(grid.count().min(1 << 20) as usize),
            spool: Spool::Memory(Vec::new()),
            pos: 0,
        })
    }
    /// Tiles written so far.
    pub fn written(&self) -> usize {
        self.entries.len()
    }
    /// Append the next tile's block (tiles must come in tile order). `prefixes` are the
    /// bytes of the block an overview K = 1, 2, … decode reads (non-decreasing towards
    /// coarser K; empty when every overview reads the whole block): they become the block's
    /// chunks, coarsest first.
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        block: &[u8],
        kind: SectionKind,
        valid: u64,
        range: Option<(f64, f64)>,
        max_error: f64,
        prefixes: &[u64],
    ) -> Result<()> {
        if self.entries.len() as u64 >= self.grid.count() {
            return Err(Error::invalid("more tiles than the grid has"));
        }
        let len = block.len() as u64;
        if len > u32::MAX as u64 {
            return Err(Error::limit(format!(
                "a tile block of {len} bytes is over the 4 GiB a version-5 index holds: use smaller tiles"
            )));
        }
        // Chunk ends, coarsest first: overview K = L reads the first, K = 1 the L-th, a full
        // decode every byte.
        let mut ends: Vec<u64> = prefixes.iter().rev().copied().collect();
        ends.push(len);
        if ends.len() > MAX_CHUNKS || ends.windows(2).any(|w| w[0] > w[1]) || ends[0] < 12 {
            ends = vec![len];
        }
        let mut chunks = Vec::with_capacity(ends.len());
        let mut from = 0usize;
        for &e in &ends {
            chunks.push((e as u32, crc32fast::hash(&block[from..e as usize])));
            from = e as usize;
        }
        let io = |e| Error::io("writing the file", e);
        match &mut self.spool {
            Spool::Memory(v) if v.len() + block.len() <= SPOOL_MEMORY => v.extend_from_slice(block),
            Spool::Memory(v) => {
                let mut f =
                    tempfile::tempfile().map_err(|e| Error::io("creating a temporary file", e))?;
                f.write_all(v).map_err(io)?;
                f.write_all(block).map_err(io)?;
                self.spool = Spool::File(f);
            }
            Spool::File(f) => f.write_all(block).map_err(io)?,
        }
        let mut e = TileEntry {
            offset: self.pos,
            length: len,
            head: len,
            tail_offset: 0,
            crc: 0,
            kind,
            valid,
            range,
            max_error,
            chunks,
        };
        e.head = e.prefix(self.split);
        self.entries.push(e);
        self.pos += len;
        Ok(())
    }
    /// Write the header, the index, the global sections, the heads and the tails; gives
    /// back the sink.
    pub fn finish(mut self) -> Result<W> {
        if self.entries.len() as u64 != self.grid.count() {
            return Err(Error::invalid(format!(
                "{} of {} tiles were written",
                self.entries.len(),
                self.grid.count()
            )));
        }
        let mut idx = Vec::with_capacity(8 + self.entries.len() * (CLOUD_ENTRY_LEN + 16));
        idx.put_u32(self.entries.len() as u32);
        for e in &self.entries {
            idx.put_u16(e.kind.code());
            idx.put_u16(if e.range.is_some() { TF_RANGE } else { 0 });
            idx.push(e.chunks.len() as u8);
            idx.extend_from_slice(&[0, 0, 0]);
            idx.put_u64(e.valid);
            let (lo, hi) = e.range.unwrap_or((0.0, 0.0));
            idx.put_f64(lo);
            idx.put_f64(hi);
            idx.put_f64(e.max_error);
            for &(end, crc) in &e.chunks {
                idx.put_u32(end);
                idx.put_u32(crc);
            }
        }
        let crc = crc32fast::hash(&idx);
        idx.put_u32(crc);
        let index_len = u32::try_from(idx.len())
            .map_err(|_| Error::limit("a tile index over 4 GiB: use larger tiles"))?;
        let head = cloud_head_bytes(&self.header, &self.grid, index_len, self.split);
        let io = |e| Error::io("writing the file", e);
        self.out.write_all(&head).map_err(io)?;
        self.out.write_all(&idx).map_err(io)?;
        self.out.write_all(&self.global).map_err(io)?;
        // The heads in tile order, then the tails: each a range of a block in the spool.
        let heads = self.entries.iter().map(|e| (e.offset, e.head));
        let tails = self
            .entries
            .iter()
            .map(|e| (e.offset + e.head, e.length - e.head));
        let parts: Vec<(u64, u64)> = heads.chain(tails).filter(|p| p.1 > 0).collect();
        match &mut self.spool {
            Spool::Memory(v) => {
                for (at, n) in parts {
                    self.out
                        .write_all(&v[at as usize..(at + n) as usize])
                        .map_err(io)?;
                }
            }
            Spool::File(f) => {
                let mut buf = Vec::new();
                for (at, n) in parts {
                    f.seek(SeekFrom::Start(at)).map_err(io)?;
                    buf.resize(n as usize, 0);
                    f.read_exact(&mut buf).map_err(io)?;
                    self.out.write_all(&buf).map_err(io)?;
                }
            }
        }
        self.out.flush().map_err(io)?;
        Ok(self.out)
    }
}

/// The index entry's fields both versions share, checked: the method, flags, valid count,
/// range and max error of tile `k`.
#[allow(clippy::too_many_arguments)]
fn check_entry(
    header: &Header,
    grid: &TileGrid,
    k: usize,
    kind: SectionKind,
    flags: u16,
    valid: u64,
    lo: f64,
    hi: f64,
    max_error: f64,
) -> Result<Option<(f64, f64)>> {
    let t = |m: String| {
        let w = grid.rect(k);
        Error::corrupt(format!("tile index: tile {k} (at {},{}): {m}", w.x, w.y))
    };
    if kind.code() == 0 || !kind.may_be_primary() {
        return Err(t(format!("method type {} is not a representation", kind.0)));
    }
    if flags & !TF_RANGE != 0 {
        return Err(t(format!("unknown flags 0x{:04x}", flags & !TF_RANGE)));
    }
    let w = grid.ext(k);
    if valid > (w.width * w.height) as u64 {
        return Err(t(format!(
            "{valid} valid samples in a {}x{} tile",
            w.width, w.height
        )));
    }
    let range = if flags & TF_RANGE != 0 {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) || valid == 0 {
            return Err(t(format!("range {lo}..{hi} is not valid")));
        }
        // The range is of sample values: each end a value of the sample type.
        for (what, v) in [("minimum", lo), ("maximum", hi)] {
            header
                .sample_type
                .check_holds(what, v, header.mapping)
                .map_err(t)?;
        }
        Some((lo, hi))
    } else {
        if valid != 0 || lo.to_bits() != 0 || hi.to_bits() != 0 {
            return Err(t("no range flag, but a valid count or range".into()));
        }
        None
    };
    if !(max_error.is_finite() && max_error >= 0.0) {
        return Err(t(format!("max error {max_error} is not valid")));
    }
    Ok(range)
}

/// A tile index's bytes (both versions): its checksum checked, its count that of the grid's
/// `n` tiles; the entries are `[4, len − 4)`.
fn read_index(inner: &mut Source, at: std::ops::Range<u64>, n: u64) -> Result<Vec<u8>> {
    let ibuf = inner.read_at(at)?;
    let (ib, crc_bytes) = ibuf.split_at(ibuf.len() - 4);
    if !checksum_ok(crc32fast::hash(ib), crc_bytes) {
        return Err(Error::corrupt("tile index checksum mismatch"));
    }
    let count = ByteReader::new(ib, "tile index").u32("tile count")? as u64;
    if count != n {
        return Err(Error::corrupt(format!(
            "tile index: {count} tiles listed, the grid has {n}"
        )));
    }
    Ok(ibuf)
}

/// Version 2's index (at `index_offset`, ending the file) and global directory (from
/// `global_start` to the first block).
#[allow(clippy::too_many_arguments)]
fn read_index_v2(
    inner: &mut Source,
    header: &Header,
    grid: &TileGrid,
    global_start: u64,
    index_offset: u64,
    index_len: u64,
    limits: &Limits,
    names: KindNames,
) -> Result<(Vec<TileEntry>, Vec<SectionEntry>)> {
    let file_len = inner.len();
    let n = grid.count();
    let want = 8 + n.saturating_mul(INDEX_ENTRY_LEN as u64);
    if index_len != want {
        return Err(Error::corrupt(format!(
            "header: the index of {n} tiles needs {want} bytes, the header says {index_len}"
        )));
    }
    index_within_limit(index_len, limits)?;
    match index_offset.checked_add(index_len) {
        Some(end) if index_offset >= global_start && end <= file_len => {
            if end != file_len {
                return Err(Error::corrupt(format!(
                    "{} unexpected bytes after the tile index",
                    file_len - end
                )));
            }
        }
        _ => {
            return Err(Error::corrupt(format!(
                "file is truncated (or the header is corrupt): the tile index should be at bytes {index_offset}..{} of a {file_len}-byte file",
                index_offset.saturating_add(index_len)
            )));
        }
    }
    let ibuf = read_index(inner, index_offset..index_offset + index_len, n)?;
    let mut r = ByteReader::new(&ibuf[4..ibuf.len() - 4], "tile index");
    let mut tiles = Vec::with_capacity(n as usize);
    let mut first = None;
    let mut expect: Option<u64> = None;
    for k in 0..n as usize {
        let t = |m: String| {
            let w = grid.rect(k);
            Error::corrupt(format!("tile index: tile {k} (at {},{}): {m}", w.x, w.y))
        };
        let offset = r.u64("offset")?;
        let length = r.u64("length")?;
        let crc = r.u32("checksum")?;
        let kind = SectionKind::from_code(r.u16("method")?);
        let flags = r.u16("flags")?;
        let valid = r.u64("valid count")?;
        let lo = r.f64("minimum")?;
        let hi = r.f64("maximum")?;
        let max_error = r.f64("max error")?;
        if let Some(e) = expect {
            if offset != e {
                return Err(t(format!(
                    "starts at byte {offset}, the previous tile ends at {e} (tiles lie back to back in tile order)"
                )));
            }
        }
        let end = offset
            .checked_add(length)
            .filter(|&e| offset >= global_start && e <= index_offset)
            .ok_or_else(|| {
                t(format!(
                    "bytes {offset}..+{length} are outside the tiles' part of the file"
                ))
            })?;
        if length < 12 {
            return Err(t(format!("a block of {length} bytes is too short")));
        }
        if length > limits.max_section_bytes {
            return Err(Error::limit(format!(
                "tile {k} of {length} bytes is over the limit of {}",
                limits.max_section_bytes
            )));
        }
        let range = check_entry(header, grid, k, kind, flags, valid, lo, hi, max_error)?;
        first.get_or_insert(offset);
        expect = Some(end);
        tiles.push(TileEntry {
            offset,
            length,
            head: length,
            tail_offset: end,
            crc,
            kind,
            valid,
            range,
            max_error,
            chunks: Vec::new(),
        });
    }
    r.finish()?;
    if expect != Some(index_offset) {
        return Err(Error::corrupt(
            "tile index: the last tile does not end where the index starts",
        ));
    }
    let global_end = first.expect("a grid has at least one tile");
    let (global, _) = super::read_directory_to(
        inner,
        global_start,
        global_end,
        true,
        limits,
        names,
        "global sections",
    )?;
    Ok((tiles, global))
}

/// Version 4's or 5's index (right after the header, `index_len` bytes) and global
/// directory (right after the index); the blocks follow back to back and the last ends the
/// file (version 5, `split` given: every block's head, then every block's tail).
#[allow(clippy::too_many_arguments)]
fn read_cloud_index(
    inner: &mut Source,
    header: &Header,
    grid: &TileGrid,
    index_at: u64,
    index_len: u64,
    split: Option<u32>,
    limits: &Limits,
    names: KindNames,
) -> Result<(Vec<TileEntry>, Vec<SectionEntry>)> {
    let file_len = inner.len();
    let n = grid.count();
    let least = 8 + n.saturating_mul(CLOUD_ENTRY_LEN as u64 + 8);
    let most = 8 + n.saturating_mul((CLOUD_ENTRY_LEN + 8 * MAX_CHUNKS) as u64);
    if index_len < least || index_len > most {
        return Err(Error::corrupt(format!(
            "header: an index of {index_len} bytes cannot hold {n} tiles ({least}..={most} bytes)"
        )));
    }
    index_within_limit(index_len, limits)?;
    if index_at + index_len > file_len {
        return Err(Error::corrupt("file is truncated in the tile index"));
    }
    let ibuf = read_index(inner, index_at..index_at + index_len, n)?;
    let mut r = ByteReader::new(&ibuf[4..ibuf.len() - 4], "tile index");
    let mut tiles = Vec::with_capacity(n as usize);
    for k in 0..n as usize {
        let t = |m: String| {
            let w = grid.rect(k);
            Error::corrupt(format!("tile index: tile {k} (at {},{}): {m}", w.x, w.y))
        };
        let kind = SectionKind::from_code(r.u16("method")?);
        let flags = r.u16("flags")?;
        let c = r.u8("chunk count")? as usize;
        let reserved = r.take(3, "reserved")?;
        let valid = r.u64("valid count")?;
        let lo = r.f64("minimum")?;
        let hi = r.f64("maximum")?;
        let max_error = r.f64("max error")?;
        if reserved != [0, 0, 0] {
            return Err(t("reserved bytes are not 0".into()));
        }
        if !(1..=MAX_CHUNKS).contains(&c) {
            return Err(t(format!("{c} chunks (1 ..= {MAX_CHUNKS})")));
        }
        let mut chunks = Vec::with_capacity(c);
        let mut prev = 0u32;
        for _ in 0..c {
            let end = r.u32("chunk end")?;
            let crc = r.u32("chunk checksum")?;
            if end < prev {
                return Err(t(format!("chunk ends {prev} then {end}: not in order")));
            }
            chunks.push((end, crc));
            prev = end;
        }
        let length = prev as u64;
        if chunks[0].0 < 12 {
            return Err(t(format!(
                "a first chunk of {} bytes is too short",
                chunks[0].0
            )));
        }
        if length > limits.max_section_bytes {
            return Err(Error::limit(format!(
                "tile {k} of {length} bytes is over the limit of {}",
                limits.max_section_bytes
            )));
        }
        let range = check_entry(header, grid, k, kind, flags, valid, lo, hi, max_error)?;
        tiles.push(TileEntry {
            offset: 0,
            length,
            head: length,
            tail_offset: 0,
            crc: 0,
            kind,
            valid,
            range,
            max_error,
            chunks,
        });
    }
    r.finish()?;
    let (global, t0) = super::read_directory_to(
        inner,
        index_at + index_len,
        file_len,
        false,
        limits,
        names,
        "global sections",
    )?;
    let mut at = t0;
    for e in &mut tiles {
        if let Some(k) = split {
            e.head = e.prefix(k);
        }
        e.offset = at;
        at = at.saturating_add(e.head);
    }
    for e in &mut tiles {
        e.tail_offset = at;
        at = at.saturating_add(e.length - e.head);
    }
    if at != file_len {
        return Err(if at > file_len {
            Error::corrupt(format!(
                "file is truncated: its tiles end at byte {at}, the file at {file_len}"
            ))
        } else {
            Error::corrupt(format!(
                "{} unexpected bytes after the last tile",
                file_len - at
            ))
        });
    }
    Ok((tiles, global))
}

/// Reads a raster file of any version as a grid of tiles. A tiled file (version 2, 4 or
/// 5): its header and index on opening, then any tile on demand. An untiled file (version 1)
/// is a one-tile grid whose tile is the file itself, read in place ([`RasterReader::whole`]):
/// its header and directory on opening, its sections on demand.
pub struct RasterReader {
    inner: Source,
    version: u16,
    header: Header,
    grid: TileGrid,
    split: Option<u32>,
    tiles: Vec<TileEntry>,
    global: Vec<SectionEntry>,
    limits: Limits,
    names: KindNames,
    /// Version 1: the file as its one tile's container.
    whole: Option<ContainerReader<Source>>,
}

impl RasterReader {
    /// Open a raster file and check its framing: the file's start ([`FileStart`]), then a
    /// version-1 file's header and directory, or a tiled file's header checksum and fields,
    /// the index's checksum, that the tile blocks lie back to back (version 2: between the
    /// global sections and the index, which ends the file; version 4: after the index and
    /// the global sections, the last ending the file; version 5: the heads there, then the
    /// tails), each entry's fields.
    /// A version-4 or -5 file's header, index and global sections are usually inside the bytes
    /// the source read on opening ([`crate::source::HEAD_BYTES`]): no further read.
    pub fn new(mut inner: Source, limits: Limits, names: KindNames) -> Result<Self> {
        let start = FileStart::read(&mut inner, |version| match version {
            super::VERSION | VERSION_TILED | VERSION_CLOUD | VERSION_HEADS => Ok(()),
            super::VERSION_POINTS => Err(Error::unsupported(
                "this is a point set (container version 3), not a raster: read it with \
                 vtz::decode_points (the CLI decodes either)",
            )),
            v => Err(Error::unsupported(format!(
                "vtz format version {v} (this decoder reads versions 1–5)"
            ))),
        })?;
        let version = start.version;
        if version == super::VERSION {
            let whole = ContainerReader::after_start(inner.clone(), &start, limits, names)?;
            let header = whole.header().clone();
            return Ok(RasterReader {
                inner,
                version,
                grid: TileGrid {
                    width: header.width,
                    height: header.height,
                    tile_w: header.width,
                    tile_h: header.height,
                    margin: 0,
                },
                header,
                split: None,
                tiles: Vec::new(),
                global: Vec::new(),
                limits,
                names,
                whole: Some(whole),
            });
        }
        let body = &start.body[..];
        let fields = match version {
            VERSION_HEADS => HEADS_FIELDS_LEN,
            VERSION_CLOUD => CLOUD_FIELDS_LEN,
            _ => TILE_FIELDS_LEN,
        };
        if body.len() < fields {
            return Err(Error::corrupt("header: too short for the tile fields"));
        }
        let mut r = ByteReader::new(body, "header");
        let mut header = Header::read_fields(&mut r)?;
        if header.primary != 0 || header.range.is_some() {
            return Err(r.corrupt("a tiled file's header has no primary section and no range"));
        }
        let grid = TileGrid {
            width: header.width,
            height: header.height,
            tile_w: r.u32("tile width")?,
            tile_h: r.u32("tile height")?,
            margin: r.u32("margin")?,
        };
        let after_header = start.end();
        let mut split = None;
        let (tiles, global) = if version == VERSION_CLOUD || version == VERSION_HEADS {
            let index_len = r.u32("index length")? as u64;
            split = if version == VERSION_HEADS {
                let k = r.u32("split")?;
                if !(1..MAX_CHUNKS as u32).contains(&k) {
                    return Err(r.corrupt(format!(
                        "split {k} is out of range (1 ..= {})",
                        MAX_CHUNKS - 1
                    )));
                }
                Some(k)
            } else {
                None
            };
            r.finish()?;
            grid.check()?;
            read_cloud_index(
                &mut inner,
                &header,
                &grid,
                after_header,
                index_len,
                split,
                &limits,
                names,
            )?
        } else {
            let index_offset = r.u64("index offset")?;
            let index_len = r.u64("index length")?;
            r.finish()?;
            grid.check()?;
            read_index_v2(
                &mut inner,
                &header,
                &grid,
                after_header,
                index_offset,
                index_len,
                &limits,
                names,
            )?
        };
        // Only metadata and GDAL metadata belong in the global directory (FORMAT.md): a
        // mask, flat regions or a representation there would apply to no tile.
        if global
            .iter()
            .any(|e| !matches!(e.kind, SectionKind::METADATA | SectionKind::GDAL_METADATA))
        {
            return Err(Error::corrupt(
                "global sections: only metadata sections belong there",
            ));
        }
        header.range = tiles
            .iter()
            .filter_map(|t| t.range)
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
        Ok(RasterReader {
            inner,
            version,
            header,
            grid,
            split,
            tiles,
            global,
            limits,
            names,
            whole: None,
        })
    }

    /// A version-1 file's one tile, the file itself, read in place (`None` for a tiled file,
    /// whose tiles are opened from their blocks, [`RasterReader::opener`]).
    pub fn whole(&mut self) -> Option<&mut ContainerReader<Source>> {
        self.whole.as_mut()
    }
    /// The container version.
    pub fn version(&self) -> u16 {
        self.version
    }
    /// Whether the file is tiled (version 2, 4 or 5).
    pub fn tiled(&self) -> bool {
        self.whole.is_none()
    }
    /// The file's own sections: a version-1 file's directory, a tiled file's global
    /// sections.
    pub fn sections(&self) -> &[SectionEntry] {
        match &self.whole {
            Some(w) => w.entries(),
            None => &self.global,
        }
    }
    /// The primary section of a version-1 file (a tiled file's are its tiles').
    pub fn primary(&self) -> Option<usize> {
        self.whole.as_ref().map(|w| w.header().primary as usize)
    }
    /// GDAL's metadata XML from the file's first gdal-metadata section, `None` when there is
    /// none; not UTF-8 is a corrupt file.
    pub fn gdal_metadata(&mut self) -> Result<Option<String>> {
        if let Some(w) = &mut self.whole {
            return w.read_gdal_metadata();
        }
        self.global_section(SectionKind::GDAL_METADATA)?
            .map(|b| {
                String::from_utf8(b)
                    .map_err(|_| Error::corrupt("gdal-metadata section is not UTF-8"))
            })
            .transpose()
    }

    /// The raster's header (its range is the union of the tiles').
    pub fn header(&self) -> &Header {
        &self.header
    }
    /// The tile grid.
    pub fn grid(&self) -> TileGrid {
        self.grid
    }
    /// Version 5's split: overviews K ≥ it read only the tiles' heads (`None`: another
    /// version).
    pub fn split(&self) -> Option<u32> {
        self.split
    }
    /// The index (empty for a version-1 file, which has none).
    pub fn tiles(&self) -> &[TileEntry] {
        &self.tiles
    }
    /// The limits the file was opened with.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// The payload of the first global section of `kind` (checksum checked), if any.
    pub fn global_section(&mut self, kind: SectionKind) -> Result<Option<Vec<u8>>> {
        let Some(e) = self.global.iter().find(|e| e.kind == kind).cloned() else {
            return Ok(None);
        };
        let buf = self.read_at(e.offset, e.length, &format!("{} section", e.name))?;
        if !checksum_ok(crc32fast::hash(&buf), &e.crc.to_le_bytes()) {
            return Err(Error::corrupt(format!(
                "{} section: checksum mismatch",
                e.name
            )));
        }
        Ok(Some(buf))
    }

    fn read_at(&mut self, offset: u64, length: u64, _what: &str) -> Result<Vec<u8>> {
        // Offsets and lengths were checked against the file's length when opening.
        self.inner.read_at(offset..offset + length)
    }

    /// Tile `k`'s block, its checksums checked.
    pub fn tile_block(&mut self, k: usize) -> Result<Vec<u8>> {
        self.tile_blocks(&[k], 0)?
            .pop()
            .ok_or_else(|| Error::invalid(format!("no tile {k}")))?
    }

    /// The blocks of tiles `ks` as an overview-`overview` decode reads them (0: a full
    /// decode; in versions 4 and 5 an overview reads a prefix of each block, its first
    /// chunks; version 5 reads a block's head and its tail), in one call to the source,
    /// which coalesces adjacent ranges and may fetch them at once.
    /// The outer error is the source's (nothing was read); each tile's own result says
    /// whether its checksums hold, so a decode may skip a corrupt tile.
    pub fn tile_blocks(&mut self, ks: &[usize], overview: u32) -> Result<Vec<Result<Vec<u8>>>> {
        let mut heads = Vec::with_capacity(ks.len());
        let mut tails = Vec::new();
        for &k in ks {
            let e = self
                .tiles
                .get(k)
                .ok_or_else(|| Error::invalid(format!("no tile {k}")))?;
            let (h, t) = e.ranges(e.prefix(overview));
            heads.push(h);
            tails.extend(t.map(|t| (heads.len() - 1, t)));
        }
        // Version 5: the heads of a row of tiles lie back to back, as do their tails, so a
        // window takes a range of heads and a range of tails per row of tiles. (Reading the
        // heads of several rows as one range, the heads between included, saves requests
        // but defeats the range caches above a source — GDAL's plugin, Python's — which
        // then fetch cached heads again: measured, a block-by-block read of every tile
        // fetched 1.5× the file.)
        let mut ranges = heads.clone();
        ranges.extend(tails.iter().map(|t| t.1.clone()));
        let mut got = self.inner.read_ranges(&ranges)?.into_iter();
        let mut blocks: Vec<Vec<u8>> = got.by_ref().take(heads.len()).collect();
        for ((i, _), t) in tails.iter().zip(got) {
            blocks[*i].extend_from_slice(&t);
        }
        Ok(ks
            .iter()
            .zip(blocks)
            .map(|(&k, buf)| {
                let e = &self.tiles[k];
                let name = tile_name(&self.grid, k);
                if e.chunks.is_empty() {
                    if !checksum_ok(crc32fast::hash(&buf), &e.crc.to_le_bytes()) {
                        return Err(Error::corrupt(format!("{name}: checksum mismatch")));
                    }
                    return Ok(buf);
                }
                let mut from = 0usize;
                for (j, &(end, crc)) in e.chunks.iter().enumerate() {
                    let end = end as usize;
                    if end > buf.len() {
                        break;
                    }
                    if !checksum_ok(crc32fast::hash(&buf[from..end]), &crc.to_le_bytes()) {
                        return Err(Error::corrupt(format!(
                            "{name}: chunk {j} checksum mismatch"
                        )));
                    }
                    from = end;
                }
                Ok(buf)
            })
            .collect())
    }

    /// What opening a tile needs, without the reader (shareable across threads).
    pub fn opener(&self) -> TileOpener<'_> {
        TileOpener {
            header: &self.header,
            grid: self.grid,
            tiles: &self.tiles,
            limits: self.limits,
            names: self.names,
        }
    }
}

/// Opens tiles whose blocks were read ([`RasterReader::tile_block`]).
#[derive(Clone, Copy)]
pub struct TileOpener<'a> {
    header: &'a Header,
    grid: TileGrid,
    tiles: &'a [TileEntry],
    limits: Limits,
    names: KindNames,
}

impl TileOpener<'_> {
    /// A container reader over tile `k`'s block, with the tile's header.
    pub fn open(&self, k: usize, block: Vec<u8>) -> Result<ContainerReader<Cursor<Vec<u8>>>> {
        let w = self.grid.ext(k);
        let e = &self.tiles[k];
        let h = Header {
            width: w.width as u32,
            height: w.height as u32,
            primary: 0,
            range: e.range,
            georef: self.header.georef.as_ref().map(|g| g.window(w.x, w.y)),
            ..self.header.clone()
        };
        let name = tile_name(&self.grid, k);
        let rd = ContainerReader::tile(
            Cursor::new(block),
            h,
            e.length,
            self.limits,
            self.names,
            &name,
        )?;
        if rd
            .entries()
            .get(rd.header().primary as usize)
            .map(|s| s.kind)
            != Some(e.kind)
        {
            return Err(Error::corrupt(format!(
                "{name}: its primary section is not the method the index names"
            )));
        }
        Ok(rd)
    }
}

/// How errors name tile `k`: its number and its top-left sample.
pub fn tile_name(grid: &TileGrid, k: usize) -> String {
    let w = grid.rect(k);
    format!("tile {k} (at {},{})", w.x, w.y)
}

/// A tile index (versions 2 and 4) of `index_len` bytes within the section byte limit.
fn index_within_limit(index_len: u64, limits: &Limits) -> Result<()> {
    if index_len > limits.max_section_bytes {
        return Err(Error::limit(format!(
            "tile index of {index_len} bytes is over the limit of {}",
            limits.max_section_bytes
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_the_denominator_at_every_sample_and_vanish_outside_the_coded_samples() {
        for (w, h, t, m) in [
            (100, 70, 32, 8),
            (100, 70, 32, 3),
            (64, 64, 16, 8),
            (1000, 40, 300, 8),
            (50, 50, 50, 8),
            (97, 33, 16, 0),
        ] {
            let g = TileGrid::balanced(w, h, t, m);
            assert!(g.check().is_ok(), "{g:?}");
            for y in 0..h as usize {
                for x in 0..w as usize {
                    let mut sum = 0;
                    for k in 0..g.count() as usize {
                        let wt = g.weight(k, x, y);
                        let e = g.ext(k);
                        let inside =
                            x >= e.x && x < e.x + e.width && y >= e.y && y < e.y + e.height;
                        assert!(
                            inside || wt == 0,
                            "{g:?}: tile {k} weighs ({x},{y}) outside"
                        );
                        sum += wt;
                    }
                    assert_eq!(sum, g.weight_den(), "{g:?} at ({x},{y})");
                }
            }
        }
    }

    /// The split is the largest overview whose longer side is still ≥ 1024 (the 20 000²
    /// mosaic: overview 4, 1250²), else 1.
    #[test]
    fn the_split_keeps_a_screen_sized_overview_in_the_heads() {
        for ((w, h), k) in [
            ((20_000, 20_000), 4),
            ((4096, 4096), 2),
            ((4097, 10), 2),
            ((2400, 2400), 1),
            ((1000, 1000), 1),
            ((100_000, 10), 6),
            ((u32::MAX, 1), 12),
        ] {
            assert_eq!(heads_split(w, h), k, "{w} x {h}");
        }
    }

    #[test]
    fn a_margin_over_half_the_smallest_tile_is_refused() {
        let mut g = TileGrid::balanced(100, 100, 40, 8);
        assert_eq!(g.margin, 8);
        g.margin = 17; // tiles of 34
        assert!(g.check().is_err());
        // Tiles are never below the smallest a decoder accepts (16), so the default margin
        // fits: 40 in tiles of at most 16 is 2 tiles of 20, not 3 of 14.
        let mut g = TileGrid::balanced(40, 40, 16, 8);
        assert_eq!((g.tile_w, g.margin), (20, 8));
        g.margin = 11;
        assert!(g.check().is_err());
    }
}
