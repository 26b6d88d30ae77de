#!/usr/bin/env python3
"""Helper of benches/remote/run.sh: one remote read through Python's `vtz.open`, in a fresh
process (its wall time, import included, is what run.sh times).

  py_read.py URL open                      vtz.open(URL) alone
  py_read.py URL window X,Y,W,H OUT.npy    vtz.open(URL).read(window=(X, Y, W, H)), saved

Exit 0 when the read worked; 3 with "n/a: <why>" on stderr when this Python has no vtz or
its vtz has no `open` (the remote reader is not in this build); 1 with the error otherwise.
"""

import sys


def main() -> int:
    url, mode = sys.argv[1], sys.argv[2]
    try:
        import vtz
    except ImportError as e:
        print(f"n/a: {sys.executable} cannot import vtz ({e})", file=sys.stderr)
        return 3
    if not hasattr(vtz, "open"):
        print(f"n/a: vtz {getattr(vtz, '__version__', '?')} has no vtz.open", file=sys.stderr)
        return 3
    try:
        ds = vtz.open(url)
        if mode == "window":
            import numpy as np

            x, y, w, h = (int(v) for v in sys.argv[3].split(","))
            a = ds.read(window=(x, y, w, h))
            np.save(sys.argv[4], np.asarray(a))
        close = getattr(ds, "close", None)
        if callable(close):
            close()
    except Exception as e:  # noqa: BLE001 - reported as the row's error
        print(f"{type(e).__name__}: {e}".splitlines()[0], file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
