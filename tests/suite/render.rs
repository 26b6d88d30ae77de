//! The `vtz render` command and `vtz compare --png`: pictures of the size and kind expected.

use crate::common;

use common::{corpus, ok, stderr, tmp, vtz};

fn picture(path: &str) -> image::RgbImage {
    image::open(path).expect("a PNG picture").to_rgb8()
}

#[test]
fn render_a_raster() {
    let d = tempfile::tempdir().unwrap();
    let out = tmp(&d, "crater.png");
    let o = vtz(["render", &corpus("scape_crater.png"), "-o", &out, "-q"]);
    ok(&o);
    let img = picture(&out);
    assert_eq!(img.dimensions(), (336, 459));
    // Not one flat colour.
    let first = *img.get_pixel(0, 0);
    assert!(img.pixels().any(|p| *p != first));
    // No clobbering without --force; --force replaces.
    let o = vtz(["render", &corpus("scape_crater.png"), "-o", &out, "-q"]);
    assert_eq!(o.status.code(), Some(2));
    let o = vtz([
        "render",
        &corpus("scape_crater.png"),
        "-o",
        &out,
        "-q",
        "--force",
        "--azimuth",
        "135",
        "--altitude",
        "30",
        "--z-factor",
        "0.1",
    ]);
    ok(&o);
    // --sites needs a .vtz.
    let o = vtz([
        "render",
        &corpus("scape_crater.png"),
        "-o",
        &tmp(&d, "s.png"),
        "--sites",
    ]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn render_sites_and_error_map_of_a_vtz() {
    let d = tempfile::tempdir().unwrap();
    let x = tmp(&d, "x.vtz");
    let src = corpus("scape_crater.png");
    ok(&vtz([
        "encode",
        &src,
        "-o",
        &x,
        "--max-error",
        "3%",
        "--method",
        "sibson",
        "-q",
    ]));

    let plain = tmp(&d, "plain.png");
    ok(&vtz(["render", &x, "-o", &plain, "-q"]));
    let sites = tmp(&d, "sites.png");
    ok(&vtz(["render", &x, "--sites", "-o", &sites, "-q"]));
    let (a, b) = (picture(&plain), picture(&sites));
    assert_eq!(b.dimensions(), (336, 459));
    let red = b
        .pixels()
        .zip(a.pixels())
        .filter(|(p, q)| p != q && p.0 == [230, 0, 0])
        .count();
    assert!(red > 100, "only {red} site pixels drawn");

    let diff = tmp(&d, "diff.png");
    ok(&vtz(["compare", &src, &x, "--png", &diff]));
    let img = picture(&diff);
    assert_eq!(img.width(), 336);
    assert!(img.height() >= 459);
    // A lossy file has errors of both signs.
    let (mut reds, mut blues) = (0, 0);
    for y in 0..459 {
        for xx in 0..336 {
            let [r, _, b] = img.get_pixel(xx, y).0;
            reds += usize::from(r > b);
            blues += usize::from(b > r);
        }
    }
    assert!(reds > 0 && blues > 0, "{reds} red, {blues} blue");

    // A grid .vtz has no sites to show.
    let g = tmp(&d, "g.vtz");
    ok(&vtz(["encode", &src, "-o", &g, "--method", "grid", "-q"]));
    let o = vtz(["render", &g, "--sites", "-o", &tmp(&d, "g.png")]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("sites section"));
}
