"""The package API: round trips within the bound for every dtype, nodata, windows, info,
read/write with a profile GDAL reads back, and a clear exception for each kind of bad input."""

import os
import re
import shutil
import subprocess
import threading
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import vtz

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "..", "..", "corpus")
TUJUNGA = os.path.join(CORPUS, "srtm30m_bigtujunga_utm11.tif")
KAUAI = os.path.join(CORPUS, "srtm3_N22W160_kauai.hgt")


def terrain(h, w, dtype, seed=0):
    """A smooth surface with noise, in the dtype's range."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    z = 80 * np.sin(x / 9.0) * np.cos(y / 7.0) + 0.05 * x * y + rng.normal(0, 2, (h, w))
    if np.dtype(dtype).kind in "iu":
        info = np.iinfo(dtype)
        z = np.clip(np.round(z - z.min() + (0 if info.min == 0 else -100)), info.min, info.max)
    return np.ascontiguousarray(z.astype(dtype))


def max_err(a, b):
    va = np.asarray(a, dtype=np.float64)
    vb = np.asarray(b, dtype=np.float64)
    ok = ~np.isnan(va)
    assert np.array_equal(np.isnan(vb), ~ok), "nodata positions changed"
    return float(np.abs(va[ok] - vb[ok]).max()) if ok.any() else 0.0


@pytest.mark.parametrize("dtype", vtz.DTYPES)
def test_lossless_round_trip_keeps_dtype_and_values(dtype):
    a = terrain(37, 53, dtype)
    b = vtz.encode(a)
    d = vtz.decode(b)
    assert d.dtype == a.dtype and d.shape == a.shape
    assert np.array_equal(d, a)
    assert vtz.info(b)["max_error"] == 0.0


@pytest.mark.parametrize("dtype", vtz.DTYPES)
@pytest.mark.parametrize("bound", [0.5, 3.0, 10.0])
def test_bound_holds_for_every_dtype(dtype, bound):
    a = terrain(64, 48, dtype, seed=int(bound))
    b = vtz.encode(a, max_error=bound)
    d = vtz.decode(b)
    assert d.dtype == a.dtype
    assert max_err(a, d) <= bound
    assert len(b) < a.nbytes


def test_corpus_rasters_hold_the_bound_and_keep_georeferencing():
    for path, bound in [(TUJUNGA, 1.0), (KAUAI, 5.0)]:
        a, prof = vtz.read(path)
        assert a.ndim == 2 and prof["crs"] is not None and prof["transform"] is not None
        b = vtz.encode(a, max_error=bound, nodata=prof["nodata"])
        d = vtz.decode(b)
        valid = a != prof["nodata"] if prof["nodata"] is not None else np.ones(a.shape, bool)
        assert np.abs(d.astype(np.int64) - a.astype(np.int64))[valid].max() <= bound
        assert np.array_equal(d[~valid], a[~valid])


def test_effort_chooses_the_residual_coding_and_keeps_the_bound():
    """effort=6 writes the residual layer's compact (range-coded) coding: other bytes than
    the default effort's (5, the lane coding, which effort 1 also writes on this integer
    raster), and all hold the bound on a real raster; None is the default itself."""
    a, prof = vtz.read(KAUAI)
    nodata = prof["nodata"]
    valid = a != nodata
    streams = {}
    for effort in (None, 1, 5, 6, 9):
        b = vtz.encode(a, max_error=1, nodata=nodata, method="residual", effort=effort)
        assert vtz.info(b)["method"] == "residual"
        d = vtz.decode(b)
        assert np.abs(d.astype(np.int64) - a.astype(np.int64))[valid].max() <= 1
        assert np.array_equal(d[~valid], a[~valid])
        streams[effort] = b
    assert streams[None] == streams[5]
    assert streams[1] == streams[5]
    assert streams[6] != streams[5]
    assert len(streams[6]) < len(streams[5])
    # numpy integers are integers too
    assert vtz.encode(a, max_error=1, nodata=nodata, method="residual",
                      effort=np.int8(6)) == streams[6]


@pytest.mark.parametrize("effort", [0, 10, -1, 300, 2**70, 2.0, "5", True])
def test_effort_out_of_range_is_a_clear_error(effort, tmp_path):
    a = terrain(20, 20, np.int16)
    with pytest.raises(vtz.InvalidArgumentError, match=r"effort .* is not an integer in 1\.\.=9"):
        vtz.encode(a, max_error=1, effort=effort)
    with pytest.raises(vtz.InvalidArgumentError, match=r"1\.\.=9"):
        vtz.write(tmp_path / "a.vtz", a, max_error=1, effort=effort)
    assert not (tmp_path / "a.vtz").exists()


def test_percent_bound_and_method_choice():
    a = terrain(40, 40, np.float32)
    rng = float(a.max() - a.min())
    b = vtz.encode(a, max_error="1%")
    assert max_err(a, vtz.decode(b)) <= 0.01 * rng * (1 + 1e-9)
    for m in ["sibson", "grid", "haar"]:
        b = vtz.encode(a, max_error=0.5, method=m)
        assert vtz.info(b)["method"] == m
        assert max_err(a, vtz.decode(b)) <= 0.5


def test_nan_and_nodata_come_back_where_they_were():
    a = terrain(30, 20, np.float32)
    a[3:6, 4:9] = np.nan
    d = vtz.decode(vtz.encode(a, max_error=0.25))
    assert max_err(a, d) <= 0.25  # checks the NaN positions too
    i = terrain(30, 20, np.int16)
    i[0, :5] = -32768
    b = vtz.encode(i, max_error=1, nodata=-32768)
    assert vtz.info(b)["nodata"] == -32768
    d = vtz.decode(b)
    assert (d[0, :5] == -32768).all()
    valid = i != -32768
    assert np.abs(d.astype(int) - i.astype(int))[valid].max() <= 1
    f = terrain(10, 10, np.float64)
    f[2, 2] = -9999.0
    d = vtz.decode(vtz.encode(f, nodata=-9999.0))
    assert d[2, 2] == -9999.0 and np.array_equal(d, f)


def test_window_and_scale():
    a = terrain(50, 70, np.int16)
    b = vtz.encode(a, max_error=2)
    full = vtz.decode(b)
    w = vtz.decode(b, window=(10, 5, 30, 20))
    assert np.array_equal(w, full[5:25, 10:40])
    s = vtz.decode(vtz.encode(a, max_error=2, method="sibson"), scale=0.5)
    assert s.shape == (25, 35) and s.dtype == a.dtype


def test_overview_is_every_2k_th_sample_of_the_full_decode():
    a = terrain(50, 70, np.int16)
    for effort in (1, 5):
        b = vtz.encode(a, max_error=2, method="residual", effort=effort)
        full = vtz.decode(b)
        for k in (1, 2, 3):
            o = vtz.decode(b, overview=k)
            assert o.dtype == a.dtype
            assert np.array_equal(o, full[:: 2**k, :: 2**k]), (effort, k)
        w = vtz.decode(b, overview=1, window=(3, 2, 10, 8))
        assert np.array_equal(w, full[::2, ::2][2:10, 3:13])
    for bad in (0, 31, -1, 1.5, True):
        with pytest.raises(vtz.InvalidArgumentError, match="overview"):
            vtz.decode(b, overview=bad)


def test_scale_decodes_every_method_as_gdal_lays_it_out():
    a = terrain(50, 70, np.int16)
    for method in (None, "residual", "grid", "haar", "fis", "sibson"):
        b = vtz.encode(a, max_error=10, method=method)
        full = vtz.decode(b)
        # floor(w * s) x floor(h * s) over the same extent, as gdal_translate -outsize.
        for scale, shape in ((2, (100, 140)), (0.5, (25, 35)), ("3/2", (75, 105)),
                             (Fraction(1, 3), (16, 23))):
            d = vtz.decode(b, scale=scale)
            assert d.shape == shape and d.dtype == a.dtype, (method, scale)
            assert np.array_equal(d, vtz.decode(b, scale=scale, threads=1))
        assert np.array_equal(vtz.decode(b, scale=1), full)
        if method != "sibson":
            # Output centres on source samples at scale 3: those samples' decoded values.
            assert np.array_equal(vtz.decode(b, scale=3)[1::3, 1::3], full)
    # Exact, never silently rounded: 1/3 as a float has no 32-bit fraction.
    with pytest.raises(vtz.InvalidArgumentError, match="not representable exactly"):
        vtz.decode(b, scale=1 / 3)
    assert vtz.decode(b, scale=0.02).shape == (1, 1)


def test_info_fields():
    a = terrain(20, 30, np.uint16)
    b = vtz.encode(a, max_error=1, method="sibson")
    i = vtz.info(b)
    assert (i["width"], i["height"], i["dtype"]) == (30, 20, "uint16")
    assert i["bytes"] == len(b)
    assert i["range"] == (float(a.min()), float(a.max()))
    assert 0 < i["max_error"] <= 1
    assert i["method"] == "sibson" and i["sections"][0]["primary"]
    assert i["crs"] is None and i["transform"] is None


@settings(max_examples=40, deadline=None)
@given(
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    dtype=st.sampled_from(vtz.DTYPES),
    bound=st.one_of(st.none(), st.sampled_from([0.5, 1.0, 4.0, 25.0])),
    seed=st.integers(0, 2**31),
)
def test_property_round_trip(h, w, dtype, bound, seed):
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind in "iu":
        info = np.iinfo(dtype)
        lo = max(info.min, -5000)
        hi = min(info.max, 5000)
        a = rng.integers(lo, hi, (h, w), endpoint=True).astype(dtype)
    else:
        a = (rng.normal(0, 300, (h, w))).astype(dtype)
        a[rng.random((h, w)) < 0.1] = np.nan
    b = vtz.encode(a, max_error=bound)
    d = vtz.decode(b)
    assert d.dtype == a.dtype and d.shape == a.shape
    if bound is None:
        assert np.array_equal(d, a, equal_nan=True)
    else:
        assert max_err(a, d) <= bound


def test_write_read_geotiff_and_vtz_keep_the_profile(tmp_path):
    a, prof = vtz.read(TUJUNGA)
    out = tmp_path / "t.vtz"
    vtz.write(out, a, prof, max_error=2)
    d, p2 = vtz.read(out)
    assert np.abs(d.astype(int) - a.astype(int)).max() <= 2
    assert p2["crs"] == prof["crs"] == "EPSG:32611"
    assert tuple(p2["transform"])[:6] == tuple(prof["transform"])[:6]
    assert p2["nodata"] == prof["nodata"] and p2["driver"] == "VTZ"
    tif = tmp_path / "t.tif"
    vtz.write(tif, d, p2)
    d3, p3 = vtz.read(tif)
    assert np.array_equal(d3, d) and p3["crs"] == "EPSG:32611"
    if shutil.which("gdalinfo"):
        txt = subprocess.run(["gdalinfo", str(tif)], capture_output=True, text=True).stdout
        assert "32611" in txt and "376313.655" in txt and "NoData Value=32767" in txt, txt
    else:
        print("SKIPPED (gdalinfo not found): GDAL's reading of the written GeoTIFF")
    with pytest.raises(vtz.InvalidArgumentError, match="exists"):
        vtz.write(tif, d, p2, overwrite=False)


def test_profile_with_a_rasterio_like_crs_object(tmp_path):
    class FakeCRS:  # what rasterio.crs.CRS offers
        def to_epsg(self):
            return 32633

        def to_wkt(self):
            return 'PROJCS["WGS 84 / UTM zone 33N"]'

    a = terrain(16, 16, np.float32)
    prof = {"crs": FakeCRS(), "transform": (2.0, 0.0, 500000.0, 0.0, -2.0, 5000000.0, 0, 0, 1)}
    vtz.write(tmp_path / "f.vtz", a, prof)
    _, p = vtz.read(tmp_path / "f.vtz")
    assert p["crs"] == "EPSG:32633"
    assert tuple(p["transform"])[:6] == (2.0, 0.0, 500000.0, 0.0, -2.0, 5000000.0)


def test_every_proper_prefix_and_a_flipped_byte_are_corrupt():
    a = terrain(12, 9, np.int16)
    b = vtz.encode(a, max_error=1)
    for n in range(len(b)):
        with pytest.raises(vtz.CorruptError):
            vtz.decode(b[:n])
    for pos in [len(b) // 2, len(b) - 3]:
        bad = bytearray(b)
        bad[pos] ^= 0x40
        with pytest.raises(vtz.CorruptError):
            vtz.decode(bytes(bad))
    assert issubclass(vtz.CorruptError, ValueError)
    assert issubclass(vtz.VtzIOError, OSError)


@pytest.mark.parametrize(
    "bad, exc, words",
    [
        (np.zeros((4, 6), np.float32)[:, ::2], vtz.InvalidArgumentError, "C-contiguous"),
        (np.zeros((4, 4), ">f4"), vtz.DtypeError, "big-endian"),
        (np.zeros((2, 4, 4), np.int16), vtz.InvalidArgumentError, "3-D"),
        (np.zeros((4, 4), np.complex64), vtz.DtypeError, "complex"),
        (np.zeros((4, 4), np.int64), vtz.DtypeError, "int64"),
        # 64-bit integers are refused always (vtz has no type that holds every one).
        (np.full((4, 4), 2**60 + 1, np.uint64), vtz.DtypeError, "uint64"),
        (np.zeros((4, 4), bool), vtz.DtypeError, "bool"),
        (np.zeros(5, np.int16), vtz.InvalidArgumentError, "1-D"),
        (np.zeros((0, 4), np.int16), vtz.InvalidArgumentError, "empty"),
    ],
)
def test_bad_arrays_raise_clear_errors(bad, exc, words):
    with pytest.raises(exc, match=words):
        vtz.encode(bad)


def test_nan_with_another_nodata_is_nodata():
    """NaN in a float array is nodata whatever ``nodata`` says (as in the CLI and GDAL):
    it decodes as the nodata value, every other sample within the bound."""
    a = terrain(8, 8, np.float32)
    nan = a.copy()
    nan[0, 0] = np.nan
    nan[3, 5] = -9999
    d = vtz.decode(vtz.encode(nan, nodata=-9999, max_error=0.5))
    assert d[0, 0] == -9999 and d[3, 5] == -9999
    ok = np.ones(a.shape, bool)
    ok[0, 0] = ok[3, 5] = False
    assert np.abs(d[ok] - a[ok]).max() <= 0.5


def test_the_readmes_say_one_nan_rule():
    """The rule above is written once, in the top-level README; python/README.md points to
    it and says nothing else (it said such an array raises)."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, "README.md"), encoding="utf-8") as f:
        top = " ".join(f.read().split())
    with open(os.path.join(root, "python", "README.md"), encoding="utf-8") as f:
        py = " ".join(f.read().split())
    assert "NaN samples of a float raster are nodata whatever its nodata value says" in top
    assert "with nodata −9999 they decode as −9999" in top
    assert "by the top-level [README](../README.md)'s rule" in py
    assert "is an error (ambiguous)" not in py and "raises" not in py.split("`nodata`:")[1][:300]


