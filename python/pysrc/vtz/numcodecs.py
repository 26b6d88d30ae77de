"""The vtz codec for numcodecs (Zarr format 2 stores, and anything else that takes a numcodecs codec).

``Vtz`` is an array-aware codec: ``encode`` takes the chunk as a numpy array (not its raw
bytes) and returns a self-describing vtz stream; ``decode`` gives the array back with its
shape and dtype. Importing this module registers the codec under the id ``"vtz"``; the
package also declares it in the ``numcodecs.codecs`` entry point group, so
``numcodecs.get_codec({"id": "vtz", ...})`` works without importing it first.

>>> import numpy as np, numcodecs, vtz.numcodecs
>>> codec = numcodecs.get_codec({"id": "vtz", "max_error": 0.5})
>>> a = np.arange(64, dtype=np.float32).reshape(8, 8)
>>> bool(np.all(np.abs(codec.decode(codec.encode(a)) - a) <= 0.5))
True

In a Zarr format 2 array (zarr-python 3 passes the chunk array itself to a ``compressor``
with no ``filters`` in front of it), give it as the compressor:
``zarr.create_array(..., zarr_format=2, compressors=vtz.numcodecs.Vtz(max_error=0.5), filters=None)``.
For Zarr format 3 use :class:`vtz.zarr.VtzCodec` as the ``serializer``.

Sample order: as every numcodecs codec, ``Vtz`` codes a chunk's samples in the order its
buffer holds them, and its callers (Zarr format 2, ``numcodecs.compat.ndarray_copy``)
reshape a decoded chunk from that order. A C-ordered chunk of shape (h, w) is coded as
the h x w raster it is; a Fortran-ordered one (``order="F"`` arrays) holds its transpose in
memory and is coded as that w x h raster (the bound and the size are the same); a chunk
that is neither C- nor Fortran-contiguous (a strided view) is coded row by row, as numpy's
``reshape(-1, order="A")`` walks it. ``decode(buf, out)`` fills ``out`` the same way: in
its memory order when it is C- or Fortran-contiguous, row by row otherwise.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np
from numcodecs.abc import Codec
from numcodecs.compat import ensure_bytes, ensure_ndarray_like
from numcodecs.registry import register_codec

import vtz

__all__ = ["Vtz"]

#: The dtypes vtz holds (native byte order).
SUPPORTED_DTYPES = ("uint8", "int16", "uint16", "int32", "float32", "float64")

_CONFIG_KEYS = ("max_error", "lossless", "nodata", "method", "threads", "effort")


def _check_params(
    max_error: Any, lossless: Any, nodata: Any, method: Any, threads: Any, effort: Any = None
) -> dict[str, Any]:
    """Check the codec parameters and return them as plain JSON types.

    Only what any valid writer produces is checked here, so that opening an array for
    reading never fails on an encode-only detail (an unknown ``method`` name or an
    ``effort`` outside 1..9, say, is left for ``vtz.encode`` to report). A configuration
    written before ``effort`` existed has none: ``None``, the library's default.
    """
    if not isinstance(lossless, (bool, np.bool_)):
        raise TypeError(f"lossless must be True or False, not {type(lossless).__name__}")
    lossless = bool(lossless)
    if max_error is not None:
        if isinstance(max_error, (bool, np.bool_)) or not isinstance(max_error, numbers.Real):
            raise TypeError(
                f"max_error must be a number in data units or None, not {type(max_error).__name__}"
            )
        max_error = float(max_error)
        if not (math.isfinite(max_error) and max_error >= 0):
            raise vtz.InvalidArgumentError(f"max_error {max_error} is not a finite number >= 0")
        if lossless:
            raise vtz.InvalidArgumentError("lossless=True and a max_error exclude each other")
    if nodata is not None:
        if isinstance(nodata, (bool, np.bool_)) or not isinstance(nodata, numbers.Real):
            raise TypeError(f"nodata must be a number or None, not {type(nodata).__name__}")
        if isinstance(nodata, numbers.Integral):
            nodata = int(nodata)
        else:
            nodata = float(nodata)
            if math.isnan(nodata):
                # NaN samples of float arrays are always nodata: nodata=NaN says nothing more.
                nodata = None
            elif not math.isfinite(nodata):
                raise vtz.InvalidArgumentError(
                    f"nodata {nodata} is not finite (NaN is always nodata in float arrays)"
                )
    if method is not None and not isinstance(method, str):
        raise TypeError(f"method must be a string such as 'best' or 'grid', not {type(method).__name__}")
    if isinstance(threads, (bool, np.bool_)) or not isinstance(threads, numbers.Integral):
        raise TypeError(f"threads must be an integer, not {type(threads).__name__}")
    threads = int(threads)
    if threads < 0:
        raise vtz.InvalidArgumentError(f"threads {threads} is negative (0 means all cores)")
    if effort is not None:
        if isinstance(effort, (bool, np.bool_)) or not isinstance(effort, numbers.Integral):
            raise vtz.InvalidArgumentError(
                f"effort {effort!r} is not an integer in 1..=9 (None = the default, 5)"
            )
        effort = int(effort)
    return {
        "max_error": max_error,
        "lossless": lossless,
        "nodata": nodata,
        "method": method,
        "threads": threads,
        "effort": effort,
    }


def _config(codec: Any) -> dict[str, Any]:
    """The codec's parameters by name; ``effort`` only when set, so that a store written
    with the default configuration reads as before ``effort`` existed (an older vtz opens it)."""
    return {
        k: getattr(codec, k)
        for k in _CONFIG_KEYS
        if k != "effort" or getattr(codec, k) is not None
    }


def _check_dtype(dtype: Any) -> np.dtype:
    """The native-byte-order form of ``dtype``, or ``vtz.DtypeError`` (an ``InvalidArgumentError``) if vtz cannot hold it."""
    dt = np.dtype(dtype)
    native = dt.newbyteorder("=") if dt.byteorder not in ("=", "|") else dt
    if native.name not in SUPPORTED_DTYPES:
        raise vtz.DtypeError(
            f"vtz cannot hold dtype {dt} (it holds {', '.join(SUPPORTED_DTYPES)})"
        )
    return native


def _plane_shape(shape: tuple[int, ...]) -> tuple[int, int]:
    """The 2-D shape vtz codes a chunk of ``shape`` as.

    A 1-D chunk of n samples is coded as 1 x n; an N-D chunk whose axes before the last
    two all have size 1 is coded as its last two axes. Anything else raises
    ``vtz.InvalidArgumentError``.
    """
    shape = tuple(int(s) for s in shape)
    if len(shape) == 0:
        raise vtz.InvalidArgumentError("vtz codes 2-D chunks; this chunk is a 0-D scalar")
    if len(shape) == 1:
        return (1, shape[0])
    if any(s != 1 for s in shape[:-2]):
        raise vtz.InvalidArgumentError(
            f"vtz codes 2-D chunks; chunk shape {shape} has axes of size > 1 before the last two"
            " (use chunks of size 1 along every axis but the last two)"
        )
    return (shape[-2], shape[-1])


def _as_plane(array: Any) -> np.ndarray:
    """``array`` as the 2-D, C-contiguous, native-endian numpy array ``vtz.encode`` takes,
    its samples at their logical places (a Zarr v3 codec's contract: the chunk's values,
    whatever its memory layout)."""
    a = np.asarray(array)
    dt = _check_dtype(a.dtype)
    a = a.reshape(_plane_shape(a.shape))
    return np.ascontiguousarray(a, dtype=dt)


def _is_fortran(a: np.ndarray) -> bool:
    """Whether ``a``'s memory holds it in Fortran order and not also in C order (an array
    that is both, such as a single row, has one memory order)."""
    return bool(a.flags.f_contiguous and not a.flags.c_contiguous)


def _memory_plane(array: Any) -> np.ndarray:
    """The samples of ``array`` in the order its buffer holds them (numcodecs' contract),
    as the 2-D, C-contiguous, native-endian plane ``vtz.encode`` takes.

    A C-ordered chunk of shape (..., h, w) gives its h x w plane; a Fortran-ordered one
    holds its transpose in memory and gives that, w x h; a chunk that is neither C- nor
    Fortran-contiguous gives its samples row by row (numpy's ``reshape(-1, order="A")``
    order, which numcodecs' callers use to flatten a decoded chunk). The shape must be
    2-D once leading axes of size 1 are dropped (or 1-D), else ``vtz.InvalidArgumentError``.
    """
    a = np.asarray(array)
    dt = _check_dtype(a.dtype)
    h, w = _plane_shape(a.shape)
    if _is_fortran(a):
        # A view: the buffer's samples in memory order, as the w x h raster they form.
        plane = a.reshape(-1, order="F").reshape(w, h)
    else:
        plane = a.reshape(h, w)
    return np.ascontiguousarray(plane, dtype=dt)


def _fill(decoded: np.ndarray, out: Any) -> Any:
    """Copy a decoded plane into ``out`` in ``out``'s own sample order (its memory order when
    C- or Fortran-contiguous, row by row otherwise), as numcodecs' ``ndarray_copy`` does, but
    never reinterpreting the samples' bits: ``out`` is an array of the chunk's dtype (any
    byte order, any shape of as many samples) or a contiguous byte buffer of its size.
    Returns ``out``; anything else raises ``vtz.InvalidArgumentError``."""
    dst = ensure_ndarray_like(out)
    if not getattr(dst.flags, "writeable", True):
        raise vtz.InvalidArgumentError("out is read-only")
    flat = decoded.reshape(-1)
    native = dst.dtype.newbyteorder("=") if dst.dtype.byteorder not in ("=", "|") else dst.dtype
    if native == decoded.dtype:
        if dst.size != flat.size:
            raise vtz.InvalidArgumentError(
                f"out holds {dst.size} samples, the chunk has {flat.size}"
                f" ({decoded.shape[0]}x{decoded.shape[1]})"
            )
        np.copyto(dst, flat.reshape(dst.shape, order="F" if _is_fortran(dst) else "C"))
        return out
    if dst.dtype.itemsize == 1 and dst.dtype.kind in "uV" and (
        dst.flags.c_contiguous or dst.flags.f_contiguous
    ):
        # A raw byte buffer: the samples' bytes, native byte order, in the stream's order.
        if dst.nbytes != decoded.nbytes:
            raise vtz.InvalidArgumentError(
                f"out holds {dst.nbytes} bytes, the chunk has {decoded.nbytes}"
                f" ({decoded.shape[0]}x{decoded.shape[1]} {decoded.dtype})"
            )
        np.copyto(dst.reshape(-1, order="A").view(np.uint8), flat.view(np.uint8))
        return out
    raise vtz.InvalidArgumentError(
        f"out has dtype {dst.dtype}, the chunk is {decoded.dtype}: pass an array of that"
        " dtype, or a contiguous byte buffer"
    )


class Vtz(Codec):
    """numcodecs codec of vtz: error-bounded compression of 2-D elevation chunks.

    Every valid sample of a chunk decodes within ``max_error`` of its value (exactly when
    lossless); each encoded chunk is a self-describing vtz stream (shape, dtype and nodata
    are stored in it, not in the codec configuration).

    Parameters
    ----------
    max_error : float, optional
        The absolute error bound in data units. ``None`` (the default) is lossless.
    lossless : bool, optional
        Lossless coding; excludes ``max_error``.
    nodata : int or float, optional
        A value meaning "no data": such samples decode to exactly this value. NaN samples
        of float chunks are always nodata (``nodata=NaN`` is the same as ``None``); with a
        non-NaN ``nodata`` they decode as that value.
    method : str, optional
        ``None``/``"best"`` (try the methods, keep the smallest), or a method name such as
        ``"sibson"``, ``"grid"``, ``"haar"``, ``"fis"``, ``"residual"`` (or a comma list).
    threads : int, optional
        Threads per chunk (0 = all cores). The bytes are the same for every value; the
        default 1 suits callers that code several chunks at once.
    effort : int, optional
        Encoder effort 1..9 (:func:`vtz.encode`'s): ``None`` is the library's default, 5;
        1 writes the residual method's lane coding, 2 its fast coding (several times faster
        to write and to read, a few per cent larger); 6-9 try the fast and range codings. An effort outside 1..9 is
        reported by ``encode``, so that a store opens for reading whatever it records.

    Notes
    -----
    vtz codes 2-D arrays. ``encode`` codes a 1-D chunk of n samples as 1 x n, and an N-D
    chunk whose axes before the last two all have size 1 as its last two axes; other
    chunks raise :class:`vtz.InvalidArgumentError`. Samples travel in the order the
    chunk's buffer holds them (see the module's docstring): a Fortran-ordered chunk is coded
    as its transpose, and ``decode`` returns the stream's 2-D raster (numcodecs' callers
    reshape it in the array's order, or pass ``out``).
    """

    codec_id = "vtz"

    def __init__(
        self,
        max_error: float | None = None,
        lossless: bool = False,
        nodata: float | None = None,
        method: str | None = None,
        threads: int = 1,
        effort: int | None = None,
    ) -> None:
        params = _check_params(max_error, lossless, nodata, method, threads, effort)
        self.max_error = params["max_error"]
        self.lossless = params["lossless"]
        self.nodata = params["nodata"]
        self.method = params["method"]
        self.threads = params["threads"]
        self.effort = params["effort"]

    def encode(self, buf: Any) -> bytes:
        """Encode one chunk.

        Parameters
        ----------
        buf : array_like
            The chunk: a numpy array (or anything ``numpy.asarray`` takes) of dtype uint8,
            int16, uint16, int32, float32 or float64, 2-D or reducible to 2-D (see Notes of
            the class), any byte order, any memory layout.

        Returns
        -------
        bytes
            The vtz stream of the chunk's samples in the order its buffer holds them: an
            (h, w) chunk in C order as an h x w raster, in Fortran order as the w x h raster
            its memory holds (its transpose), neither (a strided view) row by row.

        Raises
        ------
        vtz.InvalidArgumentError
            The chunk's shape or dtype cannot be coded, or the parameters do not fit it.
        vtz.UnmetError
            The chosen method cannot meet the bound on this chunk.
        """
        plane = _memory_plane(buf)
        return vtz.encode(
            plane,
            max_error=self.max_error,
            lossless=self.lossless,
            nodata=self.nodata,
            method=self.method,
            threads=self.threads,
            effort=self.effort,
        )

    def decode(self, buf: Any, out: Any = None) -> np.ndarray:
        """Decode one chunk.

        Parameters
        ----------
        buf : bytes-like
            A vtz stream (bytes, bytearray, memoryview or a uint8 numpy array).
        out : numpy.ndarray or writable buffer, optional
            Where to put the samples: an array of the chunk's dtype (any byte order) and
            number of samples, any shape, filled in its memory order when it is C- or
            Fortran-contiguous and row by row otherwise (as numcodecs' ``ndarray_copy``
            and Zarr format 2 read a chunk); or a contiguous byte buffer of the chunk's
            size, which gets the samples' native bytes.

        Returns
        -------
        numpy.ndarray
            ``out`` when given; else the stream's 2-D raster, C-ordered: the chunk itself
            for a chunk encoded from C order, its transpose (the memory it came from) for
            one encoded from Fortran order, which numcodecs' callers reshape in that order.
            Nodata samples are the nodata value, or NaN in float chunks without one.

        Raises
        ------
        vtz.CorruptError
            The bytes are truncated or damaged.
        vtz.InvalidArgumentError
            ``out`` has another dtype or number of samples, or is read-only.
        """
        decoded = vtz.decode(ensure_bytes(buf), threads=self.threads)
        if out is None:
            return decoded
        return _fill(decoded, out)

    def get_config(self) -> dict[str, Any]:
        """The codec's configuration as a JSON-ready dict (``id`` and the constructor's arguments).

        Returns
        -------
        dict
            ``{"id": "vtz", "max_error": ..., "lossless": ..., "nodata": ..., "method": ...,
            "threads": ...}``, all plain Python types, and ``"effort"`` when it is set.
        """
        return {"id": self.codec_id, **_config(self)}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> Vtz:
        """Build the codec from a configuration made by :meth:`get_config`.

        Parameters
        ----------
        config : dict
            The configuration; an ``id`` key, if present, must be ``"vtz"``.

        Returns
        -------
        Vtz
        """
        config = dict(config)
        codec_id = config.pop("id", cls.codec_id)
        if codec_id != cls.codec_id:
            raise vtz.InvalidArgumentError(f"codec id {codec_id!r} is not {cls.codec_id!r}")
        unknown = sorted(set(config) - set(_CONFIG_KEYS))
        if unknown:
            raise vtz.InvalidArgumentError(f"unknown vtz codec parameters: {', '.join(unknown)}")
        return cls(**config)

    def __repr__(self) -> str:
        """The constructor call that rebuilds this codec."""
        args = ", ".join(f"{k}={getattr(self, k)!r}" for k in _CONFIG_KEYS)
        return f"Vtz({args})"


register_codec(Vtz)
