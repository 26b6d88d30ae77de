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

use clap::{Parser, Subcommand};
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
    /// Draw a raster or .vtz as a shaded relief PNG (optionally with its sites).
    Render(render::Args),
    /// Check .vtz files end to end: every checksum, every section decoded, the decodes
    /// against the stored mask, range and max errors; one line per file, exit 1 on a problem.
    Verify(verify::Args),
    /// Rate–distortion table of methods × error bounds on rasters (CSV, plot, baseline check).
    Rd(rd::Args),
}

fn main() -> ExitCode {
    // Ctrl-C or SIGTERM: remove the temporaries of outputs still being written (an output
    // appears only by a rename once complete), then stop with 130 as a shell expects.
    let _ = ctrlc::set_handler(|| {
        vtz::formats::remove_temporaries();
        eprintln!("vtz: interrupted; unfinished outputs removed");
        std::process::exit(130);
    });
    let cli = Cli::parse();
    let ui = common::Ui { quiet: cli.quiet };
    let res = match cli.cmd {
        // Point sets (`points`) share encode, decode and info with rasters: routed here, so
        // the raster commands know nothing of them.
        Cmd::Encode(a) => points::check_encode_options(&a).and_then(|()| {
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
        Cmd::Convert(a) => convert::run(a, &ui),
        Cmd::Sites(a) => sites::run(a, &ui),
        Cmd::Cells(a) => cells::run(a, &ui),
        Cmd::Mesh(a) => mesh::run(a, &ui),
        Cmd::Lsystem(a) => lsystem::run(a, &ui),
        Cmd::Tiles(a) => tiles::run(a, &ui),
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
