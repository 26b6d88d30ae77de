"""The exceptions vtz raises, one class per cause (the Rust crate's ``vtz::Error``)."""


class VtzError(Exception):
    """Base class of every error vtz raises."""


class CorruptError(VtzError, ValueError):
    """The bytes are not a valid vtz stream: truncated, damaged, a checksum mismatch."""


class UnsupportedError(VtzError, ValueError):
    """Valid input using something vtz does not implement (a newer version, a rotated grid)."""


class InvalidArgumentError(VtzError, ValueError):
    """An argument is wrong: the array's shape or dtype, the bound, the window."""


class UnmetError(VtzError, ValueError):
    """The chosen method cannot meet the request on this data."""


class LimitError(VtzError, ValueError):
    """The input would need more memory or work than vtz's limits allow."""


class VtzIOError(VtzError, OSError):
    """Reading or writing a file failed."""


class DtypeError(InvalidArgumentError, TypeError):
    """The array's type is not one vtz codes (complex, object, big-endian, an unknown dtype)."""


__all__ = [
    "VtzError",
    "CorruptError",
    "UnsupportedError",
    "InvalidArgumentError",
    "UnmetError",
    "LimitError",
    "VtzIOError",
    "DtypeError",
]
