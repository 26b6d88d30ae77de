//! Shared CLI plumbing: reading inputs, raster options, progress display.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::Duration;
use vtz::formats::{Format, PngMapping, ReadOptions, WriteOptions};
use vtz::source::RangeSource;
use vtz::source::remote::RemoteOptions;
use vtz::{Error, Limits, Raster, Result};

/// Global output settings.
pub struct Ui {
    pub quiet: bool,
}

impl Ui {
    /// Print a summary line to stderr unless --quiet.
    pub fn say(&self, msg: impl std::fmt::Display) {
        if !self.quiet {
            eprintln!("{msg}");
        }
    }

    /// Run `f` with a spinner that appears only when the work takes over a second and
    /// stderr is a terminal.
    pub fn busy<T>(&self, msg: &str, f: impl FnOnce() -> T) -> T {
        if self.quiet {
            return f();
        }
        let pb = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
        pb.set_style(
            ProgressStyle::with_template("{spinner} {msg} {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        pb.set_message(msg.to_string());
        let shown = ShowAfterASecond::new(&pb);
        let out = f();
        shown.done();
        out
    }
}

/// Keeps a bar hidden for the first second, then draws it ticking (so elapsed time and the
/// ETA move even while the work reports nothing) until `done`.
struct ShowAfterASecond {
    pb: ProgressBar,
    tx: mpsc::Sender<()>,
    t: std::thread::JoinHandle<()>,
}

impl ShowAfterASecond {
    fn new(pb: &ProgressBar) -> Self {
        let (tx, rx) = mpsc::channel::<()>();
        let pb2 = pb.clone();
        let t = std::thread::spawn(move || {
            if rx.recv_timeout(Duration::from_secs(1)).is_err() {
                pb2.set_draw_target(ProgressDrawTarget::stderr());
                pb2.enable_steady_tick(Duration::from_millis(200));
                let _ = rx.recv();
            }
        });
        ShowAfterASecond {
            pb: pb.clone(),
            tx,
            t,
        }
    }

    fn done(self) {
        let _ = self.tx.send(());
        let _ = self.t.join();
        self.pb.finish_and_clear();
    }

    /// End a bar: one whose work reported its end stays drawn, full (`100%`, `16/16
    /// tiles`); one that stopped short (an error) is cleared.
    fn end(self, complete: bool) {
        let _ = self.tx.send(());
        let _ = self.t.join();
        if complete {
            self.pb.finish();
        } else {
            self.pb.finish_and_clear();
        }
    }
}

/// The ETA of a bar as `HH:MM:SS`, or `--:--:--` before the first progress (indicatif's
/// own says 00:00:00 then).
fn eta(state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write) {
    if state.pos() == 0 {
        let _ = w.write_str("--:--:--");
        return;
    }
    let t = state.eta().as_secs();
    let _ = write!(w, "{:02}:{:02}:{:02}", t / 3600, (t / 60) % 60, t % 60);
}

impl Ui {
    /// [`Ui::progress`] for work done tile by tile: the bar counts `tiles` (a plain bar
    /// when there is one).
    pub fn progress_tiles<T>(
        &self,
        msg: &str,
        tiles: u64,
        f: impl FnOnce(&(dyn Fn(f64) + Sync)) -> T,
    ) -> T {
        if tiles <= 1 {
            return self.progress(msg, f);
        }
        self.bar(msg, tiles, "{pos}/{len} tiles", true, f)
    }

    /// Run `f` with a progress bar fed by its callback (fraction 0..1): percentage, elapsed
    /// time and ETA, drawn from the first second on a terminal (ticking even while the work
    /// reports nothing), never moving backwards, left drawn at 100 % when the work reports
    /// its end (1.0); hidden with --quiet.
    pub fn progress<T>(&self, msg: &str, f: impl FnOnce(&(dyn Fn(f64) + Sync)) -> T) -> T {
        self.bar(msg, 1000, "{percent:>3}%", false, f)
    }

    /// The one progress bar: `len` steps (a fraction rounded to the nearest step with
    /// `round`, else down), `count` (indicatif's template keys) after the bar.
    fn bar<T>(
        &self,
        msg: &str,
        len: u64,
        count: &str,
        round: bool,
        f: impl FnOnce(&(dyn Fn(f64) + Sync)) -> T,
    ) -> T {
        if self.quiet {
            return f(&|_| {});
        }
        let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
        pb.set_style(
            ProgressStyle::with_template(&format!(
                "{{msg}} [{{bar:30}}] {count} {{elapsed_precise}} ETA {{vtz_eta}}"
            ))
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .with_key("vtz_eta", eta)
            .progress_chars("=> "),
        );
        pb.set_message(msg.to_string());
        let shown = ShowAfterASecond::new(&pb);
        let high = AtomicU64::new(0);
        let out = f(&|frac: f64| {
            // Monotonic: a later, lower estimate never moves the bar back.
            let pos = frac.clamp(0.0, 1.0) * len as f64;
            let pos = if round { pos.round() } else { pos } as u64;
            let prev = high.fetch_max(pos, Ordering::Relaxed);
            if pos > prev {
                pb.set_position(pos);
            }
        });
        shown.end(high.load(Ordering::Relaxed) == len);
        out
    }
}

/// `--force`: replace an existing output (a command whose outputs differ says which in
/// its help, `#[command(mut_arg("force", ...))]`).
#[derive(clap::Args, Clone, Copy, Debug, Default)]
pub struct Force {
    /// Replace an existing output file.
    #[arg(short, long)]
    pub force: bool,
}

/// `--json`: the result as JSON on stdout (a command's own help may say more of it).
#[derive(clap::Args, Clone, Copy, Debug, Default)]
pub struct Json {
    /// Print the result as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `--format`: the input raster's format, when its extension does not tell.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct InputFormat {
    /// Input format, when the extension does not tell (tif, png, terrain-rgb, exr, hgt, asc,
    /// f32).
    #[arg(long, value_name = "FMT")]
    pub format: Option<String>,
}

impl InputFormat {
    /// The format named, if any (an unknown name is a usage error).
    pub fn get(&self) -> Result<Option<Format>> {
        parse_format(self.format.as_deref())
    }
}

/// `--max-error`: the bound, E data units or E% of the value range (each command's help says
/// what it bounds).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct Bound {
    /// Every sample within E data units, or E% of the value range (e.g. 1%).
    #[arg(long, value_name = "E")]
    pub max_error: Option<String>,
}

impl Bound {
    /// The bound given, if any (a bad one is a usage error naming `--max-error`).
    pub fn get(&self) -> Result<Option<vtz::ErrorBound>> {
        self.max_error
            .as_deref()
            .map(|s| bound("--max-error", s))
            .transpose()
    }
}

/// `--threads`: the threads of the work (0: all cores); outputs do not depend on it.
#[derive(clap::Args, Clone, Copy, Debug, Default)]
pub struct Threads {
    /// Threads (default: all cores); the output is the same for any count.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub threads: usize,
}

/// Options shared by every command that reads or writes rasters.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct RasterOpts {
    /// 16-bit PNG value mapping: value = offset + scale * code.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub png_scale: Option<f64>,
    /// 16-bit PNG value mapping offset (e.g. -32768 for SRTM PNGs).
    #[arg(long, value_name = "O", allow_negative_numbers = true)]
    pub png_offset: Option<f64>,
    /// 16-bit PNG code that marks nodata (e.g. 0).
    #[arg(long, value_name = "CODE")]
    pub png_nodata: Option<u16>,
}

