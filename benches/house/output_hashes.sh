#!/usr/bin/env bash
# Output hashes of a fixed list of CLI commands over the corpus (issue 39, "every output byte
# unchanged"): every method, tiled and untiled, windows, overviews, scale, point sets, meshes,
# Cesium tiles, web tiles, cells, sites, render, convert, rd. Run it with a binary built before
# a refactor and with one built after; the two lists must be equal line for line.
#   benches/house/output_hashes.sh target/ci/vtz > after.txt
#   diff benches/house/hashes_baseline.txt after.txt
# Timings and paths are not outputs: `rd` is hashed through its CSV (bits per sample and
# errors, no time column) (its enc_s and dec_s columns cut). About 40 s on 2 cores; run twice on one binary it gives the same list.
set -euo pipefail
vtz="$(realpath "${1:?usage: output_hashes.sh VTZ_BINARY}")"
here="$(cd "$(dirname "$0")/../.." && pwd)"
corpus="$here/corpus"
shared="$here/../shared"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
run() { "$vtz" "$@" -q; }
# Encodes: every method, bounds, efforts, tiled and untiled, lossless, rate targets.
run encode "$corpus/scape_crater.png" -o crater_res.vtz --max-error 1
run encode "$corpus/scape_crater.png" -o crater_res_e1.vtz --max-error 1 --effort 1
run encode "$corpus/scape_crater.png" -o crater_res_e6.vtz --max-error 0.5 --effort 6
run encode "$corpus/scape_crater.png" -o crater_lossless.vtz
run encode "$corpus/scape_crater.png" -o crater_sites.vtz --method sibson --max-error 2%
run encode "$corpus/scape_crater.png" -o crater_grid.vtz --method grid --max-error 1%
run encode "$corpus/scape_crater.png" -o crater_haar.vtz --method haar --max-error 1%
run encode "$corpus/nasadem_west_bijou_escarpment_landlab.asc" -o crater_fis.vtz --method fis --max-error 5%
run encode "$corpus/scape_crater.png" -o crater_best.vtz --method best --max-error 1%
run encode "$corpus/scape_crater.png" -o crater_bps.vtz --bps 1
run encode "$corpus/srtm3_N22W160_kauai.hgt" -o kauai.vtz --max-error 1
run encode "$corpus/srtm3_N22W160_kauai.hgt" -o kauai_tiled.vtz --max-error 1 --tile 256
run encode "$corpus/srtm3_N22W160_kauai.hgt" -o kauai_tiled_lossless.vtz --tile 300 --threads 2
run encode "$corpus/srtm30m_bigtujunga_utm11.tif" -o tujunga.vtz --max-error 0.5
run encode "$corpus/srtm30m_bigtujunga_utm11.tif" -o tujunga_tiled.vtz --max-error 0.5 --tile 200 --effort 2
run encode "$corpus/ahn3_delft_dsm_50cm.f32" -o delft.vtz --max-error 0.05
run encode "$corpus/nasadem_west_bijou_escarpment_landlab.asc" -o bijou.vtz --max-error 0.25
run encode "$corpus/srtm1_N45E013_istria_crop2400.png" -o istria_tiled.vtz --max-error 2 --tile 1024 \
  --png-offset -32768
# Point sets.
run encode "$corpus/scape_crater.png" -o crater_points.vtz --band "$corpus/scape_crater.png" --max-error 1
if [ -d "$shared/corpus/points" ]; then
  laz="$(ls "$shared"/corpus/points/*.laz | head -n 1)"
  run encode "$laz" -o cloud.vtz --max-error 0.1 --class 2
  run decode cloud.vtz -o cloud.xyz
  run decode cloud.vtz -o cloud_sites.xyz --sites-only
  run decode cloud.vtz -o cloud_cell.tif --cell 1
fi
run decode crater_points.vtz -o crater_points.xyz
run decode crater_points.vtz -o crater_points.tif --cell 1 --only-positions
# Decodes: untiled and tiled, windows, overviews, scale, sections, sites prefixes, formats.
for f in crater_res crater_res_e1 crater_res_e6 crater_lossless crater_sites crater_grid crater_haar \
  crater_fis crater_best crater_bps kauai kauai_tiled kauai_tiled_lossless tujunga tujunga_tiled delft bijou istria_tiled; do
  run decode "$f.vtz" -o "$f.f32"