def test_bad_arguments_raise_clear_errors(tmp_path):
    a = terrain(8, 8, np.float32)
    with pytest.raises(vtz.InvalidArgumentError, match="exclude"):
        vtz.encode(a, max_error=1, lossless=True)
    with pytest.raises(vtz.InvalidArgumentError, match="max_error"):
        vtz.encode(a, max_error=-1)
    with pytest.raises(TypeError):
        vtz.encode(a, max_error=[1])
    with pytest.raises(vtz.InvalidArgumentError, match="unknown method"):
        vtz.encode(a, method="jpeg")
    with pytest.raises(vtz.InvalidArgumentError, match="not a value of dtype"):
        vtz.encode(terrain(8, 8, np.uint8), nodata=-1)
    b = vtz.encode(a)
    with pytest.raises(vtz.InvalidArgumentError):
        vtz.decode(b, window=(4, 4, 10, 10))
    with pytest.raises(vtz.InvalidArgumentError):
        vtz.decode(b, scale="zero")
    with pytest.raises(TypeError):
        vtz.decode("not bytes")
    with pytest.raises(vtz.CorruptError):
        vtz.decode(b"hello world, not a vtz stream")
    with pytest.raises(vtz.VtzIOError):
        vtz.read(tmp_path / "missing.vtz")
    with pytest.raises(vtz.VtzIOError):
        vtz.write(tmp_path / "no" / "such" / "dir.vtz", a)
    with pytest.raises(vtz.InvalidArgumentError, match="max_error applies"):
        vtz.write(tmp_path / "x.tif", a, max_error=1)


