"""The compiled kernels: the one-line notice printed at the first real compile of a process,
once, on stderr (a kernel loaded from numba's cache fires no compile event); the former
estimator.kernels setting still loads, ignored, with a FutureWarning."""

import numba

from zfloc_stream import numba_support


def test_the_first_compile_says_so_once_on_stderr(capsys, monkeypatch):
    monkeypatch.setattr(numba_support, "_noticed", False)
    numba.njit(lambda x: x + 1)(1)  # not cached: always a real compile
    numba.njit(lambda x: x + 2)(1)
    err = capsys.readouterr().err
    assert err.count(numba_support.COMPILE_NOTICE) == 1 and "once per machine, cached" in err


def test_the_former_kernels_setting_still_loads_and_is_ignored():
    import pytest

    from zfloc_stream.config import Settings, load_settings

    for kernels in ("numpy", "numba"):
        with pytest.warns(FutureWarning, match="estimator.kernels is ignored"):
            settings = load_settings(overrides=[f"estimator.kernels={kernels}"])
        assert settings == Settings() and "kernels" not in settings.estimator.model_dump()
