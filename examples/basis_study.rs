//! Reproduce the basis-function paper (`../shared/papers/004_*`, Silva, Vidal & Cavalcante
//! Neto, after Chaturvedi & Piegl) and set its surfaces against Sibson's interpolant:
//!
//! 1. the paper's sinc experiment (200 random samples, polyhedral / Chaturvedi–Piegl /
//!    expanded trajectories, error on a regular grid in %), over many seeds;
//! 2. three corpus DEMs with 200 and 2000 samples (random, and vtz's greedy sites), max error
//!    and RMSE against every raster sample inside the hull;
//! 3. evaluation time per point.
//!
//! Prints Markdown tables (see `benches/basis_study.md`).
//!
//! `cargo run --release --example basis_study [-- --quick]`
//!
//! The basis surfaces live in `src/geometry/basis.rs`, a private module of the library; this
//! example compiles that file, the triangulation and Sibson's interpolant into itself (the
//! `#[path]` modules below) so the library exports nothing for it.

use std::io::Cursor;
use std::path::Path;
use std::time::Instant;

/// The library's error type under the name the included files use.
mod error {
    pub use vtz::{Error, Result};
}

// (basis.rs allows its own dead code outside tests.)
#[path = "../src/geometry/basis.rs"]
mod basis;
#[allow(dead_code)]
#[path = "../src/geometry/sibson/mod.rs"]
mod sibson;
#[allow(dead_code)]
#[path = "../src/geometry/triangulation.rs"]
mod triangulation;
/// The library's module path for the included files (`crate::geometry::…`).
mod geometry {
    pub(crate) use super::{basis, sibson, triangulation};
}

use geometry::basis::{BasisSurface, Params, Trajectory};
use geometry::sibson::Surface;
use geometry::triangulation::Triangulation;

/// SplitMix64.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, var.sqrt())
}

/// The four interpolants of one sample set.
struct Interpolants {
    tri: Triangulation,
    heights: Vec<f64>,
    sibson: Surface,
}

impl Interpolants {
    fn new(pts: &[[i64; 2]], heights: &[f64]) -> Interpolants {
        let mut sibson = Surface::new();
        let mut hs = Vec::new();
        for (p, &h) in pts.iter().zip(heights) {
            if sibson.insert(*p, h).is_ok() {
                hs.push(h);
            }
        }
        sibson.compact();
        Interpolants {
            tri: sibson.triangulation().clone(),
            heights: hs,
            sibson,
        }
    }
    fn basis(&self, p: Params) -> BasisSurface {
        BasisSurface::new(&self.tri, &self.heights, p).expect("2-D sites")
    }
}

/// Error statistics of one interpolant against reference values.
#[derive(Default, Clone, Copy)]
struct Err {
    n: usize,
    sum_abs: f64,
    sum_sq: f64,
    max: f64,
    ref_abs: f64,
    ref_sq: f64,
    secs: f64,
}

impl Err {
    fn add(&mut self, got: f64, want: f64) {
        let e = got - want;
        self.n += 1;
        self.sum_abs += e.abs();
        self.sum_sq += e * e;
        self.max = self.max.max(e.abs());
        self.ref_abs += want.abs();
        self.ref_sq += want * want;
    }
    fn rmse(&self) -> f64 {
        (self.sum_sq / self.n as f64).sqrt()
    }
    /// 100 Σ|e| / Σ|z|.
    fn rel_l1(&self) -> f64 {
        100.0 * self.sum_abs / self.ref_abs
    }
    /// 100 √(Σe² / Σz²).
    fn rel_l2(&self) -> f64 {
        100.0 * (self.sum_sq / self.ref_sq).sqrt()
    }
    fn ns_per_point(&self) -> f64 {
        1e9 * self.secs / self.n as f64
    }
}