def test_the_gil_is_released_while_encoding():
    """Another Python thread runs while a large encode is under way."""
    a = terrain(700, 700, np.float32)
    state = {"started": False, "done": False}

    def work():
        state["started"] = True
        vtz.encode(a, max_error=0.1, threads=1)
        state["done"] = True

    t = threading.Thread(target=work)
    t.start()
    while not state["started"]:
        pass
    spins = 0
    while not state["done"]:
        spins += 1
    t.join()
    # Holding the GIL for the whole encode would leave this loop a few switch intervals.
    assert spins > 10_000, spins


def test_bytes_are_the_same_for_every_thread_count():
    a = terrain(120, 90, np.float32)
    assert vtz.encode(a, max_error=0.5, threads=1) == vtz.encode(a, max_error=0.5, threads=2)
    b = vtz.encode(a, max_error=0.5)
    assert np.array_equal(vtz.decode(b, threads=1), vtz.decode(b, threads=2))


def test_offset_and_scale_map_codes_and_bound_the_values(tmp_path):
    """Issue 35, items 2, 6 and 11: integer codes with GDAL's offset and scale. The bound is
    in values (metres); a scale comes back as codes with info's/read's offset and scale; a
    unit scale with an offset of -32768 over uint16 comes back as int16 values."""
    codes = terrain(60, 80, np.int16)
    b = vtz.encode(codes, max_error=25, scale=10.0)
    i = vtz.info(b)
    assert (i["dtype"], i["offset"], i["scale"]) == ("int16", 0.0, 10.0)
    assert (i["codes_dtype"], i["value_scale"]) == ("int16", 10.0)
    assert 0 < i["max_error"] <= 25
    back = vtz.decode(b)
    assert back.dtype == np.int16
    err = np.abs(10.0 * back.astype(np.float64) - 10.0 * codes.astype(np.float64)).max()
    assert err <= 25, err  # codes move by up to 2: the bound is on metres
    out = tmp_path / "s.tif"
    vtz.write(out, codes, {"scale": 10.0, "offset": -5.0, "nodata": None})
    a, prof = vtz.read(out)
    assert (prof["scale"], prof["offset"]) == (10.0, -5.0) and np.array_equal(a, codes)
    if shutil.which("gdalinfo"):
        txt = subprocess.run(["gdalinfo", str(out)], capture_output=True, text=True).stdout
        assert re.search(r"Offset: -5,\s*Scale:10\b", txt), txt
    else:
        print("SKIPPED (gdalinfo not found): GDAL's offset and scale of the written GeoTIFF")
    u = (codes.astype(np.int32) + 32768 - 150).astype(np.uint16)
    b = vtz.encode(u, offset=-32768)
    assert vtz.info(b)["dtype"] == "int16" and vtz.info(b)["codes_dtype"] == "uint16"
    d = vtz.decode(b)
    assert d.dtype == np.int16 and np.array_equal(d, u.astype(np.int32) - 32768)
    with pytest.raises(vtz.InvalidArgumentError, match="integer codes"):
        vtz.encode(codes.astype(np.float32), scale=0.1)
