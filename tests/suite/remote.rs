//! Remote `.vtz` files (feature `remote`) against real servers that each test starts and
//! stops: nginx (Debian's `nginx-light`) serving a temporary directory with byte ranges and
//! logging every request with its `Range` and `If-Match` headers, and moto's S3 server
//! (`moto_server`, PyPI `moto[server]`). Found through `VTZ_NGINX` / `VTZ_MOTO_SERVER` or on
//! the PATH (and `/usr/sbin/nginx`); a missing one prints `SKIPPED <test>: <why>`, and fails
//! the test with `VTZ_REQUIRE_SERVERS=1` (set by `.ci/run`, which installs both).
//!
//! Expectations hold for any container version: a remote decode gives the same bits and the
//! same error kind as a local one, and the requests it sends are the ones predicted from what
//! the library asks of a local counting source for the same decode (the ranges of each read,
//! merged within `COALESCE_GAP`), checked against the server's own log.
#![cfg(all(feature = "remote", feature = "cli"))]

use crate::common;

use common::{Counting, Kind, bits, encode_opts, terrain};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::ops::Range;
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use vtz::source::remote::{RemoteOptions, RemoteSource};
use vtz::source::{COALESCE_GAP, FileSource, HEAD_BYTES, RangeSource, coalesce};
use vtz::{DecodeOptions, Decoder, Error, ErrorBound, Limits, Method, Raster, SampleType, Window};

const REQUIRE: &str = "VTZ_REQUIRE_SERVERS";

/// A server this test needs is missing: say so, or fail under `VTZ_REQUIRE_SERVERS=1`.
fn missing(why: &str) {
    let name = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    if std::env::var_os(REQUIRE).is_some_and(|v| v == "1") {
        panic!("{name}: {why} ({REQUIRE}=1)");
    }
    let _ = writeln!(std::io::stderr(), "SKIPPED {name}: {why}");
}

