#!/usr/bin/env bash
# What tiling costs in bytes: each file at each bound, untiled (--tile 0) and at each tile
# size, `--method best`. Prints a Markdown table (bytes, and the tiled/untiled ratio).
# Usage: benches/tiles/cost.sh VTZ_BIN [TILES] ; env BOUNDS (default "0.3% 1% 3% 10%"),
# FILES (default: the four files of issue 12, from ../shared/corpus).
set -euo pipefail
VTZ=${1:?usage: cost.sh VTZ_BIN [TILES]}
TILES=${2:-"512 1024"}
HERE=$(cd "$(dirname "$0")" && pwd)
CORPUS=${CORPUS:-$HERE/../../../shared/corpus}
BOUNDS=${BOUNDS:-"0.3% 1% 3% 10%"}
FILES=${FILES:-"scape_crater.png srtm1_N45E013_istria_crop2400.png ned1_halfdome_yosemite.f32 srtm3_N44W072_white_mountains.f32"}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
printf '| file | bound | untiled bytes |'
for t in $TILES; do printf ' tile %s bytes | tile %s cost |' "$t" "$t"; done
printf '\n|---|---|---|'
for t in $TILES; do printf -- '---|---|'; done
printf '\n'
for f in $FILES; do
  for b in $BOUNDS; do
    "$VTZ" encode "$CORPUS/$f" -o "$TMP/u.vtz" --max-error "$b" --tile 0 -f -q >/dev/null
    u=$(stat -c %s "$TMP/u.vtz")
    printf '| %s | %s | %s |' "$f" "$b" "$u"
    for t in $TILES; do
      "$VTZ" encode "$CORPUS/$f" -o "$TMP/t.vtz" --max-error "$b" --tile "$t" -f -q >/dev/null
      s=$(stat -c %s "$TMP/t.vtz")
      printf ' %s | %+.2f %% |' "$s" "$(echo "100 * ($s - $u) / $u" | bc -l)"
    done
    printf '\n'
  done
done
