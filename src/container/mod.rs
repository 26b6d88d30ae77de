//! The `.vtz` byte layout: magic, version, header, a checksummed section directory and the
//! section payloads (spec/FORMAT.md). Only this module knows section framing.

pub mod bitmap;
pub mod bytes;
pub mod flat;
pub mod header;
pub mod mask;
pub mod points;
pub mod tiled;

pub use header::Header;

use crate::error::{Error, Result};
use bytes::{ByteReader, PutLe};
use std::io::{Read, Seek, SeekFrom};

/// The 8 magic bytes every `.vtz` file starts with.
pub const MAGIC: [u8; 8] = [0x89, b'V', b'T', b'Z', 0x0d, 0x0a, 0x1a, 0x0a];
/// The container version of an untiled raster (one container).
pub const VERSION: u16 = 1;
/// The container version of tiled files (`tiled`) with the index at the end (read forever, no
/// longer written).
pub const VERSION_TILED: u16 = 2;
/// The container version of tiled files laid out for range reads: header, tile index and
/// global sections first, progressive tile blocks (spec/FORMAT.md, "Version 4").
pub const VERSION_CLOUD: u16 = 4;
/// The container version of tiled files laid out for range reads with every tile's coarse
/// chunks together before the rest (spec/FORMAT.md, "Version 5"): an overview at or coarser
/// than the file's split is one range. What vtz writes for tiled rasters.
pub const VERSION_HEADS: u16 = 5;
/// The container version of a point set (`points`).
pub const VERSION_POINTS: u16 = 3;
/// Most sections a decoder accepts in one file.
pub const MAX_SECTIONS: u32 = 4096;
/// Bytes of one directory entry.
pub const DIR_ENTRY_LEN: usize = 16;

/// Section flag: a decoder that does not know this section's type must reject the file.
pub const SF_REQUIRED: u16 = 1;
const SF_KNOWN: u16 = SF_REQUIRED;

/// A section type code (spec/FORMAT.md, "Section types"). The container knows the framing
/// types (mask, metadata) and the reserved residual type; the codes of the methods' sections
/// belong to the methods, and the codec names them to the reader ([`KindNames`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SectionKind(pub u16);

impl SectionKind {
    /// Validity mask (nodata samples).
    pub const MASK: SectionKind = SectionKind(1);
    /// Free-form UTF-8 JSON metadata.
    pub const METADATA: SectionKind = SectionKind(7);
    /// GDAL's metadata XML (GeoTIFF tag 42112 `GDAL_METADATA`), UTF-8, verbatim.
    pub const GDAL_METADATA: SectionKind = SectionKind(8);
    /// Flat regions: samples every method decodes to their region's exact value.
    pub const FLAT: SectionKind = SectionKind(9);

    /// The type code as stored.
    pub fn code(self) -> u16 {
        self.0
    }
    /// The type of a stored code.
    pub fn from_code(c: u16) -> SectionKind {
        SectionKind(c)
    }
    /// Whether a section of this type may be the primary one: any type but the framing
    /// types that hold data *about* the raster (mask, metadata, gdal-metadata). Unknown types
    /// may be, so that a future representation can be primary.
    pub fn may_be_primary(self) -> bool {
        !matches!(
            self,
            SectionKind::MASK
                | SectionKind::METADATA
                | SectionKind::GDAL_METADATA
                | SectionKind::FLAT
        )
    }
    /// The name of a framing or reserved type, `None` for the methods' types.
    fn framing_name(self) -> Option<&'static str> {
        match self {
            SectionKind::MASK => Some("mask"),
            SectionKind::METADATA => Some("metadata"),
            SectionKind::GDAL_METADATA => Some("gdal-metadata"),
            SectionKind::FLAT => Some("flat"),
            _ => None,
        }
    }
}

/// The names of the section types the methods own (`None` for a code no method owns); the
/// codec passes its registry's so the container can name and check them without knowing
/// any method.
pub type KindNames = fn(SectionKind) -> Option<&'static str>;

