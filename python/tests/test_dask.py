"""Dask on more than one worker: the ``examples/dask_mosaic.py`` pipeline, vtz only.

A mosaic of GeoTIFF tiles cut from a real DEM (``corpus/srtm30m_bigtujunga_utm11.tif``,
1197 x 643 int16, UTM 11N) behind a GDAL VRT is opened with rioxarray, written to a Zarr v3
store with ``vtz.zarr.VtzCodec`` by a ``LocalCluster`` of 2 worker processes, read back
through Dask, and every sample is checked against the bound. A second mosaic with a void
checks that nodata samples stay nodata. Needs GDAL's command line tools (gdal_translate,
gdalbuildvrt) and the packages of ``requirements-dask.txt``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip(
    "dask.distributed",
    reason="dask.distributed is not installed (pip install -r python/requirements-dask.txt)",
)

import dask.array as da  # noqa: E402
import rasterio  # noqa: E402
import zarr  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
sys.path.insert(0, str(EXAMPLES))
import dask_mosaic  # noqa: E402

SOURCE = dask_mosaic.TEST_SOURCE
BOUND = 1.0


@pytest.fixture(scope="module")
def client():
    """One cluster of 2 single-threaded worker processes for the whole module."""
    with dask_mosaic.local_cluster(2) as c:
        yield c


@pytest.fixture(scope="module")
def mosaic(tmp_path_factory):
    """The test mosaic: 3 x 2 GeoTIFF tiles of (at most) 400 x 400 and their VRT."""
    return dask_mosaic.build_mosaic(SOURCE, tmp_path_factory.mktemp("mosaic"), tile=400)


def test_mosaic_is_tiles_behind_a_vrt(mosaic):
    assert len(mosaic["tiles"]) == 6
    with rasterio.open(SOURCE) as src:
        whole = src.read(1)
        crs, transform = src.crs, src.transform
    with rasterio.open(mosaic["vrt"]) as vrt:
        assert vrt.driver == "VRT"
        assert vrt.crs == crs and vrt.transform == transform
        np.testing.assert_array_equal(vrt.read(1), whole)
    with rasterio.open(mosaic["tiles"][-1]) as last:   # bottom-right tile: the remainder
        assert (last.width, last.height) == (1197 - 800, 643 - 400)
        assert last.crs == crs


def test_two_workers_write_vtz_store_within_bound(client, mosaic, tmp_path):
    assert len(client.scheduler_info()["workers"]) == 2
    store = tmp_path / "mosaic.zarr"
    rec = dask_mosaic.run_one(client, mosaic, "vtz", BOUND, 400, store)

    # Both worker processes encoded chunks, and every sample was checked.
    assert rec["workers_used"] == 2
    assert rec["samples"] == 1197 * 643
    assert rec["valid"] == rec["samples"]          # the declared nodata (32767) is unused
    assert rec["nodata_mismatch"] == 0
    assert rec["max_error"] <= BOUND
    assert rec["bound_ok"] and rec["georef_ok"]
    assert rec["array_bytes"] < 1197 * 643 * 2 / 4  # compresses well below raw int16

    # The store decodes on its own too (plain zarr, no Dask): vtz chunks, within the bound.
    arr = zarr.open_array(store / dask_mosaic.VAR, mode="r")
    assert arr.metadata.to_dict()["codecs"][0]["name"] == "vtz"
    assert arr.metadata.to_dict()["codecs"][0]["configuration"]["max_error"] == BOUND
    got = arr[:]
    with rasterio.open(SOURCE) as src:
        want = src.read(1)
    assert got.dtype == want.dtype and got.shape == want.shape
    assert np.abs(got.astype(np.int32) - want).max() <= BOUND
    assert not np.array_equal(got, want)           # lossy: the bound was used


def test_nodata_samples_stay_nodata(client, tmp_path):
    # A 500 x 300 crop with a void (and a partial chunk at each far edge).
    with rasterio.open(SOURCE) as src:
        profile = src.profile
        a = src.read(1, window=((100, 400), (300, 800)))
    nodata = int(profile["nodata"])
    a[120:170, 40:210] = nodata
    profile.update(width=a.shape[1], height=a.shape[0],
                   transform=rasterio.windows.transform(((100, 400), (300, 800)),
                                                        profile["transform"]))
    source = tmp_path / "void.tif"
    with rasterio.open(source, "w", **profile) as dst:
        dst.write(a, 1)
    info = dask_mosaic.build_mosaic(source, tmp_path / "m", tile=250)
    rec = dask_mosaic.run_one(client, info, "vtz", 2.0, 200, tmp_path / "void.zarr")
    assert rec["samples"] == a.size
    assert rec["valid"] == a.size - 50 * 170
    assert rec["nodata_mismatch"] == 0 and rec["max_error"] <= 2.0 and rec["bound_ok"]
    got = zarr.open_array(tmp_path / "void.zarr" / dask_mosaic.VAR, mode="r")[:]
    np.testing.assert_array_equal(got == nodata, a == nodata)


def test_check_bound_catches_violations(client):
    # The checker itself: an error above the bound, and a lost nodata sample, are caught.
    src = np.arange(64, dtype=np.int16).reshape(8, 8)
    src[0, 0] = -32768
    good = src.copy()
    good[1:, :] += 1
    s = da.from_array(src, chunks=4)
    ok = dask_mosaic.check_bound(client, da.from_array(good, chunks=4), s, 1.0, -32768)
    assert ok["bound_ok"] and ok["max_error"] == 1.0 and ok["valid"] == 63

    far = good.copy()
    far[7, 7] += 1
    bad = dask_mosaic.check_bound(client, da.from_array(far, chunks=4), s, 1.0, -32768)
    assert not bad["bound_ok"] and bad["max_error"] == 2.0

    lost = good.copy()
    lost[0, 0] = 5
    bad = dask_mosaic.check_bound(client, da.from_array(lost, chunks=4), s, 1.0, -32768)
    assert not bad["bound_ok"] and bad["nodata_mismatch"] == 1
