#!/usr/bin/env python3
# Requires: Python 3 with GDAL's bindings (osgeo) and numpy: Debian's python3-gdal, i.e.
# /usr/bin/python3 on the project's machines (the `python3` on PATH may lack osgeo).
"""Helper of benches/remote/run.sh: the files' layout, checks of what a read returned, and
nginx's access log split per read into a table.

  remote_table.py layout DATA_DIR --vtz-info INFO.json --window X,Y,W,H ... -o LAYOUT.json
      File sizes; for each COG the bytes of its full-resolution tiles and of its overviews
      (GDAL's TIFF metadata BLOCK_SIZE_x_y); for each window the tiles (COG blocks, .vtz
      tiles whose coded samples it meets) it touches at full resolution and their bytes.
  remote_table.py check SRC.tif X,Y,W,H FILE [--bound E]
      Compares a window read (any GDAL raster or a .npy) with the source's samples there:
      prints one line, e.g. "max err 1 (bound 1), nodata same"; exit 1 when the bound
      or the nodata mask fails or the size is wrong.
  remote_table.py size FILE
      Prints "W×H" of a GDAL raster or .npy (overview reads).
  remote_table.py table ACCESS.log RUNS.tsv LAYOUT.json --csv OUT.csv --runs-csv RUNS.csv
      Splits the log at run.sh's marker requests (GET /__mark__/begin/KEY and
      /__mark__/end/KEY), counts each run's requests and body bytes, and prints the
      Markdown tables (files; reads: requests, bytes, median wall seconds).

The access log's lines are nginx's
  log_format ranges '$request_method $uri $http_range $status $body_bytes_sent $request_time';
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import sys
from pathlib import Path

COGS = {"COG LERC": "mosaic_lerc.tif", "COG DEFLATE": "mosaic_deflate.tif"}
VTZ_FILE = "mosaic.vtz"
MARK = "/__mark__/"


def _win(text: str) -> tuple[int, int, int, int]:
    x, y, w, h = (int(v) for v in text.split(","))
    return x, y, w, h


def _meets(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    return a[0] < b[0] + b[2] and b[0] < a[0] + a[2] and a[1] < b[1] + b[3] and b[1] < a[1] + a[3]


def _cog_layout(path: Path, windows: list[tuple[int, int, int, int]]) -> dict:
    from osgeo import gdal

    gdal.UseExceptions()
    ds = gdal.Open(str(path))
    band = ds.GetRasterBand(1)
    bw, bh = band.GetBlockSize()

    def block_bytes(b, bx: int, by: int) -> int:
        v = b.GetMetadataItem(f"BLOCK_SIZE_{bx}_{by}", "TIFF")
        return int(v) if v else 0

    def band_bytes(b) -> int:
        nx = (b.XSize + bw - 1) // bw
        ny = (b.YSize + bh - 1) // bh
        return sum(block_bytes(b, bx, by) for by in range(ny) for bx in range(nx))

    full = band_bytes(band)
    ovr = [band.GetOverview(i) for i in range(band.GetOverviewCount())]
    out = {
        "bytes": path.stat().st_size,
        "block": [bw, bh],
        "full_resolution_tile_bytes": full,
        "overview_tile_bytes": sum(band_bytes(o) for o in ovr),
        "overviews": [[o.XSize, o.YSize] for o in ovr],
        "windows": {},
    }
    for w in windows:
        bx0, by0 = w[0] // bw, w[1] // bh
        bx1, by1 = (w[0] + w[2] - 1) // bw, (w[1] + w[3] - 1) // bh
        blocks = [(bx, by) for by in range(by0, by1 + 1) for bx in range(bx0, bx1 + 1)]
        out["windows"][",".join(map(str, w))] = {
            "tiles": len(blocks),
            "bytes": sum(block_bytes(band, bx, by) for bx, by in blocks),
        }
    return out


def _vtz_layout(path: Path, info_path: Path | None, windows) -> dict:
    out: dict = {"bytes": path.stat().st_size if path.exists() else None, "windows": {}}
    if info_path is None or not info_path.exists():
        return out
    try:
        info = json.loads(info_path.read_text())
    except json.JSONDecodeError:
        return out
    t = info.get("tiles")
    if not t or "index" not in t:
        return out
    out["tile"] = [t.get("tile_width"), t.get("tile_height")]
    out["grid"] = [t.get("cols"), t.get("rows")]
    out["margin"] = t.get("margin")
    def coded(e) -> tuple[int, int, int, int] | None:
        if "coded" in e:  # the samples a tile codes: its core and margins
            return tuple(e["coded"])
        if all(k in e for k in ("x", "y", "width", "height")):
            return e["x"], e["y"], e["width"], e["height"]
        return None

    if any(coded(e) is None or "bytes" not in e for e in t["index"]):
        return out
    for w in windows:
        hit = [e for e in t["index"] if _meets(coded(e), w)]
        out["windows"][",".join(map(str, w))] = {
            "tiles": len(hit),
            "bytes": sum(int(e["bytes"]) for e in hit),
        }
    return out


def cmd_layout(a) -> int:
    data = Path(a.data_dir)
    windows = [_win(w) for w in a.window]
    lay = {name: _cog_layout(data / f, windows) for name, f in COGS.items()}
    lay[".vtz"] = _vtz_layout(data / VTZ_FILE, Path(a.vtz_info) if a.vtz_info else None, windows)
    Path(a.o).write_text(json.dumps(lay, indent=1) + "\n")
    return 0


def _read_any(path: str):
    import numpy as np

    if path.endswith(".npy"):
        return np.load(path), None
    from osgeo import gdal

    gdal.UseExceptions()
    ds = gdal.Open(path)
    b = ds.GetRasterBand(1)
    return b.ReadAsArray(), b.GetNoDataValue()


def cmd_check(a) -> int:
    import numpy as np
    from osgeo import gdal

    gdal.UseExceptions()
    x, y, w, h = _win(a.window)
    src_ds = gdal.Open(a.src)  # kept: a band outlives no dataset in osgeo
    src = src_ds.GetRasterBand(1)
    ref = src.ReadAsArray(x, y, w, h).astype(np.float64)
    nd = src.GetNoDataValue()
    got, got_nd = _read_any(a.file)
    got = np.asarray(got, dtype=np.float64)
    if got.shape != ref.shape:
        print(f"BAD: {got.shape[1]}×{got.shape[0]}, not {w}×{h}")
        return 1
    ref_void = np.isnan(ref) if nd is None else (ref == nd) | np.isnan(ref)
    got_void = np.isnan(got)
    for v in (got_nd, nd):
        if v is not None:
            got_void |= got == v
    mism = int(np.count_nonzero(ref_void != got_void))
    valid = ~ref_void & ~got_void
    err = float(np.max(np.abs(ref[valid] - got[valid]))) if valid.any() else 0.0
    ok = mism == 0 and err <= a.bound
    voids = int(np.count_nonzero(ref_void))
    print(
        f"{'' if ok else 'BAD: '}max err {err:g} (bound {a.bound:g}), "
        + (f"nodata same ({voids})" if mism == 0 else f"{mism} nodata mismatches")
    )
    return 0 if ok else 1


def cmd_size(a) -> int:
    got, _ = _read_any(a.file)
    print(f"{got.shape[1]}×{got.shape[0]}")
    return 0


def _parse_log(path: Path) -> dict[str, list[tuple[str, str, str, int, int]]]:
    """KEY -> [(method, uri, range, status, body bytes)] between its begin and end marks."""
    runs: dict[str, list] = {}
    cur = None
    for line in path.read_text().splitlines():
        parts = line.split(" ")
        if len(parts) < 6:
            continue
        method, uri, rng, status, nbytes = parts[0], parts[1], parts[2], parts[3], parts[4]
        if uri.startswith(MARK):
            kind, _, key = uri[len(MARK) :].partition("/")
            if kind == "begin":
                cur = key
                runs[key] = []
            elif kind == "end":
                cur = None
            continue
        if cur is not None:
            runs[cur].append((method, uri, rng, int(status), int(nbytes)))
    return runs


def _fmt_int(n) -> str:
    return f"{n:,}".replace(",", " ") if isinstance(n, int) else str(n)


def cmd_table(a) -> int:
    log = _parse_log(Path(a.log))
    lay = json.loads(Path(a.layout).read_text())
    rows = []
    with open(a.runs_tsv, newline="") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            reqs = log.get(r["key"], [])
            r["requests"] = len(reqs)
            r["bytes"] = sum(q[4] for q in reqs)
            gets = [q for q in reqs if q[0] == "GET"]
            r["first_request_bytes"] = gets[0][4] if gets else ""
            r["largest_request_bytes"] = max((q[4] for q in reqs), default="")
            r["methods"] = " ".join(f"{m}×{sum(q[0] == m for q in reqs)}" for m in sorted({q[0] for q in reqs}))
            r["statuses"] = " ".join(sorted({str(q[3]) for q in reqs}))
            r["ranges"] = " ".join(f"{q[0]}:{q[2]}" for q in reqs) if len(reqs) <= 40 else ""
            rows.append(r)

    run_fields = ["read", "position", "format", "tool", "run", "rc", "wall_s", "requests",
                  "bytes", "first_request_bytes", "largest_request_bytes", "methods", "statuses",
                  "check", "note", "ranges"]
    with open(a.runs_csv, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=run_fields, extrasaction="ignore")
        wr.writeheader()
        wr.writerows(rows)

    # One summary row per (read, position, format, tool), in run.sh's order.
    groups: dict[tuple, list] = {}
    for r in rows:
        groups.setdefault((r["read"], r["position"], r["format"], r["tool"]), []).append(r)
    summary = []
    for (read, pos, fmt, tool), rs in groups.items():
        ok = [r for r in rs if r["rc"] == "0"]
        first = rs[0]
        win = pos.split(" ")[-1] if read == "window" else None
        touched = lay.get(fmt, {}).get("windows", {}).get(f"{win},256,256") if win else None
        if ok and first["check"].startswith("BAD"):  # read, but not the right samples
            walls, reqs, byts = [], [first["requests"]], [first["bytes"]]
            status, note = "FAILED", first["check"].removeprefix("BAD: ")
        elif ok:
            walls = [float(r["wall_s"]) for r in ok]
            reqs = sorted({r["requests"] for r in ok})
            byts = sorted({r["bytes"] for r in ok})
            status = "ok"
            note = first["note"]
        else:
            walls, reqs, byts = [], [first["requests"]], [first["bytes"]]
            status = "n/a" if first["note"].startswith("n/a") else "FAILED"
            note = first["note"] or f"exit {first['rc']}"
        summary.append({
            "read": read, "position": pos, "format": fmt, "tool": tool,
            "requests": "–".join(map(str, (reqs[0], reqs[-1]))) if len(reqs) > 1 else reqs[0],
            "bytes": "–".join(map(str, (byts[0], byts[-1]))) if len(byts) > 1 else byts[0],
            "first_request_bytes": first["first_request_bytes"],
            "methods": first["methods"],
            "wall_s_median": f"{statistics.median(walls):.3f}" if walls else "",
            "runs": len(ok),
            "touched_tiles": touched["tiles"] if touched else "",
            "touched_bytes": touched["bytes"] if touched else "",
            "check": first["check"], "status": status, "note": note,
        })
    fields = list(summary[0].keys()) if summary else []
    with open(a.csv, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=fields)
        wr.writeheader()
        wr.writerows(summary)

    print("| file | bytes | full-resolution tiles | overviews | tiles |")
    print("|---|--:|--:|--:|---|")
    for fmt in ("COG LERC", "COG DEFLATE"):
        c = lay[fmt]
        ovr = ", ".join(f"{w}²" if w == h else f"{w}×{h}" for w, h in c["overviews"])
        print(f"| {COGS[fmt]} ({fmt}) | {_fmt_int(c['bytes'])} | "
              f"{_fmt_int(c['full_resolution_tile_bytes'])} | {_fmt_int(c['overview_tile_bytes'])} "
              f"({ovr}) | {c['block'][0]}² blocks |")
    v = lay[".vtz"]
    grid = (f"{v['tile'][0]}×{v['tile'][1]} tiles, {v['grid'][0]}×{v['grid'][1]}, margin {v['margin']}"
            if v.get("tile") else "n/a")
    print(f"| {VTZ_FILE} (.vtz) | {_fmt_int(v['bytes'])} | – | – | {grid} |")
    lerc = lay["COG LERC"]["bytes"]
    if v["bytes"] and lerc:
        print(f"\n.vtz / LERC COG with overviews = {v['bytes'] / lerc:.3f}; "
              f".vtz / DEFLATE COG = {v['bytes'] / lay['COG DEFLATE']['bytes']:.3f}")
    print()
    print("| read | format | tool | requests | bytes | wall s (median) | tiles touched (bytes) | check / note |")
    print("|---|---|---|--:|--:|--:|--:|---|")
    for s in summary:
        read = s["read"] + (f" {s['position']}" if s["position"] != "-" else "")
        touched = (f"{s['touched_tiles']} ({_fmt_int(s['touched_bytes'])})"
                   if s["touched_tiles"] != "" else "")
        if s["status"] == "ok":
            extra = s["check"]
            if s["read"] == "open" and s["first_request_bytes"] != "":
                extra = (extra + "; " if extra else "") + (
                    f"{s['methods']}, first GET {_fmt_int(s['first_request_bytes'])} B")
            if s["note"]:
                extra = (extra + "; " if extra else "") + s["note"]
            print(f"| {read} | {s['format']} | {s['tool']} | {s['requests']} | "
                  f"{_fmt_int(s['bytes'])} | {s['wall_s_median']} | {touched} | {extra} |")
        else:
            print(f"| {read} | {s['format']} | {s['tool']} | – | – | – | {touched} | "
                  f"{s['note'] if s['status'] == 'n/a' else 'FAILED: ' + s['note']} |")
    print()
    _targets(summary, lay)
    return 1 if any(s["status"] == "FAILED" for s in summary) else 0


def _num(v) -> int | None:
    """A summary's requests/bytes as one number (the larger when runs differed)."""
    if v == "" or v is None:
        return None
    return int(str(v).split("–")[-1])


