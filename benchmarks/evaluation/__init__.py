"""Evaluations: how well the localizer does (accuracy, robustness, failure diagnosis), not
how fast a stage runs. Run from the repository root, e.g.
python -m benchmarks.evaluation.eval_real --workers 2."""