/// The name of a section type: framing, a method's, or `unknown-N`.
pub fn kind_name(k: SectionKind, names: KindNames) -> String {
    match k.framing_name().or_else(|| names(k)) {
        Some(n) => n.to_string(),
        None => format!("unknown-{}", k.0),
    }
}

/// A section as it is written: its kind, flags and payload.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// Its type.
    pub kind: SectionKind,
    /// Its flags ([`SF_REQUIRED`]).
    pub flags: u16,
    /// Its bytes.
    pub payload: Vec<u8>,
}

/// A directory entry as read: where a section is and how to check it.
#[derive(Clone, Debug, PartialEq)]
pub struct SectionEntry {
    /// Its type.
    pub kind: SectionKind,
    /// The type's name (`unknown-N` for a type this decoder does not know).
    pub name: String,
    /// Its flags ([`SF_REQUIRED`]).
    pub flags: u16,
    /// CRC-32 of the payload.
    pub crc: u32,
    /// Byte offset of the payload in the file.
    pub offset: u64,
    /// Payload length in bytes.
    pub length: u64,
}

/// Resource limits a decoder enforces on untrusted input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Most samples (width × height) a decoded raster may have.
    pub max_samples: u64,
    /// Most bytes any one section may hold.
    pub max_section_bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_samples: crate::model::DEFAULT_MAX_SAMPLES,
            max_section_bytes: 1 << 32,
        }
    }
}

/// Serialize a complete file: header then `sections` in order.
pub fn write(header: &Header, sections: &[Section]) -> Vec<u8> {
    let body = header.to_bytes();
    let payload_len: usize = sections.iter().map(|s| s.payload.len()).sum();
    let mut out =
        Vec::with_capacity(32 + body.len() + sections.len() * DIR_ENTRY_LEN + payload_len);
    FileStart::write(&mut out, VERSION, &body);
    directory_bytes(&mut out, sections);
    out
}

pub(crate) fn read_exact<R: Read>(r: &mut R, buf: &mut [u8], what: &str) -> Result<()> {
    r.read_exact(buf).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            Error::corrupt(format!("file is truncated in the {what}"))
        } else {
            Error::io(format!("reading the {what}"), e)
        }
    })
}

/// Reads a `.vtz` file's header and directory, then sections on demand, from any seekable
/// source. Construction checks the framing (magic, version, checksums, that the declared
/// lengths add up to the file's length); `read_section` checks each payload's checksum.
pub struct ContainerReader<R> {
    inner: R,
    header: Header,
    entries: Vec<SectionEntry>,
    limits: Limits,
    /// The bytes `inner` holds: the file's length, or for a version-4 tile read for an
    /// overview a prefix of its block, whose last (primary) section may end beyond it.
    available: u64,
}

/// The start every `.vtz` file has, whatever its version (spec/FORMAT.md): the magic, the
/// version, the required feature flags, the header's length, its body and the checksum over
/// all of them. Read and checked here once for every reader; what follows it (a section
/// directory, a tile index, a point-set header's body) is the version's.
pub struct FileStart {
    /// The container version.
    pub version: u16,
    /// The header body, its checksum checked.
    pub body: Vec<u8>,
    /// The file's length.
    pub file_len: u64,
}

impl FileStart {
    /// Write a file's start: the magic, `version`, no required flags (none is defined), the
    /// length of `body`, `body` and the checksum over all of them (what [`FileStart::read`]
    /// reads back), at the start of `out`.
    pub fn write(out: &mut Vec<u8>, version: u16, body: &[u8]) {
        let start = out.len();
        out.extend_from_slice(&MAGIC);
        out.put_u16(version);
        out.put_u16(0);
        out.put_u32(body.len() as u32);
        out.extend_from_slice(body);
        let crc = crc32fast::hash(&out[start..]);
        out.put_u32(crc);
    }

