//! Hostile headers: the golden files with their size (and other header fields) edited and
//! the mask or flat section made a private optional type, checksums recomputed by the
//! spec's rules, so only the decoder's own checks stand between such a file and an
//! allocation or a loop sized by the edited header. Every one must decode or fail cleanly
//! (exit 0 or 1, never a panic) within a time and memory budget, run as the `vtz` binary:
//! CPU time and peak resident memory are read from `/proc` while it runs (Linux only).
//!
//! The same edits make hostile fuzz seeds (`fuzz/hostile.py`, run by `fuzz/make_seeds.py`).

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const MASK: u16 = 1;
const FLAT: u16 = 9;
const PRIVATE: u16 = 0x8000;

/// CPU seconds a hostile file may cost (today's decoder needs ~0.01 s for any of them).
const CPU_BUDGET: f64 = 1.0;
/// Peak resident memory a hostile file may cost over the decode of the file it was made
/// from (the files are ≤ 64 KB: their payloads do not count).
const RSS_BUDGET_KB: u64 = 64 * 1024;

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

/// `data` with the header fields `(offset, little-endian bytes)` set and the directory
/// entries of the types in `retype` made private and optional; both checksums recomputed
/// (FORMAT.md: CRC-32 of `[0, 16+H)` and of the count and entries).
fn edited(data: &[u8], fields: &[(usize, Vec<u8>)], retype: &[u16]) -> Vec<u8> {
    let mut b = data.to_vec();
    for (at, v) in fields {
        b[*at..*at + v.len()].copy_from_slice(v);
    }
    let hend = 16 + u32_at(&b, 12) as usize;
    let crc = crc32fast::hash(&b[..hend]);
    b[hend..hend + 4].copy_from_slice(&crc.to_le_bytes());
    let dir = hend + 4;
    let count = u32_at(&b, dir) as usize;
    for k in 0..count {
        let e = dir + 4 + 16 * k;
        if retype.contains(&u16_at(&b, e)) {
            b[e..e + 2].copy_from_slice(&PRIVATE.to_le_bytes());
            b[e + 2..e + 4].copy_from_slice(&0u16.to_le_bytes());
        }
    }
    let end = dir + 4 + 16 * count;
    let crc = crc32fast::hash(&b[dir..end]);
    b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    b
}

