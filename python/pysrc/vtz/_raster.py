"""``vtz.open``: a ``.vtz`` file read lazily, window by window, from a path, bytes, a URL
(through fsspec) or a binary file-like.

Opening reads the first 64 KB (the header and, in a tiled file, the tile index); each
:meth:`Raster.read` then reads only the blocks of the tiles its window touches, all of them
in one request batch (one ``fs.cat_ranges`` call for an fsspec filesystem).
"""

from __future__ import annotations

import math
import os
from typing import Any, List, Optional, Tuple, Union

import numpy as np

from . import _vtz
from ._errors import InvalidArgumentError, VtzIOError

#: Bytes of recently read tile blocks a URL's or file-like's :class:`Raster` keeps (see
#: :func:`open`'s ``cache_bytes``).
DEFAULT_CACHE_BYTES = 64 << 20

#: Overviews listed by :attr:`Raster.overviews`: levels 1, 2, ... while the longer side
#: keeps at least this many samples (as GDAL's VTZ driver lists them).
MIN_OVERVIEW_SIDE = 64

_FSSPEC_HINT = (
    "pip install fsspec, plus the filesystem's package: s3fs for s3://, gcsfs for gs://, "
    "adlfs for az://, aiohttp for http(s)://"
)


def _is_url(s: str) -> bool:
    head, sep, _ = s.partition("://")
    # A Windows drive (C:\\...) has no "://"; a URL's scheme is letters, digits, + - .
    return bool(sep) and len(head) > 1 and all(c.isalnum() or c in "+-." for c in head)


def _fsspec_url(url: str, storage_options: dict) -> Tuple[Any, str]:
    try:
        import fsspec
    except ImportError as e:
        raise ImportError(f"reading {url!r} needs fsspec ({_FSSPEC_HINT})") from e
    fs, path = fsspec.core.url_to_fs(url, **storage_options)
    return fs, path


def _size(fs: Any, path: str, name: str) -> int:
    try:
        size = fs.size(path)
    except OSError as e:  # as a local file's: vtz's I/O error naming it, fsspec's as the cause
        raise VtzIOError(f"I/O error: opening {name}: {type(e).__name__}: {e}") from e
    if size is None:
        raise InvalidArgumentError(
            f"{name}: the server does not say the object's size (no Content-Length); "
            "vtz reads byte ranges of an object of known size"
        )
    return int(size)


def _open_native(spec: tuple, cache_bytes: int) -> Tuple[Any, str]:
    """The native reader of a source spec (see :func:`open`) and its name for messages."""
    kind = spec[0]
    if kind == "bytes":
        return _vtz.Reader.from_bytes(spec[1]), "bytes in memory"
    if kind == "path":
        return _vtz.Reader.from_path(spec[1]), spec[1]
    if kind == "url":
        url, storage_options = spec[1], spec[2]
        fs, path = _fsspec_url(url, storage_options)
        return _vtz.Reader.from_fsspec(fs, path, _size(fs, path, url), url, cache_bytes), url
    if kind == "fsspec":
        fs, path = spec[1], spec[2]
        name = fs.unstrip_protocol(path) if hasattr(fs, "unstrip_protocol") else str(path)
        return _vtz.Reader.from_fsspec(fs, path, _size(fs, path, name), name, cache_bytes), name
    if kind == "file":
        f = spec[1]
        name = str(getattr(f, "name", None) or f"a {type(f).__name__}")
        pos = f.tell() if hasattr(f, "tell") else None
        size = f.seek(0, 2)
        if size is None:  # a seek() that returns nothing
            size = f.tell()
        if pos is not None:
            f.seek(pos)
        return _vtz.Reader.from_file(f, int(size), name, cache_bytes), name
    raise AssertionError(kind)  # pragma: no cover


