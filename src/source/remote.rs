//! Remote `.vtz` files (feature `remote`): an object over HTTP(S) or on S3 (or an
//! S3-compatible store) read by byte ranges through Apache Arrow's `object_store`, and
//! uploads of a local file to `s3://bucket/key` as a multipart upload.
//!
//! [`RemoteSource`] owns a small current-thread tokio runtime. Its first request is a ranged
//! GET of the first [`HEAD_BYTES`], which also gives the object's length and ETag, so
//! opening a file costs one request; every later GET carries `If-Match` with that ETag, so
//! an object replaced while it is read fails clearly instead of mixing two files. A read of
//! several ranges merges those within [`COALESCE_GAP`] of each other and issues the merged
//! ranges concurrently. A server that ignores `Range` (answers 200 with the whole body, or
//! more bytes than asked) is an error, never a silent download of the whole file.
//!
//! Settings: S3 credentials, region and endpoint from the usual `AWS_*` variables
//! (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`, `AWS_REGION`,
//! `AWS_ENDPOINT_URL` or `AWS_ENDPOINT` for an S3-compatible store, `AWS_SKIP_SIGNATURE=true`
//! for a public bucket, `AWS_ALLOW_HTTP=true` for a plain-HTTP endpoint other than a
//! loopback one); `VTZ_REMOTE_TIMEOUT` (seconds) for the time limits ([`RemoteOptions`]).

use super::{COALESCE_GAP, HEAD_BYTES, RangeSource, coalesce, past_end, split};
use crate::error::{Error, Result};
use futures_util::{StreamExt, TryStreamExt};
use object_store::aws::{AmazonS3, AmazonS3Builder, AmazonS3ConfigKey};
use object_store::client::{HttpError, HttpErrorKind};
use object_store::http::HttpBuilder;
use object_store::multipart::{MultipartStore, PartId};
use object_store::path::Path as ObjectPath;
use object_store::{
    BackoffConfig, ClientConfigKey, ClientOptions, GetOptions, GetRange, GetResult, ObjectStore,
    ObjectStoreExt, PutPayload, RetryConfig,
};
use std::io::{ErrorKind, Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The environment variable that sets [`RemoteOptions::timeout`] (seconds, e.g. `30` or `2.5`).
pub const TIMEOUT_VAR: &str = "VTZ_REMOTE_TIMEOUT";

/// The part size of a multipart upload, in bytes (S3 takes parts of 5 MiB or more but the last).
pub const PART_BYTES: usize = 8 * 1024 * 1024;

/// How a remote object is reached.
#[derive(Clone, Debug)]
pub struct RemoteOptions {
    /// The limit on connecting, and on one request from sending it to the last byte of its
    /// answer (default 30 s; [`RemoteOptions::from_env`] reads [`TIMEOUT_VAR`]).
    pub timeout: Duration,
    /// Retries of a request that failed for a passing cause (a timeout, a dropped
    /// connection, a 5xx answer), with exponential backoff from 100 ms. Default 2.
    pub retries: usize,
    /// Requests in flight at once for one read of several ranges. Default 8.
    pub concurrency: usize,
    /// S3 settings by `object_store`'s names (`aws_endpoint`, `aws_region`,
    /// `aws_access_key_id`, `aws_secret_access_key`, `aws_skip_signature`, …), applied over
    /// the `AWS_*` environment variables. Empty by default.
    pub s3: Vec<(String, String)>,
}

impl Default for RemoteOptions {
    fn default() -> Self {
        RemoteOptions {
            timeout: Duration::from_secs(30),
            retries: 2,
            concurrency: 8,
            s3: Vec::new(),
        }
    }
}

impl RemoteOptions {
    /// The defaults, with [`TIMEOUT_VAR`] (seconds) as the timeout when it is set.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the variable is not a positive number of seconds.
    pub fn from_env() -> Result<RemoteOptions> {
        let mut o = RemoteOptions::default();
        if let Ok(v) = std::env::var(TIMEOUT_VAR) {
            let s: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|s: &f64| *s > 0.0 && s.is_finite() && *s < 1e9)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "{TIMEOUT_VAR} must be a positive number of seconds, not '{v}'"
                    ))
                })?;
            o.timeout = Duration::from_secs_f64(s);
        }
        Ok(o)
    }
}

/// Where a URL points.
enum Target {
    /// `http(s)://host[:port]/path`: the server's root and the object's path under it.
    Http { root: String, path: String },
    /// `s3://bucket/key`.
    S3 { bucket: String, key: String },
}