/// The hostile edits of one valid file, by name (as `fuzz/hostile.py` makes them).
fn variants(data: &[u8]) -> Vec<(String, Vec<u8>)> {
    let version = u16_at(data, 8);
    let hlen = u32_at(data, 12) as usize;
    let le32 = |v: u32| v.to_le_bytes().to_vec();
    let le64 = |v: u64| v.to_le_bytes().to_vec();
    let mut out = Vec::new();
    match version {
        1 | 2 => {
            let (w, h) = (u32_at(data, 16), u32_at(data, 20));
            let sizes = [
                (16384, 16384),
                (4096, 4096),
                (256, 256),
                (1 << 28, 1),
                (1, 1 << 28),
                (65536, 4096),
                (2 * w, h),
                (w, h + 1),
                (w + 1, h),
                ((w - 1).max(1), h),
            ];
            for (nw, nh) in sizes {
                let f = [(16, le32(nw)), (20, le32(nh))];
                let name = format!("size{nw}x{nh}");
                out.push((name.clone(), edited(data, &f, &[])));
                out.push((format!("{name}.nomask"), edited(data, &f, &[MASK])));
                out.push((
                    format!("{name}.nomaskflat"),
                    edited(data, &f, &[MASK, FLAT]),
                ));
            }
            if version == 2 {
                // The tile fields end the header body: tile_width, tile_height, margin, index.
                let t = 16 + hlen - 28;
                for (tw, th) in [(16, 16), (w, 16), (16, h)] {
                    let f = [(t, le32(tw)), (t + 4, le32(th))];
                    out.push((format!("tile{tw}x{th}"), edited(data, &f, &[])));
                }
                out.push((
                    "margin".into(),
                    edited(data, &[(t + 8, le32(1 << 30))], &[]),
                ));
            }
        }
        3 => {
            let big = 1u64 << 27;
            let ext = le32((1 << 24) + 1);
            for (name, f) in [
                ("points", vec![(16, le64(big))]),
                ("positions", vec![(24, le64(big))]),
                ("both", vec![(16, le64(big)), (24, le64(big))]),
                ("extent", vec![(60, ext.clone()), (64, ext.clone())]),
                (
                    "all",
                    vec![
                        (16, le64(big)),
                        (24, le64(big)),
                        (60, ext.clone()),
                        (64, ext),
                    ],
                ),
            ] {
                out.push((name.into(), edited(data, &f, &[])));
            }
        }
        4 | 5 => {
            // Versions 4 and 5: the tile index follows the header, so only the header's
            // fields are edited (its checksum recomputed): sizes, tile sides, the margin, the
            // index length and (version 5) the split, which end the header body.
            let (w, h) = (u32_at(data, 16), u32_at(data, 20));
            let t = 16 + hlen - if version == 5 { 20 } else { 16 };
            let header_only = |f: &[(usize, Vec<u8>)]| {
                let mut b = data.to_vec();
                for (at, v) in f {
                    b[*at..*at + v.len()].copy_from_slice(v);
                }
                let crc = crc32fast::hash(&b[..16 + hlen]);
                b[16 + hlen..20 + hlen].copy_from_slice(&crc.to_le_bytes());
                b
            };
            for (nw, nh) in [
                (16384, 16384),
                (1 << 28, 1),
                (1, 1 << 28),
                (2 * w, h),
                (w + 1, h),
            ] {
                out.push((
                    format!("size{nw}x{nh}"),
                    header_only(&[(16, le32(nw)), (20, le32(nh))]),
                ));
            }
            for (tw, th) in [(16, 16), (w, 16), (16, h)] {
                out.push((
                    format!("tile{tw}x{th}"),
                    header_only(&[(t, le32(tw)), (t + 4, le32(th))]),
                ));
            }
            out.push(("margin".into(), header_only(&[(t + 8, le32(1 << 30))])));
            for (name, v) in [
                ("index_max", u32::MAX),
                ("index_small", 8),
                ("index_plus1", u32_at(data, t + 12) + 1),
            ] {
                out.push((name.into(), header_only(&[(t + 12, le32(v))])));
            }
            if version == 5 {
                for v in [0, 12, 13, u32::MAX] {
                    out.push((format!("split{v}"), header_only(&[(t + 16, le32(v))])));
                }
            }
            // Index entries edited, the index's CRC recomputed (entry 0: a chunk end of
            // 4 GiB, a huge valid count, the most chunks), as fuzz/hostile.py makes them.
            let ilen = u32_at(data, t + 12) as usize;
            let entry = |at: usize, v: &[u8]| {
                let mut b = data.to_vec();
                let e = 20 + hlen + 4 + at;
                b[e..e + v.len()].copy_from_slice(v);
                let end = 20 + hlen + ilen - 4;
                let crc = crc32fast::hash(&b[20 + hlen..end]);
                b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
                b
            };
            out.push(("chunk_end_max".into(), entry(40, &u32::MAX.to_le_bytes())));
            out.push(("valid_max".into(), entry(8, &(1u64 << 62).to_le_bytes())));
            out.push(("chunks13".into(), entry(4, &[13])));
        }
        v => panic!("a golden file of version {v}"),
    }
    out
}

/// What one run of the binary cost: CPU seconds and peak resident KB, both read from
/// `/proc/<pid>` while it runs (the last reading before it exits), and how it ended.
struct Cost {
    cpu: f64,
    rss_kb: u64,
    code: Option<i32>,
    stderr: String,
    killed: bool,
}

