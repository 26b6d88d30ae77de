"""Tests of the chunk codecs: ``vtz.numcodecs.Vtz`` (numcodecs, Zarr format 2) and
``vtz.zarr.VtzCodec`` (Zarr format 3).

Every test checks a property that can fail: the bound on every valid sample (exact when
lossless), nodata/NaN positions kept, configurations surviving JSON, clear exceptions for
what vtz cannot hold, and a damaged chunk in a store named in the error while the other
chunks still read.
"""

from __future__ import annotations

import json
import math
import os
import pickle
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

numcodecs = pytest.importorskip("numcodecs")
zarr = pytest.importorskip("zarr")
hypothesis = pytest.importorskip("hypothesis")

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import vtz  # noqa: E402
from vtz.numcodecs import Vtz  # noqa: E402
from vtz.zarr import VtzCodec  # noqa: E402

CORPUS = Path(__file__).resolve().parents[2] / "corpus"
DTYPES = ["uint8", "int16", "uint16", "int32", "float32", "float64"]


# -- data and checks --------------------------------------------------------------------


def terrain(rng: np.random.Generator, shape, dtype, amplitude: float = 500.0, noise: float = 0.0):
    """A smooth random surface (a double random walk, scaled) plus optional noise, as ``dtype``.

    Integer dtypes are clipped to their range, so large amplitudes reach the extremes.
    """
    h, w = shape
    walk = np.cumsum(np.cumsum(rng.normal(size=(h, w)), axis=0), axis=1)
    span = np.ptp(walk) or 1.0
    z = (walk - walk.min()) / span * amplitude + noise * rng.normal(size=(h, w))
    dt = np.dtype(dtype)
    if dt.kind in "ui":
        info = np.iinfo(dt)
        z = z + (info.min if dt.kind == "i" and amplitude > info.max else 0)
        z = np.clip(np.round(z), info.min, info.max)
    return z.astype(dt)


def check_decoded(original, decoded, bound, nodata=None):
    """Assert the codec's contract: shape and dtype kept, nodata (and NaN) positions kept,
    every valid sample within ``bound`` (``None``: exactly equal)."""
    original = np.asarray(original)
    decoded = np.asarray(decoded)
    assert decoded.shape == original.shape
    assert decoded.dtype == original.dtype
    o = original.astype(np.float64)
    d = decoded.astype(np.float64)
    invalid = np.isnan(o)
    if nodata is not None:
        invalid |= o == nodata
    assert not np.isnan(d[~invalid]).any(), "a valid sample decoded to NaN"
    if nodata is None:
        assert np.isnan(d[invalid]).all(), "a NaN sample did not decode to NaN"
    else:
        assert (d[invalid] == nodata).all(), "a nodata sample did not decode to nodata"
    err = np.abs(d[~invalid] - o[~invalid])
    if err.size == 0:
        return
    if bound is None:
        assert err.max() == 0, f"lossless coding changed a sample by {err.max()}"
    else:
        assert err.max() <= bound, f"error {err.max()} over the bound {bound}"


def bound_for(dtype, frac: float = 0.01, amplitude: float = 500.0):
    """A bound that is lossy for this dtype's test data (at least 1 for integers)."""
    b = amplitude * frac
    return max(1.0, round(b)) if np.dtype(dtype).kind in "ui" else b


def v3_array(store, data, chunks, codec, fill_value=0, **kw):
    """A Zarr v3 array holding ``data``, vtz as the serializer and nothing after it."""
    z = zarr.create_array(
        store,
        shape=data.shape,
        chunks=chunks,
        dtype=data.dtype,
        serializer=codec,
        compressors=None,
        fill_value=fill_value,
        **kw,
    )
    z[...] = data
    return z


# -- numcodecs codec --------------------------------------------------------------------


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("lossless", [True, False])
def test_numcodecs_round_trip_dtypes(dtype, lossless):
    rng = np.random.default_rng(DTYPES.index(dtype))
    a = terrain(rng, (40, 57), dtype, amplitude=200.0, noise=1.0)
    bound = None if lossless else bound_for(dtype, amplitude=200.0)
    codec = Vtz(lossless=True) if lossless else Vtz(max_error=bound)
    enc = codec.encode(a)
    assert isinstance(enc, bytes)
    assert vtz.info(enc)["width"] == 57 and vtz.info(enc)["height"] == 40
    check_decoded(a, codec.decode(enc), bound)


def test_numcodecs_decode_into_out():
    """``out`` of another shape (numcodecs passes flat buffers) is filled, and returned."""
    a = terrain(np.random.default_rng(1), (30, 20), "int16")
    codec = Vtz(max_error=2)
    enc = codec.encode(a)
    flat = np.zeros(600, dtype="int16")
    got = codec.decode(enc, out=flat)
    assert got is flat
    check_decoded(a, flat.reshape(30, 20), 2)
    # from a memoryview / uint8 array of the bytes, as zarr hands them over
    check_decoded(a, codec.decode(np.frombuffer(enc, dtype="uint8")), 2)
    check_decoded(a, codec.decode(memoryview(enc)), 2)


def test_numcodecs_config_json_round_trip():
    codec = Vtz(max_error=0.75, nodata=-9999, method="grid", threads=2)
    config = codec.get_config()
    text = json.dumps(config, allow_nan=False)  # plain JSON: no NaN, no numpy types
    back = numcodecs.get_codec(json.loads(text))
    assert isinstance(back, Vtz)
    assert back == codec
    assert back.get_config() == config == {
        "id": "vtz",
        "max_error": 0.75,
        "lossless": False,
        "nodata": -9999,
        "method": "grid",
        "threads": 2,
    }
    a = terrain(np.random.default_rng(2), (33, 21), "float32")
    a[3:6, 4:9] = -9999
    assert back.encode(a) == codec.encode(a)
    check_decoded(a, back.decode(codec.encode(a)), 0.75, nodata=-9999)
    # defaults survive too, and numpy scalars become plain numbers
    d = Vtz(max_error=np.float32(0.5), nodata=np.int16(-32768)).get_config()
    assert type(d["max_error"]) is float and type(d["nodata"]) is int
    assert json.loads(json.dumps(Vtz().get_config())) == Vtz().get_config()


