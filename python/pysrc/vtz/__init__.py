"""vtz: error-bounded compression of elevation rasters (DEMs, height fields).

Every valid sample decodes within the ``max_error`` you give (lossless without one),
checked by the encoder on exactly what the decoder produces.

>>> import numpy as np, vtz
>>> dem = (np.add.outer(np.arange(64), np.arange(48)) % 37).astype(np.int16)
>>> b = vtz.encode(dem, max_error=1)
>>> back = vtz.decode(b)
>>> back.dtype, int(np.abs(back.astype(int) - dem).max()) <= 1
(dtype('int16'), True)

The codecs for chunked stores are :class:`vtz.numcodecs.Vtz` (numcodecs, id ``"vtz"``) and
:class:`vtz.zarr.VtzCodec` (a Zarr v3 array-to-bytes codec, name ``"vtz"``).

:func:`vtz.open` reads a ``.vtz`` file lazily (a path, bytes, a URL through fsspec, a file-like),
window by window; ``xarray.open_dataset(path, engine="vtz")`` (:mod:`vtz.xarray`) gives it to
xarray and Dask, one chunk per tile.
"""

from __future__ import annotations

import os
from typing import Any, Optional, Tuple, Union

import numpy as np

from ._errors import (
    CorruptError,
    DtypeError,
    InvalidArgumentError,
    LimitError,
    UnmetError,
    UnsupportedError,
    VtzError,
    VtzIOError,
)
from . import _errors, _vtz
from ._raster import Raster, open  # noqa: A004 - vtz.open, as rasterio.open

__version__ = _vtz.__version__

#: The dtypes vtz codes (and gives back on decode).
DTYPES = ("uint8", "int16", "uint16", "int32", "float32", "float64")

__all__ = [
    "encode",
    "decode",
    "info",
    "read",
    "write",
    "open",
    "Raster",
    "DTYPES",
    *_errors.__all__,
]


def _check_array(array: Any) -> np.ndarray:
    """The array as vtz takes it, or a clear exception saying what is wrong."""
    if not isinstance(array, np.ndarray):
        try:
            array = np.asarray(array)
        except Exception as e:  # pragma: no cover - numpy's own message is kept
            raise DtypeError(f"cannot make an array of {type(array).__name__}: {e}") from e
    if array.dtype.kind == "c":
        raise DtypeError(f"complex arrays ({array.dtype}) are not elevation data")
    if array.dtype.byteorder not in ("=", "|") and array.dtype.byteorder != _NATIVE:
        raise DtypeError(
            f"the array is big-endian ({array.dtype.str}); pass "
            "a.astype(a.dtype.newbyteorder('='))"
        )
    if array.dtype.name not in DTYPES:
        raise DtypeError(
            f"dtype {array.dtype} is not supported ({', '.join(DTYPES)})"
        )
    if array.ndim != 2:
        hint = " (one band: pass a[0])" if array.ndim == 3 and array.shape[0] == 1 else ""
        raise InvalidArgumentError(
            f"the array is {array.ndim}-D with shape {array.shape}; vtz codes 2-D arrays{hint}"
        )
    if array.size == 0:
        raise InvalidArgumentError(f"the array is empty (shape {array.shape})")
    if not array.flags.c_contiguous:
        raise InvalidArgumentError(
            "the array is not C-contiguous (a slice or a transpose): pass numpy.ascontiguousarray(a)"
        )
    return array


_NATIVE = "<" if np.little_endian else ">"


def _bound(max_error: Any) -> Any:
    if max_error is None:
        return None
    if isinstance(max_error, (str, int, float, np.integer, np.floating)) and not isinstance(
        max_error, bool
    ):
        return max_error if isinstance(max_error, str) else float(max_error)
    raise TypeError(
        f"max_error must be a number or a string like '0.5%', not {type(max_error).__name__}"
    )


def _nodata(nodata: Any) -> Optional[float]:
    if nodata is None:
        return None
    try:
        return float(nodata)
    except (TypeError, ValueError) as e:
        raise TypeError(f"nodata must be a number, not {nodata!r}") from e