/// Evaluate a basis surface at lattice points against `truth` (NaN: skip).
fn eval_basis(s: &BasisSurface, pts: &[[i64; 2]], truth: &[f64]) -> Err {
    let mut e = Err::default();
    let t0 = Instant::now();
    for (q, &z) in pts.iter().zip(truth) {
        if z.is_nan() {
            continue;
        }
        if let Some(v) = s.eval([q[0] as f64, q[1] as f64]) {
            e.add(v, z);
        }
    }
    e.secs = t0.elapsed().as_secs_f64();
    e
}

/// Sibson at the lattice `(x0 + i step, y0 + j step)`, `w × h`, against `truth` (row-major).
fn eval_sibson(s: &Surface, x0: i64, y0: i64, w: usize, h: usize, step: i64, truth: &[f64]) -> Err {
    let t0 = Instant::now();
    let vals = s.eval_lattice(x0, y0, w, h, step, &|_, _| true);
    let secs = t0.elapsed().as_secs_f64();
    let mut e = Err::default();
    for (v, &z) in vals.iter().zip(truth) {
        if !z.is_nan() && !v.is_nan() {
            e.add(*v, z);
        }
    }
    e.secs = secs;
    e
}

// ---------------------------------------------------------------------------------------
// 1. The sinc experiment.

/// Lattice units per unit of the sinc domain.
const SCALE: f64 = (1u64 << 20) as f64;

#[derive(Clone, Copy)]
struct SincDef {
    label: &'static str,
    /// sin(k r) / (k r).
    k: f64,
    half: f64,
}

impl SincDef {
    fn z(&self, x: f64, y: f64) -> f64 {
        let r = self.k * (x * x + y * y).sqrt();
        if r == 0.0 { 1.0 } else { r.sin() / r }
    }
}

/// One seed of the sinc experiment: 200 samples (the domain's 4 corners and 196 uniform
/// random points, snapped to the 2^20-per-unit lattice), the true surface on a `g × g` grid.
struct SincRun {
    ip: Interpolants,
    grid: Vec<[i64; 2]>,
    truth: Vec<f64>,
    x0: i64,
    step: i64,
    g: usize,
}

fn sinc_run(def: SincDef, n: usize, g: usize, seed: u64, corners: bool) -> SincRun {
    let mut rng = Rng(seed.wrapping_mul(0x5851_F42D_4C95_7F2D) ^ 0xB5);
    let lat = |v: f64| (v * SCALE).round() as i64;
    let (lo, hi) = (lat(-def.half), lat(def.half));
    let mut pts: Vec<[i64; 2]> = if corners {
        vec![[lo, lo], [hi, lo], [hi, hi], [lo, hi]]
    } else {
        Vec::new()
    };
    while pts.len() < n {
        let p = [
            lat(-def.half + 2.0 * def.half * rng.unit()),
            lat(-def.half + 2.0 * def.half * rng.unit()),
        ];
        if !pts.contains(&p) {
            pts.push(p);
        }
    }
    let z = |p: [i64; 2]| def.z(p[0] as f64 / SCALE, p[1] as f64 / SCALE);
    let hs: Vec<f64> = pts.iter().map(|&p| z(p)).collect();
    // A grid whose step is a whole number of lattice units.
    let step = (hi - lo) / (g as i64 - 1);
    let mut grid = Vec::with_capacity(g * g);
    for j in 0..g as i64 {
        for i in 0..g as i64 {
            grid.push([lo + i * step, lo + j * step]);
        }
    }
    let truth = grid.iter().map(|&p| z(p)).collect();
    SincRun {
        ip: Interpolants::new(&pts, &hs),
        grid,
        truth,
        x0: lo,
        step,
        g,
    }
}

impl SincRun {
    fn basis(&self, p: Params) -> Err {
        eval_basis(&self.ip.basis(p), &self.grid, &self.truth)
    }
    fn sibson(&self) -> Err {
        eval_sibson(
            &self.ip.sibson,
            self.x0,
            self.x0,
            self.g,
            self.g,
            self.step,
            &self.truth,
        )
    }
}

