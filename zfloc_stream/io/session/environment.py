"""Where a session was made: the facts that decide the last bits of its numbers.

numpy picks SIMD kernels by CPU at import time and OpenBLAS picks its kernels by CPU core
type, so the same code and inputs can differ in the last bits between machines (see
replay's tolerance). A session records these facts as metadata; a replay compares them
with its own and says in one line what differs.
"""

from __future__ import annotations

import platform
from importlib import metadata
from functools import cache
from pathlib import Path

from ... import __version__

# the keys compared between the recording and the replay, in the order they are reported
KEYS = ("zfloc_stream", "python", "numpy", "scipy", "numba", "blas", "simd", "machine", "cpu")
# recorded only since the compiled kernels (estimator.kernels: numba): a session from before
# does not say, and is not reported as different for that
OPTIONAL_KEYS = ("numba",)


def _numpy_simd() -> str:
    """numpy's SIMD features in use: the baseline plus the dispatched ones this CPU has
    (what NPY_DISABLE_CPU_FEATURES removes)."""
    try:
        from numpy._core import _multiarray_umath as umath  # numpy >= 2
    except ImportError:  # pragma: no cover - numpy 1.x
        from numpy.core import _multiarray_umath as umath
    features = getattr(umath, "__cpu_features__", {})
    used = list(getattr(umath, "__cpu_baseline__", [])) + [f for f in getattr(umath, "__cpu_dispatch__", []) if features.get(f)]
    return " ".join(dict.fromkeys(used)) or "unknown"


def _blas() -> str:
    """The BLAS libraries of numpy and scipy: api, version and the kernel set each picked
    for this CPU (e.g. 'openblas 0.3.31 Haswell'). Wheels bundle them in numpy.libs /
    scipy.libs; libraries other packages loaded (opencv, scikit-learn) are left out so the
    answer does not depend on import order, unless numpy and scipy bundle none."""
    import scipy.linalg  # noqa: F401 - loads scipy's own BLAS so it is listed too

    try:
        from threadpoolctl import threadpool_info
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        return "unknown"
    blas = [lib for lib in threadpool_info() if lib.get("user_api") == "blas"]
    bundled = [lib for lib in blas if Path(lib.get("filepath", "")).parent.name in ("numpy.libs", "scipy.libs")]
    texts = [" ".join(str(lib[k]) for k in ("internal_api", "version", "architecture") if lib.get(k)) for lib in bundled or blas]
    return ", ".join(sorted(set(texts))) or "none found"  # sorted: load order varies


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _installed_version(package: str) -> str:
    """The installed version of an optional package, without importing it ('none' if absent)."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "none"


@cache
def current() -> dict[str, str]:
    """This process's environment (computed once: it cannot change while running)."""
    import numpy
    import scipy

    return {
        "zfloc_stream": __version__,
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "numba": _installed_version("numba"),
        "blas": _blas(),
        "simd": _numpy_simd(),
        "machine": f"{platform.system()} {platform.machine()}",
        "cpu": _cpu_model(),
    }


def differences(recorded: dict[str, str], here: dict[str, str] | None = None) -> list[str]:
    """'key: recorded -> here' for each fact that differs."""
    here = current() if here is None else here
    return [f"{k}: {recorded.get(k, '?')} -> {here.get(k, '?')}" for k in KEYS
            if recorded.get(k) != here.get(k) and not (k in OPTIONAL_KEYS and k not in recorded)]


def describe(recorded: dict[str, str] | None) -> str:
    """One line on where the session was recorded, relative to this process."""
    if not recorded:
        return "environment: the session does not record where it was made"
    diff = differences(recorded)
    if not diff:
        return "environment: same as the recording (zfloc-stream, python, numpy, scipy, numba, BLAS, SIMD, CPU)"
    return "environment: recorded elsewhere: " + "; ".join(diff)
