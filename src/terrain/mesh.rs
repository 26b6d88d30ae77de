//! Meshes from files: the sites a `.vtz` stores (or a prefix of them), or sites selected
//! from any raster (the greedy sites encoder, or the quadtree detail selector), triangulated
//! by `mesh`.

use crate::codec::{DecodeOptions, Decoder, EncodeOptions, Surface, encode};
use crate::error::{Error, Result};
use crate::mesh::{self, Mesh, MeshOptions, Vertex};
use crate::methods::Method;
use crate::model::Raster;
use crate::quant::ErrorBound;

/// How a mesh's vertices are chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Select {
    /// vtz's greedy Voronoi hierarchy: the sites the sites encoder keeps.
    Greedy,
    /// The height-map-to-mesh paper's quadtree: split while more than `threshold` % of a
    /// quadrant's samples lie outside one standard deviation of its mean.
    Quadtree {
        /// Percent of samples, 0..=100.
        threshold: f64,
    },
}

/// What `vtz mesh` asks for.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct MeshRequest {
    /// Greedy selection from a raster: the bound the sites meet (default 1 % of the range).
    pub max_error: Option<ErrorBound>,
    /// The first N sites (a `.vtz` prefix, or a greedy selection stopped at N).
    pub sites: Option<usize>,
    /// The first K progressive levels of a `.vtz`'s sites.
    pub levels: Option<usize>,
    /// Greedy or quadtree.
    pub select: Select,
    /// No triangle edge longer than this many samples.
    pub max_edge: Option<f64>,
    /// Placement and attributes.
    pub mesh: MeshOptions,
    /// The surface that gives heights to vertices that are not sites (`max_edge`) when
    /// meshing a `.vtz`'s sites.
    pub surface: Surface,
}

impl Default for MeshRequest {
    fn default() -> Self {
        MeshRequest {
            max_error: None,
            sites: None,
            levels: None,
            select: Select::Greedy,
            max_edge: None,
            mesh: MeshOptions::default(),
            surface: Surface::Sibson,
        }
    }
}

/// The mesh of a raster: sites selected as `req` says, their heights the raster's own
/// samples (quadtree) or the sites' stored heights (greedy).
pub fn mesh_raster(raster: &Raster, req: &MeshRequest) -> Result<Mesh> {
    if req.levels.is_some() {
        return Err(Error::invalid(
            "--level needs a .vtz input with a sites section",
        ));
    }
    if raster.width < 2 || raster.height < 2 {
        // One row or column of samples has no area between sample centres: mesh the
        // samples' cells instead (each sample repeated at its cell's two edges).
        return mesh_raster(&cell_edges(raster), req);
    }
    if let (Select::Greedy, None, Some((lo, hi))) = (req.select, req.sites, raster.valid_range())
        && lo == hi
    {
        // One height everywhere: the flat rectangle of two triangles is exact (any bound
        // holds, including a percent of the range 0).
        let (w, h) = (raster.width, raster.height);
        let mut corners: Vec<Vertex> = [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)]
            .into_iter()
            .map(|(col, row)| Vertex {
                col,
                row,
                height: lo,
            })
            .collect();
        return finish(
            &mut corners,
            (w, h),
            raster.georef.as_ref(),
            Some(raster),
            req,
            None,
        );
    }
    let mut bound = None;
    let mut vertices = match req.select {
        Select::Greedy => {
            let mut o = EncodeOptions {
                methods: vec![Method::SIBSON],
                tile: Some(0),
                ..Default::default()
            };
            match (req.sites, req.max_error) {
                (Some(n), _) => o.params.sibson.sites = Some(n),
                (None, b) => {
                    let b = b.unwrap_or(ErrorBound::PercentOfRange(1.0));
                    let abs = b.absolute(raster.valid_range());
                    bound = Some(abs);
                    // Measured: starting from sites at 1.5–3 × the bound saves nothing.
                    o.max_error = Some(ErrorBound::Abs(abs));
                }
            }
            let bytes = encode(raster, &o)?;
            let mut d = Decoder::new(std::io::Cursor::new(bytes))?;
            // Each vertex at its sample's own height (the file stores them quantized).
            d.sites()?
                .into_iter()
                .map(|s| Vertex {
                    col: s.col,
                    row: s.row,
                    height: raster.data[s.row * raster.width + s.col],
                })
                .collect::<Vec<_>>()
        }
        Select::Quadtree { threshold } => {
            if req.sites.is_some() || req.max_error.is_some() {
                return Err(Error::invalid(
                    "the quadtree selector takes --threshold, not --sites or --max-error",
                ));
            }
            let valid = |i: usize| raster.is_valid(i);
            mesh::quadtree::select(&raster.data, &valid, raster.width, raster.height, threshold)?
                .into_iter()
                .map(|(c, r)| Vertex {
                    col: c,
                    row: r,
                    height: raster.data[r * raster.width + c],
                })
                .collect()
        }
    };
    let size = (raster.width, raster.height);
    finish(
        &mut vertices,
        size,
        raster.georef.as_ref(),
        Some(raster),
        req,
        bound,
    )
}