fn sinc(seeds: u64) {
    println!("## 1. Sinc surface, 200 samples\n");
    // Which definition and error measure make the polyhedral error 40.35 %?
    let defs = [
        SincDef {
            label: "sin r / r, [-10, 10]²",
            k: 1.0,
            half: 10.0,
        },
        SincDef {
            label: "sin r / r, [-8, 8]²",
            k: 1.0,
            half: 8.0,
        },
        SincDef {
            label: "sin r / r, [-2π, 2π]²",
            k: 1.0,
            half: 2.0 * std::f64::consts::PI,
        },
        SincDef {
            label: "sin r / r, [-4π, 4π]²",
            k: 1.0,
            half: 4.0 * std::f64::consts::PI,
        },
        SincDef {
            label: "sin r / r, [-12, 12]²",
            k: 1.0,
            half: 12.0,
        },
        SincDef {
            label: "sin r / r, [-15, 15]²",
            k: 1.0,
            half: 15.0,
        },
        SincDef {
            label: "sin πr / πr, [-3, 3]²",
            k: std::f64::consts::PI,
            half: 3.0,
        },
    ];
    let g = 101;
    println!(
        "### Calibration: polyhedral error by definition and error measure ({seeds} seeds, 4 corners + 196 random samples, {g}×{g} grid)\n"
    );
    println!(
        "| surface, domain | 100 Σ\\|e\\| / Σ\\|z\\| | 100 √(Σe² / Σz²) | RMSE / range % | max / range % |"
    );
    println!("|---|--:|--:|--:|--:|");
    for def in defs {
        let (mut l1, mut l2, mut rr, mut mr) = (vec![], vec![], vec![], vec![]);
        for seed in 0..seeds {
            let run = sinc_run(def, 200, g, seed, true);
            let e = run.basis(Params::polyhedral());
            let (lo, hi) = run
                .truth
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
            l1.push(e.rel_l1());
            l2.push(e.rel_l2());
            rr.push(100.0 * e.rmse() / (hi - lo));
            mr.push(100.0 * e.max / (hi - lo));
        }
        let f = |v: &[f64]| {
            let (m, s) = mean_sd(v);
            format!("{m:.2} ± {s:.2}")
        };
        println!(
            "| {} | {} | {} | {} | {} |",
            def.label,
            f(&l1),
            f(&l2),
            f(&rr),
            f(&mr)
        );
    }
    println!();
}

/// The paper's table 1 with the chosen definition: rows α = λ.
/// The paper's table 1 rows: row k of the paper against (α, λ) = `lambda(k)`.
const PAPER: [(f64, &str); 4] = [
    (0.25, "40.35 / 39.71 / 37.78"),
    (0.5, "40.35 / 40.08 / 37.46"),
    (0.75, "40.35 / 40.74 / 37.29"),
    (1.0, "40.35 / 41.63 / 37.31"),
];

