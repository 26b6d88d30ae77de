"""Type stubs of the native module (the public API is in ``vtz``; see its docstrings)."""

from typing import Any, Optional, Tuple, Union

import numpy as np

__version__: str

def encode(
    array: np.ndarray,
    max_error: Union[float, str, None] = ...,
    lossless: bool = ...,
    nodata: Optional[float] = ...,
    method: Optional[str] = ...,
    threads: int = ...,
    effort: Optional[int] = ...,
    offset: Optional[float] = ...,
    scale: Optional[float] = ...,
    tile: Optional[int] = ...,
) -> bytes: ...
def decode(
    data: bytes,
    window: Optional[Tuple[int, int, int, int]] = ...,
    scale: Optional[str] = ...,
    overview: Optional[int] = ...,
    threads: int = ...,
) -> np.ndarray: ...
def info(data: bytes) -> dict: ...
def read(path: str) -> Tuple[np.ndarray, Optional[dict], Optional[float]]: ...
def write(
    path: str,
    array: np.ndarray,
    nodata: Optional[float] = ...,
    transform: Optional[Tuple[float, float, float, float, float, float]] = ...,
    epsg: Optional[int] = ...,
    wkt: Optional[str] = ...,
    max_error: Union[float, str, None] = ...,
    lossless: bool = ...,
    method: Optional[str] = ...,
    force: bool = ...,
    threads: int = ...,
    effort: Optional[int] = ...,
    offset: Optional[float] = ...,
    scale: Optional[float] = ...,
    tile: Optional[int] = ...,
) -> None: ...

class Reader:
    """A .vtz file opened for lazy reads (vtz.open wraps it in vtz.Raster)."""

    @staticmethod
    def from_path(path: str) -> Reader: ...
    @staticmethod
    def from_bytes(data: bytes) -> Reader: ...
    @staticmethod
    def from_fsspec(
        fs: Any, path: Any, size: int, name: str, cache_bytes: int = ...
    ) -> Reader: ...
    @staticmethod
    def from_file(file: Any, size: int, name: str, cache_bytes: int = ...) -> Reader: ...
    def info(self) -> dict: ...
    def max_error(self) -> float: ...
    def read(
        self,
        window: Optional[Tuple[int, int, int, int]] = ...,
        overview: Optional[int] = ...,
        threads: int = ...,
    ) -> np.ndarray: ...
    def close(self) -> None: ...
    @property
    def closed(self) -> bool: ...
