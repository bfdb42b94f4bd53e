"""Where the shared real-building data lie, for the benchmarks, the evaluations and the
tests: ../shared/data beside the repository (a checkout next to the shared folder), else
/work/shared/data (where the shared folder is mounted for a clone elsewhere, as CI's)."""

from pathlib import Path

_BESIDE = Path(__file__).resolve().parents[2] / "shared" / "data"
SHARED_DATA = _BESIDE if _BESIDE.is_dir() else Path("/work/shared/data")