def encode(
    array: np.ndarray,
    max_error: Union[float, str, None] = None,
    lossless: bool = False,
    nodata: Optional[float] = None,
    method: Optional[str] = None,
    threads: int = 0,
    effort: Optional[int] = None,
    offset: Optional[float] = None,
    scale: Optional[float] = None,
    tile: Optional[int] = None,
) -> bytes:
    """Encode a 2-D array as a vtz stream.

    Parameters
    ----------
    array : numpy.ndarray
        2-D, C-contiguous, native-endian; uint8, int16, uint16, int32, float32 or float64.
    max_error : float or str, optional
        Every valid sample decodes within this absolute bound (data units), or within a
        percentage of the value range (``"0.1%"``). ``None``: lossless.
    lossless : bool
        Lossless (the default when no ``max_error`` is given); excludes ``max_error``.
    nodata : float, optional
        A value meaning "no data". NaN samples of float arrays are always nodata (as GDAL
        treats NaN in a float raster); with a non-NaN ``nodata`` they decode as that value.
    method : str, optional
        ``"best"`` (default), ``"sibson"``, ``"grid"``, ``"haar"``, ``"fis"``, ``"residual"``,
        or a comma list.
    threads : int
        Threads (0 = all cores). The bytes are the same for every value.
    effort : int, optional
        Encoder effort 1..9, speed against size (the CLI's ``--effort``); ``None``: the
        library's default, 5. Effort 1 writes the residual method's lane coding (the fastest
        to decode, 4-6x faster to encode, 6-8 % larger), 2 its fast coding (3-5 % larger);
        3-5 its range-coded predictors; 6-9 try those and the fast coding, keeping the
        smallest. Other methods ignore it.
        Anything but ``None`` or an integer 1..9 raises :class:`InvalidArgumentError`.
    offset, scale : float, optional
        The array holds integer codes whose values are ``offset + scale * code`` (GDAL's band
        offset and scale, e.g. decimetres as int16 with ``scale=0.1``); ``nodata`` is then a
        code too. The stream keeps the mapping and ``max_error`` bounds the values (metres),
        as ``vtz encode`` does for a GeoTIFF with a GDAL scale. Integer dtypes only.
    tile : int, optional
        Tile side in samples (the CLI's ``--tile``; at least 16): a raster larger than it is
        coded as independent tiles (container version 2) that :func:`vtz.open` reads one by
        one. ``None``: tiles of 4096 for rasters of more than 4096**2 samples, else untiled;
        ``0``: never tiled.

    Returns
    -------
    bytes
        A self-describing vtz stream (shape, dtype, nodata and bound inside).

    Raises
    ------
    DtypeError, InvalidArgumentError, UnmetError, LimitError
    """
    a = _check_array(array)
    return _vtz.encode(
        a,
        max_error=_bound(max_error),
        lossless=bool(lossless),
        nodata=_nodata(nodata),
        method=method,
        threads=_threads(threads),
        effort=effort,
        offset=_opt_float(offset, "offset"),
        scale=_opt_float(scale, "scale"),
        tile=_tile(tile),
    )


def _tile(tile: Any) -> Optional[int]:
    if tile is None:
        return None
    if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or tile < 0:
        raise InvalidArgumentError(f"tile must be an int >= 0 (0: untiled), not {tile!r}")
    return int(tile)


def _opt_float(v: Any, what: str) -> Optional[float]:
    if v is None:
        return None
    try:
        return float(v)
    except (TypeError, ValueError) as e:
        raise InvalidArgumentError(f"{what} {v!r} is not a number") from e


def _threads(threads: Any) -> int:
    t = int(threads)
    if t < 0:
        raise InvalidArgumentError(f"threads {t} is negative (0 = all cores)")
    return t


def _bytes(data: Any) -> bytes:
    if isinstance(data, bytes):
        return data
    if isinstance(data, (bytearray, memoryview)):
        return bytes(data)
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data).tobytes()
    raise TypeError(f"expected bytes, not {type(data).__name__}")


