"""Type stubs of the vtz package."""

import os
from typing import Any, List, Optional, Tuple, Union

import numpy as np

from ._errors import (
    CorruptError as CorruptError,
    DtypeError as DtypeError,
    InvalidArgumentError as InvalidArgumentError,
    LimitError as LimitError,
    UnmetError as UnmetError,
    UnsupportedError as UnsupportedError,
    VtzError as VtzError,
    VtzIOError as VtzIOError,
)

__version__: str
DTYPES: Tuple[str, ...]

def encode(
    array: np.ndarray,
    max_error: Union[float, str, None] = None,
    lossless: bool = False,
    nodata: Optional[float] = None,
    method: Optional[str] = None,
    threads: int = 0,
    effort: Optional[int] = None,
    offset: Optional[float] = None,
    scale: Optional[float] = None,
    tile: Optional[int] = None,
) -> bytes: ...
def decode(
    data: Union[bytes, bytearray, memoryview],
    window: Optional[Tuple[int, int, int, int]] = None,
    scale: Union[float, str, None] = None,
    threads: int = 0,
    overview: Optional[int] = None,
) -> np.ndarray: ...
def info(data: Union[bytes, bytearray, memoryview]) -> dict[str, Any]: ...
def read(path: Union[str, os.PathLike[str]]) -> Tuple[np.ndarray, dict[str, Any]]: ...
def write(
    path: Union[str, os.PathLike[str]],
    array: np.ndarray,
    profile: Optional[dict[str, Any]] = None,
    max_error: Union[float, str, None] = None,
    lossless: bool = False,
    method: Optional[str] = None,
    overwrite: bool = True,
    threads: int = 0,
    effort: Optional[int] = None,
    tile: Optional[int] = None,
) -> None: ...

class Raster:
    name: str
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def shape(self) -> Tuple[int, int]: ...
    @property
    def dtype(self) -> np.dtype: ...
    @property
    def nodata(self) -> Optional[float]: ...
    @property
    def offset(self) -> Optional[float]: ...
    @property
    def scale(self) -> Optional[float]: ...
    @property
    def transform(self) -> Any: ...
    @property
    def geotransform(self) -> Optional[Tuple[float, float, float, float, float, float]]: ...
    @property
    def crs(self) -> Optional[str]: ...
    @property
    def crs_wkt(self) -> Optional[str]: ...
    @property
    def tile_shape(self) -> Optional[Tuple[int, int]]: ...
    @property
    def tile_grid(self) -> Optional[Tuple[int, int]]: ...
    @property
    def overviews(self) -> List[Tuple[int, int]]: ...
    @property
    def max_error(self) -> float: ...
    @property
    def profile(self) -> dict[str, Any]: ...
    @property
    def closed(self) -> bool: ...
    def overview_shape(self, overview: Optional[int]) -> Tuple[int, int]: ...
    def read(
        self,
        window: Any = None,
        overview: Optional[int] = None,
        masked: bool = False,
        threads: int = 0,
    ) -> np.ndarray: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Raster": ...
    def __exit__(self, *exc: Any) -> None: ...

def open(source: Any, *, cache_bytes: int = ..., **storage_options: Any) -> Raster: ...