/// A raster of one row or column as two, each sample repeated at its cell's two edges:
/// sample centres half a pixel before and after the originals, so the mesh covers the
/// samples' cells (a 1 × 1 raster becomes its pixel's flat square).
fn cell_edges(r: &Raster) -> Raster {
    let (w2, h2) = (r.width.max(2), r.height.max(2));
    let (sx, sy) = (usize::from(r.width < 2), usize::from(r.height < 2));
    let mut out = r.clone();
    out.width = w2;
    out.height = h2;
    out.data = (0..w2 * h2)
        .map(|i| r.data[(i / w2) / (1 + sy) * r.width + (i % w2) / (1 + sx)])
        .collect();
    out.mask = r.mask.as_ref().map(|m| {
        (0..w2 * h2)
            .map(|i| m[(i / w2) / (1 + sy) * r.width + (i % w2) / (1 + sx)])
            .collect()
    });
    if let Some(g) = out.georef.as_mut() {
        // The new centres sit on the old cell's edges: half a pixel west / north of the
        // old centres, one old pixel apart.
        g.origin[0] -= 0.5 * g.pixel_size[0] * sx as f64;
        g.origin[1] += 0.5 * g.pixel_size[1] * sy as f64;
    }
    out
}

/// The mesh of a `.vtz`: its stored sites (a prefix with `req.sites` / `req.levels`) when
/// it has a sites section; otherwise the decoded raster, meshed as [`mesh_raster`] does.
pub fn mesh_file(d: &mut Decoder, req: &MeshRequest) -> Result<Mesh> {
    let has_sites = d.info().tiles.is_none()
        && d.info()
            .sections
            .iter()
            .any(|s| s.method == Some(Method::SIBSON));
    if req.surface != Surface::Sibson && !has_sites {
        return Err(Error::invalid(
            "--surface needs a .vtz with a sites section",
        ));
    }
    if !has_sites || req.select != Select::Greedy || req.max_error.is_some() {
        if req.levels.is_some() {
            return Err(Error::invalid(
                "--level needs an untiled .vtz with a sites section (and greedy selection)",
            ));
        }
        d.options(DecodeOptions {
            surface: req.surface,
            ..Default::default()
        });
        let r = d.decode()?;
        return mesh_raster(&r, req);
    }
    let all = d.sites()?;
    let n = match (req.sites, req.levels) {
        (Some(n), _) => n.min(all.len()),
        (None, Some(k)) => all.iter().take_while(|s| s.level < k).count(),
        (None, None) => all.len(),
    };
    let mut vertices: Vec<Vertex> = all[..n]
        .iter()
        .map(|s| Vertex {
            col: s.col,
            row: s.row,
            height: s.height,
        })
        .collect();
    // The decoded surface gives added vertices their heights and measures the fit.
    d.options(DecodeOptions {
        surface: req.surface,
        ..Default::default()
    });
    let surface = d.decode()?;
    let info = d.info();
    let size = (info.width as usize, info.height as usize);
    let georef = info.georef.clone();
    finish(
        &mut vertices,
        size,
        georef.as_ref(),
        Some(&surface),
        req,
        None,
    )
}

/// Refine to the maximum edge and to `bound` (heights from `surface`'s samples), measure
/// the fit, and triangulate. Added vertices can lengthen edges and splitting edges can move
/// the surface, so the two refinements alternate until neither adds a vertex.
fn finish(
    vertices: &mut Vec<Vertex>,
    size: (usize, usize),
    georef: Option<&crate::model::Georef>,
    surface: Option<&Raster>,
    req: &MeshRequest,
    bound: Option<f64>,
) -> Result<Mesh> {
    let mut fit = None;
    if let Some(r) = surface {
        let at = |c: usize, row: usize| {
            let i = row * r.width + c;
            r.is_valid(i).then(|| r.data[i])
        };
        let mut added = 0;
        for _ in 0..16 {
            let before = vertices.len();
            if let Some(l) = req.max_edge {
                mesh::refine_max_edge(vertices, size, &at, l)?;
            }
            if let Some(b) = bound {
                added += mesh::refine_to_bound(vertices, size, &at, b)?.added;
            }
            if vertices.len() == before || (req.max_edge.is_none() || bound.is_none()) {
                break;
            }
        }
        if vertices.len() >= 3 {
            let mut f = mesh::fit(vertices, size, &at)?;
            f.added = added;
            fit = Some(f);
        }
    }
    if vertices.len() < 3 {
        return Err(Error::invalid(format!(
            "{} vertices cannot make a mesh",
            vertices.len()
        )));
    }
    let mut m = mesh::triangulate(vertices, size, georef, &req.mesh)?;
    m.fit = fit;
    Ok(m)
}