def _targets(summary: list[dict], lay: dict) -> None:
    """Issue 36's targets, judged on the rows above: one line per target and tool that reads
    the .vtz, its values in the table's order (the six windows: corner … far)."""
    def row(read, pos, fmt):
        for s in summary:
            if (s["read"], s["position"], s["format"]) == (read, pos, fmt):
                return s
        return None

    out: dict[tuple[str, str], list] = {}

    def judge(target, who, value, ok):
        out.setdefault((target, who), []).append((value, ok))

    vtz_bytes = lay[".vtz"]["bytes"]
    lerc_bytes = lay["COG LERC"]["bytes"]
    if vtz_bytes and lerc_bytes:
        judge("the .vtz ≤ 0.3× the LERC COG with overviews", "–",
              f"{vtz_bytes / lerc_bytes:.3f}×", vtz_bytes <= 0.3 * lerc_bytes)
    for s in summary:
        if s["format"] != ".vtz":
            continue
        who = s["tool"] + (" (plugin)" if s["tool"].startswith("gdal") else "")
        ok = s["status"] == "ok"
        req, byt = _num(s["requests"]), _num(s["bytes"])
        cogs = [row(s["read"], s["position"], f) for f in ("COG LERC", "COG DEFLATE")]
        cog_req = [_num(c["requests"]) for c in cogs if c and c["status"] == "ok"]
        read = s["read"]
        if not ok:
            judge(f"{read}: (not measured)", who, "", None)
            continue
        if read == "open" and who in ("vtz info", "vtz.open"):
            judge("open: 1 request of ≤ 64 KB", who, f"{req} req, {byt} B",
                  req == 1 and byt <= 65536)
        if read == "window":
            touched = _num(s["touched_bytes"])
            judge("window: ≤ 3 requests", who, str(req), req <= 3)
            if touched:
                judge("window: bytes ≤ 1.5× those of the tiles it touches", who,
                      f"{byt / touched:.2f}×", byt <= 1.5 * touched)
        if read == "overview":
            lerc = row("overview", s["position"], "COG LERC")
            lerc_b = _num(lerc["bytes"]) if lerc and lerc["status"] == "ok" else None
            if vtz_bytes:
                judge("overview: bytes ≤ 10 % of the .vtz", who, f"{byt / vtz_bytes:.1%}",
                      byt <= 0.1 * vtz_bytes)
            if lerc_b is not None:
                judge("overview: bytes ≤ the LERC COG's", who, f"{byt / lerc_b:.2f}×",
                      byt <= lerc_b)
        if cog_req:
            judge(f"{read}: requests ≤ the COGs' (LERC/DEFLATE)", who,
                  f"{req} vs {'/'.join(map(str, cog_req))}", all(req <= c for c in cog_req))
    print("| target (issue 36) | .vtz read by | values | |")
    print("|---|---|---|---|")
    for (target, who), vals in out.items():
        judged = [ok for _, ok in vals if ok is not None]
        if not judged:
            verdict = "n/a"
        elif all(judged):
            verdict = "met"
        else:
            verdict = f"**not met** ({judged.count(False)} of {len(judged)})"
        text = ", ".join(v for v, _ in vals if v)
        print(f"| {target} | {who} | {text} | {verdict} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("layout")
    p.add_argument("data_dir")
    p.add_argument("--vtz-info")
    p.add_argument("--window", action="append", default=[])
    p.add_argument("-o", required=True)
    p = sub.add_parser("check")
    p.add_argument("src")
    p.add_argument("window")
    p.add_argument("file")
    p.add_argument("--bound", type=float, default=0.0)
    p = sub.add_parser("size")
    p.add_argument("file")
    p = sub.add_parser("table")
    p.add_argument("log")
    p.add_argument("runs_tsv")
    p.add_argument("layout")
    p.add_argument("--csv", required=True)
    p.add_argument("--runs-csv", required=True)
    a = ap.parse_args()
    return {"layout": cmd_layout, "check": cmd_check, "size": cmd_size, "table": cmd_table}[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())