def test_numcodecs_effort_in_the_config():
    """``effort`` is recorded when set, reaches the encoder, and a configuration written
    before it existed (none) still loads as the default."""
    a, profile = corpus("srtm3_N22W160_kauai.hgt")
    a = np.ascontiguousarray(a[:400, :400])
    codec = Vtz(max_error=1.0, method="residual", effort=6)
    config = codec.get_config()
    assert config["effort"] == 6
    back = numcodecs.get_codec(json.loads(json.dumps(config, allow_nan=False)))
    assert back == codec and back.effort == 6
    enc = back.encode(a)
    assert enc == vtz.encode(a, max_error=1.0, method="residual", effort=6)
    assert enc != Vtz(max_error=1.0, method="residual").encode(a)
    check_decoded(a, back.decode(enc), 1.0)
    old = {"id": "vtz", "max_error": 1.0, "lossless": False, "nodata": None,
           "method": "residual", "threads": 1}
    assert Vtz.from_config(old).effort is None
    assert Vtz.from_config(old) == Vtz(max_error=1.0, method="residual")
    assert "effort" not in Vtz().get_config()
    assert Vtz(effort=np.int64(2)).get_config()["effort"] == 2
    with pytest.raises(vtz.InvalidArgumentError, match=r"1\.\.=9"):
        Vtz(effort="fast")
    # an effort outside 1..9 loads (a store opens for reading) and fails when encoding
    with pytest.raises(vtz.InvalidArgumentError, match=r"effort 10 is not an integer in 1\.\.=9"):
        Vtz.from_config({"id": "vtz", "effort": 10}).encode(a)


def test_numcodecs_nan_nodata_is_none():
    """NaN is always nodata in float chunks: ``nodata=NaN`` is stored as ``None`` (JSON-safe)."""
    codec = Vtz(max_error=0.5, nodata=float("nan"))
    assert codec.nodata is None
    a = terrain(np.random.default_rng(3), (20, 20), "float64")
    a[2:5, 2:5] = np.nan
    check_decoded(a, codec.decode(codec.encode(a)), 0.5)


def test_numcodecs_pickle():
    codec = Vtz(max_error=1.5, method="residual")
    back = pickle.loads(pickle.dumps(codec))
    assert back == codec and back.get_config() == codec.get_config()


def test_numcodecs_shapes():
    codec = Vtz(max_error=1)
    rng = np.random.default_rng(4)
    # 1-D: coded as 1 x n
    line = terrain(rng, (1, 50), "int16")[0]
    out = codec.decode(codec.encode(line))
    assert out.shape == (1, 50)
    check_decoded(line, out.reshape(50), 1)
    # leading axes of size 1 are dropped
    cube = terrain(rng, (12, 13), "uint16").reshape(1, 1, 12, 13)
    check_decoded(cube[0, 0], codec.decode(codec.encode(cube)), 1)
    # a Fortran-ordered chunk is coded as the buffer holds it (its transpose), a strided
    # view row by row, big-endian input converted: none refused
    t = terrain(rng, (16, 24), "float32").T
    check_decoded(t.T, codec.decode(codec.encode(t)), 1)
    check_decoded(t, codec.decode(codec.encode(t), out=np.empty_like(t)), 1)
    v = terrain(rng, (32, 48), "float32")[::2, ::3]
    assert not (v.flags.c_contiguous or v.flags.f_contiguous)
    check_decoded(v, codec.decode(codec.encode(v)), 1)
    be = terrain(rng, (10, 11), "int32").astype(">i4")
    check_decoded(be.astype("int32"), codec.decode(codec.encode(be)), 1)
    # a genuine 3-D chunk is refused with a message that says why
    with pytest.raises(vtz.InvalidArgumentError, match=r"2-D chunks.*\(2, 8, 8\)"):
        codec.encode(np.zeros((2, 8, 8), "int16"))
    with pytest.raises(vtz.InvalidArgumentError, match="0-D"):
        codec.encode(np.int16(3))


def layouts(a):
    """``a`` as the layouts numcodecs' callers can hand a codec: C-ordered, Fortran-ordered,
    and a strided view (neither), each holding the same values."""
    big = np.zeros((a.shape[0] * 2, a.shape[1] * 3), dtype=a.dtype)
    strided = big[::2, 1::3]
    strided[...] = a
    assert not (strided.flags.c_contiguous or strided.flags.f_contiguous)
    return {"C": np.ascontiguousarray(a), "F": np.asfortranarray(a), "strided": strided}


def out_buffers(a):
    """Empty ``out`` buffers of ``a``'s shape and dtype in each layout of :func:`layouts`."""
    return {k: np.zeros_like(v) if k != "strided" else layouts(np.zeros_like(a))[k]
            for k, v in layouts(a).items()}