/// A program named by `var`, else on the PATH, else at one of `also`.
fn find(var: &str, name: &str, also: &[&str]) -> Option<PathBuf> {
    if let Some(p) = std::env::var_os(var) {
        return Some(PathBuf::from(p)).filter(|p| p.is_file());
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .chain(also.iter().map(PathBuf::from))
        .find(|p| p.is_file())
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn wait_for(port: u16, child: &mut Child, what: &str) {
    let start = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        if let Ok(Some(s)) = child.try_wait() {
            panic!("{what} exited at start: {s}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "{what} did not listen on {port}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// One plain HTTP/1.1 request; gives the status and the body.
fn http(port: u16, method: &str, path: &str, body: &[u8]) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .unwrap();
    s.write_all(body).unwrap();
    let mut got = Vec::new();
    s.read_to_end(&mut got).unwrap();
    let end = got.windows(4).position(|w| w == b"\r\n\r\n").unwrap() + 4;
    let head = String::from_utf8_lossy(&got[..end]).into_owned();
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    let mut body = got[end..].to_vec();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        body = dechunk(&body);
    }
    (status, body)
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let eol = b.windows(2).position(|w| w == b"\r\n").unwrap();
        let n = usize::from_str_radix(std::str::from_utf8(&b[..eol]).unwrap().trim(), 16).unwrap();
        if n == 0 {
            return out;
        }
        out.extend_from_slice(&b[eol + 2..eol + 2 + n]);
        b = &b[eol + 4 + n..];
    }
}

/// One request in nginx's log.
#[derive(Debug, Clone, PartialEq)]
struct Logged {
    method: String,
    uri: String,
    /// The `Range` header's bytes, as a half-open range.
    range: Option<Range<u64>>,
    if_match: bool,
    status: u16,
    bytes: u64,
}

struct Nginx {
    child: Child,
    dir: tempfile::TempDir,
    port: u16,
}

impl Nginx {
    /// nginx on a free port of 127.0.0.1 serving `<dir>/www` (`/forbidden/` denied,
    /// `/norange/` without byte ranges), in the foreground as this process's user.
    fn start() -> Option<Nginx> {
        let Some(bin) = find("VTZ_NGINX", "nginx", &["/usr/sbin/nginx"]) else {
            missing("nginx is not installed (apt-get install nginx-light, or set VTZ_NGINX)");
            return None;
        };
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().display().to_string();
        for sub in ["www/forbidden", "www/norange"] {
            std::fs::create_dir_all(dir.path().join(sub)).unwrap();
        }
        let port = free_port();
        let conf = format!(
            "daemon off;\nmaster_process off;\nworker_processes 1;\nerror_log {d}/error.log;\npid {d}/nginx.pid;\n\
             events {{ worker_connections 64; }}\n\
             http {{\n\
               log_format ranges '$request_method $uri \"$http_range\" \"$http_if_match\" $status $body_bytes_sent';\n\
               access_log {d}/access.log ranges;\n\
               default_type application/octet-stream;\n\
               client_body_temp_path {d}/tmp;\n\
               server {{\n\
                 listen 127.0.0.1:{port};\n\
                 root {d}/www;\n\
                 location /forbidden/ {{ deny all; }}\n\
                 location /norange/ {{ max_ranges 0; }}\n\
               }}\n\
             }}\n"
        );
        std::fs::write(dir.path().join("nginx.conf"), conf).unwrap();
        let mut child = Command::new(bin)
            .args(["-p", &format!("{d}/"), "-c", &format!("{d}/nginx.conf")])
            .args(["-e", &format!("{d}/error.log")])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start nginx");
        wait_for(port, &mut child, "nginx");
        Some(Nginx { child, dir, port })
    }

    fn url(&self, name: &str) -> String {
        format!("http://127.0.0.1:{}/{name}", self.port)
    }

    fn put(&self, name: &str, bytes: &[u8]) {
        std::fs::write(self.dir.path().join("www").join(name), bytes).unwrap();
    }

    /// Every request logged so far.
    fn log(&self) -> Vec<Logged> {
        // nginx writes a request's line after it has sent the response, so a client may see
        // the answer before the line is there: read until the log stops growing.
        let path = self.dir.path().join("access.log");
        let mut text = std::fs::read_to_string(&path).unwrap_or_default();
        for _ in 0..40 {
            std::thread::sleep(std::time::Duration::from_millis(50));
            let again = std::fs::read_to_string(&path).unwrap_or_default();
            if again == text {
                break;
            }
            text = again;
        }
        text.lines()
            .map(|l| {
                let q: Vec<&str> = l.split('"').collect();
                let head: Vec<&str> = q[0].split_whitespace().collect();
                let tail: Vec<&str> = q[4].split_whitespace().collect();
                let range = q[1].strip_prefix("bytes=").map(|r| {
                    let (a, b) = r.split_once('-').unwrap();
                    a.parse().unwrap()..b.parse::<u64>().unwrap() + 1
                });
                Logged {
                    method: head[0].into(),
                    uri: head[1].into(),
                    range,
                    if_match: q[3] != "-",
                    status: tail[0].parse().unwrap(),
                    bytes: tail[1].parse().unwrap(),
                }
            })
            .collect()
    }

    /// The requests logged for `uri` since the log had `since` lines.
    fn requests(&self, uri: &str, since: usize) -> Vec<Logged> {
        self.log()
            .into_iter()
            .skip(since)
            .filter(|l| l.uri == uri)
            .collect()
    }
}

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// moto's S3 server on a free port of 127.0.0.1.
struct Moto {
    child: Child,
    port: u16,
}

impl Moto {
    fn start() -> Option<Moto> {
        Moto::start_with(&[])
    }

    /// moto checking every request's credentials (`INITIAL_NO_AUTH_ACTION_COUNT=0`: a key
    /// it has not issued is refused with 403).
    fn start_checking_keys() -> Option<Moto> {
        Moto::start_with(&[("INITIAL_NO_AUTH_ACTION_COUNT", "0")])
    }

    fn start_with(env: &[(&str, &str)]) -> Option<Moto> {
        let Some(bin) = find("VTZ_MOTO_SERVER", "moto_server", &[]) else {
            missing(
                "moto_server is not installed (pip install 'moto[server]', or set VTZ_MOTO_SERVER)",
            );
            return None;
        };
        let port = free_port();
        let mut child = Command::new(bin)
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .envs(env.iter().copied())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start moto_server");
        wait_for(port, &mut child, "moto_server");
        Some(Moto { child, port })
    }

    fn endpoint(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// The settings a source needs here (moto takes any key).
    fn options(&self) -> RemoteOptions {
        RemoteOptions {
            s3: [
                ("aws_endpoint", self.endpoint()),
                ("aws_access_key_id", "test".into()),
                ("aws_secret_access_key", "test".into()),
                ("aws_region", "us-east-1".into()),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            ..Default::default()
        }
    }

    /// The same as environment variables, for the CLI.
    fn env(&self) -> Vec<(&'static str, String)> {
        vec![
            ("AWS_ENDPOINT_URL", self.endpoint()),
            ("AWS_ACCESS_KEY_ID", "test".into()),
            ("AWS_SECRET_ACCESS_KEY", "test".into()),
            ("AWS_REGION", "us-east-1".into()),
        ]
    }

    fn put(&self, path: &str, bytes: &[u8]) {
        let (status, body) = http(self.port, "PUT", path, bytes);
        assert_eq!(
            status,
            200,
            "PUT {path}: {}",
            String::from_utf8_lossy(&body)
        );
    }

    fn get(&self, path: &str) -> (u16, Vec<u8>) {
        http(self.port, "GET", path, b"")
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The requests a remote source sends for the reads a local source saw: the first
/// `HEAD_BYTES` (the open), then each later read's ranges past those first bytes, merged
/// within `COALESCE_GAP`.
fn predicted(calls: &[Vec<Range<u64>>], len: u64) -> Vec<Range<u64>> {
    let head = len.min(HEAD_BYTES);
    let mut out = Vec::new();
    out.push(0..HEAD_BYTES);
    for c in calls.iter().skip(1) {
        let far: Vec<Range<u64>> = c
            .iter()
            .filter(|r| r.end > head && r.start < r.end)
            .cloned()
            .collect();
        out.extend(coalesce(&far, COALESCE_GAP).0);
    }
    out
}

/// A tiled file large enough that windows fetch a few of its tiles: 1024² i16 samples,
/// 256² tiles (16), the residual layer within 0.5.
fn tiled_file() -> Vec<u8> {
    let src = terrain(Kind::Fbm, 1024, 1024, 3, true, SampleType::I16);
    let mut o = encode_opts(&[Method::RESIDUAL], Some(ErrorBound::Abs(0.5)));
    o.tile = Some(256);
    let bytes = vtz::encode(&src, &o).unwrap();
    assert!(bytes.len() as u64 > 2 * HEAD_BYTES, "{} bytes", bytes.len());
    bytes
}

fn same_bits(a: &Raster, b: &Raster, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}: size");
    assert_eq!(a.mask, b.mask, "{what}: mask");
    assert_eq!(a.georef, b.georef, "{what}: georef");
    assert!(bits(a) == bits(b), "{what}: samples differ");
}

fn win(x: usize, y: usize, width: usize, height: usize) -> Window {
    Window {
        x,
        y,
        width,
        height,
    }
}

fn decode(src: Arc<dyn RangeSource>, o: &DecodeOptions) -> vtz::Result<Raster> {
    Decoder::open_with_limits(src, Limits::default())?
        .options(o.clone())
        .decode()
}

/// The decodes every remote check repeats: full, windows, an overview, a window of it.
fn decodes() -> Vec<(&'static str, DecodeOptions)> {
    let mut v = vec![("full", DecodeOptions::default())];
    for (name, w) in [
        ("one tile", win(300, 300, 100, 100)),
        ("four tiles", win(200, 200, 100, 100)),
        ("a row", win(0, 600, 1024, 20)),
    ] {
        let mut o = DecodeOptions::default();
        o.window = Some(w);
        v.push((name, o));
    }
    let mut o = DecodeOptions::default();
    o.overview = Some(2);
    v.push(("overview 2", o.clone()));
    o.window = Some(win(10, 10, 100, 50));
    v.push(("a window of overview 2", o));
    v
}

fn vtz_cmd(args: &[&str], env: &[(&str, String)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vtz"))
        .args(args)
        .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
        .stdin(Stdio::null())
        .output()
        .expect("run vtz")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A failed command: exit `code`, one line on stderr holding every one of `says`.
fn fails(o: &Output, code: i32, says: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(code), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "not one line: {e}");
    for s in says {
        assert!(e.contains(s), "'{s}' not in: {e}");
    }
}

/// `vtz info --json` without its `file` (a path or a URL).
fn info_json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", stderr(o));
    let mut v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    v.as_object_mut().unwrap().remove("file");
    v
}

#[test]
fn http_reads_give_the_local_bits_for_every_golden_file_and_window() {
    let Some(ng) = Nginx::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    for g in crate::common::golden_files() {
        let name = g.file_name().unwrap().to_string_lossy().into_owned();
        ng.put(&name, &std::fs::read(&g).unwrap());
        let url = ng.url(&name);
        let local: Arc<dyn RangeSource> = Arc::new(FileSource::open(&g).unwrap());
        let remote: Arc<dyn RangeSource> =
            Arc::new(RemoteSource::open(&url, &RemoteOptions::default()).unwrap());
        assert_eq!(remote.len().unwrap(), local.len().unwrap(), "{name}");
        if vtz::is_points_file(&std::fs::read(&g).unwrap()) {
            // A point set decodes from its bytes (the CLI reads the object whole); the
            // library's raster decoder treats it alike from either source.
            let l = Decoder::open(local).map(|_| ()).map_err(|e| e.to_string());
            let r = Decoder::open(remote).map(|_| ()).map_err(|e| e.to_string());
            assert_eq!(l.is_ok(), r.is_ok(), "{name}: {l:?} / {r:?}");
            for out in ["l.csv", "r.csv"] {
                let _ = std::fs::remove_file(dir.path().join(out));
            }
            let lo = dir.path().join("l.csv");
            let ro = dir.path().join("r.csv");
            let a = vtz_cmd(
                &["decode", g.to_str().unwrap(), "-o", lo.to_str().unwrap()],
                &[],
            );
            let b = vtz_cmd(&["decode", &url, "-o", ro.to_str().unwrap()], &[]);
            assert!(
                a.status.success() && b.status.success(),
                "{}{}",
                stderr(&a),
                stderr(&b)
            );
            assert_eq!(
                std::fs::read(&lo).unwrap(),
                std::fs::read(&ro).unwrap(),
                "{name}"
            );
        } else {
            let l = decode(local, &DecodeOptions::default()).unwrap();
            let r = decode(remote, &DecodeOptions::default()).unwrap();
            same_bits(&l, &r, &name);
            let w = win(l.width / 4, l.height / 3, l.width / 2, l.height / 3);
            let o = common::decode_opts(|o| o.window = Some(w));
            let l = decode(Arc::new(FileSource::open(&g).unwrap()), &o).unwrap();
            let r = decode(
                vtz::source::remote::open_url(&url, &Default::default()).unwrap(),
                &o,
            )
            .unwrap();
            same_bits(&l, &r, &format!("{name} {w:?}"));
        }
        // The CLI: info and verify say the same of the URL as of the path.
        let li = vtz_cmd(&["info", "--json", g.to_str().unwrap()], &[]);
        let since = ng.log().len();
        let ri = vtz_cmd(&["info", "--json", &url], &[]);
        assert_eq!(info_json(&li), info_json(&ri), "{name}");
        // Every golden file lies within the first bytes: `info` costs one request.
        let sent = ng.requests(&format!("/{name}"), since);
        assert_eq!(sent.len(), 1, "{name}: {sent:?}");
        let v = vtz_cmd(&["verify", &url], &[]);
        assert!(v.status.success(), "{name}: {}", stderr(&v));
        assert!(String::from_utf8_lossy(&v.stdout).starts_with(&format!("{url}: ok")));
    }
    // A tiled file larger than the first read: every decode and window, and the CLI's
    // decode of a window to GeoTIFF, byte for byte.
    let bytes = tiled_file();
    ng.put("tiled.vtz", &bytes);
    let path = dir.path().join("tiled.vtz");
    std::fs::write(&path, &bytes).unwrap();
    let url = ng.url("tiled.vtz");
    let since = ng.log().len();
    let ri = vtz_cmd(&["info", "--json", &url], &[]);
    let li = vtz_cmd(&["info", "--json", path.to_str().unwrap()], &[]);
    assert_eq!(info_json(&li), info_json(&ri));
    // Version 5 (what vtz writes): the header, the tile index and the global sections are
    // in the first 64 KB, so `info` is one request (version 2's index at the end took two).
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 5);
    let sent = ng.requests("/tiled.vtz", since);
    assert_eq!(sent.len(), 1, "{sent:?}");
    for (what, o) in decodes() {
        let l = decode(Arc::new(FileSource::open(&path).unwrap()), &o).unwrap();
        let r = decode(
            vtz::source::remote::open_url(&url, &Default::default()).unwrap(),
            &o,
        )
        .unwrap();
        same_bits(&l, &r, what);
    }
    for args in [&["--window", "200,200,300,100"][..], &["--overview", "1"]] {
        let lo = dir.path().join("l.tif");
        let ro = dir.path().join("r.tif");
        let a = vtz_cmd(
            &[
                &[
                    "decode",
                    path.to_str().unwrap(),
                    "-f",
                    "-o",
                    lo.to_str().unwrap(),
                ],
                args,
            ]
            .concat(),
            &[],
        );
        let b = vtz_cmd(
            &[&["decode", &url, "-f", "-o", ro.to_str().unwrap()], args].concat(),
            &[],
        );
        assert!(
            a.status.success() && b.status.success(),
            "{}{}",
            stderr(&a),
            stderr(&b)
        );
        assert_eq!(
            std::fs::read(&lo).unwrap(),
            std::fs::read(&ro).unwrap(),
            "{args:?}"
        );
    }
}

#[test]
fn a_window_sends_the_requests_predicted_from_the_files_layout() {
    let Some(ng) = Nginx::start() else { return };
    let bytes = tiled_file();
    let len = bytes.len() as u64;
    ng.put("tiled.vtz", &bytes);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiled.vtz");
    std::fs::write(&path, &bytes).unwrap();
    let url = ng.url("tiled.vtz");
    for (what, o) in decodes().into_iter().skip(1) {
        let counting = Counting::new(FileSource::open(&path).unwrap());
        let l = decode(counting.clone(), &o).unwrap();
        let calls = counting.calls.lock().unwrap().clone();
        let mut want = predicted(&calls, len);

        let since = ng.log().len();
        let remote = Arc::new(RemoteSource::open(&url, &RemoteOptions::default()).unwrap());
        let r = decode(remote.clone(), &o).unwrap();
        same_bits(&l, &r, what);
        let logged = ng.requests("/tiled.vtz", since);
        // Every request is a ranged GET answered with exactly its range.
        for q in &logged {
            let r = q
                .range
                .clone()
                .unwrap_or_else(|| panic!("{what}: no Range: {q:?}"));
            assert_eq!((q.method.as_str(), q.status), ("GET", 206), "{what}: {q:?}");
            assert_eq!(q.bytes, r.end.min(len) - r.start, "{what}: {q:?}");
        }
        // The open carries no If-Match (it learns the ETag); every later GET does.
        assert!(
            logged.iter().skip(1).all(|q| q.if_match),
            "{what}: {logged:?}"
        );
        let mut got: Vec<Range<u64>> = logged.iter().map(|q| q.range.clone().unwrap()).collect();
        assert_eq!(got[0], 0..HEAD_BYTES, "{what}: the open");
        want[1..].sort_by_key(|r| r.start);
        got[1..].sort_by_key(|r| r.start);
        assert_eq!(got, want, "{what}: the requests sent");
        // The source counts what the server logged.
        let sent: u64 = logged.iter().map(|q| q.bytes).sum();
        assert_eq!(remote.requests(), logged.len() as u64, "{what}");
        assert_eq!(remote.bytes_fetched(), sent, "{what}");
        // A window reads its tiles, not the file; one read of a band is one round of
        // concurrent requests, fewer than its ranges when neighbours merge.
        if o.overview.is_none() {
            assert!(sent < len / 2, "{what}: {sent} of {len} bytes");
        }
        let asked: usize = calls.iter().skip(1).map(Vec::len).sum();
        assert!(
            logged.len() <= 1 + asked,
            "{what}: {} requests for {asked} ranges",
            logged.len()
        );
        // Version 5 (header and tile index first; issue 36): opening reads nothing past the
        // first bytes, a window reads one band of tiles per call: one request for the heads
        // and one for the tails of each row of tiles (heads and tails lie back to back), so
        // a window within two rows of tiles (these 100² windows, any 256² window in 256²
        // tiles) takes at most 5 requests in all, 3 within one row; an overview reads at
        // most one call per row of tiles (the rows that fit in 64 MB at once; each block's
        // first chunks, fetched concurrently).
        let rows = vtz::info(&bytes, Default::default())
            .unwrap()
            .tiles
            .unwrap()
            .rows as usize;
        if o.overview.is_none() {
            assert!(logged.len() <= 5, "{what}: {} requests", logged.len());
        } else {
            assert!(
                calls.len() - 1 <= rows,
                "{what}: {} reads for {rows} rows of tiles",
                calls.len() - 1
            );
        }
        eprintln!(
            "{what}: {} requests, {sent} of {len} bytes ({} reads after the open, {asked} ranges)",
            logged.len(),
            calls.len() - 1
        );
    }
}

/// A server that accepts connections and never answers.
fn silent_server() -> u16 {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for s in l.incoming() {
            held.push(s);
        }
    });
    port
}

#[test]
fn http_failures_are_one_line_errors_and_leave_no_output() {
    let Some(ng) = Nginx::start() else { return };
    let bytes = tiled_file();
    ng.put("tiled.vtz", &bytes);
    ng.put("forbidden/tiled.vtz", &bytes);
    ng.put("norange/tiled.vtz", &bytes);
    let half = &bytes[..bytes.len() / 2];
    ng.put("truncated.vtz", half);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.tif");
    let o = out.to_str().unwrap();
    let decode_url = |url: &str, env: &[(&str, String)]| {
        let r = vtz_cmd(&["decode", url, "-o", o, "--window", "0,0,300,300"], env);
        assert!(!out.exists(), "{url}: an output was left");
        r
    };
    fails(
        &decode_url(&ng.url("missing.vtz"), &[]),
        1,
        &["not found (HTTP 404)", "/missing.vtz"],
    );
    fails(
        &decode_url(&ng.url("forbidden/tiled.vtz"), &[]),
        1,
        &["access denied", "forbidden/tiled.vtz"],
    );
    fails(
        &decode_url(&ng.url("norange/tiled.vtz"), &[]),
        1,
        &[
            "the server does not support range requests (it sent the whole file); download the file first",
        ],
    );
    // A truncated object: the error a local copy of it gives (corrupt, exit 1).
    let local = dir.path().join("truncated.vtz");
    std::fs::write(&local, half).unwrap();
    let l = decode(
        Arc::new(FileSource::open(&local).unwrap()),
        &DecodeOptions::default(),
    );
    let r = vtz::source::remote::open_url(&ng.url("truncated.vtz"), &Default::default())
        .and_then(|s| decode(s, &DecodeOptions::default()));
    assert!(matches!(l, Err(Error::Corrupt { .. })), "{l:?}");
    assert!(matches!(r, Err(Error::Corrupt { .. })), "{r:?}");
    fails(
        &decode_url(&ng.url("truncated.vtz"), &[]),
        1,
        &["corrupt input"],
    );
    // A server that never answers, with a short timeout: a timeout, not a hang.
    let port = silent_server();
    let t = Instant::now();
    let slow = format!("http://127.0.0.1:{port}/a.vtz");
    fails(
        &decode_url(&slow, &[("VTZ_REMOTE_TIMEOUT", "0.5".into())]),
        1,
        &["no answer within 0.5 s", "VTZ_REMOTE_TIMEOUT", &slow],
    );
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    // Nothing listening.
    let closed = format!("http://127.0.0.1:{}/a.vtz", free_port());
    fails(
        &decode_url(&closed, &[("VTZ_REMOTE_TIMEOUT", "2".into())]),
        1,
        &["cannot connect", &closed],
    );
    // Usage errors: a bad timeout, an HTTP output.
    fails(
        &decode_url(
            &ng.url("tiled.vtz"),
            &[("VTZ_REMOTE_TIMEOUT", "soon".into())],
        ),
        2,
        &["VTZ_REMOTE_TIMEOUT"],
    );
    let corpus = common::corpus("srtm3_N22W160_kauai.hgt");
    fails(
        &vtz_cmd(&["encode", &corpus, "-o", &ng.url("up.vtz")], &[]),
        2,
        &["s3://bucket/key"],
    );
    assert!(ng.requests("/up.vtz", 0).is_empty());

    // An object replaced between the open and a read: the ETag no longer matches.
    let src = Arc::new(RemoteSource::open(&ng.url("tiled.vtz"), &Default::default()).unwrap());
    let mut d = Decoder::open(src.clone()).unwrap();
    ng.put("tiled.vtz", &bytes[..bytes.len() - 1]);
    let e = d
        .window(win(500, 500, 100, 100))
        .decode()
        .unwrap_err()
        .to_string();
    assert!(e.contains("the object changed while it was read"), "{e}");
    assert!(e.contains(&ng.url("tiled.vtz")), "{e}");
    assert!(!e.contains('\n'), "{e}");
    // The refused GET's line (nginx logs it after answering; wait for it a little).
    let mut last = ng.requests("/tiled.vtz", 0).pop().unwrap();
    for _ in 0..20 {
        if last.status == 412 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
        last = ng.requests("/tiled.vtz", 0).pop().unwrap();
    }
    assert_eq!((last.status, last.if_match), (412, true), "{last:?}");
}

#[test]
fn s3_reads_uploads_and_errors() {
    let Some(s3) = Moto::start() else { return };
    s3.put("/vtz-test", b"");
    let opts = s3.options();
    let env = s3.env();
    // Reads: the local bits for every golden file and the tiled file's windows, with the
    // requests predicted from the local reads.
    for g in crate::common::golden_files() {
        let name = g.file_name().unwrap().to_string_lossy().into_owned();
        let bytes = std::fs::read(&g).unwrap();
        s3.put(&format!("/vtz-test/golden/{name}"), &bytes);
        let url = format!("s3://vtz-test/golden/{name}");
        if vtz::is_points_file(&bytes) {
            let ri = vtz_cmd(&["info", "--json", &url], &env);
            let li = vtz_cmd(&["info", "--json", g.to_str().unwrap()], &[]);
            assert_eq!(info_json(&li), info_json(&ri), "{name}");
            continue;
        }
        let l = decode(
            Arc::new(FileSource::open(&g).unwrap()),
            &DecodeOptions::default(),
        )
        .unwrap();
        let r = decode(
            vtz::source::remote::open_url(&url, &opts).unwrap(),
            &DecodeOptions::default(),
        )
        .unwrap();
        same_bits(&l, &r, &name);
    }
    let bytes = tiled_file();
    s3.put("/vtz-test/tiled.vtz", &bytes);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiled.vtz");
    std::fs::write(&path, &bytes).unwrap();
    for (what, o) in decodes() {
        let counting = Counting::new(FileSource::open(&path).unwrap());
        let l = decode(counting.clone(), &o).unwrap();
        let remote = Arc::new(RemoteSource::open("s3://vtz-test/tiled.vtz", &opts).unwrap());
        let r = decode(remote.clone(), &o).unwrap();
        same_bits(&l, &r, what);
        let want = predicted(&counting.calls.lock().unwrap(), bytes.len() as u64);
        assert_eq!(remote.requests(), want.len() as u64, "{what}");
        let sent: u64 = want
            .iter()
            .map(|r| r.end.min(bytes.len() as u64) - r.start)
            .sum();
        assert_eq!(remote.bytes_fetched(), sent, "{what}");
    }
    // 404s: a key, a bucket.
    let o = dir.path().join("out.tif");
    let out = o.to_str().unwrap();
    for url in ["s3://vtz-test/missing.vtz", "s3://no-such-bucket/a.vtz"] {
        fails(
            &vtz_cmd(&["decode", url, "-o", out], &env),
            1,
            &["not found (HTTP 404)", url],
        );
        assert!(!o.exists());
    }
    // encode -o s3://… then decode s3://…: the object is the bytes a local encode writes,
    // and decodes as the local file does.
    let corpus = common::corpus("srtm3_N22W160_kauai.hgt");
    let local = dir.path().join("kauai.vtz");
    let a = vtz_cmd(
        &[
            "encode",
            &corpus,
            "--max-error",
            "2",
            "-o",
            local.to_str().unwrap(),
        ],
        &[],
    );
    assert!(a.status.success(), "{}", stderr(&a));
    let url = "s3://vtz-test/up/kauai.vtz";
    let b = vtz_cmd(
        &["encode", &corpus, "--max-error", "2", "-o", url, "--json"],
        &env,
    );
    assert!(b.status.success(), "{}", stderr(&b));
    let j: serde_json::Value = serde_json::from_slice(&b.stdout).unwrap();
    assert_eq!(j["output"], url);
    let (status, stored) = s3.get("/vtz-test/up/kauai.vtz");
    assert_eq!(status, 200);
    assert!(
        stored == std::fs::read(&local).unwrap(),
        "the uploaded object differs"
    );
    let lo = dir.path().join("l.tif");
    let ro = dir.path().join("r.tif");
    let a = vtz_cmd(
        &[
            "decode",
            local.to_str().unwrap(),
            "-o",
            lo.to_str().unwrap(),
        ],
        &[],
    );
    let b = vtz_cmd(&["decode", url, "-o", ro.to_str().unwrap()], &env);
    assert!(
        a.status.success() && b.status.success(),
        "{}{}",
        stderr(&a),
        stderr(&b)
    );
    assert_eq!(std::fs::read(&lo).unwrap(), std::fs::read(&ro).unwrap());
    let v = vtz_cmd(&["verify", url], &env);
    assert!(v.status.success(), "{}", stderr(&v));
    // vtz web -o s3://…: the archive a local run writes, uploaded.
    let web_local = dir.path().join("kauai.pmtiles");
    let w = ["web", &corpus, "--max-zoom", "7", "-q", "-o"];
    let a = vtz_cmd(&[&w[..], &[web_local.to_str().unwrap()]].concat(), &[]);
    let b = vtz_cmd(
        &[&w[..], &["s3://vtz-test/up/kauai.pmtiles"]].concat(),
        &env,
    );
    assert!(
        a.status.success() && b.status.success(),
        "{}{}",
        stderr(&a),
        stderr(&b)
    );
    let (status, stored) = s3.get("/vtz-test/up/kauai.pmtiles");
    assert_eq!(status, 200);
    assert!(
        stored == std::fs::read(&web_local).unwrap(),
        "the uploaded archive differs"
    );
    assert_eq!(&stored[..7], b"PMTiles");
    // An existing object needs --force; an upload to a missing bucket fails (404) and
    // leaves nothing: no object, no staged file in the temporary directory.
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let env: Vec<_> = env
        .into_iter()
        .chain([("TMPDIR", tmp.to_string_lossy().into_owned())])
        .collect();
    fails(
        &vtz_cmd(&["encode", &corpus, "-o", url], &env),
        2,
        &["exists (use --force"],
    );
    let f = vtz_cmd(&["encode", &corpus, "-o", url, "--force", "-q"], &env);
    assert!(f.status.success(), "{}", stderr(&f));
    fails(
        &vtz_cmd(
            &["encode", &corpus, "-o", "s3://no-such-bucket/a.vtz"],
            &env,
        ),
        1,
        &["not found (HTTP 404)", "s3://no-such-bucket/a.vtz"],
    );
    assert_eq!(
        std::fs::read_dir(&tmp).unwrap().count(),
        0,
        "a staged file was left"
    );
    // A failure after the multipart upload began (the local "file" is a directory, which
    // opens but cannot be read): the upload is aborted, no object appears.
    let e = vtz::source::remote::upload(&tmp, "s3://vtz-test/broken.vtz", &opts, &|_| ())
        .unwrap_err()
        .to_string();
    assert!(e.contains("reading"), "{e}");
    assert_eq!(s3.get("/vtz-test/broken.vtz").0, 404);
    // No multipart upload was left behind.
    let (status, list) = s3.get("/vtz-test?uploads");
    assert_eq!(status, 200);
    let list = String::from_utf8_lossy(&list);
    assert!(!list.contains("<Upload>"), "{list}");
    drop(s3);
    // A key the store refuses: 403, for a read and for an upload.
    let Some(strict) = Moto::start_checking_keys() else {
        return;
    };
    let env = strict.env();
    let url = "s3://vtz-test/a.vtz";
    fails(
        &vtz_cmd(&["info", url], &env),
        1,
        &["access denied (HTTP 403", url],
    );
    fails(
        &vtz_cmd(&["encode", &corpus, "-o", url], &env),
        1,
        &["access denied (HTTP 403", url],
    );
}

/// A server of `bytes` with byte ranges that answers each request after `delay`, counting
/// the most requests it held at once.
fn slow_range_server(bytes: Vec<u8>, delay: Duration) -> (u16, Arc<Mutex<(usize, usize)>>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let load = Arc::new(Mutex::new((0usize, 0usize))); // (now, most)
    let bytes = Arc::new(bytes);
    let seen = load.clone();
    std::thread::spawn(move || {
        for s in l.incoming() {
            let (mut s, bytes, load) = (s.unwrap(), bytes.clone(), seen.clone());
            std::thread::spawn(move || {
                let mut buf = Vec::new();
                let mut b = [0u8; 4096];
                loop {
                    while !buf.windows(4).any(|w| w == b"\r\n\r\n") {
                        match s.read(&mut b) {
                            Ok(0) | Err(_) => return,
                            Ok(n) => buf.extend_from_slice(&b[..n]),
                        }
                    }
                    let end = buf.windows(4).position(|w| w == b"\r\n\r\n").unwrap() + 4;
                    let head = String::from_utf8_lossy(&buf[..end]).to_ascii_lowercase();
                    buf.drain(..end);
                    let r = head
                        .lines()
                        .find_map(|l| l.strip_prefix("range: bytes="))
                        .and_then(|r| r.trim().split_once('-'))
                        .map(|(a, b)| (a.parse::<usize>().unwrap(), b.parse::<usize>().unwrap()))
                        .unwrap();
                    let (a, b) = (r.0, r.1.min(bytes.len() - 1));
                    {
                        let mut l = load.lock().unwrap();
                        l.0 += 1;
                        l.1 = l.1.max(l.0);
                    }
                    std::thread::sleep(delay);
                    load.lock().unwrap().0 -= 1;
                    let head = format!(
                        "HTTP/1.1 206 Partial Content\r\nContent-Length: {}\r\nContent-Range: bytes {a}-{b}/{}\r\nETag: \"v1\"\r\n\r\n",
                        b + 1 - a,
                        bytes.len()
                    );
                    if s.write_all(head.as_bytes()).is_err() || s.write_all(&bytes[a..=b]).is_err()
                    {
                        return;
                    }
                }
            });
        }
    });
    (port, load)
}

#[test]
fn far_apart_ranges_are_fetched_concurrently_and_near_ones_merged() {
    let bytes: Vec<u8> = (0..1_000_000u32).map(|i| (i * 7 % 251) as u8).collect();
    let delay = Duration::from_millis(400);
    let (port, load) = slow_range_server(bytes.clone(), delay);
    let url = format!("http://127.0.0.1:{port}/x.vtz");
    let src = RemoteSource::open(&url, &RemoteOptions::default()).unwrap();
    assert_eq!(
        (src.len().unwrap(), src.requests()),
        (bytes.len() as u64, 1)
    );
    // Four ranges far apart (one request each, at once), two near the first (merged into
    // it), one inside the first bytes (no request).
    let ranges = [
        100_000..110_000,
        300_000..300_500,
        500_000..520_000,
        900_000..1_000_000,
        112_000..115_000,
        95_000..99_000,
        10..20,
    ];
    let t = Instant::now();
    let got = src.read_ranges(&ranges).unwrap();
    let took = t.elapsed();
    for (r, g) in ranges.iter().zip(&got) {
        assert!(g[..] == bytes[r.start as usize..r.end as usize], "{r:?}");
    }
    assert_eq!(src.requests(), 1 + 4);
    assert_eq!(
        src.bytes_fetched(),
        HEAD_BYTES + 20_000 + 500 + 20_000 + 100_000
    );
    let most = load.lock().unwrap().1;
    assert!(most >= 2, "at most {most} request(s) in flight at once");
    assert!(
        took < delay * 4,
        "four requests took {took:?}: one after another"
    );
    eprintln!("4 requests of {delay:?} each took {took:?}, {most} at once");
}

/// A TCP proxy to `port` that passes what clients send at about 1.6 MB/s (16 KB per 10 ms):
/// an upload through it takes seconds.
fn throttling_proxy(port: u16) -> u16 {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let me = l.local_addr().unwrap().port();
    std::thread::spawn(move || {
        for c in l.incoming() {
            let Ok(mut c) = c else { return };
            let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) else {
                return;
            };
            let (mut c2, mut s2) = (c.try_clone().unwrap(), s.try_clone().unwrap());
            std::thread::spawn(move || {
                let _ = std::io::copy(&mut s2, &mut c2);
                let _ = c2.shutdown(std::net::Shutdown::Both);
            });
            std::thread::spawn(move || {
                let mut b = [0u8; 16 * 1024];
                while let Ok(n) = c.read(&mut b) {
                    if n == 0 || s.write_all(&b[..n]).is_err() {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(10));
                }
                let _ = s.shutdown(std::net::Shutdown::Both);
            });
        }
    });
    me
}

#[test]
fn ctrl_c_during_an_upload_aborts_it_and_leaves_nothing() {
    let Some(s3) = Moto::start() else { return };
    s3.put("/vtz-test", b"");
    let dir = tempfile::tempdir().unwrap();
    // Noise that does not compress: a .vtz of about 4 MB, seconds through the proxy.
    let mut rng = common::Rng(5);
    let noise: Vec<u8> = (0..1000 * 1000)
        .flat_map(|_| ((rng.below(1 << 20) as f32) / 8.0).to_le_bytes())
        .collect();
    let input = dir.path().join("noise.f32");
    std::fs::write(&input, noise).unwrap();
    std::fs::write(
        dir.path().join("noise.json"),
        r#"{"width": 1000, "height": 1000}"#,
    )
    .unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let proxy = throttling_proxy(s3.port);
    let mut env = s3.env();
    env[0].1 = format!("http://127.0.0.1:{proxy}");
    env.push(("TMPDIR", tmp.to_string_lossy().into_owned()));
    let url = "s3://vtz-test/noise.vtz";
    let mut child = Command::new(env!("CARGO_BIN_EXE_vtz"))
        .args([
            "encode",
            input.to_str().unwrap(),
            "--lossless",
            "--method",
            "grid",
            "-q",
            "-o",
            url,
        ])
        .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the multipart upload is under way (moto lists it), then interrupt.
    let start = Instant::now();
    loop {
        let (_, list) = s3.get("/vtz-test?uploads");
        if String::from_utf8_lossy(&list).contains("<Upload>") {
            break;
        }
        if let Some(s) = child.try_wait().unwrap() {
            panic!("vtz ended ({s}) before its upload was seen");
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no upload began");
        std::thread::sleep(Duration::from_millis(20));
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(stderr(&out).contains("interrupted"), "{}", stderr(&out));
    let (_, list) = s3.get("/vtz-test?uploads");
    assert!(
        !String::from_utf8_lossy(&list).contains("<Upload>"),
        "the upload was left"
    );
    assert_eq!(s3.get("/vtz-test/noise.vtz").0, 404, "an object appeared");
    assert_eq!(
        std::fs::read_dir(&tmp).unwrap().count(),
        0,
        "a staged file was left"
    );
}
