"""The compiled kernels' one-line notice: printed at the first real compile of a process,
once, on stderr (a kernel loaded from numba's cache fires no compile event)."""

import numba

from zfloc_stream import numba_support


def test_the_first_compile_says_so_once_on_stderr(capsys, monkeypatch):
    monkeypatch.setattr(numba_support, "_noticed", False)
    numba.njit(lambda x: x + 1)(1)  # not cached: always a real compile
    numba.njit(lambda x: x + 2)(1)
    err = capsys.readouterr().err
    assert err.count(numba_support.COMPILE_NOTICE) == 1 and "once per machine, cached" in err
