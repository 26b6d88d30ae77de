//! Rate–distortion measurement of the codec (what `vtz rd` runs): methods × max-error
//! bounds on rasters, as rows with bits per sample, errors and times; the rows as a Markdown
//! table or CSV, and a baseline check of bits per sample against an earlier CSV (CI's
//! `benches/rd_baseline.csv`).
//!
//! Every run encodes with one method and bound, decodes, and compares with the source. A
//! method that cannot meet a bound (or is not available) gives a row marked "not available"
//! with the reason; a decoded raster outside its bound is a codec bug: its row has
//! `bound_ok == Some(false)`.

use crate::{EncodeOptions, Error, ErrorBound, Method, Raster, Result};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// A method's name in the table: the registry's, or `best` for `None` (the smallest of all).
pub fn method_name(m: Option<Method>) -> &'static str {
    m.map_or("best", |m| m.name())
}

/// A method's name (as [`Method::parse`] takes it) or `best` (`None`).
pub fn parse_method(s: &str) -> Result<Option<Method>> {
    if s.trim().eq_ignore_ascii_case("best") {
        Ok(None)
    } else {
        Method::parse(s.trim()).map(Some)
    }
}

/// What to measure on each raster: every method at every bound.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct RdOptions {
    /// The methods, `None` for `best`, each once, in table order.
    pub methods: Vec<Option<Method>>,
    /// The bounds, each once, in table order.
    pub bounds: Vec<ErrorBound>,
}

impl RdOptions {
    /// Options from comma-separated lists (`residual,sibson,best`, `0.1%,1%,2.5`); repeats
    /// are dropped. Errors ([`Error::InvalidArgument`]): an unknown method, a bad bound, or
    /// an empty list, named as the options `--methods` and `--bounds`.
    pub fn parse(methods: &str, bounds: &str) -> Result<RdOptions> {
        Ok(RdOptions {
            methods: parse_list(methods, "methods", parse_method)?,
            bounds: parse_list(bounds, "bounds", ErrorBound::parse)?,
        })
    }
}

/// One (raster, method, bound) run. `bytes` and the measures are `None` when the method gave
/// no result (`note` says why).
#[derive(Clone, Debug, Serialize)]
#[non_exhaustive]
pub struct Row {
    /// The raster's key ([`file_key`]).
    pub file: String,
    /// The method measured ([`method_name`]).
    pub method: String,
    /// The bound as given, spelled canonically (`1%`, `0.25%`, `2.5`).
    pub bound: String,
    /// The bound in data units.
    pub bound_abs: f64,
    /// Samples of the raster.
    pub samples: usize,
    /// Size of the encoded file in bytes.
    pub bytes: Option<u64>,
    /// Bits per sample of the encoded file.
    pub bps: Option<f64>,
    /// Source bits per sample (sample type) over bits per sample.
    pub ratio: Option<f64>,
    /// RMSE of the decoded raster, in data units.
    pub rmse: Option<f64>,
    /// Max error of the decoded raster, in data units.
    pub max_error: Option<f64>,
    /// RMSE in % of the value range.
    pub rmse_pct: Option<f64>,
    /// Max error in % of the value range.
    pub max_error_pct: Option<f64>,
    /// Encoding time in seconds (measured: differs run to run).
    pub enc_s: Option<f64>,
    /// Decoding time in seconds (measured: differs run to run).
    pub dec_s: Option<f64>,
    /// Whether the decoded raster kept the bound (and every valid/nodata sample).
    pub bound_ok: Option<bool>,
    /// The method written (differs from `method` for best).
    pub written: Option<String>,
    /// Sites kept, for a sites section.
    pub sites: Option<usize>,
    /// Why there is no result, or what went wrong.
    pub note: String,
}

const COLUMNS: [&str; 18] = [
    "file",
    "method",
    "bound",
    "bound_abs",
    "samples",
    "bytes",
    "bps",
    "ratio",
    "rmse",
    "max_error",
    "rmse_pct",
    "max_error_pct",
    "enc_s",
    "dec_s",
    "bound_ok",
    "written",
    "sites",
    "note",
];

/// Decimals of bits per sample in the CSV (and so in the baseline comparison).
const BPS_DECIMALS: usize = 6;

/// The canonical spelling of a bound: `1%`, `0.25%`, `2.5`.
fn bound_label(b: ErrorBound) -> String {
    match b {
        ErrorBound::PercentOfRange(v) => format!("{v}%"),
        ErrorBound::Abs(v) => format!("{v}"),
    }
}