    /// Read and check a file's start from `inner` (any position; left after the header's
    /// checksum). `accept` says whether this reader reads the version (checked before the
    /// flags and the header, which a version it does not read may lay out otherwise).
    pub fn read<R: Read + Seek>(
        inner: &mut R,
        accept: impl FnOnce(u16) -> Result<()>,
    ) -> Result<FileStart> {
        let file_len = inner
            .seek(SeekFrom::End(0))
            .map_err(|e| Error::io("measuring the file", e))?;
        inner
            .seek(SeekFrom::Start(0))
            .map_err(|e| Error::io("seeking", e))?;
        let mut fixed = [0u8; 16];
        if file_len < 16 {
            // Tell "not a vtz file" apart from "a truncated one" where the bytes allow.
            let mut head = vec![0u8; file_len as usize];
            read_exact(inner, &mut head, "file start")?;
            if MAGIC.starts_with(&head[..head.len().min(8)]) {
                return Err(Error::corrupt("file is truncated in the file start"));
            }
            return Err(Error::corrupt("not a vtz file (bad magic)"));
        }
        read_exact(inner, &mut fixed, "file start")?;
        if fixed[..8] != MAGIC {
            return Err(Error::corrupt("not a vtz file (bad magic)"));
        }
        let version = u16::from_le_bytes([fixed[8], fixed[9]]);
        accept(version)?;
        let req = u16::from_le_bytes([fixed[10], fixed[11]]);
        if req != 0 {
            return Err(Error::unsupported(format!(
                "required feature flags 0x{req:04x} are not known to this decoder"
            )));
        }
        let hlen = u32::from_le_bytes([fixed[12], fixed[13], fixed[14], fixed[15]]);
        if hlen > header::MAX_HEADER_LEN {
            return Err(Error::corrupt(format!(
                "header length {hlen} is over the limit of {}",
                header::MAX_HEADER_LEN
            )));
        }
        if 16 + hlen as u64 + 4 > file_len {
            return Err(Error::corrupt("file is truncated in the header"));
        }
        let mut body = vec![0u8; hlen as usize + 4];
        read_exact(inner, &mut body, "header")?;
        let crc_bytes = body.split_off(hlen as usize);
        let mut h = crc32fast::Hasher::new();
        h.update(&fixed);
        h.update(&body);
        if !checksum_ok(h.finalize(), &crc_bytes) {
            return Err(Error::corrupt("header checksum mismatch"));
        }
        Ok(FileStart {
            version,
            body,
            file_len,
        })
    }

    /// Where the header's checksum ends: what the version puts after its header starts.
    pub fn end(&self) -> u64 {
        16 + self.body.len() as u64 + 4
    }
}

impl<R: Read + Seek> ContainerReader<R> {
    /// Open a version-1 file: its start, header and directory checked (the decoder opens
    /// every version through [`tiled::RasterReader`]).
    #[cfg(any(test, feature = "internals"))]
    pub fn new(mut inner: R, limits: Limits, names: KindNames) -> Result<Self> {
        let start = FileStart::read(&mut inner, |version| {
            if version != VERSION {
                return Err(Error::unsupported(format!(
                    "vtz format version {version} (this decoder reads versions 1–5)"
                )));
            }
            Ok(())
        })?;
        ContainerReader::after_start(inner, &start, limits, names)
    }

    /// A version-1 file whose start was read ([`FileStart::read`]): its header and directory.
    pub fn after_start(
        mut inner: R,
        start: &FileStart,
        limits: Limits,
        names: KindNames,
    ) -> Result<Self> {
        let file_len = start.file_len;
        let body = &start.body[..];
        let header = Header::from_bytes(body)?;
        if header.samples() > limits.max_samples {
            return Err(Error::limit(format!(
                "raster of {}x{} = {} samples is over the limit of {}",
                header.width,
                header.height,
                header.samples(),
                limits.max_samples
            )));
        }
        let entries = read_directory(&mut inner, start.end(), file_len, &limits, names, "")?;
        check_primary(&entries, header.primary)?;
        Ok(ContainerReader {
            inner,
            header,
            entries,
            limits,
            available: file_len,
        })
    }

