"""Type stubs of the vtz package."""

import os
from typing import Any, Optional, Tuple, Union

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
) -> bytes: ...
def decode(
    data: Union[bytes, bytearray, memoryview],
    window: Optional[Tuple[int, int, int, int]] = None,
    scale: Union[float, str, None] = None,
    threads: int = 0,
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
) -> None: ...
