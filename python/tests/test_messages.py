"""Error messages speak Python: they name the keyword arguments (``scale=``,
``window=``, ``overwrite=True``), never the command line's flags."""

import numpy as np
import pytest

import vtz


def test_scale_and_window_errors_name_keywords():
    y, x = np.mgrid[0:40, 0:50]
    a = (100 * np.sin(x / 7.0) + y).astype(np.float32)
    b = vtz.encode(a, max_error=1, method="sibson")
    with pytest.raises(vtz.InvalidArgumentError) as e:
        vtz.decode(b, window=(0, 0, 10, 10), scale=2)
    msg = str(e.value)
    assert "scale=" in msg and "window=" in msg, msg
    assert "--" not in msg, msg


def test_existing_file_error_names_overwrite(tmp_path):
    a = np.arange(64, dtype=np.int16).reshape(8, 8)
    p = tmp_path / "x.vtz"
    vtz.write(p, a)
    with pytest.raises(vtz.VtzError) as e:
        vtz.write(p, a, overwrite=False)
    msg = str(e.value)
    assert "overwrite=True" in msg and "--force" not in msg, msg
