#!/usr/bin/env bash
# Window latency: `vtz decode FILE.vtz --window X,Y,S,S` from a fresh process (a cold file
# handle; the OS page cache is warm after the first run) at a few positions, RUNS runs each,
# the median wall time and how many bytes of the file the window needed (`vtz info --json`:
# header, index and the tiles it touches). Usage: window.sh VTZ_BIN FILE.vtz [S] [RUNS]
set -euo pipefail
VTZ=${1:?usage: window.sh VTZ_BIN FILE.vtz [SIZE] [RUNS]}
F=${2:?usage: window.sh VTZ_BIN FILE.vtz [SIZE] [RUNS]}
S=${3:-512}
RUNS=${4:-5}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
read -r W H < <("$VTZ" info --json "$F" | python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["width"], j["height"])')
echo "| window | tiles touched | median s | runs (s) |"
echo "|---|---|---|---|"
for pos in "0,0" "$((W / 2 - S / 2)),$((H / 2 - S / 2))" "$((W / 3)),$((H / 5))" "$((W - S)),$((H - S))"; do
  x=${pos%,*}; y=${pos#*,}
  times=()
  for _ in $(seq "$RUNS"); do
    t=$( { /usr/bin/time -f %e "$VTZ" decode "$F" -o "$TMP/w.tif" --window "$x,$y,$S,$S" -f -q; } 2>&1 )
    times+=("$t")
  done
  med=$(printf '%s\n' "${times[@]}" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
  touched=$("$VTZ" info --json "$F" | python3 -c "
import json,sys
j=json.load(sys.stdin); x,y,s=$x,$y,$S
t=[e for e in j['tiles']['index'] if e['x']<x+s and x<e['x']+e['width'] and e['y']<y+s and y<e['y']+e['height']]
print(len(t), sum(e['width']*e['height'] for e in t))")
  echo "| $x,$y ${S}² | ${touched% *} (${touched#* } samples) | $med | ${times[*]} |"
done