fn parse_url(url: &str) -> Result<Target> {
    let bad = |why: &str| Error::invalid(format!("{url}: {why}"));
    let (scheme, rest) = url
        .split_once("://")
        .ok_or_else(|| bad("not a URL (http://, https:// or s3://)"))?;
    let scheme = scheme.to_ascii_lowercase();
    if rest.contains(['?', '#']) {
        return Err(bad(
            "a URL with a query string or fragment (a presigned URL) is not supported",
        ));
    }
    let (host, path) = rest.split_once('/').unwrap_or((rest, ""));
    if host.is_empty() || path.is_empty() || path.ends_with('/') {
        return Err(bad(match scheme.as_str() {
            "s3" => "an S3 URL is s3://bucket/key",
            _ => "the URL names no file",
        }));
    }
    match scheme.as_str() {
        "http" | "https" => Ok(Target::Http {
            root: format!("{scheme}://{host}"),
            path: path.to_string(),
        }),
        "s3" => Ok(Target::S3 {
            bucket: host.to_string(),
            key: path.to_string(),
        }),
        _ => Err(bad("the scheme must be http://, https:// or s3://")),
    }
}

/// rustls without a default crypto provider is built with ring here (no C toolchain beyond
/// `cc`, no cmake): install it once, before any client is built.
fn install_crypto() {
    let _ = rustls::crypto::ring::default_provider().install_default();
}

fn retry_config(opts: &RemoteOptions) -> RetryConfig {
    RetryConfig {
        backoff: BackoffConfig {
            init_backoff: Duration::from_millis(100),
            max_backoff: Duration::from_secs(2),
            base: 2.0,
        },
        max_retries: opts.retries,
        retry_timeout: opts.timeout * (opts.retries as u32 + 1),
    }
}

fn millis(d: Duration) -> String {
    format!("{}ms", d.as_millis().max(1))
}

/// Whether an endpoint is on this machine (plain HTTP is then allowed without asking).
fn is_loopback(endpoint: &str) -> bool {
    let e = endpoint.to_ascii_lowercase();
    ["http://127.", "http://localhost", "http://[::1]"]
        .iter()
        .any(|p| e.starts_with(p))
}

fn s3_builder(bucket: &str, opts: &RemoteOptions) -> Result<AmazonS3Builder> {
    let mut b = AmazonS3Builder::from_env();
    for (k, v) in &opts.s3 {
        let key: AmazonS3ConfigKey = k
            .parse()
            .map_err(|_| Error::invalid(format!("unknown S3 setting '{k}'")))?;
        b = b.with_config(key, v);
    }
    if b.get_config_value(&AmazonS3ConfigKey::Endpoint)
        .is_some_and(|e| is_loopback(&e))
    {
        b = b.with_allow_http(true);
    }
    Ok(b.with_bucket_name(bucket)
        .with_config(
            AmazonS3ConfigKey::Client(ClientConfigKey::Timeout),
            millis(opts.timeout),
        )
        .with_config(
            AmazonS3ConfigKey::Client(ClientConfigKey::ConnectTimeout),
            millis(opts.timeout),
        )
        .with_retry(retry_config(opts)))
}

fn s3_store(url: &str, bucket: &str, opts: &RemoteOptions) -> Result<AmazonS3> {
    s3_builder(bucket, opts)?
        .build()
        .map_err(|e| Error::invalid(format!("{url}: {}", one_line(&e.to_string()))))
}

fn object_path(url: &str, path: &str, percent_encoded: bool) -> Result<ObjectPath> {
    let p = if percent_encoded {
        ObjectPath::from_url_path(path)
    } else {
        ObjectPath::parse(path)
    };
    p.map_err(|e| Error::invalid(format!("{url}: {}", one_line(&e.to_string()))))
}

/// The store and the object's path for a URL.
fn store_of(url: &str, opts: &RemoteOptions) -> Result<(Arc<dyn ObjectStore>, ObjectPath)> {
    install_crypto();
    match parse_url(url)? {
        Target::Http { root, path } => {
            let client = ClientOptions::new()
                .with_timeout(opts.timeout)
                .with_connect_timeout(opts.timeout)
                // The user typed http://: plain HTTP is what they asked for.
                .with_allow_http(true);
            let store = HttpBuilder::new()
                .with_url(root)
                .with_client_options(client)
                .with_retry(retry_config(opts))
                .build()
                .map_err(|e| Error::invalid(format!("{url}: {}", one_line(&e.to_string()))))?;
            Ok((Arc::new(store), object_path(url, &path, true)?))
        }
        Target::S3 { bucket, key } => Ok((
            Arc::new(s3_store(url, &bucket, opts)?),
            object_path(url, &key, false)?,
        )),
    }
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Error::io("starting the network runtime", e))
}

