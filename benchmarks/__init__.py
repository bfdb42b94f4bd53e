"""Stage benchmarks (bench_*.py, one harness: harness.py), the evaluations apart
(evaluation/), and the inputs they share with the tests (inputs/, shared_data.py).
Run from the repository root: python -m benchmarks.bench_round --quick."""
