//! The `vtz` command line: a thin layer over the library, one file per subcommand.
#![forbid(unsafe_code)]

/// `println!` that never panics: when the reader of stdout has gone (`vtz info F | head`),
/// the command stops quietly with success, as the reader chose; another write error is a
/// one-line I/O error, exit 1.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::common::out(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` with the same rules as [`outln!`].
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::common::out(format_args!($($arg)*))
    };
}

mod cells;
mod common;
mod compare;
mod convert;
mod decode;
mod encode;
mod info;
mod lsystem;
mod mesh;
mod points;
mod rd;
mod render;
mod sites;
mod tiles;
mod verify;
mod web;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use std::process::ExitCode;

/// Compress elevation rasters (DEMs, height fields) with a hard error bound.
#[derive(Parser)]
#[command(name = "vtz", version, about, max_term_width = 100)]
struct Cli {
    /// No progress bars or summary lines (errors are still printed).
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Compress a raster into a .vtz file.
    Encode(encode::Args),
    /// Decompress a .vtz file into a raster file.
    Decode(decode::Args),
    /// Show a .vtz file's header and sections.
    Info(info::Args),
    /// Compare two rasters (either may be a .vtz): RMSE, max error, PSNR, bits per sample.
    Compare(compare::Args),
    /// Convert a raster between formats.
    Convert(convert::Args),
    /// List a .vtz file's sites (importance rank, level, position, height) as CSV.
    Sites(sites::Args),
    /// One level's Voronoi cells of a .vtz's sites with their residual (eps_max, eps_rms):
    /// GeoJSON polygons or a PNG picture.
    Cells(cells::Args),
    /// A raster or .vtz as a triangle mesh: OBJ, PLY, STL or binary glTF (.glb).
    Mesh(mesh::Args),
    /// A 3D L-system's tips as points (.xyz) or a triangulated cover (.obj, .ply, .stl, .glb).
    Lsystem(lsystem::Args),
    /// A geographic raster or .vtz as Cesium terrain tiles (quantized-mesh-1.0, layer.json).
    Tiles(tiles::Args),
    /// A georeferenced raster or .vtz as raster-dem tiles for web maps (MapLibre): a
    /// Web Mercator pyramid in a PMTiles archive, vtz tiles or Terrarium/Terrain-RGB.
    Web(web::Args),
    /// Draw a raster or .vtz as a shaded relief PNG (optionally with its sites).
    Render(render::Args),
    /// Check .vtz files end to end: every checksum, every section decoded, the decodes
    /// against the stored mask, range and max errors; one line per file, exit 1 on a problem.
    Verify(verify::Args),
    /// Rate–distortion table of methods × error bounds on rasters (CSV, plot, baseline check).
    Rd(rd::Args),
}

/// The command line as clap reads it, every option that takes a value allowing a negative
/// number as that value (`--max-error -1` is the value -1, which the option's check then
/// refuses with its own message, not "unexpected argument '-1'").
fn command() -> clap::Command {
    fn negative(c: clap::Command) -> clap::Command {
        c.mut_args(|a| {
            if a.get_action().takes_values() {
                a.allow_negative_numbers(true)
            } else {
                a
            }
        })
        .mut_subcommands(negative)
    }
    negative(Cli::command())
}

/// Parse the command line; `--help` and `--version` print and exit 0, a usage error is
/// printed as one line (exit 2), as every other error is.
fn parse() -> Result<Cli, ExitCode> {
    let res = command()
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    match res {
        Ok(cli) => Ok(cli),
        Err(e) => {
            use clap::error::ErrorKind;
            match e.kind() {
                // Help and version on stdout; `vtz` alone shows the help (on stderr, exit 2).
                ErrorKind::DisplayHelp
                | ErrorKind::DisplayVersion
                | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
                    let _ = e.print();
                    Err(ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2)))
                }
                _ => {
                    // The subcommand the user typed, for the pointer to its help (clap's
                    // message names it only in its usage line, which some errors lack).
                    let sub = std::env::args()
                        .skip(1)
                        .find(|a| !a.starts_with('-'))
                        .filter(|a| command().find_subcommand(a).is_some());
                    eprintln!("vtz: {}", usage_error_line(&e, sub.as_deref()));
                    Err(ExitCode::from(2))
                }
            }
        }
    }
}

