"""An xarray backend for ``.vtz`` rasters: ``xarray.open_dataset(path, engine="vtz")``.

The Dataset has one variable, ``elevation``, of dims ``("y", "x")``, read lazily through
:func:`vtz.open`; ``x``/``y`` are the pixel centres' coordinates from the geotransform, and
the CRS is a ``spatial_ref`` coordinate as rioxarray and GDAL read it (``crs_wkt``,
``spatial_ref`` and ``GeoTransform`` attributes; the variable's ``grid_mapping`` names it).
The tiles are the variable's ``preferred_chunks``: with ``chunks={}`` Dask makes one chunk
per tile, and each chunk's task reads only the tiles its window touches (its own, and the
neighbours whose margins it blends).

>>> ds = xr.open_dataset("dem.vtz", engine="vtz", chunks={})          # doctest: +SKIP
>>> ds = xr.open_dataset("s3://bucket/dem.vtz", engine="vtz", chunks={},
...                      storage_options={"anon": True})             # doctest: +SKIP
>>> ds = xr.open_dataset("dem.vtz", engine="vtz", overview=3)        # doctest: +SKIP
"""

from __future__ import annotations

import os
from typing import Any, Iterable, Optional, Tuple

import numpy as np
import xarray as xr
from xarray.backends import BackendArray, BackendEntrypoint
from xarray.core import indexing

from ._raster import Raster, _is_url
from ._raster import open as _open

#: The name of the Dataset's one variable.
VARIABLE = "elevation"


class VtzBackendArray(BackendArray):
    """Overview K of a :class:`vtz.Raster` as xarray's lazily indexed array: an index of
    integers and slices becomes one window read (steps are taken from the window)."""

    def __init__(self, raster: Raster, overview: Optional[int]) -> None:
        self.raster = raster
        self.overview = overview or None
        self.shape = raster.overview_shape(overview)
        self.dtype = raster.dtype

    def __getitem__(self, key: indexing.ExplicitIndexer) -> np.ndarray:
        return indexing.explicit_indexing_adapter(
            key, self.shape, indexing.IndexingSupport.BASIC, self._read
        )

    def _read(self, key: Tuple[Any, ...]) -> np.ndarray:
        spans = []
        for k, n in zip(key, self.shape):
            if isinstance(k, slice):
                spans.append((range(*k.indices(n)), False))
            else:  # an integer: that one row (column), dropped from the result's shape
                i = int(k) + n if int(k) < 0 else int(k)
                spans.append((range(i, i + 1), True))
        (rows, drop_r), (cols, drop_c) = spans
        if len(rows) == 0 or len(cols) == 0:
            out = np.empty((len(rows), len(cols)), dtype=self.dtype)
        else:
            r0, r1 = min(rows), max(rows) + 1
            c0, c1 = min(cols), max(cols) + 1
            a = self.raster.read(((r0, r1), (c0, c1)), overview=self.overview)
            out = a
            if rows.step != 1 or cols.step != 1:
                out = a[np.asarray(rows) - r0][:, np.asarray(cols) - c0]
        if drop_c:
            out = out[:, 0]
        if drop_r:
            out = out[0]
        return out


def _centres(start: float, step: float, n: int) -> np.ndarray:
    return start + step * (np.arange(n, dtype=np.float64) + 0.5)


