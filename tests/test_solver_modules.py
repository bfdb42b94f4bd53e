"""The minimal solvers' layout (issue 42): one module per solver with one plain public
solve function, and compiled kernels whose signatures a reader can hold (arrays bundled
into named tuples, not passed as a score of loose columns and scalars)."""

import inspect

import pytest

from zfloc_stream.estimation import draws
from zfloc_stream.estimation.solvers import line_circle, models, three_lines, two_circles, two_lines

SOLVERS = {three_lines: "solve_3l", two_lines: "solve_2l", two_circles: "solve_2c", line_circle: "solve_lc"}


@pytest.mark.parametrize("module", list(SOLVERS), ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_each_solver_module_has_one_solve_function(module):
    solves = [name for name, fn in vars(module).items()
              if name.startswith("solve_") and inspect.isfunction(fn) and fn.__module__ == module.__name__]
    assert solves == [SOLVERS[module]]


def kernels(module):
    """The module's own compiled functions (numba dispatchers carry py_func)."""
    return {name: fn.py_func for name, fn in vars(module).items()
            if hasattr(fn, "py_func") and fn.py_func.__module__ == module.__name__}


@pytest.mark.parametrize("module", [three_lines, two_lines, models, draws], ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_no_solver_or_draw_kernel_takes_ten_parameters(module):
    found = kernels(module)
    assert found  # the module does have kernels
    wide = {name: len(inspect.signature(fn).parameters) for name, fn in found.items()
            if len(inspect.signature(fn).parameters) >= 10}
    assert not wide, wide


def test_the_solvers_inner_loops_are_private():
    for module in (three_lines, two_lines):
        public = [name for name in kernels(module) if not name.startswith("_")]
        assert public == [], (module.__name__, public)