@pytest.mark.parametrize("dtype", ["float32", "int16"])
def test_numcodecs_follows_memory_order_as_zlib(dtype):
    """numcodecs' contract: a codec codes the samples in the order the buffer holds them and
    decodes into ``out`` in ``out``'s order. Lossless, vtz gives what ``Zlib`` gives for
    every C/F input and C/F/strided ``out`` (Zlib refuses strided input; vtz codes it row by
    row), directly and through ``ndarray_copy`` (zarr-python 2's path)."""
    from numcodecs.compat import ndarray_copy

    a = terrain(np.random.default_rng(7), (24, 37), dtype, amplitude=3000.0, noise=2.0)
    vc, zl = Vtz(lossless=True), numcodecs.Zlib()
    for kin, x in layouts(a).items():
        enc = vc.encode(x)
        for kout, y in out_buffers(a).items():
            got = vc.decode(enc, out=y)
            assert got is y
            via_copy = ndarray_copy(vc.decode(enc), np.zeros_like(y) if kout != "strided"
                                    else out_buffers(a)["strided"])
            if kin == "strided":
                # Zlib takes no strided input; vtz codes it row by row, as C order
                want = ndarray_copy(zl.decode(zl.encode(x.copy())), np.zeros_like(y))
            else:
                want = ndarray_copy(zl.decode(zl.encode(x)), np.zeros_like(y))
            np.testing.assert_array_equal(y, want, err_msg=f"{kin} in, {kout} out")
            np.testing.assert_array_equal(via_copy, want, err_msg=f"{kin} in, {kout} via copy")
        # same layout in and out: the chunk itself
        same = out_buffers(a)["F" if kin == "F" else "C"]
        check_decoded(a, vc.decode(enc, out=same), None)


@pytest.mark.parametrize("dtype", ["float32", "int16"])
@pytest.mark.parametrize("order", ["C", "F"])
def test_numcodecs_lossy_into_out_of_the_same_order(dtype, order):
    """A lossy chunk decodes within the bound into an ``out`` of its own layout (zarr-python
    2 decodes a chunk straight into the array's memory), and into a flat buffer as
    ``ndarray_copy`` reshapes it; the no-``out`` decode holds the buffer's order."""
    from numcodecs.compat import ndarray_copy

    a = terrain(np.random.default_rng(8), (40, 29), dtype, amplitude=5000.0, noise=3.0)
    x = np.asarray(a, order=order)
    bound = 2.0
    codec = Vtz(max_error=bound)
    enc = codec.encode(x)
    check_decoded(a, codec.decode(enc, out=np.empty_like(x)), bound)
    flat = codec.decode(enc, out=np.empty(a.size, a.dtype))
    check_decoded(a, flat.reshape(a.shape, order=order), bound)
    back = codec.decode(enc)
    check_decoded(a if order == "C" else a.T, back, bound)
    check_decoded(a, ndarray_copy(back, np.empty_like(x)), bound)


def test_numcodecs_out_is_checked():
    """``out`` of another dtype, size, or read-only is refused (never a reinterpretation of
    the samples' bits, as ``ndarray_copy``'s ``view`` would do); a byte buffer of the
    chunk's size gets its native bytes; another byte order is converted."""
    a = terrain(np.random.default_rng(9), (12, 10), "int16")
    codec = Vtz(lossless=True)
    enc = codec.encode(a)
    with pytest.raises(vtz.InvalidArgumentError, match="dtype float32.*int16"):
        codec.decode(enc, out=np.empty((6, 10), "float32"))
    with pytest.raises(vtz.InvalidArgumentError, match="dtype int8"):
        codec.decode(enc, out=np.empty(240, "int8"))
    with pytest.raises(vtz.InvalidArgumentError, match="holds 121 samples.*120"):
        codec.decode(enc, out=np.empty(121, "int16"))
    ro = np.empty(120, "int16")
    ro.flags.writeable = False
    with pytest.raises(vtz.InvalidArgumentError, match="read-only"):
        codec.decode(enc, out=ro)
    raw = bytearray(a.nbytes)
    assert codec.decode(enc, out=raw) is raw and bytes(raw) == a.tobytes()
    with pytest.raises(vtz.InvalidArgumentError, match="holds 239 bytes"):
        codec.decode(enc, out=bytearray(239))
    be = np.empty((12, 10), ">i2")
    codec.decode(enc, out=be)
    np.testing.assert_array_equal(be, a)


@pytest.mark.parametrize("dtype", ["int8", "bool", "complex64", "float16", "int64", "uint32"])
def test_numcodecs_unsupported_dtype(dtype):
    with pytest.raises(vtz.InvalidArgumentError, match=f"cannot hold dtype {dtype}"):
        Vtz().encode(np.zeros((4, 4), dtype))


def test_numcodecs_bad_parameters():
    with pytest.raises(vtz.InvalidArgumentError, match="exclude each other"):
        Vtz(max_error=1, lossless=True)
    with pytest.raises(vtz.InvalidArgumentError, match="finite number >= 0"):
        Vtz(max_error=-1)
    with pytest.raises(vtz.InvalidArgumentError, match="finite number >= 0"):
        Vtz(max_error=float("inf"))
    with pytest.raises(TypeError, match="max_error must be a number"):
        Vtz(max_error="1%")
    with pytest.raises(TypeError, match="lossless"):
        Vtz(lossless="yes")
    with pytest.raises(vtz.InvalidArgumentError, match="nodata -inf is not finite"):
        Vtz(nodata=-math.inf)
    with pytest.raises(vtz.InvalidArgumentError, match="negative"):
        Vtz(threads=-1)
    with pytest.raises(vtz.InvalidArgumentError, match="unknown vtz codec parameters: level"):
        numcodecs.get_codec({"id": "vtz", "level": 5})
    # an unknown method is vtz's to report, at encode time (reading never needs it)
    codec = Vtz(method="no-such-method")
    with pytest.raises(vtz.InvalidArgumentError, match="unknown method"):
        codec.encode(np.zeros((4, 4), "int16"))