fn sinc_table(
    def: SincDef,
    seeds: u64,
    corners: bool,
    measure: fn(&Err) -> f64,
    name: &str,
    fixed_lambda: Option<f64>,
) {
    let g = 101;
    println!(
        "### {}: {name}, {seeds} seeds, {} ({g}×{g} grid; mean ± sd over seeds)\n",
        def.label,
        if corners {
            "4 corners + 196 random samples"
        } else {
            "200 random samples, grid points inside the hull"
        }
    );
    println!(
        "| {} | polyhedral | Chaturvedi–Piegl | CP (local strip) | expanded | Sibson | CP < poly | exp < CP | exp gain over CP | exp gain over poly | paper (poly / CP / exp) |",
        match fixed_lambda {
            Some(l) => format!("α (λ = {l})"),
            None => "α = λ".to_string(),
        }
    );
    println!("|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|");
    let runs: Vec<SincRun> = (0..seeds)
        .map(|s| sinc_run(def, 200, g, s, corners))
        .collect();
    let poly: Vec<f64> = runs
        .iter()
        .map(|r| measure(&r.basis(Params::polyhedral())))
        .collect();
    let sib: Vec<f64> = runs.iter().map(|r| measure(&r.sibson())).collect();
    let f = |v: &[f64]| {
        let (m, s) = mean_sd(v);
        format!("{m:.2} ± {s:.2}")
    };
    for (a, pap) in PAPER {
        let l = fixed_lambda.unwrap_or(a);
        let err = |p: Params| -> Vec<f64> { runs.iter().map(|r| measure(&r.basis(p))).collect() };
        let cp = err(Params::chaturvedi_piegl(a, l));
        let cpl = err(Params {
            trajectory: Trajectory::ChaturvediPieglLocal,
            alpha: a,
            lambda: l,
        });
        let ex = err(Params::expanded(a, l));
        let cp_wins = cp.iter().zip(&poly).filter(|(c, p)| c < p).count();
        let ex_wins = ex.iter().zip(&cp).filter(|(e, c)| e < c).count();
        let gain: Vec<f64> = ex.iter().zip(&cp).map(|(e, c)| c - e).collect();
        let gain_p: Vec<f64> = ex.iter().zip(&poly).map(|(e, c)| c - e).collect();
        println!(
            "| {a} | {} | {} | {} | {} | {} | {cp_wins}/{seeds} | {ex_wins}/{seeds} | {} | {} | {pap} |",
            f(&poly),
            f(&cp),
            f(&cpl),
            f(&ex),
            f(&sib),
            f(&gain),
            f(&gain_p)
        );
    }
    println!();
}

/// α and λ apart: expanded and Chaturvedi–Piegl on the chosen sinc definition.
fn sinc_sweep(def: SincDef, seeds: u64, measure: fn(&Err) -> f64) {
    let g = 101;
    println!(
        "### α and λ apart ({}, {seeds} seeds, mean error %; CP / expanded)\n",
        def.label
    );
    let lambdas = [0.0, 0.25, 0.5, 0.75, 1.0];
    print!("| α \\ λ |");
    for l in lambdas {
        print!(" {l} |");
    }
    println!();
    println!("|--:|{}", "--:|".repeat(lambdas.len()));
    let runs: Vec<SincRun> = (0..seeds).map(|s| sinc_run(def, 200, g, s, true)).collect();
    for a in [0.0, 0.25, 0.5, 0.75, 1.0] {
        print!("| {a} |");
        for l in lambdas {
            let cp: Vec<f64> = runs
                .iter()
                .map(|r| measure(&r.basis(Params::chaturvedi_piegl(a, l))))
                .collect();
            let ex: Vec<f64> = runs
                .iter()
                .map(|r| measure(&r.basis(Params::expanded(a, l))))
                .collect();
            print!(" {:.2} / {:.2} |", mean_sd(&cp).0, mean_sd(&ex).0);
        }
        println!();
    }
    let mut cases = [0usize; 3];
    for r in &runs {
        let c = r.ip.basis(Params::expanded(0.25, 1.0)).chord_cases();
        for (a, b) in cases.iter_mut().zip(c) {
            *a += b;
        }
    }
    let total = cases.iter().sum::<usize>() as f64;
    println!(
        "\nChords (expanded, α = 0.25): {:.1} % straight (cases 1, 4, 5, inward tangents, or no room), {:.1} % one conic (case 2), {:.1} % split by a new vertex (case 3).",
        100.0 * cases[0] as f64 / total,
        100.0 * cases[1] as f64 / total,
        100.0 * cases[2] as f64 / total
    );
    let local = |alpha| Params {
        trajectory: Trajectory::ChaturvediPieglLocal,
        alpha,
        lambda: 1.0,
    };
    let bulge = |p: Params| {
        let v: Vec<f64> = runs.iter().map(|r| r.ip.basis(p).mean_bulge()).collect();
        mean_sd(&v).0
    };
    println!(
        "\nMean bulge of a trajectory beyond its chord (fraction of the chord): α = 0.25: CP {:.3}, CP local {:.3}, expanded {:.3}; α = 1: CP {:.3}, CP local {:.3}, expanded {:.3}.\n",
        bulge(Params::chaturvedi_piegl(0.25, 1.0)),
        bulge(local(0.25)),
        bulge(Params::expanded(0.25, 1.0)),
        bulge(Params::chaturvedi_piegl(1.0, 1.0)),
        bulge(local(1.0)),
        bulge(Params::expanded(1.0, 1.0)),
    );
}