/// Run `f` to completion on `rt`, also when called from inside another tokio runtime (on a
/// scoped thread then, since a runtime cannot block inside another).
fn block_on<F>(rt: &tokio::runtime::Runtime, f: F) -> F::Output
where
    F: std::future::Future + Send,
    F::Output: Send,
{
    if tokio::runtime::Handle::try_current().is_ok() {
        std::thread::scope(|s| {
            s.spawn(|| rt.block_on(f))
                .join()
                .unwrap_or_else(|p| std::panic::resume_unwind(p))
        })
    } else {
        rt.block_on(f)
    }
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn io_error(url: &str, kind: ErrorKind, msg: impl Into<String>) -> Error {
    Error::io(url.to_string(), std::io::Error::new(kind, msg.into()))
}

/// The error of a server that answered a range request with more than the range.
fn no_ranges(url: &str) -> Error {
    io_error(
        url,
        ErrorKind::Unsupported,
        "the server does not support range requests (it sent the whole file); download the file first",
    )
}

fn changed(url: &str) -> Error {
    io_error(
        url,
        ErrorKind::Other,
        "the object changed while it was read (its ETag or length is not the one it had when opened); open it again",
    )
}

/// An `object_store` error as one line naming the URL: 404, 403/401, a changed object, a
/// server without range requests, a timeout, a refused connection, or the store's message.
fn remote_error(url: &str, timeout: Duration, e: object_store::Error) -> Error {
    use object_store::Error as E;
    match &e {
        E::NotFound { .. } => return io_error(url, ErrorKind::NotFound, "not found (HTTP 404)"),
        E::PermissionDenied { .. } | E::Unauthenticated { .. } => {
            let why = if url
                .get(..5)
                .is_some_and(|s| s.eq_ignore_ascii_case("s3://"))
            {
                "access denied (HTTP 403 or 401): check the credentials (AWS_ACCESS_KEY_ID, \
                 AWS_SECRET_ACCESS_KEY, AWS_SESSION_TOKEN) and the bucket's permissions"
            } else {
                "access denied (HTTP 403 or 401): the server refuses this file"
            };
            return io_error(url, ErrorKind::PermissionDenied, why);
        }
        E::Precondition { .. } => return changed(url),
        _ => {}
    }
    let mut texts = Vec::new();
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(&e);
    while let Some(c) = cause {
        if let Some(h) = c.downcast_ref::<HttpError>() {
            match h.kind() {
                HttpErrorKind::Timeout => {
                    return io_error(
                        url,
                        ErrorKind::TimedOut,
                        format!(
                            "no answer within {} s (set {TIMEOUT_VAR} to wait longer)",
                            timeout.as_secs_f64()
                        ),
                    );
                }
                HttpErrorKind::Connect => {
                    let mut inner = c.source();
                    let mut last = c.to_string();
                    while let Some(i) = inner {
                        last = i.to_string();
                        inner = i.source();
                    }
                    return io_error(
                        url,
                        ErrorKind::ConnectionRefused,
                        format!("cannot connect: {}", one_line(&last)),
                    );
                }
                _ => {}
            }
        }
        texts.push(c.to_string());
        cause = c.source();
    }
    let all = texts.join(" ");
    if all.contains("non-partial response")
        || all.contains("Range request not supported")
        || (all.contains("Requested ") && all.contains(", got "))
    {
        return no_ranges(url);
    }
    if all.contains("416 Range Not Satisfiable") || all.contains("InvalidRange") {
        return Error::corrupt(format!(
            "{url} is truncated: the server has no bytes at the range asked"
        ));
    }
    io_error(url, ErrorKind::Other, one_line(&e.to_string()))
}

/// An object on an HTTP(S) server or an S3 bucket, read by byte ranges. See the
/// [module docs](self).
///
/// Its reads block the calling thread (any thread, several at once); called from inside an
/// async runtime they run on a scoped thread. It owns a tokio runtime, which tokio does not
/// let an async task drop: drop it outside async code (or in `spawn_blocking`).
pub struct RemoteSource {
    store: Arc<dyn ObjectStore>,
    path: ObjectPath,
    url: String,
    rt: tokio::runtime::Runtime,
    opts: RemoteOptions,
    len: u64,
    etag: Option<String>,
    /// The object's first `min(len, HEAD_BYTES)` bytes, from the first request.
    head: Vec<u8>,
    requests: AtomicU64,
    fetched: AtomicU64,
}

impl RemoteSource {
    /// Open `url` (`http://`, `https://` or `s3://bucket/key`) with one request: a ranged GET
    /// of its first [`HEAD_BYTES`], which gives the length and the ETag too.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a URL that is not one of those, an unknown S3 setting
    /// or an S3 configuration `object_store` refuses; [`Error::Io`] naming the URL for a
    /// missing object (404), denied access (403/401), a timeout, a refused connection, a
    /// server that does not support range requests, or another failure.
    pub fn open(url: &str, opts: &RemoteOptions) -> Result<RemoteSource> {
        let rt = runtime()?;
        let (store, path) = {
            let _in = rt.enter();
            store_of(url, opts)?
        };
        let mut src = RemoteSource {
            store,
            path,
            url: url.to_string(),
            rt,
            opts: opts.clone(),
            len: 0,
            etag: None,
            head: Vec::new(),
            requests: AtomicU64::new(0),
            fetched: AtomicU64::new(0),
        };
        let first = block_on(&src.rt, src.first());
        let (len, etag, head) = first?;
        src.len = len;
        src.etag = etag;
        src.head = head;
        Ok(src)
    }

    /// Requests this source has issued (the first one included).
    pub fn requests(&self) -> u64 {
        self.requests.load(Ordering::Relaxed)
    }

    /// Bytes of answers this source has received.
    pub fn bytes_fetched(&self) -> u64 {
        self.fetched.load(Ordering::Relaxed)
    }

    fn err(&self, e: object_store::Error) -> Error {
        remote_error(&self.url, self.opts.timeout, e)
    }

    /// The first request: length, ETag and the first bytes.
    async fn first(&self) -> Result<(u64, Option<String>, Vec<u8>)> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        let o = GetOptions {
            range: Some(GetRange::Bounded(0..HEAD_BYTES)),
            ..Default::default()
        };
        match self.store.get_opts(&self.path, o).await {
            Ok(res) => {
                let len = res.meta.size;
                let etag = res.meta.e_tag.clone();
                if res.range.start != 0 {
                    return Err(no_ranges(&self.url));
                }
                let want = len.min(HEAD_BYTES);
                let head = self.body(res, want).await?;
                Ok((len, etag, head))
            }
            Err(e) => {
                let e = self.err(e);
                if !matches!(e, Error::Corrupt { .. }) {
                    return Err(e);
                }
                // 416 for the first bytes: an empty object (a HEAD tells).
                self.requests.fetch_add(1, Ordering::Relaxed);
                let meta = self.store.head(&self.path).await.map_err(|e| self.err(e))?;
                if meta.size != 0 {
                    return Err(e);
                }
                Ok((0, meta.e_tag, Vec::new()))
            }
        }
    }

    /// The body of `res`, which must be exactly `want` bytes: more is a server that ignores
    /// ranges (stopped at the first byte too many), fewer an object that changed.
    async fn body(&self, res: GetResult, want: u64) -> Result<Vec<u8>> {
        if res.range.end - res.range.start > want {
            return Err(no_ranges(&self.url));
        }
        let mut out = Vec::with_capacity(want as usize);
        let mut stream = res.into_stream();
        while let Some(chunk) = stream.next().await {
            let chunk = chunk.map_err(|e| self.err(e))?;
            self.fetched
                .fetch_add(chunk.len() as u64, Ordering::Relaxed);
            if (out.len() + chunk.len()) as u64 > want {
                return Err(no_ranges(&self.url));
            }
            out.extend_from_slice(&chunk);
        }
        if (out.len() as u64) < want {
            return Err(changed(&self.url));
        }
        Ok(out)
    }

    /// One ranged GET, checked against the ETag the object had when opened.
    async fn get(&self, r: Range<u64>) -> Result<Vec<u8>> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        let want = r.end - r.start;
        let o = GetOptions {
            range: Some(GetRange::Bounded(r.clone())),
            if_match: self.etag.clone(),
            ..Default::default()
        };
        let res = self
            .store
            .get_opts(&self.path, o)
            .await
            .map_err(|e| self.err(e))?;
        if res.meta.size != self.len
            || (self.etag.is_some() && res.meta.e_tag.is_some() && res.meta.e_tag != self.etag)
        {
            return Err(changed(&self.url));
        }
        if res.range != r {
            return Err(no_ranges(&self.url));
        }
        self.body(res, want).await
    }
}