/// How many /proc readings of a vtz process `run` made: the test fails if none was, since
/// then no budget was checked.
static READINGS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Run `vtz args`, polling its CPU time and peak RSS; kill it as soon as it is over twice
/// the budget (so a regression fails in seconds, not minutes).
fn run(args: &[&Path]) -> Cost {
    let mut child = Command::new(env!("CARGO_BIN_EXE_vtz"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run vtz");
    let pid = child.id();
    let (mut cpu, mut rss_kb, mut killed) = (0.0f64, 0u64, false);
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        // Until the child has called exec it shares (vfork) or copies (fork) this test
        // process's memory, and /proc shows that: the whole suite's peak, hundreds of MB.
        // Only readings of the vtz binary itself count; `comm` becomes "vtz" at exec.
        let execed = std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|st| {
            st.split_once(" (")
                .is_some_and(|(_, r)| r.starts_with("vtz)"))
        });
        if !execed {
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        if let Ok(st) = std::fs::read_to_string(format!("/proc/{pid}/status")) {
            if let Some(kb) = st
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            {
                rss_kb = rss_kb.max(kb);
                READINGS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
        if let Ok(st) = std::fs::read_to_string(format!("/proc/{pid}/stat")) {
            // utime and stime: fields 14 and 15, in clock ticks (100 a second on Linux),
            // counted after the command name's closing parenthesis.
            let rest = &st[st.rfind(')').map_or(0, |i| i + 1)..];
            let f: Vec<&str> = rest.split_whitespace().collect();
            if let (Some(u), Some(s)) = (f.get(11), f.get(12)) {
                let ticks = u.parse::<u64>().unwrap_or(0) + s.parse::<u64>().unwrap_or(0);
                cpu = cpu.max(ticks as f64 / 100.0);
            }
        }
        let over = cpu > 2.0 * CPU_BUDGET
            || rss_kb > 4 * RSS_BUDGET_KB
            || start.elapsed() > Duration::from_secs(60);
        if over && !killed {
            let _ = child.kill();
            killed = true;
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut stderr);
    }
    Cost {
        cpu,
        rss_kb,
        code: status.code(),
        stderr,
        killed,
    }
}

#[test]
#[cfg(target_os = "linux")]
fn every_hostile_header_decodes_or_fails_within_budget() {
    let d = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    let mut count = 0;
    for g in crate::common::golden_files() {
        let data = std::fs::read(&g).unwrap();
        let stem = g.file_stem().unwrap().to_string_lossy().into_owned();
        let out = d.path().join(if u16_at(&data, 8) == 3 {
            "out.xyz"
        } else {
            "out.f32"
        });
        let decode = |p: &Path| {
            run(&[
                Path::new("decode"),
                p,
                Path::new("-o"),
                &out,
                Path::new("--force"),
                Path::new("-q"),
            ])
        };
        // The binary's own cost on the valid file is the baseline.
        let base = decode(&g);
        assert_eq!(base.code, Some(0), "{stem}: {}", base.stderr);
        for (name, bytes) in variants(&data) {
            let p = d.path().join(format!("{stem}.{name}.vtz"));
            std::fs::write(&p, &bytes).unwrap();
            let mut cases = vec![
                ("decode", decode(&p)),
                ("verify", run(&[Path::new("verify"), &p])),
            ];
            if u16_at(&data, 8) != 3 {
                // Overviews: the residual layer's early stop and a tiled file's own path.
                cases.push((
                    "decode --overview 1",
                    run(&[
                        Path::new("decode"),
                        &p,
                        Path::new("-o"),
                        &out,
                        Path::new("--force"),
                        Path::new("-q"),
                        Path::new("--overview"),
                        Path::new("1"),
                    ]),
                ));
            }
            for (what, c) in cases {
                count += 1;
                let line = c.stderr.trim();
                let ok = !c.killed
                    && matches!(c.code, Some(0 | 1))
                    && c.cpu <= CPU_BUDGET
                    && c.rss_kb <= base.rss_kb + RSS_BUDGET_KB
                    && !line.contains("panicked")
                    && (c.code == Some(0) || (!line.is_empty() && !line.contains('\n')));
                if !ok {
                    failures.push(format!(
                        "{what} {stem}.{name}: exit {:?}{}, {:.2} s CPU, {} KB peak (baseline {} KB): {}",
                        c.code,
                        if c.killed { " (killed over budget)" } else { "" },
                        c.cpu,
                        c.rss_kb,
                        base.rss_kb,
                        line.lines().last().unwrap_or("")
                    ));
                }
            }
            let _ = std::fs::remove_file(&p);
        }
    }
    assert!(count > 500, "only {count} hostile runs");
    let readings = READINGS.load(std::sync::atomic::Ordering::Relaxed);
    assert!(readings > 100, "only {readings} readings of a running vtz");
    assert!(
        failures.is_empty(),
        "{} of {count} hostile runs over budget or not clean:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
