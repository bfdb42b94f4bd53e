"""ARCHITECTURE.md stays the map of the package: every folder is in its layout tree, every
module in its module index, and every function the path of one frame through push names
still exists (a rename that forgets the doc fails here)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "zfloc_stream"
DOC = (ROOT / "ARCHITECTURE.md").read_text(encoding="utf-8")


def section(title: str) -> str:
    start = DOC.index(f"## {title}")
    end = DOC.find("\n## ", start + 1)
    return DOC[start:end if end >= 0 else None]


def test_every_folder_of_the_package_is_in_the_layout_tree():
    tree = section("Layout")
    folders = sorted({p.parent.relative_to(PACKAGE).parts[0] for p in PACKAGE.rglob("*.py") if p.parent != PACKAGE})
    missing = [f for f in folders if not re.search(rf"^\s+{re.escape(f)}/", tree, re.M)]
    assert not missing, f"folders missing from ARCHITECTURE.md's layout tree: {missing}"


def test_every_module_is_in_the_module_index():
    index = section("Modules")
    modules = [p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
               if p.name != "__init__.py" or p.read_text().strip() and p.parent != PACKAGE]
    missing = [m for m in modules if f"`{m}`" not in index]
    assert not missing, f"modules missing from ARCHITECTURE.md's module index: {missing}"
    named = set(re.findall(r"^\| `([\w/]+\.py)` \|", index, re.M))
    gone = sorted(n for n in named if not (PACKAGE / n).exists())
    assert not gone, f"ARCHITECTURE.md indexes modules that no longer exist: {gone}"


def named_callables() -> list[str]:
    """The functions and methods the path names: `fn`, `Type.method` (not `Type`, a file
    path or a setting such as `localizer.every_k_frames`)."""
    names = set()
    for token in re.findall(r"`([A-Za-z_][\w.]*)`", section("One frame through `Localizer.push`")):
        head, _, attr = token.rpartition(".")
        if head and head[0].isupper():
            names.add(attr)
        elif not head and token[0].islower() or token.startswith("_"):
            names.add(token)
    return sorted(names)


@pytest.mark.parametrize("name", named_callables())
def test_the_path_of_a_frame_names_functions_that_exist(name):
    source = "\n".join(p.read_text(encoding="utf-8") for p in PACKAGE.rglob("*.py"))
    assert re.search(rf"def {re.escape(name)}\(|self\.{re.escape(name)}(: [^=\n]+)? = ", source), \
        f"ARCHITECTURE.md's path of a frame names {name}, defined nowhere"


def test_the_path_of_a_frame_has_at_most_ten_steps():
    steps = re.findall(r"^(\d+)\. ", section("One frame through `Localizer.push`"), re.M)
    assert 1 <= len(steps) <= 10
