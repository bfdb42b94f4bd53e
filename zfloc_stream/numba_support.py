"""The optional compiled kernels (`estimator.kernels: numba`, the [fast] extra).

numba is imported here only, on first use: the package itself never needs it. Kernels are
compiled once per machine and cached next to their module (numba's on-disk cache), so a
new process pays milliseconds, not the compile, from the second run on. Every kernel is
compiled without fastmath (no reassociation, no fused multiply-add), so an element-wise
kernel gives numpy's bits; kernels that sum in another order than numpy say so.
"""

from __future__ import annotations

from .errors import ConfigError

INSTALL_HINT = "pip install 'zfloc-stream[fast]' (numba)"


def require_numba(purpose: str = "estimator.kernels: numba"):
    """numba, or a ConfigError that says exactly what to install."""
    try:
        import numba
    except ImportError as err:
        raise ConfigError(f"{purpose} needs the optional [fast] extra ({err}): install it with: {INSTALL_HINT}") from None
    return numba


def numba_available() -> bool:
    try:
        require_numba()
    except ConfigError:
        return False
    return True


def njit(fn):
    """numba.njit with the package's fixed options: cached on disk, releases the GIL (a
    pipelined round's kernels run beside the stream's fusion), numpy's error model (a
    division by zero gives inf/nan like numpy, no exception), IEEE arithmetic."""
    numba = require_numba()
    return numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=False)(fn)


def check_kernels(kernels: str) -> None:
    """Fail early, in one line, when numba kernels are asked for without numba."""
    if kernels == "numba":
        require_numba()
