"""Fixtures shared by the lazy-read tests (test_open.py, test_xarray.py): a tiled file of a
corpus DEM, a file-like that logs every read, and a range-capable HTTP server on 127.0.0.1
that logs every Range it serves."""

from __future__ import annotations

import io
import os
import re
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

import vtz

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..", "..")
TUJUNGA = os.path.join(ROOT, "corpus", "srtm30m_bigtujunga_utm11.tif")
GOLDEN = os.path.join(ROOT, "tests", "golden")
#: Tile side of the tiled test file: 1197 x 643 samples make 10 x 6 tiles of 120 x 108.
TILE = 128


@pytest.fixture(scope="session")
def tiled(tmp_path_factory):
    """A tiled .vtz (UTM 11N, nodata 32767, 60 tiles) of the Big Tujunga DEM: its path,
    bytes and the source's profile."""
    a, profile = vtz.read(TUJUNGA)
    path = str(tmp_path_factory.mktemp("tiled") / "tujunga.vtz")
    vtz.write(path, a, profile, max_error=1, method="residual", effort=1, tile=TILE)
    with open(path, "rb") as f:
        data = f.read()
    return {"path": path, "bytes": data, "profile": profile}


def golden_files():
    """The golden rasters (tests/golden/*.vtz; v3 is a point set, not a raster)."""
    names = sorted(n for n in os.listdir(GOLDEN) if n.endswith(".vtz") and not n.startswith("v3_"))
    assert names, f"no golden files in {GOLDEN}"
    return [os.path.join(GOLDEN, n) for n in names]


class LoggingFile(io.RawIOBase):
    """A binary file-like over bytes that logs each read as (offset, bytes)."""

    def __init__(self, data: bytes, fail: bool = False) -> None:
        self._data = data
        self._pos = 0
        self.reads: list = []
        self.fail = fail
        self.name = "logging-file"

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, pos: int, whence: int = 0) -> int:
        base = {0: 0, 1: self._pos, 2: len(self._data)}[whence]
        self._pos = base + pos
        return self._pos

    def tell(self) -> int:
        return self._pos

    def read(self, n: int = -1) -> bytes:
        if self.fail:
            raise PermissionError(13, "access denied by the test")
        end = len(self._data) if n is None or n < 0 else min(len(self._data), self._pos + n)
        out = self._data[self._pos:end]
        self.reads.append((self._pos, len(out)))
        self._pos = end
        return out

    def bytes_read(self) -> int:
        return sum(n for _, n in self.reads)


class _Handler(BaseHTTPRequestHandler):
    """GET with a Range (206, one range) or without (200), HEAD with Content-Length."""

    def log_message(self, *args):  # keep pytest's output quiet
        pass

    def _object(self):
        obj = self.server.objects.get(self.path)
        if obj is None:
            self.send_error(404)
        return obj

    def do_HEAD(self):
        obj = self._object()
        if obj is None:
            return
        self.send_response(200)
        self.send_header("Content-Length", str(len(obj)))
        self.send_header("Accept-Ranges", "bytes")
        self.end_headers()

    def do_GET(self):
        obj = self._object()
        if obj is None:
            return
        rng = self.headers.get("Range")
        if rng is None:
            self.server.log.append((self.path, 0, len(obj)))
            body, status = obj, 200
        else:
            m = re.fullmatch(r"bytes=(\d+)-(\d*)", rng.strip())
            start = int(m.group(1))
            end = min(len(obj), int(m.group(2)) + 1 if m.group(2) else len(obj))
            if start >= len(obj):
                self.send_error(416)
                return
            self.server.log.append((self.path, start, end))
            body, status = obj[start:end], 206
        self.send_response(status)
        if status == 206:
            self.send_header("Content-Range", f"bytes {start}-{end - 1}/{len(obj)}")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Accept-Ranges", "bytes")
        self.end_headers()
        self.wfile.write(body)


@pytest.fixture(scope="session")
def http_server():
    """A range-capable HTTP server on 127.0.0.1: put bytes under `objects[path]`; `log` holds
    (path, start, end) of every GET it served."""
    srv = ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    srv.objects = {}
    srv.log = []
    srv.daemon_threads = True
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    srv.url = f"http://127.0.0.1:{srv.server_address[1]}"
    yield srv
    srv.shutdown()
    srv.server_close()