// ---------------------------------------------------------------------------------------
// 2. Real terrain.

/// The raster's valid samples and the greedy sites of vtz's Sibson encoder.
struct Dem {
    name: &'static str,
    r: vtz::Raster,
    range: f64,
    greedy: Vec<[i64; 2]>,
}

fn load_dem(
    dir: &Path,
    name: &'static str,
    max_sites: usize,
) -> Result<Dem, Box<dyn std::error::Error>> {
    let r = vtz::read_path(&dir.join(format!("{name}.f32")), &Default::default())?;
    let (lo, hi) = r.valid_range().ok_or("no valid samples")?;
    let mut opts = vtz::EncodeOptions::default();
    opts.methods = vec![vtz::Method::SIBSON];
    opts.params.sibson.sites = Some(max_sites);
    opts.tile = Some(0);
    let t0 = Instant::now();
    let bytes = vtz::encode(&r, &opts)?;
    let mut dec = vtz::Decoder::new(Cursor::new(bytes))?;
    let mut sites = dec.sites()?;
    sites.sort_by_key(|s| s.rank);
    eprintln!(
        "{name}: {}×{}, {} greedy sites in {:.1} s",
        r.width,
        r.height,
        sites.len(),
        t0.elapsed().as_secs_f64()
    );
    let greedy = sites.iter().map(|s| [s.col as i64, s.row as i64]).collect();
    Ok(Dem {
        name,
        r,
        range: hi - lo,
        greedy,
    })
}

/// N random valid samples, the raster's corners among them.
fn random_sites(d: &Dem, n: usize, seed: u64) -> Vec<[i64; 2]> {
    let (w, h) = (d.r.width, d.r.height);
    let mut rng = Rng(seed ^ 0xD1B5_4A32_D192_ED03);
    let mut seen = std::collections::HashSet::new();
    let mut pts = Vec::new();
    for (x, y) in [(0, 0), (w - 1, 0), (w - 1, h - 1), (0, h - 1)] {
        if d.r.is_valid(y * w + x) && seen.insert((x, y)) {
            pts.push([x as i64, y as i64]);
        }
    }
    while pts.len() < n {
        let (x, y) = (rng.below(w as u64) as usize, rng.below(h as u64) as usize);
        if d.r.is_valid(y * w + x) && seen.insert((x, y)) {
            pts.push([x as i64, y as i64]);
        }
    }
    pts
}

struct TerrainRow {
    label: String,
    err: Err,
    build: f64,
}

/// Every interpolant of one site set against the raster; timings are the best of `reps`.
fn terrain_case(
    d: &Dem,
    pts: &[[i64; 2]],
    settings: &[(&str, Params)],
    reps: usize,
) -> Vec<TerrainRow> {
    let (w, h) = (d.r.width, d.r.height);
    let hs: Vec<f64> = pts
        .iter()
        .map(|p| d.r.data[p[1] as usize * w + p[0] as usize])
        .collect();
    let t0 = Instant::now();
    let ip = Interpolants::new(pts, &hs);
    let sib_build = t0.elapsed().as_secs_f64();
    let grid: Vec<[i64; 2]> = (0..h as i64)
        .flat_map(|y| (0..w as i64).map(move |x| [x, y]))
        .collect();
    let truth: Vec<f64> = (0..w * h)
        .map(|i| {
            if d.r.is_valid(i) {
                d.r.data[i]
            } else {
                f64::NAN
            }
        })
        .collect();
    let mut rows = Vec::new();
    for (label, p) in settings {
        let t0 = Instant::now();
        let s = ip.basis(*p);
        let build = t0.elapsed().as_secs_f64();
        rows.push(TerrainRow {
            label: label.to_string(),
            err: best_of(reps, || eval_basis(&s, &grid, &truth)),
            build,
        });
    }
    rows.push(TerrainRow {
        label: "Sibson".into(),
        err: best_of(reps, || eval_sibson(&ip.sibson, 0, 0, w, h, 1, &truth)),
        build: sib_build,
    });
    rows
}