impl RangeSource for RemoteSource {
    fn len(&self) -> Result<u64> {
        Ok(self.len)
    }

    fn read_ranges(&self, ranges: &[Range<u64>]) -> Result<Vec<Vec<u8>>> {
        for r in ranges {
            if r.end > self.len || r.start > r.end {
                return Err(past_end(&self.url, r, self.len));
            }
        }
        let hl = self.head.len() as u64;
        let far: Vec<Range<u64>> = ranges
            .iter()
            .filter(|r| r.end > hl && r.start < r.end)
            .cloned()
            .collect();
        let (merged, owner) = coalesce(&far, COALESCE_GAP);
        let got: Vec<Vec<u8>> = if merged.is_empty() {
            Vec::new()
        } else {
            let fetch = futures_util::stream::iter(merged.iter().cloned().map(|r| self.get(r)))
                .buffered(self.opts.concurrency.max(1))
                .try_collect::<Vec<Vec<u8>>>();
            block_on(&self.rt, fetch)?
        };
        let mut parts = split(&far, &merged, &owner, &got).into_iter();
        Ok(ranges
            .iter()
            .map(|r| {
                if r.start >= r.end {
                    Vec::new()
                } else if r.end <= hl {
                    self.head[r.start as usize..r.end as usize].to_vec()
                } else {
                    parts.next().unwrap_or_default()
                }
            })
            .collect())
    }