@pytest.mark.parametrize("dtype", ["uint8", "int16", "uint16", "int32"])
@pytest.mark.parametrize("method", [None, "grid"])
def test_integer_extremes_stay_in_range(dtype, method):
    """A lossy chunk holding its dtype's extremes decodes (within the bound, in range).

    Minimal case found by the zarr property test: uint8 [[255, 0, 0, ...]] (1 x 33),
    max_error 6 decoded 260 with the grid method, which ``best`` picks.
    """
    info = np.iinfo(dtype)
    a = np.zeros((1, 33), dtype)
    a[0, 0], a[0, 5] = info.max, info.min
    codec = Vtz(max_error=6.0, method=method)
    check_decoded(a, codec.decode(codec.encode(a)), 6.0)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty"])
def test_numcodecs_corrupt_bytes(damage):
    codec = Vtz(max_error=1)
    enc = codec.encode(terrain(np.random.default_rng(5), (32, 32), "int16"))
    bad = {"garbage": b"\x00garbage" * 8, "truncated": enc[: len(enc) // 2], "empty": b""}[damage]
    with pytest.raises(vtz.CorruptError):
        codec.decode(bad)


def test_entry_points_in_a_fresh_interpreter(tmp_path):
    """The entry points alone (no import of vtz's codec modules) find both codecs: numcodecs'
    ``get_codec`` and zarr opening v3 and v2 stores written with them."""
    a = terrain(np.random.default_rng(6), (50, 70), "float32")
    a[10:20, 10:20] = np.nan
    np.save(tmp_path / "a.npy", a)
    v3_array(zarr.storage.LocalStore(tmp_path / "v3.zarr"), a, (32, 32), VtzCodec(max_error=0.5),
             fill_value=np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        z2 = zarr.create_array(zarr.storage.LocalStore(tmp_path / "v2.zarr"), shape=a.shape,
                               chunks=(32, 32), dtype=a.dtype, zarr_format=2,
                               compressors=Vtz(max_error=0.5), filters=None, fill_value=np.nan)
    z2[...] = a
    script = textwrap.dedent(f"""
        import sys, numpy as np, numcodecs, zarr
        codec = numcodecs.get_codec({{"id": "vtz", "max_error": 1.0}})
        assert type(codec).__module__ == "vtz.numcodecs", type(codec)
        a = np.load({str(tmp_path / "a.npy")!r})
        for name in ("v3.zarr", "v2.zarr"):
            b = zarr.open_array({str(tmp_path)!r} + "/" + name, mode="r")[...]
            valid = ~np.isnan(a)
            assert np.array_equal(np.isnan(b), ~valid), name
            assert np.abs(b[valid] - a[valid]).max() <= 0.5, name
        print("ok", "vtz.zarr" in sys.modules)
    """)
    # the entry points are read from the installed distribution's metadata
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["ok", "True"]


# -- Zarr v3 codec: configuration and validation ----------------------------------------


def test_zarr_codec_dict_round_trip():
    codec = VtzCodec(max_error=2.5, nodata=-32768, method="residual", threads=0)
    d = codec.to_dict()
    assert d == {
        "name": "vtz",
        "configuration": {"max_error": 2.5, "lossless": False, "nodata": -32768,
                          "method": "residual", "threads": 0},
    }
    back = VtzCodec.from_dict(json.loads(json.dumps(d, allow_nan=False)))
    assert back == codec
    assert VtzCodec.from_dict({"name": "vtz"}) == VtzCodec()
    assert pickle.loads(pickle.dumps(codec)) == codec
    with pytest.raises(vtz.InvalidArgumentError, match="unknown vtz codec parameters: level"):
        VtzCodec.from_dict({"name": "vtz", "configuration": {"level": 3}})
    with pytest.raises(ValueError):
        VtzCodec.from_dict({"name": "bytes", "configuration": {}})
    with pytest.raises(vtz.InvalidArgumentError, match="exclude each other"):
        VtzCodec(max_error=1, lossless=True)


def test_zarr_codec_effort_round_trips(tmp_path):
    """``effort`` goes into the store's metadata, comes back when the store is opened, and
    the chunks it wrote decode within the bound; a configuration without it loads."""
    a, profile = corpus("srtm3_N22W160_kauai.hgt")
    nodata = int(profile["nodata"])
    a = np.ascontiguousarray(a[:600, :600])
    codec = VtzCodec(max_error=1, nodata=nodata, method="residual", effort=1)
    assert codec.to_dict()["configuration"]["effort"] == 1
    assert VtzCodec.from_dict(json.loads(json.dumps(codec.to_dict()))) == codec
    assert codec != VtzCodec(max_error=1, nodata=nodata, method="residual")
    v3_array(zarr.storage.LocalStore(tmp_path / "e.zarr"), a, (300, 300), codec,
             fill_value=nodata)
    meta = json.loads((tmp_path / "e.zarr" / "zarr.json").read_text())
    assert meta["codecs"][0]["configuration"]["effort"] == 1
    z = zarr.open_array(zarr.storage.LocalStore(tmp_path / "e.zarr"), mode="r")
    assert z.metadata.codecs[0] == codec
    check_decoded(a, z[...], 1, nodata=nodata)
    chunk = (tmp_path / "e.zarr" / "c" / "0" / "0").read_bytes()
    assert chunk == vtz.encode(np.ascontiguousarray(a[:300, :300]), max_error=1, nodata=nodata,
                               method="residual", threads=1, effort=1)
    old = {"name": "vtz", "configuration": {"max_error": 1.0, "lossless": False,
                                            "nodata": -1, "method": None, "threads": 1}}
    assert VtzCodec.from_dict(old).effort is None
    assert "effort" not in VtzCodec().to_dict()["configuration"]
    with pytest.raises(vtz.InvalidArgumentError, match=r"1\.\.=9"):
        VtzCodec(effort=2.5)
    bad = VtzCodec.from_dict({"name": "vtz", "configuration": {"effort": 0}})
    with pytest.raises(vtz.InvalidArgumentError, match=r"effort 0 is not an integer in 1\.\.=9"):
        v3_array(zarr.storage.MemoryStore(), terrain(np.random.default_rng(8), (20, 20), "int16"),
                 (10, 10), bad)


def test_zarr_metadata_names_the_codec(tmp_path):
    a = terrain(np.random.default_rng(7), (20, 20), "int16")
    v3_array(zarr.storage.LocalStore(tmp_path / "a.zarr"), a, (10, 10),
             VtzCodec(max_error=1, nodata=-1))
    meta = json.loads((tmp_path / "a.zarr" / "zarr.json").read_text())
    assert meta["codecs"] == [{"name": "vtz", "configuration": {
        "max_error": 1.0, "lossless": False, "nodata": -1, "method": None, "threads": 1}}]


@pytest.mark.parametrize("dtype", ["int8", "bool", "int64", "float16", "complex64"])
def test_zarr_rejects_dtypes(dtype):
    with pytest.raises(vtz.InvalidArgumentError, match=f"cannot hold dtype {dtype}"):
        zarr.create_array({}, shape=(8, 8), chunks=(4, 4), dtype=dtype, serializer=VtzCodec(),
                          compressors=None)


@pytest.mark.parametrize("chunks", [(2, 8, 8), (4, 1, 8)])
def test_zarr_rejects_chunks_not_2d(chunks):
    with pytest.raises(vtz.InvalidArgumentError, match="2-D chunks"):
        zarr.create_array({}, shape=(4, 8, 8), chunks=chunks, dtype="int16",
                          serializer=VtzCodec(), compressors=None)


def test_zarr_rejects_nan_fill_with_nodata():
    with pytest.raises(vtz.InvalidArgumentError, match="fill value is NaN but nodata is -9999"):
        zarr.create_array({}, shape=(8, 8), chunks=(4, 4), dtype="float32",
                          serializer=VtzCodec(nodata=-9999), compressors=None, fill_value=np.nan)


def test_zarr_variable_size():
    assert VtzCodec.is_fixed_size is False
    with pytest.raises(NotImplementedError):
        VtzCodec().compute_encoded_size(100, None)


# -- Zarr v3 codec: round trips ---------------------------------------------------------


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("lossless", [True, False])
def test_zarr_round_trip_dtypes_partial_chunks(tmp_path, dtype, lossless):
    """Chunks (40, 48) do not divide (100, 130): the edge chunks are padded by zarr."""
    rng = np.random.default_rng(10 + DTYPES.index(dtype))
    a = terrain(rng, (100, 130), dtype, amplitude=300.0, noise=0.5)
    bound = None if lossless else bound_for(dtype, amplitude=300.0)
    codec = VtzCodec(lossless=True) if lossless else VtzCodec(max_error=bound)
    v3_array(zarr.storage.LocalStore(tmp_path / "a.zarr"), a, (40, 48), codec)
    z = zarr.open_array(zarr.storage.LocalStore(tmp_path / "a.zarr"), mode="r")
    assert z.metadata.codecs == (codec,)
    check_decoded(a, z[...], bound)
    # each stored chunk is a vtz stream of the chunk's full (padded) shape
    enc = (tmp_path / "a.zarr" / "c" / "2" / "2").read_bytes()
    assert (vtz.info(enc)["height"], vtz.info(enc)["width"]) == (40, 48)
    assert vtz.info(enc)["dtype"] == dtype


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_zarr_nan_fill_and_holes(tmp_path, dtype):
    rng = np.random.default_rng(20)
    a = terrain(rng, (90, 75), dtype, amplitude=1000.0, noise=0.2)
    a[rng.random(a.shape) < 0.05] = np.nan  # scattered holes
    a[30:45, 10:70] = np.nan  # a large void crossing chunk borders
    a[64:, 64:] = np.nan  # a whole (partial) edge chunk of nothing: not stored at all
    root = tmp_path / "a.zarr"
    z = v3_array(zarr.storage.LocalStore(root), a, (32, 32), VtzCodec(max_error=0.5),
                 fill_value=np.nan)
    assert (root / "c" / "2" / "1").is_file() and not (root / "c" / "2" / "2").exists()
    check_decoded(a, z[...], 0.5)
    # a region never written reads as the fill value
    z2 = zarr.create_array({}, shape=(40, 40), chunks=(16, 16), dtype=dtype,
                           serializer=VtzCodec(max_error=0.5), compressors=None, fill_value=np.nan)
    z2[:10, :10] = a[:10, :10]
    out = z2[...]
    check_decoded(a[:10, :10], out[:10, :10], 0.5)
    assert np.isnan(out[16:, 16:]).all()


def test_zarr_integer_nodata_fill():
    """nodata = fill value: voids and the edge padding are exact, the rest within the bound."""
    rng = np.random.default_rng(21)
    a = terrain(rng, (70, 90), "int16", amplitude=2000.0)
    a[10:25, 30:50] = -32768
    z = v3_array(zarr.storage.MemoryStore(), a, (32, 40), VtzCodec(max_error=3, nodata=-32768),
                 fill_value=-32768)
    check_decoded(a, z[...], 3, nodata=-32768)


def test_zarr_leading_unit_axes():
    """A (band, y, x) array chunked (1, ny, nx): each chunk is coded as its 2-D plane."""
    rng = np.random.default_rng(22)
    a = np.stack([terrain(rng, (50, 45), "uint16", amplitude=900.0) for _ in range(3)])
    z = v3_array(zarr.storage.MemoryStore(), a, (1, 32, 32), VtzCodec(max_error=2))
    check_decoded(a, z[...], 2)
    check_decoded(a[1, 5:40, 7], z[1, 5:40, 7], 2)


def test_zarr_one_dimensional():
    a = terrain(np.random.default_rng(23), (1, 300), "float32")[0]
    z = v3_array(zarr.storage.MemoryStore(), a, (128,), VtzCodec(max_error=0.1))
    check_decoded(a, z[...], 0.1)
    check_decoded(a[100:200], z[100:200], 0.1)


def test_zarr_partial_reads_match_full_read():
    """Reads of parts of chunks (the codec's partial-decode entry applies zarr's selection to
    the decoded chunk) give exactly the samples of a full read, for every kind of selection."""
    rng = np.random.default_rng(24)
    a = terrain(rng, (150, 140), "float32", amplitude=800.0, noise=0.5)
    a[40:60, 40:60] = np.nan
    z = v3_array(zarr.storage.MemoryStore(), a, (64, 64), VtzCodec(max_error=1.0),
                 fill_value=np.nan)
    full = z[...]
    check_decoded(a, full, 1.0)
    for sel in [
        (slice(5, 70), slice(3, 9)),
        (slice(65, 66), slice(3, 139)),
        (65, slice(3, 139)),
        (slice(None), 7),
        (slice(None, None, 3), slice(1, 100, 7)),
        (slice(130, 150), slice(130, 140)),
        (-1, -1),
    ]:
        assert np.array_equal(z[sel], full[sel], equal_nan=True), sel
    rows, cols = [1, 5, 80, 149], [3, 64, 100]
    assert np.array_equal(z.oindex[rows, cols], full[np.ix_(rows, cols)], equal_nan=True)
    assert np.array_equal(z.vindex[rows, cols[:1] * 4], full[rows, cols[:1] * 4], equal_nan=True)
    mask = np.zeros(a.shape, bool)
    mask[::17, ::13] = True
    assert np.array_equal(z.vindex[mask], full[mask], equal_nan=True)


def test_zarr_sharding_inner_codec():
    a = terrain(np.random.default_rng(25), (120, 100), "int32", amplitude=5e5)
    z = zarr.create_array(zarr.storage.MemoryStore(), shape=a.shape, chunks=(32, 25),
                          shards=(64, 50), dtype=a.dtype, serializer=VtzCodec(max_error=10),
                          compressors=None, fill_value=0)
    z[...] = a
    check_decoded(a, z[...], 10)
    check_decoded(a[70:90, 3:60], z[70:90, 3:60], 10)


def test_zarr_with_a_compressor_after_vtz():
    """zarr adds zstd by default; it works (errors then cannot name the chunk)."""
    a = terrain(np.random.default_rng(26), (60, 60), "float64")
    z = zarr.create_array({}, shape=a.shape, chunks=(25, 25), dtype=a.dtype,
                          serializer=VtzCodec(max_error=0.01))
    assert len(z.metadata.codecs) == 2
    z[...] = a
    check_decoded(a, z[...], 0.01)


def corpus(name):
    path = CORPUS / name
    if not path.exists():
        pytest.skip(f"corpus file {path} is missing")
    return vtz.read(path)


def test_zarr_corpus_bigtujunga():
    """SRTM 30 m (643 x 1197 int16) in (200, 300) chunks: lossless, and within 1 m."""
    a, profile = corpus("srtm30m_bigtujunga_utm11.tif")
    store = zarr.storage.MemoryStore()
    check_decoded(a, v3_array(store, a, (200, 300), VtzCodec(lossless=True))[...], None)
    lossy = v3_array({}, a, (200, 300), VtzCodec(max_error=1.0, method="residual"))
    check_decoded(a, lossy[...], 1.0)
    check_decoded(a[150:420, 250:700], lossy[150:420, 250:700], 1.0)


def test_zarr_corpus_kauai():
    """SRTM 3" (1201 x 1201 int16, ocean voids -32768) in (512, 512) chunks, best method."""
    a, profile = corpus("srtm3_N22W160_kauai.hgt")
    nodata = int(profile["nodata"])
    assert (a == nodata).any()
    z = v3_array(zarr.storage.MemoryStore(), a, (512, 512), VtzCodec(max_error=2, nodata=nodata),
                 fill_value=nodata)
    check_decoded(a, z[...], 2, nodata=nodata)


# -- hypothesis: random arrays ----------------------------------------------------------


@st.composite
def chunk_arrays(draw, max_side=64):
    """(array, max_error or None, nodata or None) over every dtype, shape <= 64 x 64."""
    dtype = draw(st.sampled_from(DTYPES))
    h = draw(st.integers(1, max_side))
    w = draw(st.integers(1, max_side))
    seed = draw(st.integers(0, 2**32 - 1))
    kind = draw(st.sampled_from(["terrain", "noise", "constant", "steps", "full range"]))
    rng = np.random.default_rng(seed)
    dt = np.dtype(dtype)
    if dt.kind in "ui":
        amplitude = draw(st.sampled_from([1.0, 50.0, 1000.0, float(np.iinfo(dt).max) * 2]))
    else:
        amplitude = draw(st.sampled_from([1e-3, 1.0, 100.0, 1e4, 1e6]))
    if kind == "terrain":
        a = terrain(rng, (h, w), dtype, amplitude, noise=amplitude * 0.002)
    elif kind == "noise":
        a = terrain(rng, (h, w), dtype, 0.0, noise=amplitude)
    elif kind == "constant":
        a = terrain(rng, (h, w), dtype, 0.0) + np.asarray(min(amplitude, 200), dtype)
    elif kind == "steps":
        a = terrain(rng, (h, w), dtype, amplitude)
        a[:, : w // 2] = a[0, 0]
    elif dt.kind in "ui":  # uniform over the dtype's whole range, extremes included
        info = np.iinfo(dt)
        a = rng.integers(int(info.min), int(info.max), (h, w), endpoint=True).astype(dt)
        a.flat[rng.integers(0, h * w, 2)] = [info.min, info.max]
    else:
        a = rng.uniform(-amplitude, amplitude, (h, w)).astype(dt)
    lossless = draw(st.booleans())
    bound = None if lossless else draw(
        st.sampled_from([0.0, 0.25, 1.0, 7.5]) | st.floats(1e-3, amplitude, allow_nan=False))
    nodata = None
    holes = rng.random((h, w)) < draw(st.sampled_from([0.0, 0.0, 0.1, 0.6]))
    if holes.any():
        if dt.kind == "f" and draw(st.booleans()):
            a[holes] = np.nan
        else:
            nodata = int(np.iinfo(dt).min) if dt.kind in "ui" else -9999.0
            a[holes] = nodata
    return np.ascontiguousarray(a), bound, nodata


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chunk_arrays())
def test_property_numcodecs_bound(case):
    a, bound, nodata = case
    codec = Vtz(max_error=bound, nodata=nodata)
    enc = codec.encode(a)
    check_decoded(a, codec.decode(enc), bound, nodata=nodata)
    back = numcodecs.get_codec(json.loads(json.dumps(codec.get_config())))
    assert back.encode(a) == enc


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chunk_arrays(), st.data())
def test_property_zarr_bound(case, data):
    a, bound, nodata = case
    h, w = a.shape
    # at most 3 x 3 chunks, often not dividing the array, sometimes larger than it
    ch = data.draw(st.integers(math.ceil(h / 3), 64), label="chunk rows")
    cw = data.draw(st.integers(math.ceil(w / 3), 64), label="chunk cols")
    if nodata is not None:
        fill = nodata
    elif a.dtype.kind == "f" and data.draw(st.booleans(), label="nan fill"):
        fill = np.nan
    else:
        fill = 0
    z = v3_array(zarr.storage.MemoryStore(), a, (ch, cw),
                 VtzCodec(max_error=bound, nodata=nodata), fill_value=fill)
    check_decoded(a, z[...], bound, nodata=nodata)


# -- Zarr format 2 (numcodecs codec) ----------------------------------------------------


@pytest.mark.parametrize("where", ["compressor", "filter"])
def test_zarr_format2_numcodecs(tmp_path, where):
    """zarr-python 3 gives a v2 array's compressor (with no filters) or first filter the
    chunk as an array: the numcodecs codec works in either place."""
    rng = np.random.default_rng(30)
    a = terrain(rng, (100, 90), "float32", amplitude=400.0)
    a[5:30, 60:] = np.nan
    codec = Vtz(max_error=0.5)
    kw = {"compressors": codec, "filters": None} if where == "compressor" else {
        "compressors": None, "filters": [codec]}
    store = zarr.storage.LocalStore(tmp_path / "v2.zarr")
    z = zarr.create_array(store, shape=a.shape, chunks=(32, 40), dtype=a.dtype, zarr_format=2,
                          fill_value=np.nan, **kw)
    z[...] = a
    meta = json.loads((tmp_path / "v2.zarr" / ".zarray").read_text())
    stored = meta["compressor"] if where == "compressor" else meta["filters"][0]
    assert stored == codec.get_config()
    z = zarr.open_array(store, mode="r")
    check_decoded(a, z[...], 0.5)
    chunk = (tmp_path / "v2.zarr" / "3.2").read_bytes()  # a partial edge chunk
    assert vtz.info(chunk)["height"] == 32 and vtz.info(chunk)["width"] == 40
    # a damaged chunk: zarr's v2 path hands the codec bytes only, so the error cannot name
    # the chunk, but it is a CorruptError and the other chunks read
    (tmp_path / "v2.zarr" / "1.1").write_bytes(chunk[:-10])
    with pytest.raises(vtz.CorruptError):
        z[40:50, 45:50]
    check_decoded(a[:32], z[:32], 0.5)


@pytest.mark.parametrize("dtype", ["float32", "int16"])
@pytest.mark.parametrize("lossless", [True, False])
@pytest.mark.parametrize("where", ["compressor", "filter"])
@pytest.mark.parametrize("chunks", [(32, 40), (32, 32)])
def test_zarr_format2_fortran_order(tmp_path, dtype, lossless, where, chunks):
    """A Zarr format 2 array with ``order="F"`` reads back as written (zarr hands the codec
    Fortran-ordered chunks and reshapes their decode in that order), as with ``Zlib``;
    square chunks too (the decoded shape then matches the chunk's)."""
    rng = np.random.default_rng(31)
    a = terrain(rng, (100, 90), dtype, amplitude=6000.0, noise=5.0)
    bound = None if lossless else 3.0
    codec = Vtz(lossless=True) if lossless else Vtz(max_error=bound)
    kw = {"compressors": codec, "filters": None} if where == "compressor" else {
        "compressors": None, "filters": [codec]}
    fill = np.nan if dtype == "float32" else 0
    for order in ("F", "C"):
        path = tmp_path / f"{order}.zarr"
        z = zarr.create_array(zarr.storage.LocalStore(path), shape=a.shape, chunks=chunks,
                              dtype=a.dtype, zarr_format=2, order=order, fill_value=fill, **kw)
        z[...] = a
        z = zarr.open_array(zarr.storage.LocalStore(path), mode="r")
        check_decoded(a, z[...], bound)
        check_decoded(a[10:70, 33:88], z[10:70, 33:88], bound)
    # the reference: Zlib on the same Fortran-ordered array is exact
    zl = zarr.create_array(zarr.storage.LocalStore(tmp_path / "zlib.zarr"), shape=a.shape,
                           chunks=chunks, dtype=a.dtype, zarr_format=2, order="F",
                           fill_value=fill, compressors=numcodecs.Zlib(), filters=None)
    zl[...] = a
    np.testing.assert_array_equal(zl[...], a)


@pytest.mark.parametrize("dtype", ["float32", "int16"])
@pytest.mark.parametrize("lossless", [True, False])
def test_zarr_v3_memory_orders(tmp_path, dtype, lossless):
    """A Zarr v3 array-to-bytes codec gets the chunk's values as an NDBuffer, in the memory
    order of the array's runtime ``config`` (C or F), from sources of any layout, inside a
    shard too: every combination reads back within the bound."""
    rng = np.random.default_rng(32)
    a = terrain(rng, (96, 80), dtype, amplitude=6000.0, noise=5.0)
    bound = None if lossless else 3.0
    fill = np.nan if dtype == "float32" else 0
    for order in ("C", "F"):
        for kin, src in layouts(a).items():
            codec = VtzCodec(lossless=True) if lossless else VtzCodec(max_error=bound)
            store = zarr.storage.MemoryStore()
            z = v3_array(store, src, (32, 48), codec, fill_value=fill, config={"order": order})
            check_decoded(a, z[...], bound)
            z = zarr.open_array(store, mode="r").with_config({"order": order})
            assert z.async_array.config.order == order
            check_decoded(a, z[...], bound)
            check_decoded(a[5:60, 7:79], z[5:60, 7:79], bound)
        sharded = zarr.create_array(
            zarr.storage.MemoryStore(), shape=a.shape, chunks=(16, 16), shards=(48, 80),
            dtype=a.dtype, serializer=codec, compressors=None, fill_value=fill,
            config={"order": order},
        )
        sharded[...] = np.asfortranarray(a)
        check_decoded(a, sharded[...], bound)


# -- a damaged chunk in a store ---------------------------------------------------------


@pytest.mark.parametrize("damage", ["garbage", "truncated", "bitflip", "other shape", "other dtype"])
def test_zarr_corrupt_chunk_is_named(tmp_path, damage):
    rng = np.random.default_rng(40)
    a = terrain(rng, (128, 100), "int16", amplitude=1500.0)
    root = tmp_path / "dem.zarr"
    z = v3_array(zarr.storage.LocalStore(root), a, (64, 50), VtzCodec(max_error=1))
    chunk = root / "c" / "1" / "0"
    good = chunk.read_bytes()
    if damage == "garbage":
        chunk.write_bytes(b"this is not a vtz stream" * 4)
    elif damage == "truncated":
        chunk.write_bytes(good[: len(good) * 2 // 3])
    elif damage == "bitflip":
        flipped = bytearray(good)
        flipped[len(flipped) // 2] ^= 0x10
        chunk.write_bytes(bytes(flipped))
    elif damage == "other shape":  # a sound vtz stream that is not this array's chunk
        chunk.write_bytes(vtz.encode(np.zeros((10, 10), "int16")))
    else:
        chunk.write_bytes(vtz.encode(np.zeros((64, 50), "uint8")))

    z = zarr.open_array(zarr.storage.LocalStore(root), mode="r")
    with pytest.raises(vtz.CorruptError, match=r"chunk '.*dem\.zarr/c/1/0'") as info:
        z[70:80, 10:20]  # inside chunk (1, 0)
    assert "\n" not in str(info.value)
    with pytest.raises(vtz.CorruptError, match=r"c/1/0"):
        z[...]
    # the other chunks still read, within the bound
    check_decoded(a[:64, :], z[:64, :], 1)
    check_decoded(a[64:, 50:], z[64:, 50:], 1)


def test_zarr_corrupt_chunk_on_merge_write_and_repair(tmp_path):
    """A partial write into a damaged chunk makes zarr decode it through the entry that has no
    key: still a CorruptError (naming the chunk's shape); a whole-chunk write repairs it."""
    a = terrain(np.random.default_rng(41), (64, 64), "uint16", amplitude=3000.0)
    root = tmp_path / "dem.zarr"
    v3_array(zarr.storage.LocalStore(root), a, (32, 32), VtzCodec(max_error=1))
    (root / "c" / "0" / "1").write_bytes(b"\x00" * 40)
    z = zarr.open_array(zarr.storage.LocalStore(root), mode="r+")
    with pytest.raises(vtz.CorruptError, match="32x32 uint16 chunk"):
        z[0:5, 40:45] = 7
    z[0:32, 32:64] = a[0:32, 32:64]
    check_decoded(a, z[...], 1)


# -- parallel chunks --------------------------------------------------------------------


def _cpu_seconds_by_thread():
    ticks = os.sysconf("SC_CLK_TCK")
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            stat = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[tid] = (int(stat[11]) + int(stat[12])) / ticks
    return out


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc per-thread CPU")
def test_zarr_chunks_encode_on_several_threads():
    """With threads=1 per chunk, zarr's concurrent chunks must run on more than one OS thread."""
    rng = np.random.default_rng(50)
    a = terrain(rng, (128, 128), "float32", amplitude=2000.0, noise=2.0)
    before = _cpu_seconds_by_thread()
    t0 = time.process_time()
    v3_array(zarr.storage.MemoryStore(), a, (64, 64), VtzCodec(max_error=0.5, method="sibson"))
    total = time.process_time() - t0
    after = _cpu_seconds_by_thread()
    busy = [t for t, s in after.items() if s - before.get(t, 0.0) >= 0.2 * total]
    assert len(busy) >= 2, f"the chunk encodes ran on {len(busy)} thread(s)"