/// Options of the commands that write a raster file (`decode`, `convert`), beside
/// [`RasterOpts`]; the commands that only read rasters do not offer them.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct OutputOpts {
    /// Let PNG output round values its codes cannot hold (16-bit codes, Terrain-RGB's
    /// 0.1 m steps); without it such a write is refused, never silently rounded.
    #[arg(long)]
    pub round: bool,
    /// Let a format that cannot place the raster (an .hgt not named after its tile,
    /// N22W160.hgt) write it without its georeferencing; without it such a write is
    /// refused.
    #[arg(long)]
    pub drop_georef: bool,
}

impl RasterOpts {
    pub fn mapping(&self) -> Option<PngMapping> {
        if self.png_scale.is_none() && self.png_offset.is_none() && self.png_nodata.is_none() {
            return None;
        }
        Some(PngMapping {
            scale: self.png_scale.unwrap_or(1.0),
            offset: self.png_offset.unwrap_or(0.0),
            nodata_code: self.png_nodata,
        })
    }
}

/// An input that is a directory is a usage error that says so (the formats would call it a
/// file with an empty extension).
pub fn check_not_dir(input: &Path) -> Result<()> {
    if input.is_dir() {
        return Err(Error::invalid(format!(
            "{} is a directory: give a raster file (or a point file to encode)",
            input.display()
        )));
    }
    Ok(())
}

