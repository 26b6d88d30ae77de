//! Other surfaces through a file's sites: `--surface linear` (the triangles of the sites'
//! Delaunay triangulation) and `--surface basis` (the basis-function surface of the
//! digital-terrain-model paper, expanded trajectories), in place of the Sibson surface the
//! sites section codes. The file's bound holds for the Sibson surface only.

use crate::error::{Error, Result};
use crate::geometry::basis::{BasisSurface, Params};
use crate::methods::Site;
use crate::model::Raster;
use std::str::FromStr;

/// The surface a decode or a mesh evaluates through a file's sites.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum Surface {
    /// Sibson's natural-neighbour interpolant: what the sites section codes (the bound
    /// holds).
    #[default]
    Sibson,
    /// Piecewise linear over the Delaunay triangles of the sites.
    Linear,
    /// The basis-function surface of the digital-terrain-model paper (expanded
    /// trajectories, α = λ = 0.25). `benches/basis_study.md`: on greedy sites of real
    /// terrain its RMSE is 11–22 % above Sibson's, so it is offered for comparison, not coded.
    Basis,
}

impl FromStr for Surface {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "sibson" => Ok(Surface::Sibson),
            "linear" => Ok(Surface::Linear),
            "basis" => Ok(Surface::Basis),
            o => Err(Error::invalid(format!(
                "unknown surface '{o}' (sibson, linear, basis)"
            ))),
        }
    }
}

/// Replace every valid sample of `r` (a decode of the sites) with `surface` through `sites`.
pub(crate) fn resurface(r: &mut Raster, sites: &[Site], surface: Surface) -> Result<()> {
    if surface == Surface::Sibson {
        return Ok(());
    }
    let cells: Vec<(usize, usize)> = sites.iter().map(|s| (s.col, s.row)).collect();
    let (tri, order) = crate::mesh::delaunay(&cells)?;
    let heights: Vec<f64> = order.iter().map(|&i| sites[i].height).collect();
    let params = match surface {
        Surface::Linear => Params::polyhedral(),
        _ => Params::expanded(0.25, 0.25),
    };
    let s = BasisSurface::new(&tri, &heights, params)?;
    for row in 0..r.height {
        for col in 0..r.width {
            let i = row * r.width + col;
            if r.is_valid(i) {
                // Outside the sites' hull (flat regions the sites section fills, e.g. sea)
                // the decode keeps the section's own values.
                let Some(v) = s.eval([col as f64, row as f64]) else {
                    continue;
                };
                // Integer samples hold whole codes, as the Sibson decode gives them.
                r.data[i] = if r.sample_type.is_integer() {
                    r.mapping.offset + r.mapping.to_code(v).round() * r.mapping.scale
                } else {
                    v
                };
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Raster;

    fn site(col: usize, row: usize, height: f64) -> Site {
        Site {
            rank: 0,
            level: 0,
            col,
            row,
            height,
        }
    }

    #[test]
    fn linear_reproduces_a_plane_and_basis_interpolates_the_sites() {
        let (w, h) = (9, 7);
        let plane = |c: usize, r: usize| 2.0 * c as f64 - 3.0 * r as f64 + 5.0;
        let mut sites = vec![
            site(0, 0, plane(0, 0)),
            site(8, 0, plane(8, 0)),
            site(8, 6, plane(8, 6)),
            site(0, 6, plane(0, 6)),
        ];
        sites.extend([(3, 2), (5, 4), (2, 5), (6, 1)].map(|(c, r)| site(c, r, plane(c, r))));
        let mut r =
            Raster::from_values(w, h, vec![0.0; w * h], None, crate::model::SampleType::F32)
                .unwrap();
        resurface(&mut r, &sites, Surface::Linear).unwrap();
        for row in 0..h {
            for col in 0..w {
                assert!((r.data[row * w + col] - plane(col, row)).abs() < 1e-9);
            }
        }
        let bumpy: Vec<Site> = sites
            .iter()
            .map(|s| site(s.col, s.row, (s.col * s.row) as f64))
            .collect();
        resurface(&mut r, &bumpy, Surface::Basis).unwrap();
        for s in &bumpy {
            assert!((r.data[s.row * w + s.col] - s.height).abs() < 1e-9);
        }
    }
}
