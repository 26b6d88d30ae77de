"""vtz.open: lazy reads of a path, bytes, an fsspec file, a file:// URL, an http:// URL and a
plain file-like give the same samples as vtz.decode, for full reads, windows (across tile
borders), overviews; a one-tile window reads a small part of the file; errors by cause."""

from __future__ import annotations

import io
import os
import pickle
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import vtz
from conftest import TILE, LoggingFile, golden_files

fsspec = pytest.importorskip("fsspec")


def same(a, b):
    """Bit-identical: the same dtype, shape and bytes (NaN payloads included)."""
    assert a.dtype == b.dtype and a.shape == b.shape
    assert a.tobytes() == b.tobytes()


def windows(h, w, tile=None):
    """Windows (x, y, width, height) of a h x w raster: corners, a sliver, and ones across
    tile borders when tiled."""
    out = [(0, 0, w, h), (0, 0, 1, 1), (w - 1, h - 1, 1, 1), (w // 3, h // 4, max(1, w // 2), max(1, h // 3))]
    if tile:
        ty, tx = tile
        if w > tx and h > ty:
            out.append((tx - 5, ty - 7, 11, 13))  # the corner of four tiles
            out.append((tx // 2, 0, tx, h))  # a column strip across every tile row
            out.append((tx, ty, min(tx, w - tx), min(ty, h - ty)))  # exactly one tile's core
    return out


def sources(path, data, fs_url):
    """Every way of opening the same file: (label, opener)."""
    return [
        ("path", lambda: vtz.open(path)),
        ("pathlib", lambda: vtz.open(__import__("pathlib").Path(path))),
        ("bytes", lambda: vtz.open(data)),
        ("file-like", lambda: vtz.open(io.BytesIO(data))),
        ("open(rb)", lambda: vtz.open(open(path, "rb"))),
        ("file:// URL", lambda: vtz.open("file://" + os.path.abspath(path))),
        ("fsspec memory URL", lambda: vtz.open(fs_url)),
        ("fsspec file", lambda: vtz.open(fsspec.open(fs_url, "rb").open())),
    ]


def check_file(path, data, fs_url, only=None):
    """Every source (or those labelled in `only`) reads what vtz.decode gives."""
    ref = vtz.decode(data)
    info = vtz.info(data)
    for label, opener in sources(path, data, fs_url):
        if only is not None and label not in only:
            continue
        with opener() as r:
            assert r.shape == ref.shape, label
            assert r.dtype == ref.dtype, label
            assert r.nodata == info["nodata"] or (r.scale is not None), label
            same(r.read(), ref)
            for x, y, w, h in windows(*ref.shape, r.tile_shape):
                same(r.read((x, y, w, h)), vtz.decode(data, window=(x, y, w, h)))
            # rasterio's ((row_start, row_stop), (col_start, col_stop)): the same samples
            x, y, w, h = windows(*ref.shape)[3]
            same(r.read(((y, y + h), (x, x + w))), ref[y:y + h, x:x + w])
            for k in range(1, len(r.overviews) + 2):
                ov = vtz.decode(data, overview=k)
                assert r.overview_shape(k) == ov.shape
                same(r.read(overview=k), ov)
            oh, ow = r.overview_shape(1)
            win = (ow // 3, oh // 3, max(1, ow // 2), max(1, oh // 2))
            same(r.read(win, overview=1), vtz.decode(data, window=win, overview=1))
        assert r.closed, label


@pytest.fixture
def memfs():
    fs = fsspec.filesystem("memory")
    yield fs
    for p in fs.find("/"):
        fs.rm(p)


def test_tiled_file_every_source_is_bit_identical_to_decode(tiled, memfs):
    memfs.pipe("/tiled/tujunga.vtz", tiled["bytes"])
    check_file(tiled["path"], tiled["bytes"], "memory://tiled/tujunga.vtz")


@pytest.mark.parametrize("path", golden_files(), ids=os.path.basename)
def test_golden_files_every_source_is_bit_identical_to_decode(path, memfs):
    with open(path, "rb") as f:
        data = f.read()
    memfs.pipe("/golden/" + os.path.basename(path), data)
    check_file(
        path, data, "memory://golden/" + os.path.basename(path),
        only=("path", "file-like", "fsspec memory URL"),
    )


def test_metadata_of_a_tiled_georeferenced_file(tiled):
    p = tiled["profile"]
    with vtz.open(tiled["path"]) as r:
        assert r.shape == (643, 1197) and r.dtype == np.int16
        assert (r.height, r.width) == r.shape
        assert r.nodata == p["nodata"] == 32767
        assert r.crs == "EPSG:32611"
        assert r.crs_wkt.startswith(("PROJCS", "PROJCRS")) and "32611" in r.crs_wkt
        assert tuple(r.transform)[:6] == tuple(p["transform"])[:6]
        a, b, c, d, e, f = tuple(p["transform"])[:6]
        assert r.geotransform == (c, a, b, f, d, e)
        # 1197 x 643 with tiles of at most 128: 10 x 6 tiles of 120 x 108.
        assert r.tile_shape == (108, 120) and r.tile_grid == (6, 10)
        assert TILE >= max(r.tile_shape)
        # Levels while the longer side keeps 64 samples: 599, 300, 150, 75.
        assert r.overviews == [(322, 599), (161, 300), (81, 150), (41, 75)]
        assert r.max_error <= 1
        prof = r.profile
        assert prof["crs"] == "EPSG:32611" and prof["blockxsize"] == 120
        assert "643x1197 int16" in repr(r)
    assert "closed" in repr(r)


def neighbourhood(info, i, j):
    """The byte ranges of the blocks (version 5: heads and tails) of tile (i, j) and its 8
    neighbours."""
    t = info["tiles"]
    out = []
    for ii in range(max(0, i - 1), min(t["rows"], i + 2)):
        for jj in range(max(0, j - 1), min(t["cols"], j + 2)):
            for off, n in (t["blocks"][ii * t["cols"] + jj], t["tails"][ii * t["cols"] + jj]):
                if n:
                    out.append((off, off + n))
    return out


def inside(reads, ranges):
    """Whether every read (offset, length) lies within the union of `ranges`."""
    rs = sorted(ranges)
    merged = [list(rs[0])]
    for a, b in rs[1:]:
        if a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return all(any(a <= off and off + n <= b for a, b in merged) for off, n in reads)


def test_a_one_tile_window_reads_only_its_tile_and_neighbours(tiled):
    data = tiled["bytes"]
    info = vtz.info(data)
    f = LoggingFile(data)
    # No block cache: what the decoder itself reads.
    with vtz.open(f, cache_bytes=0) as r:
        # The head (first 64 KB), then a version-2 file's tile index (written last).
        assert f.reads[0] == (0, 64 * 1024)
        print(f"opening: {len(f.reads)} reads, {f.bytes_read()} of {len(data)} bytes")
        assert len(f.reads) <= 2 and f.bytes_read() < 64 * 1024 + len(data) / 8
        ty, tx = r.tile_shape
        f.reads.clear()
        # The core of an interior tile (row 2, column 4): its block and the neighbours' it
        # blends with across the margins (those inside the head cost nothing), no other.
        win = ((2 * ty, 3 * ty), (4 * tx, 5 * tx))
        same(r.read(win), vtz.decode(data, window=(4 * tx, 2 * ty, tx, ty)))
        one_tile = f.bytes_read()
        print(f"one-tile window: {len(f.reads)} reads, {one_tile} of {len(data)} bytes")
        assert f.reads and inside(f.reads, neighbourhood(info, 2, 4))
        assert len(f.reads) <= 9 and one_tile < len(data) / 4
        # A tile far away reads other blocks.
        f.reads.clear()
        r.read(((5 * ty, 643), (9 * tx, 1197)))
        assert f.reads and inside(f.reads, neighbourhood(info, 5, 9))
        assert not inside(f.reads, neighbourhood(info, 2, 4))
        f.reads.clear()
        r.read()
        # Every block's bytes past the head, once (a block reaching past the head is
        # fetched from the head's end).
        head = 64 * 1024
        parts = info["tiles"]["blocks"] + info["tiles"]["tails"]
        past_head = [off + n - max(off, head) for off, n in parts if n and off + n > head]
        assert f.bytes_read() == sum(past_head)
    # With the block cache (the default), a window read again fetches nothing.
    f = LoggingFile(data)
    with vtz.open(f) as r:
        ty, tx = r.tile_shape
        f.reads.clear()
        first = r.read(((2 * ty, 3 * ty), (4 * tx, 5 * tx)))
        n = len(f.reads)
        assert n > 0
        same(r.read(((2 * ty, 3 * ty), (4 * tx, 5 * tx))), first)
        assert len(f.reads) == n
    with pytest.raises(vtz.InvalidArgumentError, match="cache_bytes"):
        vtz.open(f, cache_bytes=-1)


class CountingMemoryFS:
    """A memory filesystem that logs its cat_ranges calls."""

    def __new__(cls):
        from fsspec.implementations.memory import MemoryFileSystem

        class Counting(MemoryFileSystem):
            cachable = False

            def cat_ranges(self, paths, starts, ends, **kw):
                self.calls.append(list(zip(starts, ends)))
                return super().cat_ranges(paths, starts, ends, **kw)

        fs = Counting()
        fs.calls = []
        return fs


def test_fsspec_file_reads_through_cat_ranges(tiled):
    fs = CountingMemoryFS()
    fs.pipe("/c/t.vtz", tiled["bytes"])
    info = vtz.info(tiled["bytes"])
    with vtz.open(fs.open("/c/t.vtz", "rb")) as r:
        assert fs.calls[0] == [(0, 64 * 1024)] and len(fs.calls) <= 2  # head (+ index)
        ty, tx = r.tile_shape
        fs.calls.clear()
        win = (4 * tx - 5, 3 * ty - 7, 11, 13)  # the corner of tiles (2..3, 3..4)
        same(r.read(win), vtz.decode(tiled["bytes"], window=win))
        reads = [(a, b - a) for call in fs.calls for a, b in call]
        assert reads and inside(reads, neighbourhood(info, 2, 3) + neighbourhood(info, 3, 4))


def container_version(data):
    """The container version of a .vtz file (the u32 after the 8-byte magic)."""
    assert data[:4] == b"\x89VTZ"
    return int.from_bytes(data[8:12], "little")


def test_fsspec_cat_ranges_calls_for_a_window_of_four_tiles(tiled):
    """A version-4 or -5 file's decoder asks for a band's tile blocks at once: one cat_ranges call
    (fsspec's async filesystems issue its ranges concurrently). A version-2 file's asks for
    them one by one: a call per block not in the head."""
    fs = CountingMemoryFS()
    fs.pipe("/c/t.vtz", tiled["bytes"])
    with vtz.open(fs.open("/c/t.vtz", "rb"), cache_bytes=0) as r:
        ty, tx = r.tile_shape
        fs.calls.clear()
        r.read((4 * tx - 5, 3 * ty - 7, 11, 13))
        print(f"version {container_version(tiled['bytes'])}: {len(fs.calls)} cat_ranges calls")
        if container_version(tiled["bytes"]) >= 4:
            assert len(fs.calls) == 1
        else:
            assert 1 <= len(fs.calls) <= 4 and all(len(c) == 1 for c in fs.calls)


def test_http_url_reads_ranges(tiled, http_server):
    data = tiled["bytes"]
    pytest.importorskip("aiohttp", reason="fsspec's HTTP filesystem needs aiohttp")
    http_server.objects["/t.vtz"] = data
    url = http_server.url + "/t.vtz"
    del http_server.log[:]
    with vtz.open(url) as r:
        assert http_server.log[0][1:] == (0, 64 * 1024) and len(http_server.log) <= 2
        ty, tx = r.tile_shape
        del http_server.log[:]
        same(r.read(((2 * ty, 3 * ty), (4 * tx, 5 * tx))), vtz.decode(data, window=(4 * tx, 2 * ty, tx, ty)))
        got = sum(e - s for _, s, e in http_server.log)
        print(f"one-tile window over HTTP: {len(http_server.log)} ranges, {got} of {len(data)} bytes")
        reads = [(s, e - s) for _, s, e in http_server.log]
        assert reads and inside(reads, neighbourhood(vtz.info(data), 2, 4))
        assert got < len(data) / 4
        same(r.read(overview=2), vtz.decode(data, overview=2))
        same(r.read(), vtz.decode(data))
    # A missing object, and one gone after opening: vtz's I/O error naming the URL, with
    # fsspec's exception as the cause.
    with pytest.raises(vtz.VtzIOError, match="missing.vtz: FileNotFoundError") as e:
        vtz.open(http_server.url + "/missing.vtz")
    assert isinstance(e.value.__cause__, FileNotFoundError)
    http_server.objects["/gone.vtz"] = data
    r = vtz.open(http_server.url + "/gone.vtz")
    del http_server.objects["/gone.vtz"]
    with pytest.raises(vtz.VtzIOError, match="reading .*/gone.vtz: FileNotFoundError") as e:
        r.read()
    assert isinstance(e.value.__cause__, FileNotFoundError)
    # Pickled (as Dask sends it to a worker) and opened again from the URL.
    with vtz.open(url) as r:
        again = pickle.loads(pickle.dumps(r))
        same(again.read((3, 4, 50, 60)), vtz.decode(data, window=(3, 4, 50, 60)))
        again.close()


def test_reads_from_threads_at_once_are_the_same(tiled):
    data = tiled["bytes"]
    ref = vtz.decode(data)
    f = LoggingFile(data)
    with vtz.open(f) as r:
        opening = list(f.reads)  # the head, then the index
        ty, tx = r.tile_shape
        cells = [(i, j) for i in range(6) for j in range(10)]

        def one(ij):
            i, j = ij
            return ij, r.read(((i * ty, min(643, (i + 1) * ty)), (j * tx, min(1197, (j + 1) * tx))))

        with ThreadPoolExecutor(4) as ex:
            for (i, j), a in ex.map(one, cells):
                same(a, ref[i * ty:(i + 1) * ty, j * tx:(j + 1) * tx])
        # The decoders opened for the other threads took the header and index from the
        # first one's reads: the file's opening reads happened once.
        for read in opening:
            assert f.reads.count(read) == 1, (read, len(f.reads))


def test_masked_read(tmp_path):
    a = np.arange(40 * 50, dtype=np.float32).reshape(40, 50)
    a[3:9, 4:7] = np.nan
    r = vtz.open(vtz.encode(a, tile=16))
    m = r.read(masked=True)
    assert isinstance(m, np.ma.MaskedArray)
    assert np.array_equal(m.mask, np.isnan(a))
    r = vtz.open(vtz.encode(np.where(np.isnan(a), -9999, a).astype(np.int16), nodata=-9999))
    m = r.read(window=((0, 10), (0, 10)), masked=True)
    assert m.mask.sum() == 6 * 3 and m.mask[3, 4] and not m.mask[0, 0]


def test_errors_by_cause(tiled, tmp_path, monkeypatch):
    data = tiled["bytes"]
    with pytest.raises(vtz.VtzIOError) as e:
        vtz.open(str(tmp_path / "missing.vtz"))
    assert isinstance(e.value, OSError) and "missing.vtz" in str(e.value)
    with pytest.raises(vtz.CorruptError):
        vtz.open(data[:1000])
    with pytest.raises(vtz.CorruptError):
        vtz.open(io.BytesIO(b"not a vtz file at all" * 10))
    # A file-like that fails: vtz's I/O error (an OSError), the file-like's own as its cause.
    f = LoggingFile(data)
    r = vtz.open(f)
    f.fail = True
    with pytest.raises(vtz.VtzIOError) as e:
        r.read()
    assert "PermissionError" in str(e.value) and "access denied by the test" in str(e.value)
    assert isinstance(e.value.__cause__, PermissionError)
    f.fail = False
    same(r.read((0, 0, 5, 5)), vtz.decode(data, window=(0, 0, 5, 5)))  # still usable
    with pytest.raises(vtz.InvalidArgumentError, match="not inside"):
        r.read(((0, 700), (0, 10)))
    with pytest.raises(vtz.InvalidArgumentError, match="not inside"):
        r.read((0, 0, 0, 5))
    with pytest.raises(vtz.InvalidArgumentError, match="overview"):
        r.read(overview=31)
    with pytest.raises(vtz.InvalidArgumentError, match="window"):
        r.read("everything")
    r.close()
    with pytest.raises(vtz.InvalidArgumentError, match="closed"):
        r.read()
    with pytest.raises(TypeError, match="path, a URL, bytes or a binary file-like"):
        vtz.open(12)
    with pytest.raises(vtz.InvalidArgumentError, match="storage_options"):
        vtz.open(tiled["path"], anon=True)
    with open(tiled["path"], "r", encoding="latin-1") as text:
        with pytest.raises(vtz.InvalidArgumentError, match="binary"):
            vtz.open(text)
    with pytest.raises(TypeError, match="cannot be pickled"):
        with open(tiled["path"], "rb") as fh:
            pickle.dumps(vtz.open(fh))
    monkeypatch.setitem(sys.modules, "fsspec", None)
    with pytest.raises(ImportError, match="needs fsspec"):
        vtz.open("s3://bucket/dem.vtz")


def test_a_point_set_is_not_a_raster():
    from conftest import GOLDEN

    with open(os.path.join(GOLDEN, "v3_points.vtz"), "rb") as f:
        data = f.read()
    with pytest.raises(vtz.VtzError) as e:
        vtz.open(data)
    with pytest.raises(type(e.value)):
        vtz.decode(data)


def test_obstore_reader_is_a_file_like(tiled):
    """obstore's readers (ReadableFile: seek, read giving its own buffer type) read as any
    binary file-like."""
    obstore = pytest.importorskip("obstore")
    from obstore.store import MemoryStore

    data = tiled["bytes"]
    store = MemoryStore()
    obstore.put(store, "dems/t.vtz", data)
    with vtz.open(obstore.open_reader(store, "dems/t.vtz")) as r:
        same(r.read(), vtz.decode(data))
        same(r.read((115, 100, 10, 20)), vtz.decode(data, window=(115, 100, 10, 20)))
        same(r.read(overview=1), vtz.decode(data, overview=1))
