"""The import rules of ARCHITECTURE.md, written as import-linter contracts in .importlinter:
the real package keeps them, and a forbidden import breaks them (so .ci/run fails)."""

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "zfloc_stream"


def lint_imports(root: Path) -> subprocess.CompletedProcess:
    """lint-imports with root's .importlinter on root's zfloc_stream (first on the path)."""
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    env = {**os.environ, "PYTHONPATH": str(root)}
    return subprocess.run([sys.executable, "-c", code, "--config", str(root / ".importlinter"), "--no-cache"],
                          cwd=root, env=env, capture_output=True, text=True, timeout=300)


def test_the_package_keeps_its_layers():
    run = lint_imports(ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "0 broken" in run.stdout and "BROKEN" not in run.stdout


@pytest.mark.parametrize(
    "module, line, broken",
    [
        # geometry (below everything but runtime and settings) importing the online loop
        ("geometry/shapes.py", "from ..stream.localizer import Localizer", "zfloc_stream.geometry.shapes -> zfloc_stream.stream.localizer"),
        # the tracker and the front end are independent siblings
        ("tracking/filter_bank.py", "from ..frontend.bev import RollingBEV", "zfloc_stream.tracking.filter_bank -> zfloc_stream.frontend.bev"),
        # the estimation stage below the tracker that ranks its hypotheses
        ("estimation/ransac.py", "from ..tracking.filter_bank import HypothesisTracker", "zfloc_stream.estimation.ransac -> zfloc_stream.tracking.filter_bank"),
        # the online loop writing its own log (io/ sits above it)
        ("stream/localizer.py", "from ..io.session.writer import SessionWriter", "zfloc_stream.stream.localizer -> zfloc_stream.io.session.writer"),
        # inside stream/: the kidnap test under the audit that can start one
        ("stream/recovery.py", "from .audit import Audit", "zfloc_stream.stream.recovery -> zfloc_stream.stream.audit"),
        # inside plans/: the raster floorplan under the vector one
        ("plans/floorplan.py", "from .vector import load_vector_floorplan", "zfloc_stream.plans.floorplan -> zfloc_stream.plans.vector"),
        # the estimation stage taking device helpers from the camera backbones (runtime/torch_support.py has them)
        ("estimation/scoring_torch.py", "from ..backbones.base import choose_device", "zfloc_stream.estimation.scoring_torch -> zfloc_stream.backbones.base"),
    ],
)
def test_a_forbidden_import_breaks_the_contracts(tmp_path, module, line, broken):
    shutil.copytree(PACKAGE, tmp_path / "zfloc_stream", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / ".importlinter", tmp_path / ".importlinter")
    assert lint_imports(tmp_path).returncode == 0  # the copy keeps them before the edit
    target = tmp_path / "zfloc_stream" / module
    target.write_text(target.read_text() + f"\n{line}  # forbidden\n")
    run = lint_imports(tmp_path)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "BROKEN" in run.stdout and broken in run.stdout, run.stdout


def test_no_private_name_is_imported_from_another_module():
    """A leading underscore means "this module's own": another module that needs it gets a
    public name. (numpy's own private modules, read for the environment record, are not ours.)"""
    found = set()
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("zfloc_stream")):
                found |= {(path.relative_to(PACKAGE).as_posix(), a.name) for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")}
    assert not found, sorted(found)