    fn name(&self) -> String {
        self.url.clone()
    }
}

/// Open `url` (`http://`, `https://` or `s3://bucket/key`) as a [`RangeSource`] for
/// [`Decoder::open`](crate::Decoder::open): one request, then only the ranges each decode
/// needs. See [`RemoteSource::open`] for the errors.
pub fn open_url(url: &str, opts: &RemoteOptions) -> Result<Arc<dyn RangeSource>> {
    Ok(Arc::new(RemoteSource::open(url, opts)?))
}

/// Whether the object at `url` exists (a HEAD request).
///
/// # Errors
/// As [`RemoteSource::open`], but a missing object is `Ok(false)`.
pub fn exists(url: &str, opts: &RemoteOptions) -> Result<bool> {
    let rt = runtime()?;
    let (store, path) = {
        let _in = rt.enter();
        store_of(url, opts)?
    };
    match block_on(&rt, store.head(&path)) {
        Ok(_) => Ok(true),
        Err(object_store::Error::NotFound { .. }) => Ok(false),
        Err(e) => Err(remote_error(url, opts.timeout, e)),
    }
}

/// Multipart uploads in flight (URL, upload id, options), for [`abort_uploads`].
static UPLOADS: Mutex<Vec<(String, String, RemoteOptions)>> = Mutex::new(Vec::new());

fn uploads() -> std::sync::MutexGuard<'static, Vec<(String, String, RemoteOptions)>> {
    UPLOADS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Upload the local file `local` to `url` (`s3://bucket/key`) as a multipart upload of
