//! Version 5 (and 4), tiled files laid out for range reads (spec/FORMAT.md, "Version 4",
//! "Version 5"): what a reader fetches (counted through a `RangeSource`), progressive tiles
//! (an overview reads a prefix of each block and decodes exactly what the whole block
//! gives; at the file's split and coarser, one range of the heads), the index's and the
//! chunks' checks. The version-4 files here are the version-5 files rewritten.

use std::io::Cursor;
use vtz::source::HEAD_BYTES;
use vtz::{Decoder, EncodeOptions, Error, ErrorBound, Window};

use crate::common;
use common::{Counting, Kind, terrain};

fn crop(r: &vtz::Raster, w: Window) -> Vec<f64> {
    let mut out = Vec::with_capacity(w.width * w.height);
    for y in w.y..w.y + w.height {
        out.extend_from_slice(&r.data[y * r.width + w.x..y * r.width + w.x + w.width]);
    }
    out
}

fn opts(e: f64, tile: u32, effort: Option<u8>) -> EncodeOptions {
    let mut o = common::encode_opts(&[], Some(ErrorBound::Abs(e)));
    o.tile = Some(tile);
    o.effort = effort;
    o
}

/// A 1024² crop of the corpus's SRTM1 tile (Istria, int16 metres) at 1 m in 8 × 8 tiles of
/// 128², larger than the head read: at the default effort its tiles take the range-coded
/// interpolation coding, at effort 1 the fast coding (both progressive).
fn big_file(effort: Option<u8>) -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus/srtm1_N45E013_istria_crop2400.png");
    let src = vtz::read_path(&path, &Default::default()).unwrap();
    let (x0, y0, n) = (700, 900, 1024);
    let mut data = Vec::with_capacity(n * n);
    for y in y0..y0 + n {
        data.extend_from_slice(&src.data[y * src.width + x0..y * src.width + x0 + n]);
    }
    let mut crop = src;
    (crop.width, crop.height, crop.data, crop.mask, crop.georef) = (n, n, data, None, None);
    vtz::encode(&crop, &opts(1.0, 128, effort)).unwrap()
}

/// How many tiles have more than one chunk (their index entries, walked).
fn progressive_tiles(bytes: &[u8]) -> usize {
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let n = u32::from_le_bytes(bytes[20 + h..24 + h].try_into().unwrap());
    let mut at = 24 + h;
    let mut k = 0;
    for _ in 0..n {
        let c = bytes[at + 4] as usize;
        k += usize::from(c > 1);
        at += 40 + 8 * c;
    }
    k
}

/// Byte offset of a version-5 file's index length (in the header's tile fields: tile
/// width, height, margin, index length, split).
fn index_len_at(bytes: &[u8]) -> usize {
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    16 + h - 8
}

#[test]
fn a_tiled_encode_writes_version_5_index_first_then_heads_then_tails() {
    let bytes = big_file(None);
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 5);
    let info = vtz::info(&bytes, Default::default()).unwrap();
    assert_eq!(info.version, 5);
    let t = info.tiles.unwrap();
    assert_eq!(t.tiles.len(), 64);
    assert!(bytes.len() as u64 > 2 * HEAD_BYTES, "{} bytes", bytes.len());
    // A 1024² raster: split 1 (overview 1 is 512², under 1024).
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    assert_eq!(
        u32::from_le_bytes(bytes[12 + h..16 + h].try_into().unwrap()),
        1
    );
    // The index and global sections end before the first head, inside the first read.
    assert!(t.tiles[0].offset < HEAD_BYTES, "{}", t.tiles[0].offset);
    // Heads back to back, then tails back to back, the last ending the file; a tile's head
    // is the prefix of its block overview 1 reads, a few % of it.
    for w in t.tiles.windows(2) {
        assert_eq!(w[0].offset + w[0].head_bytes, w[1].offset);
        assert_eq!(
            w[0].tail_offset + w[0].bytes - w[0].head_bytes,
            w[1].tail_offset
        );
    }
    let last = t.tiles.last().unwrap();
    assert_eq!(last.offset + last.head_bytes, t.tiles[0].tail_offset);
    assert_eq!(
        last.tail_offset + last.bytes - last.head_bytes,
        bytes.len() as u64
    );
    // At 1 m the finest level (3/4 of the samples) is about half the bytes.
    let heads: u64 = t.tiles.iter().map(|e| e.head_bytes).sum();
    assert!(
        heads > 0 && heads < bytes.len() as u64 * 3 / 4,
        "heads {heads} of {}",
        bytes.len()
    );
}