def open_raster_dataset(
    raster: Raster, overview: Optional[int] = None, mask_and_scale: bool = False
) -> xr.Dataset:
    """The Dataset of an opened :class:`vtz.Raster` (overview K when given); closing the
    Dataset closes the raster."""
    k = overview or None
    rows, cols = raster.overview_shape(k)
    t = raster._corner_transform(k)
    a, _, c, _, e, f = t if t is not None else (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    coords: dict = {
        "y": ("y", _centres(f, e, rows)),
        "x": ("x", _centres(c, a, cols)),
    }
    attrs: dict = {}
    if raster.nodata is not None:
        attrs["_FillValue"] = raster.dtype.type(raster.nodata)
    if raster.scale is not None:
        attrs["scale_factor"] = raster.scale
        attrs["add_offset"] = raster.offset
    if t is not None:
        a_, b_, c_, d_, e_, f_ = t
        gt = " ".join(repr(float(v)) for v in (c_, a_, b_, f_, d_, e_))
        sr = {"GeoTransform": gt}
        crs = raster.crs_wkt
        if crs:
            if crs.lstrip().upper().startswith(("EPSG:", "+PROJ", "+INIT")):
                sr["spatial_ref"] = crs
            else:
                sr["crs_wkt"] = crs
                sr["spatial_ref"] = crs
        coords["spatial_ref"] = xr.Variable((), np.int64(0), attrs=sr)
        attrs["grid_mapping"] = "spatial_ref"
    data = indexing.LazilyIndexedArray(VtzBackendArray(raster, k))
    ry, rx = raster._tile_bounds(k)
    var = xr.Variable(("y", "x"), data, attrs=attrs)
    var.encoding = {
        "dtype": raster.dtype,
        "preferred_chunks": {"y": ry, "x": rx},
        "source": raster.name,
    }
    if mask_and_scale:
        var = xr.conventions.decode_cf_variable(
            VARIABLE, var, mask_and_scale=True, decode_times=False
        )
    ds = xr.Dataset({VARIABLE: var}, coords=coords)
    ds.encoding["source"] = raster.name
    ds.set_close(raster.close)
    return ds


class VtzBackendEntrypoint(BackendEntrypoint):
    """``xarray.open_dataset(path_or_url_or_file, engine="vtz", chunks=..., overview=K,
    storage_options={...}, mask_and_scale=False)``.

    - ``overview=K``: overview K (every 2**K-th sample; its pixels 2**K times larger).
    - ``storage_options``: given to fsspec with a URL (``s3://``, ``https://``, ...).
    - ``cache_bytes``: :func:`vtz.open`'s (the blocks a URL's raster keeps; 64 MiB).
    - ``mask_and_scale=True``: nodata samples become NaN and codes become values (xarray's
      CF decoding of ``_FillValue``, ``scale_factor``, ``add_offset``); the default gives the
      samples as :meth:`vtz.Raster.read` does.
    - ``chunks={}``: one Dask chunk per tile (the file's tiles are the preferred chunks);
      ``chunks="auto"`` merges whole tiles.
    """

    description = "Read .vtz elevation rasters (error-bounded compression) lazily, tile by tile"
    url = "https://github.com/vtz/vtz/blob/main/python/README.md"
    open_dataset_parameters = (
        "filename_or_obj",
        "drop_variables",
        "overview",
        "storage_options",
        "mask_and_scale",
        "cache_bytes",
    )

    def open_dataset(  # type: ignore[override]
        self,
        filename_or_obj: Any,
        *,
        drop_variables: Optional[Iterable[str]] = None,
        overview: Optional[int] = None,
        storage_options: Optional[dict] = None,
        mask_and_scale: bool = False,
        cache_bytes: Optional[int] = None,
    ) -> xr.Dataset:
        kw = {} if cache_bytes is None else {"cache_bytes": cache_bytes}
        raster = _open(filename_or_obj, **kw, **(storage_options or {}))
        try:
            ds = open_raster_dataset(raster, overview, mask_and_scale=bool(mask_and_scale))
        except BaseException:
            raster.close()
            raise
        if drop_variables:
            ds = ds.drop_vars(list(drop_variables), errors="ignore")
        return ds

    def guess_can_open(self, filename_or_obj: Any) -> bool:
        if isinstance(filename_or_obj, (str, os.PathLike)):
            s = os.fspath(filename_or_obj)
            if isinstance(s, bytes):
                s = os.fsdecode(s)
            if _is_url(s):
                s = s.split("?", 1)[0]
            return s.lower().endswith(".vtz")
        return False
