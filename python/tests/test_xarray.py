"""The xarray backend: open_dataset(engine="vtz") gives one Dask chunk per tile, each chunk's
task reads only its tile's (and neighbours') blocks, selections and computes equal vtz.decode,
overviews, URLs, and the CRS and transform as rioxarray reads them."""

from __future__ import annotations

import io
import pickle

import numpy as np
import pytest

import vtz
from conftest import TUJUNGA, LoggingFile

xr = pytest.importorskip("xarray")
dask = pytest.importorskip("dask")
pytest.importorskip("dask.array")

from test_open import inside, neighbourhood, same  # noqa: E402


def test_engine_is_registered():
    assert "vtz" in xr.backends.list_engines()
    from vtz.xarray import VtzBackendEntrypoint

    assert isinstance(xr.backends.list_engines()["vtz"], VtzBackendEntrypoint)


def test_one_chunk_per_tile_and_values_equal_decode(tiled):
    ref = vtz.decode(tiled["bytes"])
    with xr.open_dataset(tiled["path"], engine="vtz", chunks={}) as ds:
        e = ds["elevation"]
        assert e.dims == ("y", "x") and e.shape == (643, 1197) and e.dtype == np.int16
        # 10 x 6 tiles of 120 x 108 (the last column 117, the last row 103)
        assert e.chunks == ((108,) * 5 + (103,), (120,) * 9 + (117,))
        assert e.data.npartitions == 60
        with dask.config.set(scheduler="threads"):
            same(e.values, ref)
            # isel and sel give what a numpy read of the window gives
            same(e.isel(y=slice(100, 300), x=slice(200, 500)).values, ref[100:300, 200:500])
            same(e.isel(y=slice(1, 300, 7), x=slice(500, 2, -3)).values, ref[1:300:7, 500:2:-3])
            same(e.isel(y=5, x=slice(3, 9)).values, ref[5, 3:9])
            x0, y0 = float(ds.x[200]), float(ds.y[100])
            x1, y1 = float(ds.x[499]), float(ds.y[299])
            same(e.sel(x=slice(x0, x1), y=slice(y0, y1)).values, ref[100:300, 200:500])
            assert int(e.sel(x=x0, y=y0, method="nearest")) == ref[100, 200]
            assert float(e.where(e != 32767).mean().compute()) == pytest.approx(
                ref[ref != 32767].mean()
            )


def test_each_task_reads_only_its_tile(tiled):
    data = tiled["bytes"]
    info = vtz.info(data)
    f = LoggingFile(data)
    ds = xr.open_dataset(f, engine="vtz", chunks={})
    ref = vtz.decode(data)
    e = ds["elevation"].data
    with dask.config.set(scheduler="synchronous"):
        for i, j in [(2, 4), (0, 0), (5, 9)]:
            f.reads.clear()
            block = e.blocks[i, j].compute()
            same(block, ref[i * 108:(i + 1) * 108, j * 120:(j + 1) * 120])
            assert inside(f.reads, neighbourhood(info, i, j)), (i, j, f.reads)
    ds.close()


def test_coordinates_and_crs_as_rioxarray_reads_them(tiled):
    p = tiled["profile"]
    a, b, c, d, e, f = tuple(p["transform"])[:6]
    with xr.open_dataset(tiled["path"], engine="vtz") as ds:
        np.testing.assert_array_equal(ds.x.values, c + a * (np.arange(1197) + 0.5))
        np.testing.assert_array_equal(ds.y.values, f + e * (np.arange(643) + 0.5))
        sr = ds["spatial_ref"].attrs
        assert sr["GeoTransform"].split() == [repr(float(v)) for v in (c, a, b, f, d, e)]
        assert "32611" in sr["crs_wkt"] and sr["spatial_ref"] == sr["crs_wkt"]
        assert ds["elevation"].attrs["grid_mapping"] == "spatial_ref"
        assert ds["elevation"].attrs["_FillValue"] == 32767
        try:
            import rioxarray  # noqa: F401
        except ImportError:
            print("SKIPPED (rioxarray not installed): ds.rio.crs and ds.rio.transform()")
            return
        assert ds.rio.crs.to_epsg() == 32611
        assert tuple(ds.rio.transform())[:6] == (a, b, c, d, e, f)
        assert ds["elevation"].rio.nodata == 32767
        ref = rioxarray.open_rasterio(TUJUNGA)
        np.testing.assert_allclose(ds.x.values, ref.x.values, rtol=0, atol=1e-6)
        np.testing.assert_allclose(ds.y.values, ref.y.values, rtol=0, atol=1e-6)


def test_overview(tiled):
    data = tiled["bytes"]
    with xr.open_dataset(tiled["path"], engine="vtz", chunks={}, overview=2) as ds:
        e = ds["elevation"]
        ov = vtz.decode(data, overview=2)
        assert e.shape == ov.shape == (161, 300)
        # tile cores at level 2: 108 / 4 = 27 rows, 120 / 4 = 30 columns
        assert e.chunks == ((27,) * 5 + (26,), (30,) * 10)
        with dask.config.set(scheduler="threads"):
            same(e.values, ov)
        a, b, c, d, e_, f = tuple(tiled["profile"]["transform"])[:6]
        np.testing.assert_array_equal(ds.x.values, c + 4 * a * (np.arange(300) + 0.5))
        gt = ds["spatial_ref"].attrs["GeoTransform"].split()
        assert float(gt[1]) == 4 * a and float(gt[5]) == 4 * e_ and float(gt[0]) == c