def decode(
    data: Union[bytes, bytearray, memoryview],
    window: Optional[Tuple[int, int, int, int]] = None,
    scale: Union[float, str, None] = None,
    threads: int = 0,
    overview: Optional[int] = None,
) -> np.ndarray:
    """Decode a vtz stream into a numpy array of the dtype it was encoded from (a stream with
    a value mapping: its values' smallest dtype, or its codes with :func:`info`'s ``offset``
    and ``scale``, as GDAL reads it; README, "Output types").

    Parameters
    ----------
    data : bytes-like
        A vtz stream.
    window : (x, y, width, height), optional
        Decode only this window (column, row, columns, rows).
    scale : float, str or fractions.Fraction, optional
        Resample by this factor (``2``, ``0.5``, ``"3/2"``) as ``vtz decode --scale`` does:
        ``floor(w * scale)`` x ``floor(h * scale)`` samples over the same extent. A float
        means the decimal Python prints for it; one with no exact 32-bit fraction (``1/3``)
        is refused: pass ``"1/3"``.
    threads : int
        Threads (0 = all cores); the result is bit-identical for every value.
    overview : int, optional
        Overview K (1..30) as ``vtz decode --overview K`` writes it: every 2**K-th sample of
        every 2**K-th row (``ceil(h / 2**K)`` x ``ceil(w / 2**K)``); an untiled stream's is
        its full decode's samples there. The residual layer decodes only its coarse levels
        for it. ``window`` is then in the overview's samples.

    Returns
    -------
    numpy.ndarray
        2-D; nodata samples hold the stream's nodata value, or NaN for floats without one.

    Raises
    ------
    CorruptError, UnsupportedError, InvalidArgumentError, LimitError
    """
    if window is not None:
        try:
            x, y, w, h = (int(v) for v in window)
        except (TypeError, ValueError) as e:
            raise InvalidArgumentError(
                f"window must be (x, y, width, height), not {window!r}"
            ) from e
        if min(x, y, w, h) < 0:
            raise InvalidArgumentError(f"window {window!r} has a negative value")
        window = (x, y, w, h)
    if scale is not None:
        scale = str(scale)
    if overview is not None:
        if isinstance(overview, bool) or not isinstance(overview, int) or not 0 <= overview <= 30:
            raise InvalidArgumentError(f"overview must be an int in 1..30, not {overview!r}")
    return _vtz.decode(
        _bytes(data), window=window, scale=scale, overview=overview, threads=_threads(threads)
    )


def info(data: Union[bytes, bytearray, memoryview]) -> dict:
    """What a vtz stream holds, without decoding its samples.

    Returns a dict with ``width``, ``height``, ``dtype`` (what :func:`decode` gives: the
    values' dtype, or the codes' when ``scale``/``offset`` are not None: the values are
    ``offset + scale * sample``), ``offset``, ``scale``, ``codes_dtype``, ``value_offset`` and
    ``value_scale`` (the stream's own codes and mapping), ``nodata`` (a value), ``range``
    (min, max of the valid values), ``max_error`` (the bound every valid sample is within; 0 = lossless; read
    from the stream without decoding), ``method``, ``sections``, ``tiles``, ``bytes``, ``crs`` and
    ``transform`` (None without georeferencing).
    """
    d = _vtz.info(_bytes(data))
    g = d.pop("georef")
    d["crs"] = _crs(g)
    d["transform"] = _transform(g["transform"]) if g else None
    return d


def _crs(g: Optional[dict]) -> Optional[str]:
    if not g:
        return None
    if g.get("epsg"):
        return f"EPSG:{g['epsg']}"
    return g.get("wkt")


def _transform(t: tuple) -> Any:
    try:
        from affine import Affine  # rasterio's own transform type
    except ImportError:
        return tuple(t)
    return Affine(*t)


_DRIVERS = {
    ".vtz": "VTZ",
    ".tif": "GTiff",
    ".tiff": "GTiff",
    ".png": "PNG",
    ".hgt": "SRTMHGT",
    ".asc": "AAIGrid",
    ".exr": "EXR",
    ".f32": "ENVI",
}