/// The run of `f` that took least time, of `reps`.
fn best_of(reps: usize, f: impl Fn() -> Err) -> Err {
    (0..reps.max(1))
        .map(|_| f())
        .min_by(|a, b| a.secs.total_cmp(&b.secs))
        .expect("one run")
}

/// Per case, the rows of the first random seed (for the timing table).
type Timing = Vec<(String, Vec<TerrainRow>)>;

fn terrain(quick: bool) -> Result<Timing, Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("../shared/corpus");
    let names = [
        "scape_crater",
        "ned1_halfdome_yosemite",
        "srtm30m_bigtujunga_utm11",
    ];
    let settings: Vec<(&str, Params)> = vec![
        ("polyhedral", Params::polyhedral()),
        ("CP α=λ=0.25", Params::chaturvedi_piegl(0.25, 0.25)),
        ("CP α=λ=0.5", Params::chaturvedi_piegl(0.5, 0.5)),
        ("CP α=λ=1", Params::chaturvedi_piegl(1.0, 1.0)),
        ("expanded α=λ=0.25", Params::expanded(0.25, 0.25)),
        ("expanded α=λ=0.5", Params::expanded(0.5, 0.5)),
        ("expanded α=λ=1", Params::expanded(1.0, 1.0)),
    ];
    let random_seeds: u64 = if quick { 1 } else { 5 };
    println!("## 2. Real terrain\n");
    println!(
        "Every valid raster sample inside the sites' hull (the raster's corners are sites, so all of them); error in data units and in % of the raster's range. Random: mean over {random_seeds} seeds (the last column: the RMSE's difference from Sibson's on the same sites, mean ± sd, and on how many seeds it is below). Greedy: the first N sites in importance order of vtz's Sibson encoder (`--sites 2000`), with the raster's own heights.\n"
    );
    let mut timing = Vec::new();
    for name in names {
        let d = load_dem(&dir, name, 2000)?;
        println!(
            "### {} ({}×{}, range {:.1})\n",
            d.name, d.r.width, d.r.height, d.range
        );
        println!(
            "| sites | N | interpolant | max | max % | RMSE | RMSE % | RMSE − Sibson's (seeds below Sibson) |"
        );
        println!("|---|--:|---|--:|--:|--:|--:|--:|");
        let mut coverage = Vec::new();
        for n in [200usize, 2000] {
            for kind in ["random", "greedy"] {
                let seeds: Vec<u64> = if kind == "greedy" {
                    vec![0]
                } else {
                    (0..random_seeds).collect()
                };
                // Per interpolant, per seed: (max, RMSE).
                let mut per: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
                // Samples evaluated (inside the hull) by each interpolant, last seed.
                let mut counted: Vec<usize> = Vec::new();
                for &seed in &seeds {
                    let pts = if kind == "greedy" {
                        d.greedy[..n.min(d.greedy.len())].to_vec()
                    } else {
                        random_sites(&d, n, seed)
                    };
                    let timed = seed == 0 && kind == "random";
                    let rows = terrain_case(&d, &pts, &settings, if timed { 3 } else { 1 });
                    if per.is_empty() {
                        per = rows.iter().map(|r| (r.label.clone(), Vec::new())).collect();
                    }
                    for (a, r) in per.iter_mut().zip(&rows) {
                        a.1.push((r.err.max, r.err.rmse()));
                    }
                    counted = rows.iter().map(|r| r.err.n).collect();
                    if timed {
                        timing.push((format!("{name}, {n} random"), rows));
                    }
                }
                let valid = (0..d.r.len()).filter(|&i| d.r.is_valid(i)).count();
                coverage.push(format!(
                    "{kind} {n}: {:.2} %{}",
                    100.0 * counted[0] as f64 / valid as f64,
                    if counted.iter().all(|&c| c == counted[0]) {
                        ""
                    } else {
                        " (the interpolants counted different samples!)"
                    }
                ));
                let sib: Vec<f64> = per.last().expect("Sibson").1.iter().map(|x| x.1).collect();
                let mean = |v: &[(f64, f64)], k: usize| {
                    v.iter()
                        .map(|x| if k == 0 { x.0 } else { x.1 })
                        .sum::<f64>()
                        / v.len() as f64
                };
                let best = per.iter().map(|a| mean(&a.1, 1)).fold(f64::MAX, f64::min);
                for (label, v) in &per {
                    let (max, rmse) = (mean(v, 0), mean(v, 1));
                    let mark = if rmse == best { "**" } else { "" };
                    let delta: Vec<f64> = v.iter().zip(&sib).map(|(x, s)| x.1 - s).collect();
                    let vs = if label == "Sibson" {
                        "".to_string()
                    } else if delta.len() > 1 {
                        let (m, sd) = mean_sd(&delta);
                        let wins = delta.iter().filter(|&&x| x < 0.0).count();
                        format!("{m:+.3} ± {sd:.3} ({wins}/{})", delta.len())
                    } else {
                        format!("{:+.3}", delta[0])
                    };
                    println!(
                        "| {kind} | {n} | {label} | {max:.2} | {:.2} | {mark}{rmse:.3}{mark} | {:.3} | {vs} |",
                        100.0 * max / d.range,
                        100.0 * rmse / d.range
                    );
                }
            }
        }
        println!(
            "\nValid samples inside the sites' hull (evaluated): {}.\n",
            coverage.join("; ")
        );
    }
    Ok(timing)
}

