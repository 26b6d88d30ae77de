#!/usr/bin/env python3
"""Write a raster mosaic to a compressed Zarr v3 store with Dask on several worker processes.

The pipeline a GIS user runs, end to end, timed:

1. **Mosaic.** A real DEM is cut into georeferenced GeoTIFF tiles (``gdal_translate
   -srcwin``) and a GDAL VRT is built over them (``gdalbuildvrt``). An SRTM1 cache PNG
   (``srtm1_N45E013_full.png``: metres = value - 32768, 0 = missing) is first turned into a
   georeferenced int16 GeoTIFF (EPSG:4326, nodata -32768); a GeoTIFF source is tiled as it is.
2. **Open.** rioxarray opens the VRT lazily, one Dask chunk per Zarr chunk.
3. **Cluster.** ``dask.distributed.LocalCluster(n_workers=W, threads_per_worker=1,
   processes=True)``.
4. **Write.** ``Dataset.to_zarr`` writes a Zarr v3 store, chunks encoded in the workers by
   the array-to-bytes codec under test (``--codecs``):

   - ``vtz``: ``vtz.zarr.VtzCodec(max_error=E, nodata=..., threads=1)`` (method ``best``);
   - ``vtz-residual``: the same with ``method="residual"`` (no trials of other methods);
   - ``vtz-e1``, ``vtz-residual-e1``: the same two at ``effort=1`` (the residual layer's
     fast coding; the others use the library's default effort, 5);
   - ``lerc``: imagecodecs' numcodecs ``Lerc(level=E)``; ``lerc-zstd`` adds LERC's own zstd
     stage (``compression="zstd"``, as GDAL's LERC_ZSTD);
   - ``sz3``: SZ3 through ``pysz`` in absolute-error mode.

   LERC and SZ3 are numcodecs-style codecs; :class:`NumcodecsSerializer` (below) is the
   small adapter that makes such a codec a Zarr v3 array-to-bytes codec.
5. **Read.** The store is opened with xarray and every chunk decoded in the workers
   (``persist``): that is the read time.
6. **Check.** Every sample of the decoded array is compared with the VRT: valid samples
   must be within E, nodata samples must stay nodata (and no valid sample may become
   nodata). The CRS and geotransform must come back from the store.

Results go to JSON and a Markdown table: codec, bound, workers, store bytes, bits per
sample, write and read seconds (median of ``--repeat``), max error, bound ok; then the
write speedup from 1 to 2 workers and the store-size ratios of vtz to the others.

Integer data and bounds. A codec that returns integers can only err by whole units, so on
int16 metres ``E = 0.5`` is lossless and ``E = 1.7`` acts as 1. SZ3 works on a float32 copy;
it gets the absolute bound ``floor(E) + 0.499`` and its output is rounded back to the
integer dtype, which keeps every sample within ``floor(E) <= E`` (the largest SZ3 bound for
which rounding cannot break E). LERC and vtz take E as given.

Nodata. vtz keeps nodata samples exact (``nodata=`` in its config). LERC and SZ3 have no
nodata in these adapters: a nodata value is coded like any sample, so it may come back
changed and the check reports it (the benchmark tile has no voids).

Examples: the benchmark in ``benches/python`` (README there), and a quick run on the
small mosaic the test uses::

    python dask_mosaic.py --codecs vtz,lerc,lerc-zstd,sz3 --workers 1,2 \\
        --max-error 1,0.5,2 --repeat 5 --out-dir /tmp/dask_mosaic \\
        --json dask_mosaic.json --md dask_mosaic.md
    python dask_mosaic.py --source ../../corpus/srtm30m_bigtujunga_utm11.tif \\
        --tile 400 --chunk 400 --repeat 1 --out-dir /tmp/dask_small
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import re
import shutil
import statistics
import struct
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from numcodecs.abc import Codec as NumcodecsCodec
from zarr.abc.codec import ArrayBytesCodec
from zarr.core.common import parse_named_configuration
from zarr.registry import register_codec

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
DEFAULT_SOURCE = Path("/work/shared/corpus/extra/srtm1_N45E013_full.png")
TEST_SOURCE = REPO / "corpus" / "srtm30m_bigtujunga_utm11.tif"
VAR = "elevation"
CODECS = ("vtz", "vtz-residual", "vtz-e1", "vtz-residual-e1", "lerc", "lerc-zstd", "sz3")


# ---------------------------------------------------------------------------------------
# 1. The mosaic
# ---------------------------------------------------------------------------------------

_SRTM_NAME = re.compile(r"([NS])(\d{2})([EW])(\d{3})", re.IGNORECASE)


def srtm_png_to_geotiff(png: Path, tif: Path) -> Path:
    """Turn an SRTM cache PNG into a georeferenced int16 GeoTIFF.

    The PNG holds ``metres + 32768`` as uint16, 0 meaning missing, so ``value - 32768``
    gives metres and maps missing to -32768, the usual SRTM void value, declared as nodata.
    The tile's corner comes from its name (``N45E013``: 45..46 N, 13..14 E, EPSG:4326).
    The n x n PNG is taken as the SRTM grid without its duplicated last row and column:
    sample centres at ``lon0 + j/n`` and ``lat0 + 1 - i/n``, cells ``1/n`` degree wide.

    Returns ``tif``.
    """
    import rasterio
    import rasterio.errors
    from rasterio.transform import from_origin

    m = _SRTM_NAME.search(png.name)
    if not m:
        raise ValueError(f"{png.name}: no SRTM tile name (like N45E013) to georeference it")
    lat0 = int(m.group(2)) * (1 if m.group(1).upper() == "N" else -1)
    lon0 = int(m.group(4)) * (1 if m.group(3).upper() == "E" else -1)
    with warnings.catch_warnings():   # the PNG has no georeferencing: that is expected
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(png) as src:
            raw = src.read(1)
    if raw.dtype != np.uint16:
        raise ValueError(f"{png}: expected a 16-bit PNG, got {raw.dtype}")
    metres = (raw.astype(np.int32) - 32768).astype(np.int16)
    h, w = metres.shape
    cell_x, cell_y = 1.0 / w, 1.0 / h
    transform = from_origin(lon0 - cell_x / 2, lat0 + 1 + cell_y / 2, cell_x, cell_y)
    profile = dict(driver="GTiff", dtype="int16", width=w, height=h, count=1,
                   crs="EPSG:4326", transform=transform, nodata=-32768)
    with rasterio.open(tif, "w", **profile) as dst:
        dst.write(metres, 1)
    return tif


def _run(cmd: list[str]) -> None:
    """Run a GDAL command line tool, raising with its stderr if it fails."""
    if shutil.which(cmd[0]) is None:
        raise RuntimeError(f"{cmd[0]} not found: install GDAL's command line tools (gdal-bin)")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr.strip()}")


def build_mosaic(source: Path, out_dir: Path, tile: int) -> dict[str, Any]:
    """Cut ``source`` into GeoTIFF tiles of ``tile`` x ``tile`` samples and build a VRT.

    ``source`` is a georeferenced single-band raster GDAL reads (GeoTIFF, ...) or an SRTM
    cache PNG (see :func:`srtm_png_to_geotiff`). Tiles are written with
    ``gdal_translate -srcwin`` (edge tiles are smaller) and ``gdalbuildvrt`` mosaics them.

    Returns a dict: ``vrt`` (path), ``tiles`` (paths), ``width``, ``height``, ``dtype``,
    ``nodata``, ``crs`` (WKT) and ``transform`` (6 numbers, GDAL order).
    """
    import rasterio

    out_dir.mkdir(parents=True, exist_ok=True)
    tiles_dir = out_dir / "tiles"
    if tiles_dir.exists():
        shutil.rmtree(tiles_dir)
    tiles_dir.mkdir()
    if source.suffix.lower() == ".png":
        base = srtm_png_to_geotiff(source, out_dir / (source.stem + ".tif"))
    else:
        base = source
    with rasterio.open(base) as src:
        if src.count != 1:
            raise ValueError(f"{base}: {src.count} bands, expected 1")
        if src.crs is None:
            raise ValueError(f"{base}: not georeferenced")
        width, height = src.width, src.height
    tiles = []
    for row, y in enumerate(range(0, height, tile)):
        for col, x in enumerate(range(0, width, tile)):
            path = tiles_dir / f"tile_r{row:02d}_c{col:02d}.tif"
            _run(["gdal_translate", "-q", "-of", "GTiff",
                  "-srcwin", str(x), str(y), str(min(tile, width - x)), str(min(tile, height - y)),
                  str(base), str(path)])
            tiles.append(path)
    vrt = out_dir / "mosaic.vrt"
    _run(["gdalbuildvrt", "-q", str(vrt), *map(str, tiles)])
    with rasterio.open(vrt) as v:
        if (v.width, v.height) != (width, height):
            raise RuntimeError(f"VRT is {v.width}x{v.height}, source {width}x{height}")
        nodata = v.nodata
        if nodata is not None and np.dtype(v.dtypes[0]).kind in "iu":
            nodata = int(nodata)
        info = dict(vrt=str(vrt), tiles=[str(t) for t in tiles], width=width, height=height,
                    dtype=v.dtypes[0], nodata=nodata, crs=v.crs.to_wkt(),
                    transform=list(v.transform.to_gdal()))
    return info


def open_mosaic(vrt: str | Path, chunk: int):
    """Open the VRT with rioxarray as a lazy ``xarray.Dataset`` holding ``elevation``.

    One Dask chunk is ``chunk`` x ``chunk`` samples, the Zarr chunk shape, so each write
    task encodes exactly one Zarr chunk. The band axis is dropped (vtz chunks are 2-D),
    and so are the x/y coordinate arrays: the CRS and geotransform travel in the
    ``spatial_ref`` variable (CF grid mapping with a ``GeoTransform`` attribute), which
    rioxarray reads back, so the store holds the elevation samples and little else.
    ``lock=False`` lets every worker process read the VRT on its own.
    """
    import rioxarray

    da = rioxarray.open_rasterio(vrt, chunks={"band": 1, "y": chunk, "x": chunk}, lock=False)
    da = da.squeeze("band", drop=True)
    crs, transform = da.rio.crs, da.rio.transform()
    ds = da.to_dataset(name=VAR).drop_vars(["x", "y", "spatial_ref"])
    ds = ds.rio.write_crs(crs).rio.write_transform(transform)
    # rioxarray keeps the link to spatial_ref in .encoding, which to_zarr does not write;
    # as a CF attribute it lands in the store and open_zarr(decode_coords="all") finds it.
    ds[VAR].encoding.pop("grid_mapping", None)
    ds[VAR].attrs["grid_mapping"] = "spatial_ref"
    return ds


# ---------------------------------------------------------------------------------------
# 4. Codecs: the numcodecs-style LERC and SZ3 codecs as Zarr v3 array-to-bytes codecs
# ---------------------------------------------------------------------------------------

class PyszSz3(NumcodecsCodec):
    """SZ3 (through ``pysz``) as a numcodecs codec with an absolute error bound.

    Floats are coded with the bound ``max_error``. Integer arrays are coded as float32 with
    the bound ``floor(max_error) + 0.499`` and the decoded values are rounded back to the
    integer dtype, so every sample stays within ``max_error`` (see the module docstring).
    The stream is an 11-byte header (dtype code, height, width) followed by SZ3's bytes,
    so it decodes without knowing the chunk.
    """

    codec_id = "dask_mosaic.sz3"
    _DTYPES = ("int16", "uint16", "int32", "uint8", "float32", "float64")
    _HEADER = "<BxxII"  # dtype code, 2 pad bytes, height, width

    def __init__(self, max_error: float):
        self.max_error = float(max_error)

    def _bound(self, dtype: np.dtype) -> float:
        if dtype.kind in "iu":
            return math.floor(self.max_error) + 0.499
        return self.max_error

    def encode(self, buf):
        from pysz import sz, szConfig, szErrorBoundMode

        a = np.asarray(buf)
        if a.ndim != 2 or a.dtype.name not in self._DTYPES:
            raise ValueError(f"SZ3 adapter takes 2-D {self._DTYPES} arrays, not {a.dtype} {a.shape}")
        work = a if a.dtype.kind == "f" else a.astype(np.float32)
        cfg = szConfig(work.shape)
        cfg.errorBoundMode = szErrorBoundMode.ABS
        cfg.absErrorBound = self._bound(a.dtype)
        comp, _ratio = sz.compress(np.ascontiguousarray(work), cfg)
        head = struct.pack(self._HEADER, self._DTYPES.index(a.dtype.name), *a.shape)
        return head + np.asarray(comp, dtype=np.uint8).tobytes()

    def decode(self, buf, out=None):
        from pysz import sz

        raw = memoryview(buf).cast("B")
        code, h, w = struct.unpack_from(self._HEADER, raw)
        dtype = np.dtype(self._DTYPES[code])
        work = dtype if dtype.kind == "f" else np.dtype(np.float32)
        body = np.frombuffer(raw, dtype=np.uint8, offset=struct.calcsize(self._HEADER))
        dec, _cfg = sz.decompress(body, work, (h, w))
        if dtype.kind in "iu":
            info = np.iinfo(dtype)
            dec = np.clip(np.rint(dec), info.min, info.max)
        dec = np.asarray(dec).astype(dtype, copy=False).reshape(h, w)
        if out is not None:
            np.copyto(np.asarray(out).reshape(h, w), dec)
            return out
        return dec

    def get_config(self):
        return {"id": self.codec_id, "max_error": self.max_error}


def _inner_codec(config: dict[str, Any]) -> NumcodecsCodec:
    """The numcodecs codec for a :class:`NumcodecsSerializer` configuration."""
    cfg = dict(config)
    kind = cfg.pop("id")
    if kind == "imagecodecs_lerc":
        from imagecodecs.numcodecs import Lerc

        return Lerc(**cfg)
    if kind == PyszSz3.codec_id:
        return PyszSz3(**cfg)
    raise ValueError(f"no adapter for numcodecs codec {kind!r}")


@dataclass(frozen=True)
class NumcodecsSerializer(ArrayBytesCodec):
    """Adapter: a numcodecs codec that takes a chunk *array* used as a Zarr v3 serializer.

    LERC (imagecodecs) and SZ3 compress the chunk as a 2-D array, so they belong in the
    array-to-bytes slot. The Zarr metadata is ``{"name": "dask_mosaic.numcodecs",
    "configuration": <the numcodecs config>}``; this module registers the name, so the
    store opens wherever this module is imported (the workers get it via
    ``Client.upload_file``).
    """

    config: dict
    is_fixed_size = False
    name = "dask_mosaic.numcodecs"

    def __post_init__(self) -> None:
        object.__setattr__(self, "_codec", _inner_codec(self.config))

    def __hash__(self) -> int:
        return hash(json.dumps(self.config, sort_keys=True))

    @classmethod
    def from_dict(cls, data: dict) -> "NumcodecsSerializer":
        _, config = parse_named_configuration(data, cls.name)
        return cls(config=dict(config))

    def to_dict(self) -> dict:
        return {"name": self.name, "configuration": dict(self.config)}

    def compute_encoded_size(self, input_byte_length: int, chunk_spec) -> int:
        raise NotImplementedError("variable-size codec")

    async def _encode_single(self, chunk_array, chunk_spec):
        a = np.ascontiguousarray(chunk_array.as_numpy_array())
        data = self._codec.encode(a)
        return chunk_spec.prototype.buffer.from_bytes(bytes(data))

    async def _decode_single(self, chunk_bytes, chunk_spec):
        dtype = chunk_spec.dtype.to_native_dtype()
        a = np.asarray(self._codec.decode(chunk_bytes.to_bytes()))
        a = a.astype(dtype, copy=False).reshape(chunk_spec.shape)
        return chunk_spec.prototype.nd_buffer.from_numpy_array(a)


def _register_once() -> None:
    """Register :class:`NumcodecsSerializer` with zarr unless a copy of it already is.

    This file is imported twice in the process that runs it as a script (as ``__main__``
    and, by ``Client.upload_file`` for the in-process scheduler, as ``dask_mosaic``); two
    classes under one codec name would make zarr warn on every open.
    """
    from zarr.registry import get_codec_class

    try:
        get_codec_class(NumcodecsSerializer.name)
    except KeyError:
        register_codec(NumcodecsSerializer.name, NumcodecsSerializer)


_register_once()


def make_serializer(codec: str, max_error: float, nodata: float | None) -> ArrayBytesCodec:
    """The Zarr v3 array-to-bytes codec for ``codec`` at absolute bound ``max_error``."""
    if codec == "vtz":
        import vtz.zarr

        return vtz.zarr.VtzCodec(max_error=max_error, nodata=nodata, threads=1)
    if codec == "vtz-residual":
        # The residual layer alone: what `best` picks on these chunks, without its trials.
        import vtz.zarr

        return vtz.zarr.VtzCodec(max_error=max_error, nodata=nodata, method="residual", threads=1)
    if codec in ("vtz-e1", "vtz-residual-e1"):
        # Effort 1: the residual layer's fast coding (with `best`, also its method choice).
        import vtz.zarr

        method = "residual" if codec == "vtz-residual-e1" else None
        return vtz.zarr.VtzCodec(max_error=max_error, nodata=nodata, method=method, threads=1,
                                 effort=1)
    if codec == "lerc":
        return NumcodecsSerializer({"id": "imagecodecs_lerc", "level": max_error})
    if codec == "lerc-zstd":
        return NumcodecsSerializer({"id": "imagecodecs_lerc", "level": max_error,
                                    "compression": "zstd"})
    if codec == "sz3":
        return NumcodecsSerializer({"id": PyszSz3.codec_id, "max_error": max_error})
    raise ValueError(f"unknown codec {codec!r} (known: {', '.join(CODECS)})")


# ---------------------------------------------------------------------------------------
# 3. The cluster
# ---------------------------------------------------------------------------------------

def _warm_worker() -> str:
    """Import what the tasks use, so no timed task pays for the imports (the peers'
    libraries when installed: the vtz-only test needs neither)."""
    import importlib

    for peer in ("imagecodecs", "pysz"):
        with contextlib.suppress(ImportError):
            importlib.import_module(peer)
    import rioxarray  # noqa: F401
    import vtz.zarr  # noqa: F401
    import zarr  # noqa: F401

    return str(os.getpid())


@contextlib.contextmanager
def local_cluster(workers: int) -> Iterator[Any]:
    """A ``LocalCluster`` of ``workers`` single-threaded worker processes and its client.

    The scheduler and its dashboard on random local ports (nothing to clash with). The
    workers import this file (``upload_file``) so the codec adapters resolve there, and
    the libraries are imported before anything is timed.
    """
    import logging

    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=":0", silence_logs=logging.ERROR,
                           host="127.0.0.1")
    client = Client(cluster)
    try:
        client.wait_for_workers(workers)
        client.upload_file(str(Path(__file__).resolve()))
        client.run(_warm_worker)
        yield client
    finally:
        client.close()
        cluster.close()


# ---------------------------------------------------------------------------------------
# 4.-6. Write, read, check
# ---------------------------------------------------------------------------------------

def _dir_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def store_bytes(store: Path) -> tuple[int, int]:
    """(all bytes of the store directory, bytes of the elevation array's chunks only)."""
    return _dir_bytes(store), _dir_bytes(store / VAR / "c")


def _worker_cpu_s() -> float:
    """CPU seconds (user + system) this worker process has used so far."""
    t = os.times()
    return t.user + t.system


def write_store(client, ds, store: Path, serializer: ArrayBytesCodec, chunk: int,
                nodata: float | None) -> dict:
    """Write ``ds`` to a new Zarr v3 store at ``store`` through ``client``.

    The elevation array gets ``serializer``, no bytes-to-bytes compressor, and ``nodata``
    as its Zarr fill value (the padding of partial edge chunks). Returns ``write_s`` (wall
    seconds of ``to_zarr``) and, to tell a slow codec from a busy machine:

    - ``task_s``: the summed compute time of the Dask tasks;
    - ``busiest_s``: the most any one worker computed (the wall time the write would take
      with no overhead);
    - ``worker_cpu_s``: the CPU seconds the worker processes got during the write;
    - ``cpu_split``: those CPU seconds over the busiest worker's (the speedup the split of
      the work allows when every worker has a core of its own, whatever else the machine
      runs);
    - ``workers_used``: how many workers computed tasks.
    """
    from dask.distributed import get_task_stream

    if store.exists():
        shutil.rmtree(store)
    enc = {VAR: {"serializer": serializer, "compressors": None, "chunks": (chunk, chunk)}}
    if nodata is not None:
        enc[VAR]["fill_value"] = nodata
    cpu0 = client.run(_worker_cpu_s)
    with client.as_current(), get_task_stream(client) as stream:
        t0 = time.perf_counter()
        ds.to_zarr(store, mode="w", zarr_format=3, consolidated=False, encoding=enc,
                   compute=True)
        wall = time.perf_counter() - t0
    cpu1 = client.run(_worker_cpu_s)
    cpu = [cpu1[w] - cpu0[w] for w in cpu1 if w in cpu0]
    busy: dict[str, float] = {}
    for task in stream.data:
        for ss in task.get("startstops", ()):
            if ss["action"] == "compute":
                busy[task["worker"]] = busy.get(task["worker"], 0.0) + ss["stop"] - ss["start"]
    return dict(write_s=wall, task_s=sum(busy.values()), busiest_s=max(busy.values(), default=0.0),
                worker_cpu_s=sum(cpu), cpu_split=sum(cpu) / max(max(cpu), 1e-9),
                workers_used=len(busy))


def read_store(client, store: Path):
    """Open the store with xarray and decode every chunk in the workers.

    Returns ``(dataset, persisted dask array of elevation, seconds)``; the time covers
    opening the metadata and decoding all chunks into worker memory.
    """
    import xarray as xr
    from dask.distributed import wait

    t0 = time.perf_counter()
    ds = xr.open_zarr(store, consolidated=False, mask_and_scale=False, chunks={},
                     decode_coords="all")
    arr = client.persist(ds[VAR].data)
    wait(arr)
    return ds, arr, time.perf_counter() - t0


def check_bound(client, decoded, source, max_error: float, nodata: float | None) -> dict:
    """Compare every sample of ``decoded`` with ``source`` (both Dask arrays, same chunks).

    Valid samples are those of ``source`` that are neither ``nodata`` nor NaN. Returns
    ``max_error`` (over valid samples; NaN if a valid sample decoded to NaN),
    ``samples``, ``valid``, ``nodata_mismatch`` (nodata samples not decoded as nodata plus
    valid samples decoded as nodata) and ``bound_ok``.
    """
    import dask
    import dask.array as da

    if decoded.shape != source.shape:
        raise ValueError(f"decoded {decoded.shape} != source {source.shape}")
    decoded = decoded.rechunk(source.chunks)

    def is_nodata(x):
        m = da.zeros(x.shape, dtype=bool, chunks=x.chunks)
        if x.dtype.kind == "f":
            m = da.isnan(x)
        if nodata is not None and not (isinstance(nodata, float) and math.isnan(nodata)):
            m = m | (x == nodata)
        return m

    src_nd, dec_nd = is_nodata(source), is_nodata(decoded)
    valid = ~src_nd
    diff = da.abs(decoded.astype(np.float64) - source.astype(np.float64))
    worst = da.where(valid, diff, 0.0).max()
    mismatch = (src_nd != dec_nd).sum()
    with client.as_current():
        worst, mismatch, n_valid = dask.compute(worst, mismatch, valid.sum())
    worst = float(worst)
    ok = bool(worst <= max_error and int(mismatch) == 0)
    return dict(max_error=worst, samples=int(np.prod(source.shape)), valid=int(n_valid),
                nodata_mismatch=int(mismatch), bound_ok=ok)


def georef_ok(ds_read, info: dict) -> bool:
    """Whether the store gives back the mosaic's CRS and geotransform (via rioxarray)."""
    import rioxarray  # noqa: F401
    from rasterio.crs import CRS

    da = ds_read[VAR]
    crs = da.rio.crs
    t = da.rio.transform()
    return (crs is not None and crs == CRS.from_wkt(info["crs"])
            and np.allclose(t.to_gdal(), info["transform"], rtol=0, atol=1e-9))


def run_one(client, info: dict, codec: str, max_error: float, chunk: int,
            store: Path) -> dict:
    """Write, read back and check one store; return a result record."""
    ds = open_mosaic(info["vrt"], chunk)
    serializer = make_serializer(codec, max_error, info["nodata"])
    load = os.getloadavg()[0]
    wr = write_store(client, ds, store, serializer, chunk, info["nodata"])
    total, array = store_bytes(store)
    ds_read, decoded, read_s = read_store(client, store)
    check = check_bound(client, decoded, ds[VAR].data, max_error, info["nodata"])
    geo = georef_ok(ds_read, info)
    client.cancel(decoded)
    n = info["width"] * info["height"]
    return dict(codec=codec, bound=max_error, **wr, read_s=read_s, load_1min=load,
                store_bytes=total, array_bytes=array, bits_per_sample=8 * array / n,
                georef_ok=geo, **check)


# ---------------------------------------------------------------------------------------
# Benchmark loop and report
# ---------------------------------------------------------------------------------------

def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    try:   # which build of vtz: the native module's hash (the version stays 0.1.0 meanwhile)
        import hashlib

        import vtz._vtz as native

        out["vtz_native_sha256"] = hashlib.sha256(Path(native.__file__).read_bytes()).hexdigest()[:16]
    except (ImportError, OSError):
        pass
    for p in ("vtz", "dask", "distributed", "xarray", "rioxarray", "rasterio", "zarr",
              "numcodecs", "imagecodecs", "pysz", "numpy"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            out[p] = "?"
    return out


def benchmark(info: dict, codecs: list[str], workers: list[int], bounds: list[float],
              repeat: int, chunk: int, out_dir: Path, log=print) -> list[dict]:
    """Run every (codec, bound, workers) ``repeat`` times; return all run records.

    All clusters stay up for the whole run; in each repeat the codecs are rotated and
    the worker counts alternate in order, so runs of one configuration on 1 and on 2
    workers sit next to each other in time (the machine is shared and noisy).
    """
    stores = out_dir / "stores"
    stores.mkdir(parents=True, exist_ok=True)
    runs = []
    with contextlib.ExitStack() as stack:
        clients = {w: stack.enter_context(local_cluster(w)) for w in workers}
        for rep in range(repeat):
            k = rep % len(codecs)
            order = codecs[k:] + codecs[:k]
            for codec in order:
                for bound in bounds:
                    ws = workers if (rep + codecs.index(codec)) % 2 == 0 else workers[::-1]
                    for w in ws:
                        store = stores / f"{codec}_e{bound:g}_w{w}.zarr"
                        rec = run_one(clients[w], info, codec, bound, chunk, store)
                        rec.update(workers=w, repeat=rep)
                        runs.append(rec)
                        log(f"rep {rep} {codec:9s} E={bound:<5g} W={w}: "
                            f"write {rec['write_s']:.2f}s read {rec['read_s']:.2f}s "
                            f"{rec['array_bytes']} B ({rec['bits_per_sample']:.3f} b/s) "
                            f"max err {rec['max_error']:g} ok={rec['bound_ok']}")
    return runs


def summarize(runs: list[dict]) -> dict[str, list[dict]]:
    """Medians per (codec, bound, workers), speedups 1 -> max workers, size ratios."""
    keys = sorted({(r["codec"], r["bound"], r["workers"]) for r in runs},
                  key=lambda k: (-k[1], CODECS.index(k[0]) if k[0] in CODECS else 99, k[2]))
    rows = []
    for codec, bound, w in keys:
        rs = [r for r in runs if (r["codec"], r["bound"], r["workers"]) == (codec, bound, w)]
        sizes = {r["array_bytes"] for r in rs}
        rows.append(dict(
            codec=codec, bound=bound, workers=w, repeats=len(rs),
            store_bytes=max(r["store_bytes"] for r in rs),
            array_bytes=max(sizes), sizes_equal=len(sizes) == 1,
            bits_per_sample=max(r["bits_per_sample"] for r in rs),
            write_s=statistics.median(r["write_s"] for r in rs),
            write_s_min=min(r["write_s"] for r in rs), write_s_max=max(r["write_s"] for r in rs),
            read_s=statistics.median(r["read_s"] for r in rs),
            read_s_min=min(r["read_s"] for r in rs), read_s_max=max(r["read_s"] for r in rs),
            task_s=statistics.median(r["task_s"] for r in rs),
            busiest_s=statistics.median(r["busiest_s"] for r in rs),
            worker_cpu_s=statistics.median(r["worker_cpu_s"] for r in rs),
            cpu_split=statistics.median(r["cpu_split"] for r in rs),
            cores_used=statistics.median(r["worker_cpu_s"] / r["write_s"] for r in rs),
            load_1min=statistics.median(r["load_1min"] for r in rs),
            max_error=max(r["max_error"] for r in rs),
            nodata_mismatch=max(r["nodata_mismatch"] for r in rs),
            bound_ok=all(r["bound_ok"] for r in rs),
            georef_ok=all(r["georef_ok"] for r in rs)))
    speedups = []
    wlist = sorted({r["workers"] for r in runs})
    if len(wlist) >= 2:
        lo, hi = wlist[0], wlist[-1]
        for codec, bound in sorted({(r["codec"], r["bound"]) for r in runs},
                                   key=lambda k: (-k[1], CODECS.index(k[0]) if k[0] in CODECS else 99)):
            pick = {w: {r["repeat"]: r for r in runs
                        if (r["codec"], r["bound"], r["workers"]) == (codec, bound, w)}
                    for w in (lo, hi)}
            reps = sorted(set(pick[lo]) & set(pick[hi]))
            if not reps:
                continue
            paired = [pick[lo][k]["write_s"] / pick[hi][k]["write_s"] for k in reps]
            paired_r = [pick[lo][k]["read_s"] / pick[hi][k]["read_s"] for k in reps]
            balance = [pick[hi][k]["task_s"] / pick[hi][k]["busiest_s"] for k in reps
                       if pick[hi][k]["busiest_s"] > 0]
            speedups.append(dict(
                codec=codec, bound=bound, workers=f"{lo}->{hi}",
                write_speedup=statistics.median(paired), write_speedup_min=min(paired),
                write_speedup_max=max(paired), read_speedup=statistics.median(paired_r),
                balance_limit=statistics.median(balance) if balance else float("nan"),
                write_s_lo=statistics.median(pick[lo][k]["write_s"] for k in reps),
                write_s_hi=statistics.median(pick[hi][k]["write_s"] for k in reps)))
    ratios = []
    for bound in sorted({r["bound"] for r in runs}, reverse=True):
        size = {r["codec"]: r["array_bytes"] for r in runs if r["bound"] == bound}
        if "vtz" not in size:
            continue
        for other in [c for c in CODECS if c != "vtz" and c in size]:
            ratios.append(dict(bound=bound, vs=other, vtz_bytes=size["vtz"],
                               other_bytes=size[other], ratio=size["vtz"] / size[other]))
    return dict(rows=rows, speedups=speedups, ratios=ratios)


def markdown(summary: dict, meta: dict) -> str:
    """The Markdown report of :func:`summarize`'s result."""
    m = meta
    out = [f"# Dask mosaic: {m['mosaic']}", "",
           f"{m['width']}x{m['height']} {m['dtype']} samples in {m['tiles']} GeoTIFF tiles "
           f"of {m['tile']}x{m['tile']} behind a VRT; Zarr v3 chunks {m['chunk']}x{m['chunk']} "
           f"({m['chunks']} chunks); LocalCluster, threads_per_worker=1, worker processes as "
           f"in the table; medians of {m['repeat']} repeats (min..max in brackets); "
           f"{m['cpus']} CPUs. Bytes are the array's chunk files; the whole store adds "
           f"metadata (column `store bytes`).", "",
           "| codec | bound | workers | array bytes | store bytes | bits/sample | write s | "
           "read s | max error | bound ok |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in summary["rows"]:
        ok = "yes" if r["bound_ok"] else "**NO**"
        if not r["georef_ok"]:
            ok += " (georef lost)"
        out.append(
            f"| {r['codec']} | {r['bound']:g} | {r['workers']} | {r['array_bytes']:,} | "
            f"{r['store_bytes']:,} | {r['bits_per_sample']:.3f} | "
            f"{r['write_s']:.2f} [{r['write_s_min']:.2f}..{r['write_s_max']:.2f}] | "
            f"{r['read_s']:.2f} [{r['read_s_min']:.2f}..{r['read_s_max']:.2f}] | "
            f"{r['max_error']:g} | {ok} |")
    if summary["speedups"]:
        out += ["", "Write speedup (median of the per-repeat ratios of paired runs, "
                "min..max; target for vtz: >= 1.7):", "",
                "| codec | bound | workers | write s (lo) | write s (hi) | write speedup | "
                "read speedup | balance limit |", "|---|---:|---|---:|---:|---:|---:|---:|"]
        for s in summary["speedups"]:
            out.append(f"| {s['codec']} | {s['bound']:g} | {s['workers']} | "
                       f"{s['write_s_lo']:.2f} | {s['write_s_hi']:.2f} | "
                       f"{s['write_speedup']:.2f}x [{s['write_speedup_min']:.2f}.."
                       f"{s['write_speedup_max']:.2f}] | {s['read_speedup']:.2f}x | "
                       f"{s['balance_limit']:.2f}x |")
        out += ["", "Balance limit: the summed task compute time over the busiest worker's, "
                "on the most workers (the speedup the chunk split allows with no overhead)."]
    out += ["", "Where the write time went (medians): Dask task compute seconds summed over "
            "workers, the busiest worker's, CPU seconds the worker processes got, and the "
            "machine's 1-minute load average when the write started.", "",
            "| codec | bound | workers | write s | task s | busiest worker s | worker CPU s | "
            "CPU split | cores used | load |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in summary["rows"]:
        out.append(f"| {r['codec']} | {r['bound']:g} | {r['workers']} | {r['write_s']:.2f} | "
                   f"{r['task_s']:.2f} | {r['busiest_s']:.2f} | {r['worker_cpu_s']:.2f} | "
                   f"{r['cpu_split']:.2f} | {r['cores_used']:.2f} | {r['load_1min']:.1f} |")
    out += ["", "CPU split: the workers' CPU seconds over the busiest worker's (the speedup "
            "the division of the work allows when each worker has a core to itself). "
            "Cores used: the workers' CPU seconds over the write's wall seconds (what the "
            "workers got of the machine)."]
    if summary["ratios"]:
        out += ["", "Store size, vtz against the others at the same bound (array bytes; "
                "< 1 means vtz is smaller):", "",
                "| bound | vs | vtz bytes | other bytes | vtz / other |",
                "|---:|---|---:|---:|---:|"]
        for q in summary["ratios"]:
            out.append(f"| {q['bound']:g} | {q['vs']} | {q['vtz_bytes']:,} | "
                       f"{q['other_bytes']:,} | {q['ratio']:.3f} |")
    lerc = {(r["bound"], r["workers"]): r for r in summary["rows"] if r["codec"] == "lerc"}
    if lerc and len(summary["rows"]) > len(lerc):
        out += ["", "Each codec over LERC at the same bound and workers (medians; the "
                "Pipelines target of issue 26: write <= 3x, read <= 2x, bytes <= 0.25x):", "",
                "| codec | bound | workers | write s | read s | array bytes | write / LERC | "
                "read / LERC | bytes / LERC |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in summary["rows"]:
            ref = lerc.get((r["bound"], r["workers"]))
            if ref is None or r["codec"] == "lerc":
                continue
            out.append(f"| {r['codec']} | {r['bound']:g} | {r['workers']} | {r['write_s']:.2f} | "
                       f"{r['read_s']:.2f} | {r['array_bytes']:,} | "
                       f"{r['write_s'] / ref['write_s']:.1f}x | {r['read_s'] / ref['read_s']:.1f}x | "
                       f"{r['array_bytes'] / ref['array_bytes']:.3f} |")
    return "\n".join(out) + "\n"


def _floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x.strip()]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", type=Path, default=DEFAULT_SOURCE,
                   help="DEM to cut into the mosaic (SRTM cache PNG or georeferenced GeoTIFF)")
    p.add_argument("--codecs", default="vtz,lerc,sz3",
                   help=f"comma list of {', '.join(CODECS)} (default vtz,lerc,sz3)")
    p.add_argument("--workers", default="1,2", help="comma list of worker process counts")
    p.add_argument("--max-error", default="1", help="comma list of absolute bounds (data units)")
    p.add_argument("--repeat", type=int, default=3, help="repeats; medians are reported")
    p.add_argument("--tile", type=int, default=900, help="mosaic tile size (samples)")
    p.add_argument("--chunk", type=int, default=900, help="Zarr/Dask chunk size (samples)")
    p.add_argument("--out-dir", type=Path, default=Path("dask_mosaic_out"),
                   help="where the tiles, VRT and stores go")
    p.add_argument("--keep-stores", action="store_true", help="keep the Zarr stores")
    p.add_argument("--json", type=Path, help="write all runs and the summary as JSON")
    p.add_argument("--md", type=Path, help="write the Markdown report")
    p.add_argument("--from-json", type=Path,
                   help="only render the report of an earlier --json file (no benchmark)")
    a = p.parse_args(argv)

    if a.from_json:
        saved = json.loads(a.from_json.read_text())
        md = markdown(summarize(saved["runs"]), saved["meta"])
        print(md)
        if a.md:
            a.md.write_text(md)
        return 0

    codecs = [c.strip() for c in a.codecs.split(",") if c.strip()]
    for c in codecs:
        if c not in CODECS:
            p.error(f"unknown codec {c!r}")
    workers = [int(w) for w in a.workers.split(",")]
    bounds = _floats(a.max_error)

    info = build_mosaic(a.source, a.out_dir, a.tile)
    print(f"mosaic: {len(info['tiles'])} tiles, {info['width']}x{info['height']} "
          f"{info['dtype']}, nodata {info['nodata']}: {info['vrt']}")
    runs = benchmark(info, codecs, workers, bounds, a.repeat, a.chunk, a.out_dir)
    summary = summarize(runs)
    nchunks = math.ceil(info["width"] / a.chunk) * math.ceil(info["height"] / a.chunk)
    meta = dict(mosaic=a.source.name, width=info["width"], height=info["height"],
                dtype=info["dtype"], nodata=info["nodata"], tiles=len(info["tiles"]),
                tile=a.tile, chunk=a.chunk, chunks=nchunks, repeat=a.repeat,
                cpus=os.cpu_count(), machine=platform.machine(), versions=_versions(),
                command=" ".join([Path(sys.argv[0]).name] + (argv if argv is not None
                                                             else sys.argv[1:])))
    md = markdown(summary, meta)
    print(md)
    if a.json:
        a.json.write_text(json.dumps(dict(meta=meta, runs=runs, **summary), indent=1) + "\n")
    if a.md:
        a.md.write_text(md)
    if not a.keep_stores:
        shutil.rmtree(a.out_dir / "stores", ignore_errors=True)
    return 0 if all(r["bound_ok"] for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