#[test]
fn an_overview_at_the_split_or_coarser_is_one_range_of_the_heads() {
    for effort in [None, Some(1)] {
        let bytes = big_file(effort);
        let src = Counting::over_bytes(&bytes);
        let mut d = Decoder::open(src.clone()).unwrap();
        let heads: u64 = d
            .info()
            .tiles
            .as_ref()
            .unwrap()
            .tiles
            .iter()
            .map(|e| e.head_bytes)
            .sum();
        for k in 1..=3 {
            src.reset();
            d.options(common::decode_opts(|o| o.overview = Some(k)));
            let r = d.decode().unwrap();
            let (n, got) = src.requests();
            assert_eq!(n, 1, "effort {effort:?}, overview {k}: {n} requests");
            assert!(got <= heads, "overview {k}: {got} bytes, heads {heads}");
            // The same samples as from whole blocks.
            let whole = overview(&one_chunk_each(&bytes), k);
            assert_eq!(
                r.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                whole.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
    }
}

#[test]
fn opening_is_one_read_and_a_window_reads_only_its_rows_of_tiles() {
    for effort in [None, Some(1)] {
        let bytes = big_file(effort);
        let src = Counting::over_bytes(&bytes);
        let mut d = Decoder::open(src.clone()).unwrap();
        let calls = src.calls.lock().unwrap().clone();
        assert_eq!(calls.len(), 1, "opening: {calls:?}");
        assert_eq!(calls[0], vec![0..HEAD_BYTES]);
        let t = d.info().tiles.clone().unwrap();
        let full = vtz::decode(&bytes).unwrap();
        for win in [
            Window {
                x: 300,
                y: 300,
                width: 256,
                height: 256,
            },
            Window {
                x: 0,
                y: 0,
                width: 256,
                height: 256,
            },
            Window {
                x: 700,
                y: 10,
                width: 256,
                height: 256,
            },
            Window {
                x: 130,
                y: 130,
                width: 100,
                height: 100,
            },
        ] {
            src.reset();
            let r = d.window(win).decode().unwrap();
            assert_eq!(r.data, crop(&full, win), "{win:?}");
            let (n, got) = src.requests();
            // The tiles whose coded samples (core and margins) meet the window.
            let touched: Vec<&vtz::TileInfo> = t
                .tiles
                .iter()
                .filter(|e| {
                    let c = e.coded;
                    c.x < win.x + win.width
                        && win.x < c.x + c.width
                        && c.y < win.y + win.height
                        && win.y < c.y + c.height
                })
                .collect();
            let rows = {
                let mut r: Vec<usize> = touched.iter().map(|e| e.window.y).collect();
                r.dedup();
                r.len()
            };
            let need: u64 = touched.iter().map(|e| e.bytes).sum();
            // A range of heads and a range of tails per row of tiles (fewer where the heads
            // lie in the first read).
            assert!(
                n <= 2 * rows,
                "{win:?}: {n} requests for {rows} rows of tiles"
            );
            assert!(
                got as f64 <= 1.5 * need as f64,
                "{win:?}: fetched {got} bytes for tiles of {need}"
            );
        }
    }
}

/// The version-5 file rewritten as a version-4 file whose tiles are one chunk each (blocks
/// back to back, each its head and tail): a decoder then reads whole blocks for overviews.
fn one_chunk_each(bytes: &[u8]) -> Vec<u8> {
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let idx_at = 20 + h;
    let idx_len = u32::from_le_bytes(bytes[h + 8..h + 12].try_into().unwrap()) as usize;
    let info = vtz::info(bytes, Default::default()).unwrap();
    let t = info.tiles.unwrap();
    let block = |e: &vtz::TileInfo| {
        let mut b = bytes[e.offset as usize..(e.offset + e.head_bytes) as usize].to_vec();
        let rest = e.bytes - e.head_bytes;
        b.extend_from_slice(&bytes[e.tail_offset as usize..(e.tail_offset + rest) as usize]);
        b
    };
    let mut idx = Vec::new();
    idx.extend_from_slice(&bytes[idx_at..idx_at + 4]);
    let mut at = idx_at + 4;
    for e in &t.tiles {
        let c = bytes[at + 4] as usize;
        let mut fixed = bytes[at..at + 40].to_vec();
        fixed[4] = 1;
        idx.extend_from_slice(&fixed);
        idx.extend_from_slice(&(e.bytes as u32).to_le_bytes());
        idx.extend_from_slice(&crc32(&block(e)).to_le_bytes());
        at += 40 + 8 * c;
    }
    assert_eq!(at + 4, idx_at + idx_len, "walked the whole index");
    let crc = crc32(&idx);
    idx.extend_from_slice(&crc.to_le_bytes());
    // Version 4's header: the same body without the split, the new index length.
    let mut out = bytes[..16 + h - 4].to_vec();
    out[8..10].copy_from_slice(&4u16.to_le_bytes());
    out[12..16].copy_from_slice(&(h as u32 - 4).to_le_bytes());
    let new_len = idx.len() as u32;
    out[h + 8..h + 12].copy_from_slice(&new_len.to_le_bytes());
    let hcrc = crc32(&out);
    out.extend_from_slice(&hcrc.to_le_bytes());
    out.extend_from_slice(&idx);
    out.extend_from_slice(&bytes[idx_at + idx_len..t.tiles[0].offset as usize]);
    for e in &t.tiles {
        out.extend_from_slice(&block(e));
    }
    out
}

fn crc32(b: &[u8]) -> u32 {
    let mut c = !0u32;
    for &x in b {
        c ^= x as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn overview(bytes: &[u8], k: u32) -> vtz::Raster {
    let o = common::decode_opts(|o| o.overview = Some(k));
    vtz::decode_with(bytes, &o).unwrap()
}

#[test]
fn an_overview_reads_a_prefix_of_each_block_and_decodes_what_the_whole_block_gives() {
    for effort in [None, Some(1)] {
        let bytes = big_file(effort);
        assert!(
            progressive_tiles(&bytes) >= 48,
            "effort {effort:?}: {} of 64 tiles progressive",
            progressive_tiles(&bytes)
        );
        let whole = one_chunk_each(&bytes);
        assert_eq!(u16::from_le_bytes([whole[8], whole[9]]), 4);
        // The rewritten file is a valid version-4 file that decodes the same.
        assert_eq!(
            vtz::decode(&whole).unwrap().data,
            vtz::decode(&bytes).unwrap().data
        );
        for k in 1..=5 {
            let a = overview(&bytes, k);
            let b = overview(&whole, k);
            assert_eq!(
                a.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                b.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                "effort {effort:?}: overview {k} differs between prefixes and whole blocks"
            );
            assert_eq!(a.mask, b.mask);
            // And reads far less.
            let src = Counting::over_bytes(&bytes);
            let mut d = Decoder::open(src.clone()).unwrap();
            src.reset();
            d.options(common::decode_opts(|o| o.overview = Some(k)));
            d.decode().unwrap();
            let share = src.asked() as f64 / bytes.len() as f64;
            eprintln!(
                "effort {effort:?}: overview {k} read {:.1} % of the file",
                100.0 * share
            );
            if k >= 3 {
                assert!(
                    share < 0.35,
                    "effort {effort:?}: overview {k} read {share:.3} of the file"
                );
            }
        }
    }
}

#[test]
fn a_corrupt_chunk_fails_naming_the_tile_and_a_coarser_overview_does_not_read_it() {
    let bytes = big_file(Some(1));
    let info = vtz::info(&bytes, Default::default()).unwrap();
    let t = info.tiles.unwrap();
    let k = 9;
    let e = &t.tiles[k];
    let mut b = bytes.clone();
    // The block's last byte (in its tail): in its last chunk, which only a full decode reads.
    assert!(e.bytes > e.head_bytes);
    b[(e.tail_offset + e.bytes - e.head_bytes - 1) as usize] ^= 0x40;
    let err = vtz::decode(&b).unwrap_err();
    assert!(matches!(err, Error::Corrupt { .. }), "{err}");
    let m = err.to_string();
    assert!(m.contains("tile 9") && m.contains("checksum"), "{m}");
    assert_eq!(overview(&b, 3).data, overview(&bytes, 3).data);
}

#[test]
fn every_proper_prefix_of_a_version_5_and_4_file_is_rejected() {
    let src = terrain(Kind::Hill, 80, 70, 5, true, vtz::SampleType::I16);
    let bytes = vtz::encode(&src, &opts(1.0, 32, None)).unwrap();
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 5);
    let v4 = one_chunk_each(&bytes);
    assert_eq!(
        vtz::decode(&v4).unwrap().data,
        vtz::decode(&bytes).unwrap().data
    );
    for n in 0..v4.len() {
        assert!(
            Decoder::new(Cursor::new(v4[..n].to_vec())).is_err(),
            "version 4: prefix of {n} of {} bytes opened",
            v4.len()
        );
    }
    for n in 0..bytes.len() {
        assert!(
            Decoder::new(Cursor::new(bytes[..n].to_vec())).is_err(),
            "prefix of {n} of {} bytes opened",
            bytes.len()
        );
    }
    let mut longer = bytes.clone();
    longer.push(0);
    let e = Decoder::new(Cursor::new(longer)).err().unwrap();
    assert!(e.to_string().contains("after the last tile"), "{e}");
}

/// Rewrite byte `at` of tile `k`'s entry (its fixed 40 bytes and chunk table) and fix the
/// index checksum.
fn patch_entry(bytes: &[u8], k: usize, at: usize, value: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let h = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    let idx_at = 20 + h;
    let il = index_len_at(&b);
    let idx_len = u32::from_le_bytes(b[il..il + 4].try_into().unwrap()) as usize;
    let mut e = idx_at + 4;
    for _ in 0..k {
        e += 40 + 8 * b[e + 4] as usize;
    }
    b[e + at..e + at + value.len()].copy_from_slice(value);
    let end = idx_at + idx_len - 4;
    let crc = crc32(&b[idx_at..end]);
    b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    b
}

fn corrupt_msg(bytes: &[u8]) -> String {
    match Decoder::new(Cursor::new(bytes.to_vec())).and_then(|mut d| d.decode()) {
        Err(e @ Error::Corrupt { .. }) => e.to_string(),
        Err(e) => panic!("not a corrupt error: {e}"),
        Ok(_) => panic!("decoded a corrupt file"),
    }
}

/// A split the file was not written with: the heads and tails are cut elsewhere than the
/// reader thinks, so a chunk fails its checksum.
#[test]
fn a_wrong_split_fails_a_chunk_checksum() {
    let bytes = big_file(Some(1));
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let il = index_len_at(&bytes);
    let mut b = bytes.clone();
    b[il + 4..il + 8].copy_from_slice(&3u32.to_le_bytes());
    let hcrc = crc32(&b[..16 + h]);
    b[16 + h..20 + h].copy_from_slice(&hcrc.to_le_bytes());
    let m = corrupt_msg(&b);
    assert!(m.contains("checksum"), "{m}");
}

#[test]
fn corrupt_version_5_indexes_are_rejected_naming_the_tile() {
    let src = terrain(Kind::Hill, 150, 100, 5, true, vtz::SampleType::I16);
    let bytes = vtz::encode(&src, &opts(1.0, 40, None)).unwrap();
    let t = vtz::info(&bytes, Default::default())
        .unwrap()
        .tiles
        .unwrap();
    assert_eq!(t.tiles.len(), 12);
    let w = t.tiles[3].window;
    // No chunks; too many; reserved bytes set.
    let m = corrupt_msg(&patch_entry(&bytes, 3, 4, &[0]));
    assert!(
        m.contains(&format!("tile 3 (at {},{})", w.x, w.y)) && m.contains("chunks"),
        "{m}"
    );
    let m = corrupt_msg(&patch_entry(&bytes, 3, 4, &[14]));
    assert!(m.contains("tile 3"), "{m}");
    let m = corrupt_msg(&patch_entry(&bytes, 3, 5, &[1]));
    assert!(m.contains("reserved"), "{m}");
    // A method that cannot be primary; unknown flags.
    let m = corrupt_msg(&patch_entry(&bytes, 2, 0, &1u16.to_le_bytes()));
    assert!(m.contains("tile 2") && m.contains("representation"), "{m}");
    let m = corrupt_msg(&patch_entry(&bytes, 2, 2, &4u16.to_le_bytes()));
    assert!(m.contains("flags"), "{m}");
    // A valid count above the tile's samples; a reversed range; a negative max error.
    let m = corrupt_msg(&patch_entry(&bytes, 2, 8, &1_000_000u64.to_le_bytes()));
    assert!(m.contains("valid samples"), "{m}");
    let m = corrupt_msg(&patch_entry(&bytes, 2, 16, &1e9f64.to_le_bytes()));
    assert!(m.contains("range"), "{m}");
    let m = corrupt_msg(&patch_entry(&bytes, 2, 32, &(-1.0f64).to_le_bytes()));
    assert!(m.contains("max error"), "{m}");
    // A chunk end beyond the file, and a first chunk too short for a block header.
    let m = corrupt_msg(&patch_entry(&bytes, 11, 40, &u32::MAX.to_le_bytes()));
    assert!(m.contains("truncated") || m.contains("tile 11"), "{m}");
    let m = corrupt_msg(&patch_entry(&bytes, 5, 40, &4u32.to_le_bytes()));
    assert!(m.contains("tile 5"), "{m}");
    // A bad checksum of the index itself.
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut b = bytes.clone();
    b[20 + h + 10] ^= 1;
    assert!(corrupt_msg(&b).contains("tile index checksum"));
    // An index length the tiles cannot fill; a split out of range (0, 13).
    let il = index_len_at(&bytes);
    for (at, v, what) in [
        (il, 7u32, "index"),
        (il + 4, 0, "split"),
        (il + 4, 13, "split"),
    ] {
        let mut b = bytes.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        let hcrc = crc32(&b[..16 + h]);
        b[16 + h..20 + h].copy_from_slice(&hcrc.to_le_bytes());
        let m = corrupt_msg(&b);
        assert!(m.contains(what), "{what} {v}: {m}");
    }
    let limits = vtz::Limits {
        max_section_bytes: 100,
        ..Default::default()
    };
    let e = Decoder::with_limits(Cursor::new(bytes.clone()), limits)
        .err()
        .unwrap();
    assert!(matches!(e, Error::LimitExceeded { .. }), "{e}");
}

/// In a version-5 (and 4) file the residual layer keeps the weighted scan (no coarse levels: an
/// overview reads its whole block) only where it saves more than 15 % over interpolation.
/// Kauai at 1 m in 256² tiles: the weighted scan is ~2 % smaller there, and before this rule
/// it coded every residual tile (none progressive); now they take the levels-first coding.
#[test]
fn tiles_prefer_codings_with_coarse_levels_first() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus/srtm3_N22W160_kauai.hgt");
    let src = vtz::read_path(&path, &Default::default()).unwrap();
    let bytes = vtz::encode(&src, &opts(1.0, 256, None)).unwrap();
    let h = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let n = u32::from_le_bytes(bytes[20 + h..24 + h].try_into().unwrap());
    let mut at = 24 + h;
    let (mut residual, mut progressive) = (0, 0);
    for _ in 0..n {
        let method = u16::from_le_bytes([bytes[at], bytes[at + 1]]);
        let c = bytes[at + 4] as usize;
        if method == 6 {
            residual += 1;
            progressive += usize::from(c > 1);
        }
        at += 40 + 8 * c;
    }
    assert!(residual >= 3, "{residual} residual tiles");
    assert!(
        progressive * 2 >= residual,
        "{progressive} of {residual} residual tiles have coarse levels first"
    );
    // Still within the bound, and the overviews decode from the prefixes.
    let d = vtz::decode(&bytes).unwrap();
    for i in 0..d.len() {
        if src.is_valid(i) {
            assert!((d.data[i] - src.data[i]).abs() <= 1.0);
        }
    }
    overview(&bytes, 2);
}