/// [`PART_BYTES`] parts, a few in flight at once; `progress` gets the fraction of bytes
/// sent (0 to 1). The object appears only when the upload completes: on any failure the
/// upload is aborted (no parts are left behind), and [`abort_uploads`] aborts uploads in
/// flight for a Ctrl-C handler.
///
/// # Errors
/// [`Error::InvalidArgument`] for a URL that is not `s3://bucket/key`; [`Error::Io`] naming
/// the file or the URL when reading or sending fails (403, a missing bucket, a timeout).
pub fn upload(
    local: &Path,
    url: &str,
    opts: &RemoteOptions,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<()> {
    let Target::S3 { bucket, key } = parse_url(url)? else {
        return Err(Error::invalid(format!(
            "{url}: uploads go to s3://bucket/key (an HTTP server takes none)"
        )));
    };
    install_crypto();
    let rt = runtime()?;
    let store = {
        let _in = rt.enter();
        s3_store(url, &bucket, opts)?
    };
    let path = object_path(url, &key, false)?;
    let file = std::fs::File::open(local)
        .map_err(|e| Error::io(format!("reading {}", local.display()), e))?;
    let size = file
        .metadata()
        .map_err(|e| Error::io(format!("reading {}", local.display()), e))?
        .len();
    let file = Mutex::new(file);
    let err = |e| remote_error(url, opts.timeout, e);
    let id = block_on(&rt, store.create_multipart(&path)).map_err(err)?;
    uploads().push((url.to_string(), id.clone(), opts.clone()));
    let parts = (size.div_ceil(PART_BYTES as u64)).max(1) as usize;
    let sent = AtomicU64::new(0);
    let read_part = |i: usize| -> Result<Vec<u8>> {
        let start = i as u64 * PART_BYTES as u64;
        let n = (size - start).min(PART_BYTES as u64) as usize;
        let mut buf = vec![0u8; n];
        let mut f = file.lock().unwrap_or_else(|e| e.into_inner());
        f.seek(SeekFrom::Start(start))
            .and_then(|_| f.read_exact(&mut buf))
            .map_err(|e| Error::io(format!("reading {}", local.display()), e))?;
        Ok(buf)
    };
    let run = async {
        let ids: Vec<PartId> = futures_util::stream::iter(0..parts)
            .map(|i| {
                let (store, path, id, read_part, sent) = (&store, &path, &id, &read_part, &sent);
                async move {
                    let bytes = read_part(i)?;
                    let n = bytes.len() as u64;
                    let part = store
                        .put_part(path, id, i, PutPayload::from(bytes))
                        .await
                        .map_err(err)?;
                    let done = sent.fetch_add(n, Ordering::Relaxed) + n;
                    progress(if size == 0 {
                        1.0
                    } else {
                        done as f64 / size as f64
                    });
                    Ok::<_, Error>(part)
                }
            })
            .buffered(opts.concurrency.clamp(1, 4))
            .try_collect::<Vec<PartId>>()
            .await?;
        store
            .complete_multipart(&path, &id, ids)
            .await
            .map_err(err)?;
        Ok::<_, Error>(())
    };
    let res = block_on(&rt, run);
    if res.is_err() {
        // The timer is made inside the runtime (tokio's timeout needs one when built).
        let _ = block_on(&rt, async {
            tokio::time::timeout(opts.timeout, store.abort_multipart(&path, &id)).await
        });
    }
    uploads().retain(|(u, i, _)| !(u == url && *i == id));
    res
}

/// Abort every multipart upload this process has in flight (for a Ctrl-C or SIGTERM
/// handler, from its own thread: each abort is one request on a runtime of its own, given
/// at most the upload's timeout). Gives how many were aborted.
pub fn abort_uploads() -> usize {
    let live: Vec<_> = uploads().drain(..).collect();
    let mut n = 0;
    for (url, id, opts) in live {
        let Ok(Target::S3 { bucket, key }) = parse_url(&url) else {
            continue;
        };
        let Ok(rt) = runtime() else { continue };
        let store = {
            let _in = rt.enter();
            s3_store(&url, &bucket, &opts)
        };
        let (Ok(store), Ok(path)) = (store, object_path(&url, &key, false)) else {
            continue;
        };
        let done = rt.block_on(async {
            tokio::time::timeout(opts.timeout, store.abort_multipart(&path, &id)).await
        });
        n += usize::from(matches!(done, Ok(Ok(()))));
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_are_parsed_or_refused_with_a_reason() {
        assert!(matches!(
            parse_url("https://example.com/dir/a%20b.vtz"),
            Ok(Target::Http { root, path }) if root == "https://example.com" && path == "dir/a%20b.vtz"
        ));
        assert!(matches!(
            parse_url("S3://bucket/dir/a.vtz"),
            Ok(Target::S3 { bucket, key }) if bucket == "bucket" && key == "dir/a.vtz"
        ));
        for bad in [
            "s3://bucket",
            "s3://bucket/",
            "https://example.com/a.vtz?X-Amz-Signature=1",
            "ftp://example.com/a.vtz",
            "https://example.com",
        ] {
            assert!(
                matches!(parse_url(bad), Err(Error::InvalidArgument { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn plain_http_is_allowed_on_loopback_endpoints_only() {
        assert!(is_loopback("http://127.0.0.1:9000"));
        assert!(!is_loopback("http://s3.example.com"));
        assert_eq!(millis(Duration::from_secs_f64(2.5)), "2500ms");
    }
}