fn parse_list<T>(s: &str, what: &str, parse: impl Fn(&str) -> Result<T>) -> Result<Vec<T>>
where
    T: PartialEq,
{
    let mut out = Vec::new();
    for p in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let v = parse(p).map_err(|e| e.context(format!("--{what}")))?;
        if !out.contains(&v) {
            out.push(v);
        }
    }
    if out.is_empty() {
        return Err(Error::invalid(format!("--{what} lists nothing")));
    }
    Ok(out)
}

/// A file's key in the table and the baseline: its name without the directory.
pub fn file_key(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

/// The first line of an error message (rows hold one line).
fn one_line(e: &Error) -> String {
    let s = e.to_string();
    s.lines().next().unwrap_or("").trim().to_string()
}

/// Measure every method at every bound of `opts` on `raster` (keyed `name` in the rows), in
/// table order (methods, then bounds). `progress` gets the fraction done (0..=1, 1 at the
/// end). A failed run is a row that says so, never an error.
pub fn measure_raster(
    raster: &Raster,
    name: &str,
    opts: &RdOptions,
    progress: &dyn Fn(f64),
) -> Vec<Row> {
    let span = raster.valid_range().map_or(0.0, |(lo, hi)| hi - lo);
    let runs = opts.methods.len() * opts.bounds.len();
    let mut rows = Vec::with_capacity(runs);
    let mut k = 0usize;
    for &m in &opts.methods {
        for &b in &opts.bounds {
            let mut sub = |f: f64| progress((k as f64 + f.clamp(0.0, 1.0)) / runs as f64);
            rows.push(measure(raster, name, m, b, span, &mut sub));
            k += 1;
            progress(k as f64 / runs as f64);
        }
    }
    rows
}

/// The curves of one raster's rows for [`plot_png`]: one per method of `opts`, the bounds
/// in % of the raster's value range.
#[cfg(feature = "plot")]
pub fn plot_curves(
    raster: &Raster,
    name: &str,
    rows: &[Row],
    opts: &RdOptions,
) -> crate::viz::plot::Raster {
    use crate::viz::plot;
    let span = raster.valid_range().map_or(0.0, |(lo, hi)| hi - lo);
    plot::Raster {
        name: name.to_string(),
        series: opts
            .methods
            .iter()
            .map(|m| {
                let pts = rows
                    .iter()
                    .filter(|r| r.method == method_name(*m))
                    .filter_map(|r| {
                        Some(plot::Point {
                            bps: r.bps?,
                            max_pct: r.max_error_pct?,
                            rmse_pct: r.rmse_pct?,
                        })
                    })
                    .collect();
                (method_name(*m).to_string(), pts)
            })
            .collect(),
        bounds_pct: opts
            .bounds
            .iter()
            .map(|&b| match b {
                ErrorBound::PercentOfRange(v) => v,
                ErrorBound::Abs(v) if span > 0.0 => 100.0 * v / span,
                ErrorBound::Abs(_) => 0.0,
            })
            .collect(),
    }
}

/// The PNG plot of the rasters' curves ([`plot_curves`]): bits per sample against max error
/// and RMSE (% of range, log–log), one row of panels per raster. Errors: drawing failed.
#[cfg(feature = "plot")]
pub fn plot_png(curves: &[crate::viz::plot::Raster], opts: &RdOptions) -> Result<Vec<u8>> {
    let title = format!(
        "vtz rate–distortion: {} raster{}, {}",
        curves.len(),
        if curves.len() == 1 { "" } else { "s" },
        opts.methods
            .iter()
            .map(|m| method_name(*m))
            .collect::<Vec<_>>()
            .join(", ")
    );
    crate::viz::plot::rd_png(curves, &title)
}

/// Encode `raster` with method `m` at bound `b`, decode, compare.
fn measure(
    raster: &Raster,
    name: &str,
    m: Option<Method>,
    b: ErrorBound,
    span: f64,
    progress: &mut dyn FnMut(f64),
) -> Row {
    let bound_abs = b.absolute(raster.valid_range());
    let mut row = Row {
        file: name.to_string(),
        method: method_name(m).to_string(),
        bound: bound_label(b),
        bound_abs,
        samples: raster.len(),
        bytes: None,
        bps: None,
        ratio: None,
        rmse: None,
        max_error: None,
        rmse_pct: None,
        max_error_pct: None,
        enc_s: None,
        dec_s: None,
        bound_ok: None,
        written: None,
        sites: None,
        note: String::new(),
    };
    let opts = EncodeOptions {
        max_error: Some(b),
        methods: m.into_iter().collect(),
        ..Default::default()
    };
    let t0 = Instant::now();
    let (bytes, report) = match crate::encode_progress(raster, &opts, progress) {
        Ok(v) => v,
        Err(e) => {
            row.note = format!("not available: {}", one_line(&e));
            return row;
        }
    };
    row.enc_s = Some(t0.elapsed().as_secs_f64());
    let n = bytes.len() as u64;
    let bps = crate::metrics::bits_per_sample(n, raster.len());
    row.bytes = Some(n);
    row.bps = Some(bps);
    row.ratio = Some(raster.sample_type.bits() as f64 / bps.max(f64::MIN_POSITIVE));
    row.written = Some(report.method.name().to_string());
    row.sites = report
        .stats
        .as_ref()
        .and_then(|s| s.count("sites"))
        .map(|n| n as usize);
    let t1 = Instant::now();
    let back = match crate::decode(&bytes) {
        Ok(r) => r,
        Err(e) => {
            row.bound_ok = Some(false);
            row.note = format!("decoding its own output failed: {}", one_line(&e));
            return row;
        }
    };
    row.dec_s = Some(t1.elapsed().as_secs_f64());
    let c = match crate::metrics::compare(raster, &back) {
        Ok(c) => c,
        Err(e) => {
            row.bound_ok = Some(false);
            row.note = format!("decoded raster differs in shape: {}", one_line(&e));
            return row;
        }
    };
    row.rmse = Some(c.rmse);
    row.max_error = Some(c.max_error);
    row.rmse_pct = Some(c.rmse_pct);
    row.max_error_pct = Some(c.max_error_pct);
    // The bound in data units is computed the way the encoder computes it; allow only the
    // rounding of that product.
    let slack = 1e-12 * span.max(bound_abs);
    let held = c.max_error <= bound_abs + slack;
    row.bound_ok = Some(held && c.lost == 0 && c.invented == 0);
    if !held {
        row.note = format!("max error {} > bound {}", c.max_error, bound_abs);
    } else if c.lost > 0 || c.invented > 0 {
        row.note = format!(
            "{} valid samples lost, {} nodata samples filled",
            c.lost, c.invented
        );
    } else if let Some(s) = row.sites {
        row.note = format!("{s} sites");
    }
    if m.is_none() {
        let w = format!("wrote {}", report.method.name());
        row.note = if row.note.is_empty() {
            w
        } else {
            format!("{w}, {}", row.note)
        };
    }
    row
}

/// A number with at most `d` decimals, trailing zeros dropped.
fn num(v: f64, d: usize) -> String {
    let s = format!("{v:.d$}");
    if s.contains('.') {
        let t = s.trim_end_matches('0').trim_end_matches('.');
        if t == "-0" { "0".into() } else { t.into() }
    } else {
        s
    }
}

/// The rows as a Markdown table (what `vtz rd` prints), one line per row.
pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| raster | method | bound | bytes | bps | ratio | RMSE | L∞ | RMSE % | L∞ % | enc s | dec s | bound | note |\n\
         |---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|---|\n",
    );
    let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or("—".to_string(), f);
    for r in rows {
        let ok = match r.bound_ok {
            Some(true) => "ok",
            Some(false) => "**VIOLATED**",
            None => "—",
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.file,
            r.method,
            r.bound,
            r.bytes.map_or("—".to_string(), |b| b.to_string()),
            opt(r.bps, &|v| format!("{v:.4}")),
            opt(r.ratio, &|v| format!("{v:.1}")),
            opt(r.rmse, &|v| num(v, 4)),
            opt(r.max_error, &|v| num(v, 4)),
            opt(r.rmse_pct, &|v| format!("{v:.4}")),
            opt(r.max_error_pct, &|v| format!("{v:.4}")),
            opt(r.enc_s, &|v| format!("{v:.2}")),
            opt(r.dec_s, &|v| format!("{v:.2}")),
            ok,
            r.note.replace('|', "\\|"),
        );
    }
    s
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The rows as CSV (what `vtz rd --csv` writes and [`read_baseline`] reads): a header line
/// with the columns, then one record per row; bits per sample with six decimals.
pub fn csv(rows: &[Row]) -> String {
    let mut s = COLUMNS.join(",");
    s.push('\n');
    let o = |v: Option<f64>, d: usize| v.map_or(String::new(), |v| num(v, d));
    for r in rows {
        let fields = [
            r.file.clone(),
            r.method.clone(),
            r.bound.clone(),
            num(r.bound_abs, 9),
            r.samples.to_string(),
            r.bytes.map_or(String::new(), |b| b.to_string()),
            o(r.bps, BPS_DECIMALS),
            o(r.ratio, 3),
            o(r.rmse, 6),
            o(r.max_error, 6),
            o(r.rmse_pct, 6),
            o(r.max_error_pct, 6),
            o(r.enc_s, 3),
            o(r.dec_s, 3),
            match r.bound_ok {
                Some(true) => "yes".into(),
                Some(false) => "no".into(),
                None => String::new(),
            },
            r.written.clone().unwrap_or_default(),
            r.sites.map_or(String::new(), |n| n.to_string()),
            r.note.clone(),
        ];
        let line: Vec<String> = fields.iter().map(|f| csv_field(f)).collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

/// Split CSV text into records (RFC 4180: quoted fields may hold commas, quotes, newlines).
fn parse_csv(text: &str) -> std::result::Result<Vec<Vec<String>>, String> {
    let mut records = Vec::new();
    let mut rec = Vec::new();
    let mut field = String::new();
    let mut chars = text.chars().peekable();
    let mut quoted = false;
    let mut any = false;
    while let Some(c) = chars.next() {
        if quoted {
            match c {
                '"' if chars.peek() == Some(&'"') => {
                    chars.next();
                    field.push('"');
                }
                '"' => quoted = false,
                _ => field.push(c),
            }
            continue;
        }
        match c {
            '"' if field.is_empty() => quoted = true,
            ',' => rec.push(std::mem::take(&mut field)),
            '\r' => {}
            '\n' => {
                rec.push(std::mem::take(&mut field));
                records.push(std::mem::take(&mut rec));
                any = false;
                continue;
            }
            _ => field.push(c),
        }
        any = true;
    }
    if quoted {
        return Err("a quoted field is not closed".into());
    }
    if any || !field.is_empty() || !rec.is_empty() {
        rec.push(field);
        records.push(rec);
    }
    Ok(records)
}

/// Baseline rows: (file, method, bound) → bits per sample (`None`: not available there).
pub type Baseline = BTreeMap<(String, String, String), Option<f64>>;

/// Read a baseline CSV (from [`csv`]): its `file`, `method`, `bound` and `bps` columns, found by
/// name. Errors: the file cannot be read ([`Error::Io`]), or it is not such a CSV (no such
/// column, a bad method, bound or number: [`Error::InvalidArgument`] naming the row).
pub fn read_baseline(path: &Path) -> Result<Baseline> {
    let text =
        std::fs::read_to_string(path).map_err(|e| Error::io(path.display().to_string(), e))?;
    let bad = |what: String| Error::invalid(format!("baseline {}: {what}", path.display()));
    let recs = parse_csv(&text).map_err(bad)?;
    let mut it = recs
        .into_iter()
        .filter(|r| !(r.len() == 1 && r[0].trim().is_empty()));
    let head = it.next().ok_or_else(|| bad("empty file".into()))?;
    let col = |name: &str| {
        head.iter()
            .position(|h| h.trim() == name)
            .ok_or_else(|| bad(format!("no '{name}' column (write it with vtz rd --csv)")))
    };
    let (cf, cm, cb, cbps) = (col("file")?, col("method")?, col("bound")?, col("bps")?);
    let mut out = Baseline::new();
    for (i, r) in it.enumerate() {
        let line = i + 2;
        let get = |c: usize| r.get(c).map(|s| s.trim()).unwrap_or("");
        let method = parse_method(get(cm))
            .map(method_name)
            .map_err(|e| bad(format!("row {line}: {}", one_line(&e))))?
            .to_string();
        let bound = ErrorBound::parse(get(cb))
            .map(bound_label)
            .map_err(|e| bad(format!("row {line}: {}", one_line(&e))))?;
        let bps = match get(cbps) {
            "" => None,
            s => Some(
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| bad(format!("row {line}: bps '{s}' is not a number")))?,
            ),
        };
        out.insert((get(cf).to_string(), method, bound), bps);
    }
    Ok(out)
}

/// The baseline check: one line per row of each kind.
#[derive(Clone, Debug, Default)]
pub struct Check {
    /// Rows found in both (not counting rows not available in either).
    pub compared: usize,
    /// Rows whose bits per sample grew by more than the tolerance, or that are no longer
    /// available.
    pub regressions: Vec<String>,
    /// Rows that became smaller.
    pub improvements: Vec<String>,
    /// Rows that grew within the tolerance.
    pub within: Vec<String>,
    /// Rows only on one side (one line per baseline file not run at all).
    pub missing: Vec<String>,
}

/// Compare the rows' bits per sample with a baseline, at the CSV's precision; a row that grew
/// by more than `tolerance` percent (or is no longer available) is a regression.
pub fn compare_baseline(rows: &[Row], base: &Baseline, tolerance: f64) -> Check {
    let mut c = Check::default();
    let mut seen = BTreeSet::new();
    for r in rows {
        let key = (r.file.clone(), r.method.clone(), r.bound.clone());
        let what = format!("{} {} {}", r.file, r.method, r.bound);
        seen.insert(key.clone());
        // Compared at the CSV's precision, so an unchanged row compares equal.
        let bps = r
            .bps
            .map(|v| num(v, BPS_DECIMALS).parse::<f64>().unwrap_or(v));
        match (base.get(&key), bps) {
            (None, _) => c.missing.push(format!("{what}: not in the baseline")),
            (Some(None), None) => {}
            (Some(None), Some(now)) => c.missing.push(format!(
                "{what}: {now:.4} bps, not available in the baseline"
            )),
            (Some(&Some(was)), None) => {
                // The method no longer meets this bound at all: worse than any growth.
                c.compared += 1;
                c.regressions.push(format!(
                    "{what}: was {was:.4} bps, now not available ({})",
                    r.note
                ));
            }
            (Some(&Some(was)), Some(now)) => {
                c.compared += 1;
                let pct = if was > 0.0 {
                    100.0 * (now - was) / was
                } else if now > 0.0 {
                    f64::INFINITY
                } else {
                    0.0
                };
                let line = format!("{what}: {was:.4} → {now:.4} bps ({pct:+.2} %)");
                if pct > tolerance {
                    c.regressions
                        .push(format!("{line}, more than the {tolerance} % allowed"));
                } else if now < was {
                    c.improvements.push(line);
                } else if now > was {
                    c.within.push(line);
                }
            }
        }
    }
    // Baseline rows this run did not make: one line per row, or per file left out entirely.
    let run_files: BTreeSet<&str> = rows.iter().map(|r| r.file.as_str()).collect();
    let mut absent: BTreeMap<&str, usize> = BTreeMap::new();
    for key in base.keys().filter(|k| !seen.contains(*k)) {
        if run_files.contains(key.0.as_str()) {
            c.missing.push(format!(
                "{} {} {}: in the baseline, not run",
                key.0, key.1, key.2
            ));
        } else {
            *absent.entry(key.0.as_str()).or_default() += 1;
        }
    }
    for (file, n) in absent {
        c.missing
            .push(format!("{file}: {n} baseline rows, file not run"));
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_quotes_and_commas() {
        let recs = parse_csv("a,b,c\n1,\"x, \"\"y\"\"\",\n2,,z").unwrap();
        assert_eq!(
            recs,
            vec![
                vec!["a", "b", "c"],
                vec!["1", "x, \"y\"", ""],
                vec!["2", "", "z"]
            ]
        );
        assert_eq!(csv_field("x, \"y\""), "\"x, \"\"y\"\"\"");
    }

    #[test]
    fn bound_labels_are_canonical() {
        assert_eq!(bound_label(ErrorBound::parse("1.0%").unwrap()), "1%");
        assert_eq!(bound_label(ErrorBound::parse(" 0.10 %").unwrap()), "0.1%");
        assert_eq!(bound_label(ErrorBound::parse("2.50").unwrap()), "2.5");
    }

    #[test]
    fn numbers_drop_trailing_zeros() {
        assert_eq!(num(1.5, 4), "1.5");
        assert_eq!(num(2.0, 4), "2");
        assert_eq!(num(-0.00001, 3), "0");
        assert_eq!(num(0.123456789, 6), "0.123457");
    }
}