def read(path: Union[str, os.PathLike]) -> Tuple[np.ndarray, dict]:
    """Read a raster file vtz reads (``.vtz``, ``.tif``, ``.hgt``, ``.png``, ``.asc``, ``.exr``,
    ``.f32`` + ``.json``).

    Returns
    -------
    (numpy.ndarray, dict)
        The samples (2-D; nodata as the nodata value or NaN) and a rasterio-style profile:
        ``driver``, ``dtype``, ``width``, ``height``, ``count``, ``crs``, ``transform``,
        ``nodata``. The dtype is GDAL's for the file (README, "Output types"): the values'
        own, or the smallest integer dtype that holds them (a uint16 PNG read with offset
        -32768 gives int16); when the values are integer codes with an offset and scale (a
        GeoTIFF with a GDAL scale), the array holds the codes and the profile also has
        ``offset`` and ``scale`` (values = offset + scale * array; ``nodata`` is a code), which
        :func:`write` takes back.
    """
    p = os.fspath(path)
    array, g, nodata, offset_scale = _vtz.read(p)
    profile = {
        "driver": _DRIVERS.get(os.path.splitext(p)[1].lower(), "unknown"),
        "dtype": array.dtype.name,
        "width": array.shape[1],
        "height": array.shape[0],
        "count": 1,
        "crs": _crs(g),
        "transform": _transform(g["transform"]) if g else None,
        "nodata": nodata,
    }
    if offset_scale is not None:
        profile["offset"], profile["scale"] = offset_scale
    return array, profile


def _crs_parts(crs: Any) -> Tuple[Optional[int], Optional[str]]:
    """(EPSG code, WKT) of a CRS given as "EPSG:n", an int, a WKT string or a rasterio CRS."""
    if crs is None:
        return None, None
    if isinstance(crs, (int, np.integer)) and not isinstance(crs, bool):
        return int(crs), None
    if isinstance(crs, str):
        s = crs.strip()
        if s.upper().startswith("EPSG:"):
            try:
                return int(s[5:]), None
            except ValueError as e:
                raise InvalidArgumentError(f"crs {crs!r} is not EPSG:<number>") from e
        return None, s
    to_epsg = getattr(crs, "to_epsg", None)
    epsg = to_epsg() if callable(to_epsg) else None
    to_wkt = getattr(crs, "to_wkt", None)
    wkt = to_wkt() if callable(to_wkt) else None
    if epsg is None and wkt is None:
        raise InvalidArgumentError(f"cannot read a CRS from {type(crs).__name__}")
    return epsg, wkt


def _transform_parts(t: Any) -> Optional[Tuple[float, ...]]:
    if t is None:
        return None
    vals = tuple(float(v) for v in tuple(t)[:6])
    if len(vals) != 6:
        raise InvalidArgumentError(f"transform needs 6 values (a, b, c, d, e, f), got {t!r}")
    return vals


def write(
    path: Union[str, os.PathLike],
    array: np.ndarray,
    profile: Optional[dict] = None,
    max_error: Union[float, str, None] = None,
    lossless: bool = False,
    method: Optional[str] = None,
    overwrite: bool = True,
    threads: int = 0,
    effort: Optional[int] = None,
    tile: Optional[int] = None,
) -> None:
    """Write a 2-D array to a raster file; the format comes from the extension.

    A ``.vtz`` is encoded within ``max_error`` (lossless without one); other formats
    (``.tif``, ``.png``, ``.asc``, ``.exr``, ``.f32``) are written exactly. The profile's
    ``crs``, ``transform`` and ``nodata`` (a rasterio profile works as it is) are kept. The
    file is written to a temporary name and renamed into place; ``overwrite=False`` refuses
    an existing file. ``method``, ``effort`` and ``tile`` are those of :func:`encode`, and so
    are the profile's ``offset`` and ``scale`` (integer codes; as :func:`read` gives them).
    """
    a = _check_array(array)
    profile = dict(profile or {})
    epsg, wkt = _crs_parts(profile.get("crs"))
    _vtz.write(
        os.fspath(path),
        a,
        nodata=_nodata(profile.get("nodata")),
        transform=_transform_parts(profile.get("transform")),
        epsg=epsg,
        wkt=wkt,
        max_error=_bound(max_error),
        lossless=bool(lossless),
        method=method,
        force=bool(overwrite),
        threads=_threads(threads),
        effort=effort,
        offset=_opt_float(profile.get("offset"), "offset"),
        scale=_opt_float(profile.get("scale"), "scale"),
        tile=_tile(tile),
    )