    /// A reader over one tile of a version-2 file: `inner` holds the tile's block
    /// (spec/FORMAT.md, "Tile block"), `header` the tile's own header (its size, and the
    /// file's sample type, mapping, nodata and georef). `what` names the tile in errors.
    ///
    /// `block_len` is the block's length; `inner` may hold only a prefix of it (a version-4
    /// tile read for an overview): the directory and every section but the primary, which
    /// is then the last, must lie in the prefix, and the primary's payload is what of it the
    /// prefix holds ([`ContainerReader::read_section`]).
    pub fn tile(
        mut inner: R,
        mut header: Header,
        block_len: u64,
        limits: Limits,
        names: KindNames,
        what: &str,
    ) -> Result<Self> {
        let available = inner
            .seek(SeekFrom::End(0))
            .map_err(|e| Error::io("measuring the tile", e))?;
        let len = block_len;
        inner
            .seek(SeekFrom::Start(0))
            .map_err(|e| Error::io("seeking", e))?;
        let mut head = [0u8; 4];
        if len < 4 {
            return Err(Error::corrupt(format!(
                "{what} is truncated in its block header"
            )));
        }
        read_exact(&mut inner, &mut head, "tile block")?;
        let primary = u16::from_le_bytes([head[0], head[1]]);
        let reserved = u16::from_le_bytes([head[2], head[3]]);
        if reserved != 0 {
            return Err(Error::corrupt(format!(
                "{what}: reserved field is {reserved}, not 0"
            )));
        }
        header.primary = primary;
        let entries = read_directory(&mut inner, 4, len, &limits, names, what)?;
        check_primary(&entries, primary).map_err(|e| e.context(what))?;
        if available < len {
            // A prefix: only the primary, the last section, may reach beyond it.
            let last = entries.len().checked_sub(1);
            for (i, e) in entries.iter().enumerate() {
                if e.offset + e.length > available && (Some(i) != last || i != primary as usize) {
                    return Err(Error::corrupt(format!(
                        "{what}: section {i} ({}) lies beyond the block's first chunks",
                        e.name
                    )));
                }
            }
        }
        Ok(ContainerReader {
            inner,
            header,
            entries,
            limits,
            available: available.min(len),
        })
    }
}

impl<R: Read + Seek> ContainerReader<R> {
    pub fn header(&self) -> &Header {
        &self.header
    }
    pub fn entries(&self) -> &[SectionEntry] {
        &self.entries
    }
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Index of the first section of `kind`, if any.
    pub fn find(&self, kind: SectionKind) -> Option<usize> {
        self.entries.iter().position(|e| e.kind == kind)
    }

    /// The validity mask (from the first mask section), or `None` when every sample is valid.
    pub fn read_mask(&mut self) -> Result<Option<Vec<bool>>> {
        let n = self.header.samples() as usize;
        match self.find(SectionKind::MASK) {
            Some(i) => Ok(Some(mask::decode(
                &self.read_section(i)?,
                self.header.width as usize,
                n,
            )?)),
            None => Ok(None),
        }
    }

    /// The flat regions (from the first flat section) of a raster with validity `mask`: per
    /// sample its region's value, NaN elsewhere; `None` when the file has none.
    pub fn read_flat(&mut self, mask: Option<&[bool]>) -> Result<Option<flat::Flat>> {
        let n = self.header.samples() as usize;
        let w = self.header.width as usize;
        match self.find(SectionKind::FLAT) {
            Some(i) => {
                let lattice = (self.header.sample_type, self.header.mapping);
                Ok(Some(flat::decode(
                    &self.read_section(i)?,
                    w,
                    n,
                    mask,
                    lattice,
                )?))
            }
            None => Ok(None),
        }
    }

    /// GDAL's metadata XML from the first gdal-metadata section, `None` when there is none.
    /// The payload must be UTF-8 (spec/FORMAT.md): anything else is a corrupt file.
    pub fn read_gdal_metadata(&mut self) -> Result<Option<String>> {
        let Some(i) = self.find(SectionKind::GDAL_METADATA) else {
            return Ok(None);
        };
        let bytes = self.read_section(i)?;
        String::from_utf8(bytes).map(Some).map_err(|e| {
            Error::corrupt(format!(
                "section {i} (gdal-metadata) is not UTF-8 (invalid byte at payload offset {})",
                e.utf8_error().valid_up_to()
            ))
        })
    }