/// An error bound option's value (`--max-error`, `--rmse`): E data units or E% of the value
/// range, E a finite number ≥ 0; anything else is a usage error naming the option.
pub fn bound(option: &str, s: &str) -> Result<vtz::ErrorBound> {
    vtz::ErrorBound::parse(s).map_err(|_| {
        Error::invalid(format!(
            "{option} must be a finite number ≥ 0 in data units or a percentage of the value range \
             (e.g. 2.5 or 1%), not '{s}'"
        ))
    })
}

pub fn parse_format(s: Option<&str>) -> Result<Option<Format>> {
    s.map(Format::from_name).transpose()
}

/// Read any raster (a `.vtz` is decoded).
pub fn read_raster(path: &Path, format: Option<Format>, opts: &RasterOpts) -> Result<Raster> {
    let ro = ReadOptions::default()
        .with_format(format)
        .with_png_mapping(opts.mapping());
    vtz::read_path(path, &ro)
}

/// The raster to encode, read band by band where its format allows (raw `.f32`, GeoTIFF),
/// else whole (a `.vtz` is decoded).
pub fn open_source(
    path: &Path,
    format: Option<Format>,
    opts: &RasterOpts,
) -> Result<Box<dyn vtz::RowSource>> {
    let f = match format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    if f == Format::Vtz {
        return Ok(Box::new(read_raster(path, format, opts)?));
    }
    let ro = ReadOptions::default()
        .with_format(format)
        .with_png_mapping(opts.mapping());
    vtz::formats::open_source(path, &ro)
}

pub fn write_options(
    format: Option<Format>,
    force: bool,
    opts: &RasterOpts,
    out: &OutputOpts,
) -> WriteOptions {
    WriteOptions::default()
        .with_format(format)
        .with_force(force)
        .with_png_mapping(opts.mapping())
        .with_round(out.round)
        .with_drop_georef(out.drop_georef)
}

/// Whether a file starts like a `.vtz` point set (container version 3).
/// The URL an input or output names (`http://`, `https://`, `s3://`), if it is one.
pub fn url_of(p: &Path) -> Option<&str> {
    p.to_str().filter(|s| vtz::source::is_url(s))
}

/// Remote inputs this command opened, by URL: each is opened once (one request) and shared
/// by the routing (point set or raster) and the decoder.
static REMOTE: std::sync::Mutex<Vec<(String, Arc<dyn RangeSource>)>> =
    std::sync::Mutex::new(Vec::new());

fn remote_source(url: &str) -> Result<Arc<dyn RangeSource>> {
    let mut open = REMOTE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, s)) = open.iter().find(|(u, _)| u == url) {
        return Ok(s.clone());
    }
    let s = vtz::source::remote::open_url(url, &RemoteOptions::from_env()?)?;
    open.push((url.to_string(), s.clone()));
    Ok(s)
}

/// A `.vtz` input's bytes as ranges: a URL through a remote source, a local file by
/// positioned reads.
pub fn input_source(input: &Path) -> Result<Arc<dyn RangeSource>> {
    match url_of(input) {
        Some(url) => remote_source(url),
        None => Ok(Arc::new(vtz::source::FileSource::open(input)?)),
    }
}

