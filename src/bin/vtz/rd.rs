//! `vtz rd`: rate–distortion table of methods × max-error bounds on rasters, with a
//! baseline check of bits per sample (for CI) and an optional plot; the measuring, the
//! table, the CSV and the baseline check are the library's (`vtz::rd`).

use crate::common::{self, RasterOpts, Ui};
use std::collections::BTreeSet;
use std::path::PathBuf;
use vtz::rd::{self, RdOptions, Row};
use vtz::{Error, Result};

#[derive(clap::Args)]
#[command(
    mut_arg("json", |a| a.help(
        "Print the rows (and the baseline check) as JSON on stdout instead of the table"
    )),
    mut_arg("force", |a| a.help("Replace existing --csv, --md and --png files"))
)]
pub struct Args {
    /// Rasters to measure (.tif, .png, .exr, .hgt, .asc, .f32 + .json).
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Methods to run, comma-separated: residual, sibson, grid, fis, haar, best.
    #[arg(
        long,
        default_value = "residual,sibson,grid,fis,haar,best",
        value_name = "LIST"
    )]
    pub methods: String,
    /// Max-error bounds, comma-separated: in % of the value range (1%) or in data units (2.5).
    #[arg(
        long,
        default_value = "0.1%,0.3%,1%,3%,10%",
        value_name = "LIST",
        allow_hyphen_values = true
    )]
    pub bounds: String,
    /// Also write the table as CSV (the format --baseline reads).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Also write the Markdown table to this file.
    #[arg(long, value_name = "FILE")]
    pub md: Option<PathBuf>,
    /// Also draw a PNG plot: bits per sample against max error and RMSE (% of range, log–log),
    /// one row of panels per raster, one curve per method.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// Compare bits per sample with this CSV (from --csv); fail if a row grew by more than
    /// --tolerance percent.
    #[arg(long, value_name = "FILE")]
    pub baseline: Option<PathBuf>,
    /// Allowed growth of bits per sample against --baseline, in percent.
    #[arg(
        long,
        default_value_t = 2.0,
        value_name = "PCT",
        requires = "baseline",
        allow_negative_numbers = true
    )]
    pub tolerance: f64,
    #[command(flatten)]
    pub json: common::Json,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let opts = RdOptions::parse(&a.methods, &a.bounds)?;
    if !(a.tolerance >= 0.0 && a.tolerance.is_finite()) {
        return Err(Error::invalid(format!(
            "--tolerance {} must be a percentage ≥ 0",
            a.tolerance
        )));
    }
    let outputs: Vec<&PathBuf> = [&a.csv, &a.md, &a.png].into_iter().flatten().collect();
    for o in &outputs {
        for f in &a.files {
            common::check_output(f, o, a.force.force)?;
        }
    }
    let mut names = BTreeSet::new();
    for f in &a.files {
        if !names.insert(rd::file_key(f)) {
            return Err(Error::invalid(format!(
                "two inputs are named {} (rows are keyed by file name)",
                rd::file_key(f)
            )));
        }
    }
    // Read the baseline first: a bad baseline should fail before minutes of encoding.
    let baseline = a.baseline.as_deref().map(rd::read_baseline).transpose()?;

    let mut rows: Vec<Row> = Vec::new();
    let mut plots = Vec::new();
    for path in &a.files {
        let raster = ui.busy("reading", || common::read_raster(path, None, &a.raster))?;
        let name = rd::file_key(path);
        let measured = ui.progress(&format!("rd {name}"), |p| {
            rd::measure_raster(&raster, &name, &opts, p)
        });
        if a.png.is_some() {
            plots.push(rd::plot_curves(&raster, &name, &measured, &opts));
        }
        rows.extend(measured);
    }

    let table = rd::markdown(&rows);
    if let Some(p) = &a.csv {
        vtz::formats::write_file(p, rd::csv(&rows).into_bytes(), a.force.force)?;
        ui.say(format!("{}: {} rows", p.display(), rows.len()));
    }
    if let Some(p) = &a.md {
        vtz::formats::write_file(p, table.clone().into_bytes(), a.force.force)?;
        ui.say(format!("{}: Markdown table", p.display()));
    }
    if let Some(p) = &a.png {
        let png = ui.busy("drawing", || rd::plot_png(&plots, &opts))?;
        vtz::formats::write_file(p, png, a.force.force)?;
        ui.say(format!("{}: plot", p.display()));
    }

    let check = baseline
        .as_ref()
        .map(|b| rd::compare_baseline(&rows, b, a.tolerance));
    if a.json.json {
        let j = serde_json::json!({
            "rows": rows,
            "baseline": check.as_ref().map(|c| serde_json::json!({
                "file": a.baseline,
                "tolerance_pct": a.tolerance,
                "regressions": c.regressions,
                "improvements": c.improvements,
                "within_tolerance": c.within,
                "missing": c.missing,
            })),
        });
        outln!("{j}");
    } else {
        out!("{table}");
    }

    let broken: Vec<&Row> = rows.iter().filter(|r| r.bound_ok == Some(false)).collect();
    for r in &broken {
        eprintln!(
            "vtz: BOUND VIOLATED (codec bug): {} {} {}: {}",
            r.file, r.method, r.bound, r.note
        );
    }
    let na = rows.iter().filter(|r| r.bound_ok.is_none()).count();
    if na > 0 {
        ui.say(format!(
            "{na} of {} runs not available (see the note column)",
            rows.len()
        ));
    }
    let mut failed = Vec::new();
    if !broken.is_empty() {
        failed.push(format!(
            "{} run{} broke the error bound",
            broken.len(),
            if broken.len() == 1 { "" } else { "s" }
        ));
    }
    if let (Some(c), Some(path)) = (&check, &a.baseline) {
        for l in &c.improvements {
            ui.say(format!("improvement: {l}"));
        }
        for l in &c.within {
            ui.say(format!("within tolerance: {l}"));
        }
        for l in &c.missing {
            ui.say(format!("not compared: {l}"));
        }
        for l in &c.regressions {
            eprintln!("vtz: regression: {l}");
        }
        ui.say(format!(
            "baseline {}: {} rows compared, {} regressions, {} improvements, {} not compared \
             (tolerance {} %)",
            path.display(),
            c.compared,
            c.regressions.len(),
            c.improvements.len(),
            c.missing.len(),
            a.tolerance
        ));
        if !c.regressions.is_empty() {
            failed.push(format!(
                "{} row{} regressed against {}",
                c.regressions.len(),
                if c.regressions.len() == 1 { "" } else { "s" },
                path.display()
            ));
        }
    }
    if !failed.is_empty() {
        // Not an argument or I/O error: the measurement itself failed. Exit 1 with one line.
        eprintln!("vtz: rd failed: {}", failed.join("; "));
        let _ = std::io::Write::flush(&mut std::io::stdout());
        std::process::exit(1);
    }
    Ok(())
}
