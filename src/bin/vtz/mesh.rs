//! `vtz mesh`: a raster or .vtz as a triangle mesh file (OBJ, PLY, STL, binary glTF).

use crate::common::{self, RasterOpts, Ui};
use std::path::PathBuf;
use vtz::{MeshFormat, MeshRequest, Result, Select};

#[derive(clap::Args)]
#[command(mut_arg("max_error", |a| a.help(
    "Greedy sites, then vertices added until every sample is within E data units or E% of the \
     range of the mesh's triangles (default 1% for rasters; a .vtz's own sites otherwise)"
)))]
pub struct Args {
    /// Input: a .vtz (its sites, or its decoded raster) or any raster.
    pub input: PathBuf,
    /// Output mesh: .obj, .ply, .stl or .glb.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub bound: common::Bound,
    /// The first N sites.
    #[arg(long, value_name = "N", conflicts_with = "max_error")]
    pub sites: Option<usize>,
    /// The first K progressive levels of a .vtz's sites.
    #[arg(long, value_name = "K", conflicts_with_all = ["sites", "max_error"])]
    pub level: Option<usize>,
    /// Vertex selection: greedy (vtz's sites) or quadtree (the height-map-to-mesh paper).
    #[arg(long, default_value = "greedy", value_parser = ["greedy", "quadtree"])]
    pub select: String,
    /// Quadtree: split while more than T % of a quadrant's samples lie outside one standard
    /// deviation of its mean (0–100). The rule's useful range is narrow: below ~28 most
    /// samples are kept, above the root quadrants' own fractions (~32–38) only 9 points
    /// (benches/quadtree.md).
    #[arg(long, value_name = "T", default_value_t = 32.0)]
    pub threshold: f64,
    /// Vertical exaggeration.
    #[arg(
        long,
        value_name = "F",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    pub z_scale: f64,
    /// Georeferenced coordinates (the raster's CRS units) instead of one unit per sample.
    #[arg(long)]
    pub georef: bool,
    /// Per-vertex normals.
    #[arg(long)]
    pub normals: bool,
    /// Texture coordinates for draping an image over the whole raster.
    #[arg(long)]
    pub uvs: bool,
    /// A skirt of this depth (height units) below the mesh's boundary.
    #[arg(long, value_name = "D")]
    pub skirt: Option<f64>,
    /// No triangle edge longer than L samples.
    #[arg(long, value_name = "L")]
    pub max_edge: Option<f64>,
    /// A .vtz's sites: the surface giving heights to added vertices (--max-edge), or the
    /// decoded raster a selection reads: sibson (the coded one), linear or basis.
    #[arg(long, default_value = "sibson", value_parser = ["sibson", "linear", "basis"])]
    pub surface: String,
    #[command(flatten)]
    pub format: common::InputFormat,
    #[command(flatten)]
    pub force: common::Force,
    #[command(flatten)]
    pub json: common::Json,
    #[command(flatten)]
    pub raster: RasterOpts,
}

pub fn run(a: Args, ui: &Ui) -> Result<()> {
    let out_format = MeshFormat::from_path(&a.output)?;
    let in_format = a.format.get()?;
    common::check_output(&a.input, &a.output, a.force.force)?;
    let select = match a.select.as_str() {
        "quadtree" => {
            if !(0.0..=100.0).contains(&a.threshold) {
                return Err(vtz::Error::invalid(format!(
                    "--threshold {} is not a percentage in 0..=100",
                    a.threshold
                )));
            }
            Select::Quadtree {
                threshold: a.threshold,
            }
        }
        _ => Select::Greedy,
    };
    let mut req = MeshRequest::default();
    req.max_error = a.bound.get()?;
    req.sites = a.sites;
    req.levels = a.level;
    req.select = select;
    req.max_edge = a.max_edge;
    req.mesh.z_scale = a.z_scale;
    req.mesh.georeferenced = a.georef;
    req.mesh.normals = a.normals;
    req.mesh.uvs = a.uvs;
    req.mesh.skirt = a.skirt;
    req.surface = a.surface.parse()?;
    let is_vtz = in_format.map_or_else(
        || vtz::formats::Format::from_path(&a.input).ok() == Some(vtz::formats::Format::Vtz),
        |f| f == vtz::formats::Format::Vtz,
    );
    if req.surface != vtz::Surface::Sibson && !is_vtz {
        return Err(vtz::Error::invalid(
            "--surface applies to a .vtz's sites; a raster input is meshed from its samples",
        ));
    }
    let mesh = ui
        .busy("meshing", || {
            if is_vtz {
                let f = std::fs::File::open(&a.input)
                    .map_err(|e| vtz::Error::io(a.input.display().to_string(), e))?;
                let mut d = vtz::Decoder::new(std::io::BufReader::new(f))?;
                vtz::mesh_file(&mut d, &req)
            } else {
                let r = common::read_raster(&a.input, in_format, &a.raster)?;
                vtz::mesh_raster(&r, &req)
            }
        })
        .map_err(|e| e.context(a.input.display()))?;
    let bytes = vtz::encode_mesh(&mesh, out_format)?;
    let n = bytes.len();
    vtz::formats::write_file(&a.output, bytes, a.force.force)?;
    if a.json.json {
        outln!(
            "{}",
            serde_json::json!({
                "input": a.input, "output": a.output, "format": out_format.name(),
                "vertices": mesh.positions.len(), "triangles": mesh.triangles.len(), "bytes": n,
                "max_error": mesh.fit.map(|f| f.max_error), "rmse": mesh.fit.map(|f| f.rmse),
                "samples": mesh.fit.map(|f| f.samples), "added": mesh.fit.map(|f| f.added),
            })
        );
    } else {
        let fit = mesh.fit.map_or_else(String::new, |f| {
            format!(", max error {:.4}, RMSE {:.4}", f.max_error, f.rmse)
        });
        ui.say(format!(
            "{}: {} vertices, {} triangles, {n} bytes ({}){fit}",
            a.output.display(),
            mesh.positions.len(),
            mesh.triangles.len(),
            out_format.name()
        ));
    }
    Ok(())
}