    /// Read section `i`'s payload and check its checksum.
    pub fn read_section(&mut self, i: usize) -> Result<Vec<u8>> {
        let e = self
            .entries
            .get(i)
            .ok_or_else(|| Error::invalid(format!("no section {i}")))?
            .clone();
        self.inner
            .seek(SeekFrom::Start(e.offset))
            .map_err(|err| Error::io("seeking", err))?;
        if e.offset + e.length > self.available {
            // The primary section of a tile read as a prefix (checked on opening): what of
            // it the prefix holds, whose bytes the chunks' checksums covered.
            let mut buf = vec![0u8; (self.available - e.offset.min(self.available)) as usize];
            read_exact(&mut self.inner, &mut buf, &format!("{} section", e.name))?;
            return Ok(buf);
        }
        // The length was checked against the file length when the directory was read.
        let mut buf = vec![0u8; e.length as usize];
        read_exact(&mut self.inner, &mut buf, &format!("{} section", e.name))?;
        if !checksum_ok(crc32fast::hash(&buf), &e.crc.to_le_bytes()) {
            return Err(Error::corrupt(format!(
                "section {i} ({}): checksum mismatch",
                e.name
            )));
        }
        Ok(buf)
    }
}

/// Read a section directory at `dir_pos` (count, entries, checksum) whose payloads follow it
/// back to back and end exactly at `end`. `what` prefixes errors (the tile, in a tiled file).
pub(crate) fn read_directory<R: Read + Seek>(
    inner: &mut R,
    dir_pos: u64,
    end: u64,
    limits: &Limits,
    names: KindNames,
    what: &str,
) -> Result<Vec<SectionEntry>> {
    read_directory_to(inner, dir_pos, end, true, limits, names, what).map(|(e, _)| e)
}

/// [`read_directory`], where the payloads end exactly at `end` (`exact`) or anywhere up to
/// it; gives the entries and where the payloads end.
pub(crate) fn read_directory_to<R: Read + Seek>(
    inner: &mut R,
    dir_pos: u64,
    end: u64,
    exact: bool,
    limits: &Limits,
    names: KindNames,
    what: &str,
) -> Result<(Vec<SectionEntry>, u64)> {
    let pre = |m: String| match (what.is_empty(), m.starts_with("truncated")) {
        (true, true) => format!("file is {m}"),
        (true, false) => m,
        (false, _) => format!("{what}: {m}"),
    };
    inner
        .seek(SeekFrom::Start(dir_pos))
        .map_err(|e| Error::io("seeking", e))?;
    let mut cnt = [0u8; 4];
    if dir_pos + 4 > end {
        return Err(Error::corrupt(pre(
            "truncated in the section directory".into()
        )));
    }
    read_exact(inner, &mut cnt, "section directory")?;
    let count = u32::from_le_bytes(cnt);
    if count > MAX_SECTIONS {
        return Err(Error::corrupt(pre(format!(
            "section count {count} is over the limit of {MAX_SECTIONS}"
        ))));
    }
    let dir_len = count as u64 * DIR_ENTRY_LEN as u64 + 4;
    if dir_pos + 4 + dir_len > end {
        return Err(Error::corrupt(pre(
            "truncated in the section directory".into()
        )));
    }
    let mut dbuf = vec![0u8; dir_len as usize];
    read_exact(inner, &mut dbuf, "section directory")?;
    let (entries_bytes, crc_bytes) = dbuf.split_at(dbuf.len() - 4);
    let mut h = crc32fast::Hasher::new();
    h.update(&cnt);
    h.update(entries_bytes);
    if !checksum_ok(h.finalize(), crc_bytes) {
        return Err(Error::corrupt(pre(
            "section directory checksum mismatch".into()
        )));
    }
    let mut r = ByteReader::new(entries_bytes, "section directory");
    let mut offset = dir_pos + 4 + dir_len;
    let mut entries = Vec::with_capacity(count as usize);
    for i in 0..count {
        let kind = SectionKind::from_code(r.u16("section type")?);
        let name = kind_name(kind, names);
        let known = kind.framing_name().is_some() || names(kind).is_some();
        let flags = r.u16("section flags")?;
        let crc = r.u32("section checksum")?;
        let length = r.u64("section length")?;
        if kind.code() == 0 {
            return Err(Error::corrupt(pre(format!(
                "section {i}: type 0 is reserved"
            ))));
        }
        if flags & !SF_KNOWN != 0 {
            return Err(Error::unsupported(pre(format!(
                "section {i} ({}): unknown flags 0x{:04x}",
                name,
                flags & !SF_KNOWN
            ))));
        }
        if !known && flags & SF_REQUIRED != 0 {
            return Err(Error::unsupported(pre(format!(
                "section {i} has type {}, which this decoder does not know and the file requires",
                kind.0
            ))));
        }
        if length > limits.max_section_bytes {
            return Err(Error::limit(pre(format!(
                "section {i} ({}) of {length} bytes is over the limit of {}",
                name, limits.max_section_bytes
            ))));
        }
        let e = offset
            .checked_add(length)
            .filter(|&e| e <= end)
            .ok_or_else(|| {
                Error::corrupt(pre(format!(
                    "truncated in section {i} ({}): it needs {length} bytes at offset {offset}, only {end} are there",
                    name
                )))
            })?;
        entries.push(SectionEntry {
            kind,
            name,
            flags,
            crc,
            offset,
            length,
        });
        offset = e;
    }
    if exact && offset != end {
        return Err(Error::corrupt(pre(format!(
            "{} unexpected bytes after the last section",
            end - offset
        ))));
    }
    Ok((entries, offset))
}