def test_url_and_storage_options(tiled, http_server):
    pytest.importorskip("fsspec")
    pytest.importorskip("aiohttp", reason="fsspec's HTTP filesystem needs aiohttp")
    http_server.objects["/x/t.vtz"] = tiled["bytes"]
    url = http_server.url + "/x/t.vtz"
    ref = vtz.decode(tiled["bytes"])
    with xr.open_dataset(
        url, engine="vtz", chunks={}, storage_options={"block_size": 0}
    ) as ds:
        with dask.config.set(scheduler="threads"):
            same(ds["elevation"].values, ref)
        assert ds.encoding["source"] == url


def test_pickled_chunks_compute_in_worker_processes(tiled):
    """What a distributed cluster does: the graph pickled, each chunk read in another
    process (a LocalCluster of 2 worker processes)."""
    distributed = pytest.importorskip("dask.distributed")
    ref = vtz.decode(tiled["bytes"])
    ds = xr.open_dataset(tiled["path"], engine="vtz", chunks={})
    arr = pickle.loads(pickle.dumps(ds["elevation"].data))
    with dask.config.set(scheduler="synchronous"):
        same(arr.compute(), ref)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        got = client.compute(ds["elevation"].data).result()
        same(got, ref)
    ds.close()


def test_mask_and_scale_and_untiled_files():
    a = np.linspace(-5, 5, 70 * 90, dtype=np.float32).reshape(70, 90)
    a[10:20, 30:35] = np.nan
    data = vtz.encode(a, max_error=0.01, nodata=-9999)
    with xr.open_dataset(io.BytesIO(data), engine="vtz", chunks={}) as ds:
        e = ds["elevation"]
        assert e.chunks == ((70,), (90,))  # untiled: one chunk
        dec = vtz.decode(data)
        same(e.values, dec)
        assert (dec == -9999).sum() == 50 and e.attrs["_FillValue"] == -9999
        assert "spatial_ref" not in ds.coords  # no georeferencing
        np.testing.assert_array_equal(ds.x.values, np.arange(90) + 0.5)
    with xr.open_dataset(io.BytesIO(data), engine="vtz", mask_and_scale=True) as ds:
        v = ds["elevation"].values
        assert np.array_equal(np.isnan(v), dec == -9999)
        assert np.array_equal(v[~np.isnan(v)], dec[dec != -9999])


def test_codes_with_offset_and_scale():
    """A file of integer codes (GDAL's offset and scale): the codes as vtz.decode gives them,
    with scale_factor/add_offset; mask_and_scale=True gives the values, nodata as NaN."""
    a = (np.arange(60 * 70).reshape(60, 70) % 500).astype(np.int16)
    a[0, :5] = -32768
    data = vtz.encode(a, scale=0.1, offset=100, nodata=-32768, tile=32)
    with vtz.open(data) as r:
        assert (r.dtype, r.nodata, r.scale, r.offset) == (np.int16, -32768, 0.1, 100)
        same(r.read(), vtz.decode(data))
    with xr.open_dataset(io.BytesIO(data), engine="vtz", chunks={}) as ds:
        e = ds["elevation"]
        assert e.attrs["scale_factor"] == 0.1 and e.attrs["add_offset"] == 100
        assert e.attrs["_FillValue"] == -32768
        same(e.values, vtz.decode(data))
    with xr.open_dataset(io.BytesIO(data), engine="vtz", mask_and_scale=True) as ds:
        v = ds["elevation"].values
        assert np.array_equal(np.isnan(v), a == -32768)
        ok = a != -32768
        np.testing.assert_allclose(v[ok], 100 + 0.1 * a[ok], rtol=0, atol=1e-9)


def test_dask_tasks_over_http_fetch_each_block_about_once(tiled, http_server):
    """Each tile's task reads its neighbours' blocks too; the raster's block cache makes the
    60 tasks fetch about the file once (without it: about six times)."""
    pytest.importorskip("aiohttp", reason="fsspec's HTTP filesystem needs aiohttp")
    data = tiled["bytes"]
    http_server.objects["/cache/t.vtz"] = data
    url = http_server.url + "/cache/t.vtz"
    ref = vtz.decode(data)
    fetched = {}
    for cache in (None, 0):
        del http_server.log[:]
        with xr.open_dataset(url, engine="vtz", chunks={}, cache_bytes=cache) as ds:
            with dask.config.set(scheduler="synchronous"):
                same(ds["elevation"].values, ref)
        fetched[cache] = sum(e - s for _, s, e in http_server.log)
        print(f"cache_bytes={cache}: {len(http_server.log)} GETs, {fetched[cache]} bytes "
              f"for a {len(data)}-byte file")
    # the head, the index and every block past the head once (one straddles the head)
    assert fetched[None] <= len(data) + 64 * 1024
    assert fetched[0] > 3 * len(data)