def _spec(source: Any, storage_options: dict) -> tuple:
    """What :func:`open` was given, as a picklable spec (a Dask worker reopens from it)."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        if storage_options:
            raise InvalidArgumentError("storage_options apply to URLs, not to bytes")
        return ("bytes", bytes(source))
    if isinstance(source, (str, os.PathLike)):
        s = os.fspath(source)
        if isinstance(s, bytes):
            s = os.fsdecode(s)
        if _is_url(s):
            return ("url", s, dict(storage_options))
        if storage_options:
            raise InvalidArgumentError(
                f"storage_options apply to URLs (s3://, https://, ...), not to the local path {s!r}"
            )
        return ("path", s)
    if storage_options:
        raise InvalidArgumentError(
            "storage_options apply to URLs; pass them to the filesystem that opened the file"
        )
    fs, path = getattr(source, "fs", None), getattr(source, "path", None)
    if fs is not None and isinstance(path, str) and hasattr(fs, "cat_ranges"):
        # An fsspec file (AbstractBufferedFile) or OpenFile: its filesystem reads the ranges.
        return ("fsspec", fs, path)
    if callable(getattr(source, "read", None)) and callable(getattr(source, "seek", None)):
        if getattr(source, "mode", "rb") not in ("rb", "br", "r+b", "rb+"):
            raise InvalidArgumentError(
                f"the file is open in mode {source.mode!r}; vtz reads binary files (mode 'rb')"
            )
        return ("file", source)
    raise TypeError(
        "vtz.open takes a path, a URL, bytes or a binary file-like (read + seek), "
        f"not {type(source).__name__}"
    )


def open(  # noqa: A001 - vtz.open
    source: Any, *, cache_bytes: int = DEFAULT_CACHE_BYTES, **storage_options: Any
) -> "Raster":
    """Open a ``.vtz`` file for lazy reads: the header and tile index now (the first 64 KB),
    the samples window by window in :meth:`Raster.read`.

    Parameters
    ----------
    source : str, os.PathLike, bytes or file-like
        A local path (read with positioned reads); a URL (``s3://``, ``gs://``, ``az://``,
        ``https://``, ``file://``, ...) read through fsspec (``pip install fsspec`` and the
        filesystem's package, e.g. ``s3fs``); the bytes of a file; an fsspec file or
        ``OpenFile`` (its filesystem's ``cat_ranges`` reads the ranges); or any binary
        file-like with ``seek`` and ``read`` (one range after another).
    cache_bytes : int
        A URL's or file-like's raster keeps this many bytes of the tile blocks it read last
        (default 64 MiB; 0: none). A window blends its tile with the neighbours' margins, so
        it reads their blocks too: with the cache, the reads of neighbouring windows (Dask's
        tasks, one per tile) fetch each block about once instead of up to nine times. Local
        paths and bytes keep none (the OS's page cache, memory).
    **storage_options
        Given to fsspec with a URL (``anon=True``, ``key=...``, ``client_kwargs=...``).

    Returns
    -------
    Raster
        A context manager; :meth:`Raster.close` lets go of the source.

    Raises
    ------
    CorruptError, UnsupportedError, LimitError
        The bytes are not a vtz raster (a point set, version 3, is not a raster).
    VtzIOError
        Reading failed (its ``__cause__`` is the Python exception a file-like or fsspec
        raised; a missing local file is a ``VtzIOError`` that is also an ``OSError``).
    ImportError
        A URL without fsspec installed.
    """
    if isinstance(cache_bytes, bool) or not isinstance(cache_bytes, (int, np.integer)) or cache_bytes < 0:
        raise InvalidArgumentError(f"cache_bytes must be an int >= 0, not {cache_bytes!r}")
    spec = _spec(source, storage_options)
    return Raster._open(spec, int(cache_bytes))


def _reopen(spec: tuple, cache_bytes: int = DEFAULT_CACHE_BYTES) -> "Raster":
    return Raster._open(spec, cache_bytes)


def _crs(g: Optional[dict]) -> Optional[str]:
    if not g:
        return None
    if g.get("epsg"):
        return f"EPSG:{g['epsg']}"
    return g.get("wkt")


def _affine(t: Tuple[float, ...]) -> Any:
    try:
        from affine import Affine  # rasterio's own transform type
    except ImportError:
        return tuple(t)
    return Affine(*t)


def _as_int(v: Any, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer, float, np.floating)):
        raise InvalidArgumentError(f"{what} must be an integer, not {v!r}")
    if isinstance(v, (float, np.floating)) and not float(v).is_integer():
        raise InvalidArgumentError(f"{what} must be a whole number of samples, not {v!r}")
    return int(v)


class Raster:
    """A ``.vtz`` raster opened by :func:`vtz.open`, read window by window.

    Attributes
    ----------
    shape : (rows, cols)
        The raster's size in samples (``height, width``).
    height, width : int
    dtype : numpy.dtype
        What :meth:`read` gives (the same as :func:`vtz.decode`: the values' dtype, or the
        codes' when :attr:`scale`/:attr:`offset` are not None).
    nodata : float or None
        The nodata value as the arrays hold it (a code when the array holds codes).
    offset, scale : float or None
        When the arrays hold integer codes: values = offset + scale * code.
    transform : affine.Affine or tuple
        The corner-based transform in affine's order ``(a, b, c, d, e, f)`` (x = c + a*col,
        y = f + e*row; a 6-tuple without the ``affine`` package), as :func:`vtz.read`'s
        profile; None without georeferencing.
    geotransform : tuple
        The same as GDAL's geotransform ``(c, a, b, f, d, e)``; None without georeferencing.
    crs : str or None
        ``"EPSG:n"`` when the file has an EPSG code, else its WKT; None without a CRS.
    crs_wkt : str or None
        The CRS as WKT (the file's own, else EPSG's from vtz's table), else ``"EPSG:n"`` or a
        PROJ string when vtz has no WKT for it.
    tile_shape : (rows, cols) or None
        A tiled file's tile size (the last row and column of tiles may be smaller); None for
        an untiled file (read as one block).
    tile_grid : (rows, cols) or None
        Tiles down and across.
    overviews : list of (rows, cols)
        The shapes of overviews 1, 2, ... (level K: every 2**K-th sample of every 2**K-th
        row, ``ceil(rows / 2**K)`` x ``ceil(cols / 2**K)``), while the longer side keeps at
        least 64 samples; :meth:`read` takes any level that keeps one sample.
    name : str
        The path or URL.
    """

    def __init__(self) -> None:  # pragma: no cover - use vtz.open
        raise TypeError("use vtz.open(path, url, bytes or file)")

    @classmethod
    def _open(cls, spec: tuple, cache_bytes: int) -> "Raster":
        self = object.__new__(cls)
        self._spec = spec
        self._cache_bytes = cache_bytes
        self._native, self.name = _open_native(spec, cache_bytes)
        self._info = self._native.info()
        return self

    def __reduce__(self) -> Any:
        if self._spec[0] == "file":
            import pickle

            try:
                pickle.dumps(self._spec[1])
            except Exception as e:
                raise TypeError(
                    f"a vtz.Raster opened from {self.name} cannot be pickled (its file cannot "
                    "be); open it from a path or URL to send it to Dask workers"
                ) from e
        return (_reopen, (self._spec, self._cache_bytes))

    # ---------------------------------------------------------------- metadata

    @property
    def width(self) -> int:
        return int(self._info["width"])

    @property
    def height(self) -> int:
        return int(self._info["height"])

    @property
    def shape(self) -> Tuple[int, int]:
        return (self.height, self.width)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self._info["dtype"])

    @property
    def nodata(self) -> Optional[float]:
        return self._info["stored_nodata"]

    @property
    def offset(self) -> Optional[float]:
        return self._info["offset"]

    @property
    def scale(self) -> Optional[float]:
        return self._info["scale"]

    @property
    def transform(self) -> Any:
        t = self._corner_transform(None)
        return None if t is None else _affine(t)

    @property
    def geotransform(self) -> Optional[Tuple[float, ...]]:
        t = self._corner_transform(None)
        if t is None:
            return None
        a, b, c, d, e, f = t
        return (c, a, b, f, d, e)

    @property
    def crs(self) -> Optional[str]:
        return _crs(self._info["georef"])

    @property
    def crs_wkt(self) -> Optional[str]:
        g = self._info["georef"]
        return g.get("crs_input") if g else None

    @property
    def tile_shape(self) -> Optional[Tuple[int, int]]:
        t = self._info["tiles"]
        return (int(t["tile_height"]), int(t["tile_width"])) if t else None

    @property
    def tile_grid(self) -> Optional[Tuple[int, int]]:
        t = self._info["tiles"]
        return (int(t["rows"]), int(t["cols"])) if t else None

    @property
    def overviews(self) -> List[Tuple[int, int]]:
        out = []
        k = 1
        while k <= 30:
            shape = self.overview_shape(k)
            if max(shape) < MIN_OVERVIEW_SIDE:
                break
            out.append(shape)
            k += 1
        return out

    @property
    def max_error(self) -> float:
        """The bound every valid sample is within (0: lossless); an untiled file reads its
        primary section's header for it."""
        return self._native.max_error()

    @property
    def profile(self) -> dict:
        """A rasterio-style profile, as :func:`vtz.read` gives."""
        p = {
            "driver": "VTZ",
            "dtype": self.dtype.name,
            "width": self.width,
            "height": self.height,
            "count": 1,
            "crs": self.crs,
            "transform": self.transform,
            "nodata": self.nodata,
        }
        if self.scale is not None:
            p["offset"], p["scale"] = self.offset, self.scale
        if self.tile_shape:
            p["tiled"] = True
            p["blockysize"], p["blockxsize"] = self.tile_shape
        return p

    def overview_shape(self, overview: Optional[int]) -> Tuple[int, int]:
        """``(rows, cols)`` of overview ``overview`` (None or 0: the full resolution)."""
        k = self._level(overview)
        s = 1 << k
        return (-(-self.height // s), -(-self.width // s))

    def _level(self, overview: Any) -> int:
        if overview is None:
            return 0
        if isinstance(overview, bool) or not isinstance(overview, (int, np.integer)):
            raise InvalidArgumentError(f"overview must be an int in 0..30, not {overview!r}")
        if not 0 <= int(overview) <= 30:
            raise InvalidArgumentError(f"overview {overview} is not in 0..30")
        return int(overview)

    def _corner_transform(self, overview: Optional[int]) -> Optional[Tuple[float, ...]]:
        """Affine-order corner transform of overview K (vtz's and GDAL's overview georef:
        the same corner, pixels 2**K times larger; a pixel-is-point file keeps the centre of
        sample (0, 0), which every overview keeps)."""
        g = self._info["georef"]
        if not g:
            return None
        a, b, c, d, e, f = (float(v) for v in g["transform"])
        k = self._level(overview)
        if k == 0:
            return (a, b, c, d, e, f)
        s = float(1 << k)
        if g.get("raster_type") == "point":
            cx, cy = c + 0.5 * a, f + 0.5 * e
            return (a * s, b, cx - 0.5 * a * s, d, e * s, cy - 0.5 * e * s)
        return (a * s, b, c, d, e * s, f)

    def _tile_bounds(self, overview: Optional[int]) -> Tuple[Tuple[int, ...], Tuple[int, ...]]:
        """Row and column chunk sizes of overview K that follow the tile grid: chunk i
        holds the samples whose full-resolution position lies in tile row (column) i."""
        rows, cols = self.overview_shape(overview)
        t = self.tile_shape
        if t is None:
            return (rows,), (cols,)
        s = 1 << self._level(overview)

        def sizes(n: int, full: int, tile: int) -> Tuple[int, ...]:
            edges = [min(n, -(-(i * tile) // s)) for i in range(math.ceil(full / tile))]
            edges.append(n)
            return tuple(b - a for a, b in zip(edges, edges[1:]) if b > a)

        return sizes(rows, self.height, t[0]), sizes(cols, self.width, t[1])

    def __repr__(self) -> str:
        state = "closed " if self.closed else ""
        tiles = f", tiles {self.tile_shape[0]}x{self.tile_shape[1]}" if self.tile_shape else ""
        return (
            f"<{state}vtz.Raster {self.name!r}: {self.height}x{self.width} "
            f"{self.dtype.name}{tiles}, crs {self.crs or 'none'}>"
        )

    # ---------------------------------------------------------------- reads

    def _window(self, window: Any, overview: Optional[int]) -> Optional[Tuple[int, int, int, int]]:
        if window is None:
            return None
        rows, cols = self.overview_shape(overview)
        if all(hasattr(window, a) for a in ("col_off", "row_off", "width", "height")):
            x, y, w, h = window.col_off, window.row_off, window.width, window.height
        else:
            try:
                parts = tuple(window)
            except TypeError as e:
                raise InvalidArgumentError(
                    "window must be ((row_start, row_stop), (col_start, col_stop)), "
                    f"(x, y, width, height) or a rasterio Window, not {window!r}"
                ) from e
            if len(parts) == 2 and all(isinstance(p, (tuple, list)) and len(p) == 2 for p in parts):
                (r0, r1), (c0, c1) = parts
                r0 = 0 if r0 is None else _as_int(r0, "row_start")
                r1 = rows if r1 is None else _as_int(r1, "row_stop")
                c0 = 0 if c0 is None else _as_int(c0, "col_start")
                c1 = cols if c1 is None else _as_int(c1, "col_stop")
                x, y, w, h = c0, r0, c1 - c0, r1 - r0
            elif len(parts) == 4:
                x, y, w, h = parts
            else:
                raise InvalidArgumentError(
                    "window must be ((row_start, row_stop), (col_start, col_stop)), "
                    f"(x, y, width, height) or a rasterio Window, not {window!r}"
                )
        x, y, w, h = (_as_int(v, n) for v, n in zip((x, y, w, h), ("x", "y", "width", "height")))
        if min(x, y) < 0 or w <= 0 or h <= 0 or x + w > cols or y + h > rows:
            what = f"overview {overview}'s" if overview else "the raster's"
            raise InvalidArgumentError(
                f"window of rows {y}..{y + h}, columns {x}..{x + w} is not inside {what} "
                f"{rows} x {cols} samples (or is empty)"
            )
        return (x, y, w, h)

    def read(
        self,
        window: Any = None,
        overview: Optional[int] = None,
        masked: bool = False,
        threads: int = 0,
    ) -> np.ndarray:
        """Decode a window of the raster (or of overview K) into a numpy array.

        Parameters
        ----------
        window : optional
            rasterio's conventions: ``((row_start, row_stop), (col_start, col_stop))``
            (half-open; None for an end), a ``rasterio.windows.Window``, or a flat
            ``(x, y, width, height)`` = ``(col_off, row_off, width, height)`` as
            :func:`vtz.decode` takes it. In overview K's samples when ``overview`` is given.
            None: everything.
        overview : int, optional
            Level K (1..30; 0 or None: full resolution): every 2**K-th sample of every
            2**K-th row, ``ceil(rows / 2**K)`` x ``ceil(cols / 2**K)``, the same samples
            ``vtz.decode(..., overview=K)`` gives.
        masked : bool
            Give a ``numpy.ma.MaskedArray`` whose nodata samples are masked.
        threads : int
            Threads for the decode (0: all cores); the samples are the same for every value.

        Returns
        -------
        numpy.ndarray
            2-D ``(rows, cols)`` of :attr:`dtype`, bit-identical to :func:`vtz.decode` of the
            same window: nodata samples hold :attr:`nodata` (NaN in floats without one).

        Raises
        ------
        InvalidArgumentError
            A window outside the raster, an overview level out of range, a closed file.
        CorruptError, VtzIOError, LimitError
        """
        k = self._level(overview)
        win = self._window(window, overview)
        t = int(threads)
        if t < 0:
            raise InvalidArgumentError(f"threads {t} is negative (0 = all cores)")
        a = self._native.read(window=win, overview=k or None, threads=t)
        if masked:
            nd = self.nodata
            if nd is not None:
                mask = a == a.dtype.type(nd)
            elif a.dtype.kind == "f":
                mask = np.isnan(a)
            else:
                mask = np.zeros(a.shape, dtype=bool)
            return np.ma.masked_array(a, mask=mask)
        return a

    # ---------------------------------------------------------------- lifetime

    def close(self) -> None:
        """Let go of the source; a later read raises :class:`InvalidArgumentError`."""
        self._native.close()

    @property
    def closed(self) -> bool:
        return bool(self._native.closed)

    def __enter__(self) -> "Raster":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