/// Check that the primary index names a representation section (any section when there
/// is none and the index is 0).
fn check_primary(entries: &[SectionEntry], primary: u16) -> Result<()> {
    if entries.is_empty() && primary == 0 {
        return Ok(());
    }
    match entries.get(primary as usize) {
        Some(e) if e.kind.may_be_primary() => Ok(()),
        Some(e) => Err(Error::corrupt(format!(
            "primary section {} is a {} section, not a representation",
            primary, e.name
        ))),
        None => Err(Error::corrupt(format!(
            "primary section {} does not exist ({} sections)",
            primary,
            entries.len()
        ))),
    }
}

/// Whether a computed CRC-32 equals the stored little-endian one. Fuzzing builds (cargo
/// fuzz sets `--cfg fuzzing`) accept any stored value, as image-png does, so the fuzzer
/// reaches the parsers behind the checksums; every other build checks.
fn checksum_ok(computed: u32, stored: &[u8]) -> bool {
    cfg!(fuzzing) || stored == computed.to_le_bytes()
}

/// A whole file in memory: header plus every section (checksums verified).
#[cfg(any(test, feature = "internals"))]
#[derive(Clone, Debug, PartialEq)]
pub struct Container {
    pub header: Header,
    pub sections: Vec<Section>,
}

/// Parse a complete file from memory, verifying every checksum.
#[cfg(any(test, feature = "internals"))]
pub fn read(bytes: &[u8], limits: Limits, names: KindNames) -> Result<Container> {
    let mut r = ContainerReader::new(std::io::Cursor::new(bytes), limits, names)?;
    let mut sections = Vec::with_capacity(r.entries().len());
    for i in 0..r.entries().len() {
        let payload = r.read_section(i)?;
        let e = &r.entries()[i];
        sections.push(Section {
            kind: e.kind,
            flags: e.flags,
            payload,
        });
    }
    Ok(Container {
        header: r.header().clone(),
        sections,
    })
}
/// The bytes of a section directory (count, entries, checksum) followed by the payloads.
pub(crate) fn directory_bytes(out: &mut Vec<u8>, sections: &[Section]) {
    let dir_start = out.len();
    out.put_u32(sections.len() as u32);
    for s in sections {
        out.put_u16(s.kind.code());
        out.put_u16(s.flags);
        out.put_u32(crc32fast::hash(&s.payload));
        out.put_u64(s.payload.len() as u64);
    }
    let crc = crc32fast::hash(&out[dir_start..]);
    out.put_u32(crc);
    for s in sections {
        out.extend_from_slice(&s.payload);
    }
}
