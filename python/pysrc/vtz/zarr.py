"""The vtz codec for Zarr format 3 (zarr-python >= 3): an array-to-bytes codec named ``"vtz"``.

Give it as the array's ``serializer``, with no compressor after it (vtz streams are
already entropy coded, and with no bytes-to-bytes codec after it zarr lets the codec read
its chunks itself, which is how a corrupt chunk gets named in the error)::

    import zarr, vtz.zarr
    z = zarr.create_array(store, shape=(3601, 3601), chunks=(512, 512), dtype="int16",
                          serializer=vtz.zarr.VtzCodec(max_error=0.5, nodata=-32768),
                          compressors=None, fill_value=-32768)

Each chunk is a self-describing vtz stream: the configuration holds only the encode
parameters (``max_error``, ``lossless``, ``nodata``, ``method``, ``threads``, and
``effort`` when it is set), no shape or dtype. Importing this module registers the codec
with ``zarr.registry``; the package also declares it in the ``zarr.codecs`` entry point
group, so stores written with it open without importing it first.

Chunks are 2-D: a chunk shape may have leading axes of size 1 (``(1, 512, 512)`` in a
``(time, y, x)`` array) and a 1-D chunk of n samples is coded as 1 x n. Zarr pads the
partial chunks at the array's edges with the fill value; a NaN fill value is nodata in
float chunks, and ``nodata=fill_value`` keeps an integer array's padding exact and cheap.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from zarr.abc.codec import ArrayBytesCodec, ArrayBytesCodecPartialDecodeMixin
from zarr.core.common import parse_named_configuration
from zarr.registry import register_codec

import vtz
from vtz.numcodecs import (
    _CONFIG_KEYS,
    _as_plane,
    _check_dtype,
    _check_params,
    _config,
    _plane_shape,
)

if TYPE_CHECKING:
    from typing import Self

    from zarr.abc.store import ByteGetter
    from zarr.core.array_spec import ArraySpec
    from zarr.core.buffer import Buffer, NDBuffer
    from zarr.core.chunk_grids import ChunkGrid
    from zarr.core.common import JSON
    from zarr.core.dtype.wrapper import TBaseDType, TBaseScalar, ZDType
    from zarr.core.indexing import SelectorTuple

__all__ = ["VtzCodec"]

CODEC_NAME = "vtz"


def _describe_chunk(byte_getter: Any) -> str:
    """How an error message names the chunk ``byte_getter`` reads."""
    coords = getattr(byte_getter, "chunk_coords", None)
    if coords is not None:
        # Sharding hands its inner chunks to the codec by their coordinates in the shard.
        return f"inner chunk {tuple(int(c) for c in coords)} of a shard"
    if hasattr(byte_getter, "store") and hasattr(byte_getter, "path"):
        # A StorePath: its string is the store's URL followed by the chunk key.
        return f"chunk {str(byte_getter)!r}"
    return f"chunk {byte_getter!r}"


def _describe_spec(chunk_spec: ArraySpec) -> str:
    """How an error message names a chunk known only by its spec."""
    shape = "x".join(str(s) for s in chunk_spec.shape)
    return f"a {shape} {chunk_spec.dtype.to_native_dtype()} chunk (zarr gave the codec no key)"


def _renamed(err: vtz.VtzError, where: str) -> vtz.VtzError:
    """``err`` as an exception of the same class whose message starts with ``where``."""
    return type(err)(f"{where}: {err}")


@dataclass(frozen=True)
class VtzCodec(ArrayBytesCodec, ArrayBytesCodecPartialDecodeMixin):
    """Zarr v3 array-to-bytes codec of vtz: error-bounded compression of elevation chunks.

    Every valid sample of a chunk decodes within ``max_error`` of its value (exactly when
    lossless). Encoding and decoding run in worker threads (``asyncio.to_thread``; vtz
    releases the GIL), so zarr codes several chunks at once.

    Parameters
    ----------
    max_error : float, optional
        The absolute error bound in data units. ``None`` (the default) is lossless.
    lossless : bool, optional
        Lossless coding; excludes ``max_error``.
    nodata : int or float, optional
        A value meaning "no data": such samples decode to exactly this value. NaN samples
        of float chunks are always nodata (``nodata=NaN`` is the same as ``None``).
    method : str, optional
        ``None``/``"best"``, or a method name (``"sibson"``, ``"grid"``, ``"haar"``,
        ``"fis"``, ``"residual"``) or a comma list of them.
    threads : int, optional
        Threads per chunk (0 = all cores); the bytes are the same for every value.
    effort : int, optional
        Encoder effort 1..9 (:func:`vtz.encode`'s): ``None`` is the library's default, 5;
        1 writes the residual method's lane coding, 2 its fast coding (several times faster
        to write and to read, a few per cent larger); 6-9 try the fast and range codings. Recorded in the store's
        metadata when set; an effort outside 1..9 is reported when a chunk is written, so
        that reading never fails on it.

    Notes
    -----
    With no other codec after it (``compressors=None``) zarr reads chunks through the
    codec's partial-decode entry, which knows each chunk's store key: a damaged chunk then
    raises :class:`vtz.CorruptError` naming it (``chunk 'file:///data/dem.zarr/c/3/1': ...``).
    Behind a bytes-to-bytes codec, or when zarr re-reads a chunk to merge a partial write,
    zarr gives the codec only the chunk's shape and dtype, and the message says so.
    """

    is_fixed_size = False

    max_error: float | None
    lossless: bool
    nodata: float | int | None
    method: str | None
    threads: int
    effort: int | None

    def __init__(
        self,
        *,
        max_error: float | None = None,
        lossless: bool = False,
        nodata: float | int | None = None,
        method: str | None = None,
        threads: int = 1,
        effort: int | None = None,
    ) -> None:
        params = _check_params(max_error, lossless, nodata, method, threads, effort)
        for key in _CONFIG_KEYS:
            object.__setattr__(self, key, params[key])

    # -- configuration ---------------------------------------------------------------

    @classmethod
    def from_dict(cls, data: dict[str, JSON]) -> Self:
        """Build the codec from its Zarr v3 metadata.

        Parameters
        ----------
        data : dict
            ``{"name": "vtz", "configuration": {...}}``; the configuration may be left out
            (all defaults), unknown keys are an error.

        Returns
        -------
        VtzCodec
        """
        _, configuration = parse_named_configuration(data, CODEC_NAME, require_configuration=False)
        configuration = dict(configuration or {})
        unknown = sorted(set(configuration) - set(_CONFIG_KEYS))
        if unknown:
            raise vtz.InvalidArgumentError(f"unknown vtz codec parameters: {', '.join(unknown)}")
        return cls(**configuration)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, JSON]:
        """The codec's Zarr v3 metadata.

        Returns
        -------
        dict
            ``{"name": "vtz", "configuration": {"max_error": ..., "lossless": ...,
            "nodata": ..., "method": ..., "threads": ...}}`` (plain JSON types), and
            ``"effort"`` when it is set.
        """
        return {"name": CODEC_NAME, "configuration": _config(self)}

    # -- checks against the array ----------------------------------------------------

    def validate(
        self,
        *,
        shape: tuple[int, ...],
        dtype: ZDType[TBaseDType, TBaseScalar],
        chunk_grid: ChunkGrid,
    ) -> None:
        """Check that vtz can hold the array's chunks.

        Parameters
        ----------
        shape : tuple of int
            The array's shape.
        dtype : ZDType
            The array's data type: uint8, int16, uint16, int32, float32 or float64.
        chunk_grid : ChunkGrid
            The chunk grid: its chunk shape must be 2-D once leading size-1 axes are
            dropped (or 1-D).

        Raises
        ------
        vtz.InvalidArgumentError
            The dtype or the chunk shape cannot be coded.
        """
        _check_dtype(dtype.to_native_dtype())
        chunk_shape = getattr(chunk_grid, "chunk_shape", None)
        if chunk_shape is not None:
            _plane_shape(tuple(chunk_shape))

    def evolve_from_array_spec(self, array_spec: ArraySpec) -> Self:
        """Check the codec against the array (or, inside a shard, the inner chunk) spec.

        Zarr calls this for every codec, including those inside a sharding codec, which
        :meth:`validate` does not reach. Nothing is inferred: the codec comes back as is.

        Parameters
        ----------
        array_spec : ArraySpec
            The spec: its dtype must be one vtz holds; a float array whose fill value is
            NaN cannot have a non-NaN ``nodata`` (its padding and unwritten chunks would be
            NaN, while vtz decodes NaN samples as the nodata value).

        Returns
        -------
        VtzCodec
            ``self``.
        """
        dt = _check_dtype(array_spec.dtype.to_native_dtype())
        fill = array_spec.fill_value
        if dt.kind == "f" and self.nodata is not None and fill is not None:
            if math.isnan(float(fill)):
                raise vtz.InvalidArgumentError(
                    f"the fill value is NaN but nodata is {self.nodata}: NaN is nodata in float "
                    "arrays, so leave nodata=None (or use fill_value=nodata)"
                )
        return self

    def compute_encoded_size(self, input_byte_length: int, chunk_spec: ArraySpec) -> int:
        """Not known in advance: vtz streams have a variable size.

        Raises
        ------
        NotImplementedError
            Always (zarr's convention for variable-size codecs).
        """
        raise NotImplementedError("vtz chunks have a variable encoded size")

    # -- encoding and decoding -------------------------------------------------------

    def _encode_sync(self, chunk_array: NDBuffer, chunk_spec: ArraySpec) -> Buffer | None:
        """Encode one chunk in the calling thread (see :meth:`_encode_single`)."""
        plane = _as_plane(chunk_array.as_numpy_array())
        data = vtz.encode(
            plane,
            max_error=self.max_error,
            lossless=self.lossless,
            nodata=self.nodata,
            method=self.method,
            threads=self.threads,
            effort=self.effort,
        )
        return chunk_spec.prototype.buffer.from_bytes(data)

    async def _encode_single(self, chunk_array: NDBuffer, chunk_spec: ArraySpec) -> Buffer | None:
        """Encode one chunk into a vtz stream, in a worker thread.

        Parameters
        ----------
        chunk_array : NDBuffer
            The chunk, of ``chunk_spec.shape`` (edge chunks come padded with the fill value).
        chunk_spec : ArraySpec
            The chunk's shape, dtype, fill value and buffer prototype.

        Returns
        -------
        Buffer
            The vtz stream.
        """
        return await asyncio.to_thread(self._encode_sync, chunk_array, chunk_spec)

    def _decode_bytes(self, data: bytes, chunk_spec: ArraySpec, where: str) -> np.ndarray:
        """Decode a stream as the 2-D plane of a chunk; errors name the chunk by ``where``.

        The stream must hold a raster of the chunk's 2-D shape and dtype, else
        ``vtz.CorruptError``: a sound stream that is not this array's chunk is damage to
        the store too.
        """
        plane = _plane_shape(chunk_spec.shape)
        dtype = _check_dtype(chunk_spec.dtype.to_native_dtype())
        try:
            out = vtz.decode(data, threads=self.threads)
        except vtz.VtzError as err:
            raise _renamed(err, where) from err
        if out.shape != plane or out.dtype != dtype:
            raise vtz.CorruptError(
                f"{where}: the stream holds a {out.shape[0]}x{out.shape[1]} {out.dtype} raster, "
                f"the array's chunks are {plane[0]}x{plane[1]} {dtype}"
            )
        return out

    def _decode_sync(self, chunk_bytes: Buffer, chunk_spec: ArraySpec) -> NDBuffer:
        """Decode one chunk in the calling thread (see :meth:`_decode_single`)."""
        out = self._decode_bytes(chunk_bytes.to_bytes(), chunk_spec, _describe_spec(chunk_spec))
        return chunk_spec.prototype.nd_buffer.from_numpy_array(out.reshape(chunk_spec.shape))

    async def _decode_single(self, chunk_bytes: Buffer, chunk_spec: ArraySpec) -> NDBuffer:
        """Decode one chunk, in a worker thread.

        Zarr uses this entry behind other codecs and when it merges a partial write; it
        gives no chunk key here, so errors name the chunk by its shape and dtype.

        Parameters
        ----------
        chunk_bytes : Buffer
            The vtz stream.
        chunk_spec : ArraySpec
            The chunk's shape and dtype (the decoded stream must match them).

        Returns
        -------
        NDBuffer
            The chunk, of ``chunk_spec.shape`` and dtype.

        Raises
        ------
        vtz.CorruptError
            The stream is damaged or does not hold a chunk of this shape and dtype.
        """
        return await asyncio.to_thread(self._decode_sync, chunk_bytes, chunk_spec)

    async def _decode_partial_single(
        self, byte_getter: ByteGetter, selection: SelectorTuple, chunk_spec: ArraySpec
    ) -> NDBuffer | None:
        """Read one chunk from the store and decode the part ``selection`` asks for.

        Zarr uses this entry when the vtz codec is the array's only codec; it is here for
        the chunk's store key, which names the chunk in errors. The whole chunk is decoded
        (a vtz window decode costs nearly as much at chunk sizes, which vtz does not tile).

        Parameters
        ----------
        byte_getter : ByteGetter
            The chunk's place in the store (a ``StorePath``, or an inner chunk of a shard).
        selection : tuple
            The chunk's samples wanted (slices, integers or index arrays).
        chunk_spec : ArraySpec
            The chunk's shape, dtype and buffer prototype.

        Returns
        -------
        NDBuffer or None
            ``chunk[selection]``, or ``None`` when the chunk is not in the store.

        Raises
        ------
        vtz.CorruptError
            The chunk is damaged; the message names it by its store key.
        """
        chunk_bytes = await byte_getter.get(prototype=chunk_spec.prototype)
        if chunk_bytes is None:
            return None
        where = _describe_chunk(byte_getter)
        out = await asyncio.to_thread(self._decode_bytes, chunk_bytes.to_bytes(), chunk_spec, where)
        part = out.reshape(chunk_spec.shape)[selection]
        return chunk_spec.prototype.nd_buffer.from_numpy_array(np.asarray(part))


register_codec(CODEC_NAME, VtzCodec)