fn timing_table(timing: &[(String, Vec<TerrainRow>)]) {
    println!("## 3. Time per evaluated point\n");
    println!(
        "One thread, release build, best of 3 runs (the machine was shared: rough); the basis surfaces evaluate each point on its own (hull test, candidate bases from a grid, one ray–conic crossing per candidate); Sibson walks the raster row by row (`eval_lattice`, reusing cavities). Build: triangulation excluded for the basis surfaces (it is shared), included for Sibson.\n"
    );
    print!("| case |");
    for r in &timing[0].1 {
        print!(" {} |", r.label);
    }
    println!();
    println!("|---|{}", "--:|".repeat(timing[0].1.len()));
    for (case, rows) in timing {
        print!("| {case} |");
        for r in rows {
            print!(
                " {:.0} ns (build {:.0} ms) |",
                r.err.ns_per_point(),
                1e3 * r.build
            );
        }
        println!();
    }
    println!();
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let has = |f: &str| args.iter().any(|a| a == f);
    let quick = has("--quick");
    let seeds = if quick { 4 } else { 20 };
    if !has("--terrain-only") {
        sinc(seeds);
        let chosen = SincDef {
            label: "sin r / r on [-12, 12]²",
            k: 1.0,
            half: 12.0,
        };
        let l1 = "100 Σ|e| / Σ|z|";
        sinc_table(chosen, seeds, true, Err::rel_l1, l1, None);
        sinc_table(chosen, seeds, true, Err::rel_l1, l1, Some(1.0));
        sinc_sweep(chosen, seeds.min(10), Err::rel_l1);
        let other = SincDef {
            label: "sin r / r on [-10, 10]²",
            k: 1.0,
            half: 10.0,
        };
        sinc_table(other, seeds, true, Err::rel_l1, l1, None);
        sinc_table(chosen, seeds, false, Err::rel_l1, l1, None);
        sinc_table(chosen, seeds, true, Err::rel_l2, "100 √(Σe² / Σz²)", None);
    }
    if !has("--sinc-only") {
        let timing = terrain(quick)?;
        timing_table(&timing);
    }
    Ok(())
}