done
run decode kauai.vtz -o kauai.tif
run decode kauai_tiled.vtz -o kauai_tiled.tif
run decode istria_tiled.vtz -o istria_tiled.tif --threads 1
run decode kauai.vtz -o kauai.asc
run decode kauai.vtz -o kauai_dec.png --round --png-offset -32768
run decode crater_res.vtz -o crater_res.png --round
run decode crater_lossless.vtz -o crater.exr
run decode kauai_tiled.vtz -o kauai_win.f32 --window 200,150,333,301
run decode kauai.vtz -o kauai_win_untiled.f32 --window 200,150,333,301
run decode istria_tiled.vtz -o istria_win.tif --window 1000,900,700,500
run decode kauai_tiled.vtz -o kauai_ov1.f32 --overview 1
run decode kauai_tiled.vtz -o kauai_ov3.tif --overview 3
run decode kauai.vtz -o kauai_ov2.f32 --overview 2
run decode crater_grid.vtz -o crater_grid_ov1.f32 --overview 1
run decode crater_haar.vtz -o crater_haar_ov1.f32 --overview 1
run decode crater_sites.vtz -o crater_sites_ov1.f32 --overview 1
run decode kauai.vtz -o kauai_s05.f32 --scale 0.5
run decode kauai_tiled.vtz -o kauai_tiled_s15.f32 --scale 3/2
run decode crater_sites.vtz -o crater_sites_s2.f32 --scale 2
run decode crater_fis.vtz -o crater_fis_s05.f32 --scale 0.5
run decode crater_sites.vtz -o crater_sites_l3.f32 --level 3
run decode crater_sites.vtz -o crater_sites_n50.f32 --sites 50
run decode crater_sites.vtz -o crater_sites_linear.f32 --surface linear
run decode crater_best.vtz -o crater_best_s1.f32 --section 1
"$vtz" sites crater_sites.vtz -o crater_sites.csv -q
# Applications: meshes, Cesium tiles, web tiles, cells, render, convert, lsystem.
run mesh "$corpus/scape_crater.png" -o crater.obj --max-error 2%
run mesh crater_sites.vtz -o crater_sites.glb --normals --uvs
run mesh "$corpus/scape_crater.png" -o crater_qt.ply --select quadtree
run mesh "$corpus/srtm3_N22W160_kauai.hgt" -o kauai.stl --georef --max-edge 40 --max-error 10
run tiles "$corpus/srtm3_N22W160_kauai.hgt" -o kauai_terrain --max-error 5
run web "$corpus/srtm3_N22W160_kauai.hgt" -o kauai.pmtiles --max-zoom 9
run web "$corpus/srtm30m_bigtujunga_utm11.tif" -o tujunga_terrarium.pmtiles --format terrarium-png --max-zoom 11
run cells crater_sites.vtz -o crater_cells.geojson --level 4
run cells crater_sites.vtz -o crater_cells.png --level 4
run render kauai.vtz -o kauai_render.png
run render crater_sites.vtz -o crater_render_sites.png --sites
run convert "$corpus/srtm3_N22W160_kauai.hgt" kauai_conv.tif
run convert "$corpus/ahn3_delft_dsm_50cm.f32" delft_conv.asc
if [ -d "$here/benches/lsystem" ]; then
  rules="$(ls "$here"/benches/lsystem/*.toml 2>/dev/null | head -n 1 || true)"
  [ -n "$rules" ] && run lsystem "$rules" -o plant.obj
fi
"$vtz" rd "$corpus/scape_crater.png" --methods residual,grid --bounds 0.3%,3% --csv rd.csv -q >/dev/null
cut -d, -f1-12,15- rd.csv > rd_notime.csv && rm rd.csv
find . -type f | LC_ALL=C sort | while read -r f; do
  printf '%s  %s\n' "$(sha256sum "$f" | cut -c1-16)" "${f#./}"
done