/// A clap usage error as one line: its message, the possible values or a similar name it
/// suggests, and where the command's help is (`vtz encode --help`). A negative number given
/// to an option that takes none says "must be ≥ 0".
fn usage_error_line(e: &clap::Error, sub: Option<&str>) -> String {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    let text = e.render().to_string();
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let first = lines.next().unwrap_or("invalid arguments");
    let mut msg = first.strip_prefix("error: ").unwrap_or(first).to_string();
    let mut help = sub.map_or("vtz --help".to_string(), |s| format!("vtz {s} --help"));
    for l in lines {
        if let Some(u) = l.strip_prefix("Usage: ") {
            // "vtz encode [OPTIONS] <INPUT>": the command's words before its arguments.
            let words: Vec<&str> = u
                .split_whitespace()
                .take_while(|w| !w.starts_with(['-', '<', '['].as_slice()))
                .collect();
            if !words.is_empty() {
                help = format!("{} --help", words.join(" "));
            }
        } else if l.starts_with("For more information") || l.contains("use '-- ") {
            // The pointer to --help is ours; "to pass '-x' as a value, use '-- -x'" is
            // not true of an option's value.
        } else {
            // "the following required arguments were not provided:" + "<INPUT>".
            msg.push_str(if msg.ends_with(':') { " " } else { "; " });
            msg.push_str(l.trim_start_matches("tip: "));
        }
    }
    let negative = match (
        e.get(ContextKind::InvalidArg),
        e.get(ContextKind::InvalidValue),
    ) {
        (Some(ContextValue::String(arg)), Some(ContextValue::String(v)))
            if e.kind() == ErrorKind::ValueValidation
                && v.trim().parse::<f64>().is_ok_and(|x| x < 0.0) =>
        {
            let name = arg.split_whitespace().next().unwrap_or(arg);
            Some(format!("{name} must be ≥ 0, not {}", v.trim()))
        }
        _ => None,
    };
    format!("{} (see {help})", negative.unwrap_or(msg))
}

fn main() -> ExitCode {
    // Ctrl-C or SIGTERM: abort the multipart uploads in flight (`-o s3://…`) and remove the
    // temporaries of outputs still being written (an output appears only by a rename once
    // complete), then stop with 130 as a shell expects.
    let _ = ctrlc::set_handler(|| {
        vtz::source::remote::abort_uploads();
        vtz::formats::remove_temporaries();
        eprintln!("vtz: interrupted; unfinished outputs removed");
        std::process::exit(130);
    });
    let cli = match parse() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let ui = common::Ui { quiet: cli.quiet };
    let res = match cli.cmd {
        // Point sets (`points`) share encode, decode and info with rasters: routed here, so
        // the raster commands know nothing of them.
        Cmd::Encode(mut a) => common::check_not_dir(&a.input)
            .and_then(|()| points::check_encode_options(&a))
            .and_then(|()| encode::stage(&mut a))
            .and_then(|()| {
                if points::is_points_input(&a) {
                    points::encode(&a, &ui)
                } else {
                    encode::run(a, &ui)
                }
            }),
        Cmd::Decode(a) => points::decode_route(&a).and_then(|bytes| match bytes {
            Some(b) => points::decode(&a, &b, &ui),
            None => decode::run(a, &ui),
        }),
        Cmd::Info(a) => common::is_points_file(&a.input).and_then(|pts| {
            if pts {
                common::read_file(&a.input).and_then(|b| points::info(&a, &b))
            } else {
                info::run(a, &ui)
            }
        }),
        Cmd::Compare(a) => compare::run(a, &ui),
        Cmd::Convert(a) => common::check_not_dir(&a.input).and_then(|()| convert::run(a, &ui)),
        Cmd::Sites(a) => sites::run(a, &ui),
        Cmd::Cells(a) => cells::run(a, &ui),
        Cmd::Mesh(a) => mesh::run(a, &ui),
        Cmd::Lsystem(a) => lsystem::run(a, &ui),
        Cmd::Tiles(a) => tiles::run(a, &ui),
        Cmd::Web(a) => web::run(a, &ui),
        Cmd::Render(a) => render::run(a, &ui),
        Cmd::Rd(a) => rd::run(a, &ui),
        Cmd::Verify(a) => verify::run(a, &ui),
    };
    match res {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vtz: {e}");
            match e {
                vtz::Error::InvalidArgument { .. } => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
    }
}