/// Open a `.vtz` input (a local path or a URL) for decoding; errors name no file (the
/// caller adds it where its messages want it).
pub fn open_decoder(input: &Path, limits: Limits) -> Result<vtz::Decoder> {
    vtz::Decoder::open_with_limits(input_source(input)?, limits)
}

/// An `s3://` output: the command writes a local temporary file (in a directory of its own,
/// removed on drop and by the Ctrl-C handler), then [`Staged::upload`] sends it.
pub struct Staged {
    dir: PathBuf,
    /// Where the command writes.
    pub local: PathBuf,
    url: String,
    opts: RemoteOptions,
}

impl Staged {
    /// Stage `-o URL`: only `s3://bucket/key` takes uploads; an existing object needs
    /// `--force` (checked now, with one HEAD request, before any work).
    pub fn new(url: &str, force: bool) -> Result<Staged> {
        if !url
            .get(..5)
            .is_some_and(|s| s.eq_ignore_ascii_case("s3://"))
        {
            return Err(Error::invalid(format!(
                "-o {url}: an output is a local path or s3://bucket/key (an HTTP server takes no uploads)"
            )));
        }
        let opts = RemoteOptions::from_env()?;
        if !force && vtz::source::remote::exists(url, &opts)? {
            return Err(Error::invalid(format!(
                "{url} exists (use --force to overwrite)"
            )));
        }
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let dir = std::env::temp_dir().join(format!("vtz-upload-{}-{nanos}", std::process::id()));
        std::fs::create_dir(&dir).map_err(|e| Error::io(dir.display().to_string(), e))?;
        vtz::formats::track_temporary(&dir);
        Ok(Staged {
            local: dir.join("upload.vtz"),
            dir,
            url: url.to_string(),
            opts,
        })
    }

    /// Upload the written file (a multipart upload, aborted on failure), with progress.
    pub fn upload(&self, ui: &Ui) -> Result<()> {
        ui.progress("uploading", |p| {
            vtz::source::remote::upload(&self.local, &self.url, &self.opts, p)
        })
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
        vtz::formats::untrack_temporary(&self.dir);
    }
}

pub fn is_points_file(path: &Path) -> Result<bool> {
    use std::io::Read;
    if let Some(url) = url_of(path) {
        let src = remote_source(url)?;
        let n = src.len()?.min(10);
        let head = src
            .read_ranges(std::slice::from_ref(&(0..n)))?
            .pop()
            .unwrap_or_default();
        return Ok(vtz::is_points_file(&head));
    }
    let mut head = [0u8; 10];
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path.display().to_string(), e))?;
    let n = f
        .read(&mut head)
        .map_err(|e| Error::io(path.display().to_string(), e))?;
    Ok(vtz::is_points_file(&head[..n]))
}

/// A whole input file (a URL: the whole object, in one request, or none when it is within
/// the first bytes read on opening).
pub fn read_file(path: &Path) -> Result<Vec<u8>> {
    if let Some(url) = url_of(path) {
        let src = remote_source(url)?;
        let all = 0..src.len()?;
        return Ok(src
            .read_ranges(std::slice::from_ref(&all))?
            .pop()
            .unwrap_or_default());
    }
    std::fs::read(path).map_err(|e| Error::io(path.display().to_string(), e))
}

/// Refuse to write an output onto the input.
pub fn check_distinct(input: &Path, output: &Path) -> Result<()> {
    let same = match (input.canonicalize(), output.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        return Err(Error::invalid(format!(
            "output {} is the input file",
            output.display()
        )));
    }
    Ok(())
}

/// Everything about an output that can fail, checked before the work starts: not the input,
/// not an existing file without `--force`, in a directory that exists and takes new files
/// (probed with a file created and removed at once).
/// Refuse a `.vtz` output named with another format's extension (`encode x.tif -o y.tif`
/// would write a container that GDAL and every other reader take for a GeoTIFF).
pub fn check_vtz_name(output: &Path) -> Result<()> {
    let other = match Format::from_path(output) {
        Ok(Format::Vtz) => None,
        Ok(f) => Some(f.name()),
        Err(_) => vtz::formats::points::PointFormat::from_path(output).map(|f| match f {
            vtz::formats::points::PointFormat::Xyz => "XYZ text",
            vtz::formats::points::PointFormat::Csv => "CSV text",
            vtz::formats::points::PointFormat::Las => "LAS",
            vtz::formats::points::PointFormat::Laz => "LAZ",
        }),
    };
    match other {
        Some(name) => Err(Error::invalid(format!(
            "{}: encode writes a .vtz container, and this name says {name}: name it .vtz \
             (vtz convert and vtz decode write {name})",
            output.display()
        ))),
        None => Ok(()),
    }
}

