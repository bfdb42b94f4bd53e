"""SR-vs-length studies (F3Loc protocol), scaled out with dask.

Each sequence is cut into consecutive non-overlapping chunks of L frames; when a sequence
holds more than study.max_chunks_per_sequence chunks of a length, that many are kept,
spread evenly along it. A cell = (dataset spec, sequence, length, chunk, seed): a fresh
Localizer (settings.seed = seed) runs on the chunk's frames and the last study.eval_frames
frames are scored (metrics.py). `run_cell` is a pure function of the cell and the
settings overrides, so results do not depend on where or in which order cells run
(rows are sorted by cell before anything is written).

Out folder: cells.jsonl (one row per finished cell, appended as cells finish: the study
resumes where it stopped; failed cells are retried), study.json (the settings the cells
were run with: a resumed study must use the same), results.csv (one row per cell of this
study, sorted), results.json (summary: per dataset and length, mean and spread over
seeds), results.md (a table shaped like the paper's), sr_vs_length.png.

Modules: plan.py (cells and their settings), cells.py (one cell), resume.py (the out folder
as a resume point), runner.py (cells on dask), report.py (summaries, tables, plot).
"""

from .plan import Cell, STUDY_BASE, cell_settings, chunk_starts, parse_lengths, plan_cells, user_overrides
from .cells import run_cell, threshold_key
from .resume import CELLS_FILE, MANIFEST_FILE, check_manifest, load_finished
from .runner import run_study
from .report import StudyOutcome, dataset_label, dataset_labels, markdown_table, plot_sr_vs_length, summarize_rows, write_outputs

__all__ = ["CELLS_FILE", "Cell", "MANIFEST_FILE", "STUDY_BASE", "StudyOutcome", "cell_settings", "check_manifest", "chunk_starts", "dataset_label", "dataset_labels", "load_finished", "markdown_table", "parse_lengths", "plan_cells", "plot_sr_vs_length", "run_cell", "run_study", "summarize_rows", "threshold_key", "user_overrides", "write_outputs"]
