"""Type stubs of the native module (the public API is in ``vtz``; see its docstrings)."""

from typing import Optional, Tuple, Union

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
) -> bytes: ...
def decode(
    data: bytes,
    window: Optional[Tuple[int, int, int, int]] = ...,
    scale: Optional[str] = ...,
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
) -> None: ...