pub fn check_output(input: &Path, output: &Path, force: bool) -> Result<()> {
    check_distinct(input, output)?;
    if !force && output.exists() {
        return Err(Error::invalid(format!(
            "{} exists (use --force to overwrite)",
            output.display()
        )));
    }
    check_parent(output)
}

/// The directory an output goes into exists and takes new files (probed with a file
/// created and removed at once).
fn check_parent(output: &Path) -> Result<()> {
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        let (kind, why) = if dir.exists() {
            (std::io::ErrorKind::NotADirectory, "is not a directory")
        } else {
            (std::io::ErrorKind::NotFound, "does not exist")
        };
        return Err(Error::io(
            format!("output {}", output.display()),
            std::io::Error::new(kind, format!("{} {why}", dir.display())),
        ));
    }
    let probe = dir.join(format!(".vtz-probe-{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .map_err(|e| Error::io(format!("cannot write in {}", dir.display()), e))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// [`check_output`] for an output directory (`vtz tiles`): not the input, its parent
/// exists and takes new entries, and an existing one is replaced only with `--force` and
/// only when it holds `marker` (what a previous run wrote there).
pub fn check_output_dir(input: &Path, output: &Path, force: bool, marker: &str) -> Result<()> {
    check_distinct(input, output)?;
    if output.exists() {
        if !force {
            return Err(Error::invalid(format!(
                "{} exists (use --force to replace it)",
                output.display()
            )));
        }
        if !output.join(marker).is_file() {
            return Err(Error::invalid(format!(
                "{} exists and holds no {marker}: not replacing it",
                output.display()
            )));
        }
    }
    check_parent(output)
}

/// `IN.ext` → `IN.vtz`.
pub fn default_output(input: &Path, ext: &str) -> PathBuf {
    input.with_extension(ext)
}

pub fn is_vtz(path: &Path, format: Option<Format>) -> bool {
    format == Some(Format::Vtz)
        || (format.is_none()
            && path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("vtz")))
}

/// `n` and the noun, plural when `n` is not 1: `1 tile`, `16 tiles`, `1 section`.
pub fn count(n: u64, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// A statistic as JSON.
pub fn stat_json(v: vtz::StatValue) -> serde_json::Value {
    match v {
        vtz::StatValue::Count(n) => n.into(),
        vtz::StatValue::Number(x) => x.into(),
        vtz::StatValue::Counts(l) => l.into(),
        _ => serde_json::Value::Null,
    }
}

/// Write to stdout for [`outln!`] / [`out!`]: a reader that has gone ends the command quietly
/// (exit 0), any other failure is a one-line I/O error (exit 1); never a panic.
pub fn out(args: std::fmt::Arguments) {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    if let Err(e) = o.write_fmt(args).and_then(|_| o.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("vtz: {}", Error::io("writing to stdout", e));
        std::process::exit(1);
    }
}

/// The samples' type as the output file holds them: a GeoTIFF's is the output type (values
/// in the smallest type that holds them, or codes with GDAL's offset and scale), any other
/// format's the raster's own sample type.
pub fn written_type(r: &vtz::Raster, to: Option<vtz::formats::Format>, path: &Path) -> String {
    let tif = to
        .or_else(|| vtz::formats::Format::from_path(path).ok())
        .is_some_and(|f| f == vtz::formats::Format::GeoTiff);
    if tif {
        vtz::OutputType::of(r.sample_type, r.mapping, r.nodata).describe()
    } else {
        r.sample_type.name().to_string()
    }
}
