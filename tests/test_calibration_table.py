"""benchmarks/evaluation/calibration.py: the reliability table counts every frame at or above a
level, per status; a wrong map's frames (error None) are never within 1 m."""

from benchmarks.evaluation import calibration


ROWS = [{"frame_status": ["initializing", "tracking", "tracking", "lost"], "frame_errors": [None, 0.2, 1.5, 0.1],
         "frame_confidence": [float("nan"), 0.95, 0.9, 0.0]},
        {"kind": "laser #20", "map": "other", "frame_status": ["ambiguous", "initializing"], "frame_errors": [None, None],
         "frame_confidence": [0.9, 0.5]}]


def test_reliability_counts_frames_at_or_above_each_level_per_status():
    table = calibration.reliability_table(ROWS, levels=(0.5, 0.9, 0.95))
    assert "| 0.5 | 4: 25.0% | 1: 0.0% | 2: 50.0% | 1: 0.0% | 0 |" in table
    assert "| 0.9 | 3: 33.3% | 0 | 2: 50.0% | 1: 0.0% | 0 |" in table
    assert "| 0.95 | 1: 100.0% | 0 | 1: 100.0% | 0 | 0 |" in table


def test_bins_cover_every_frame_with_a_confidence():
    table = calibration.bins_table(ROWS)
    assert "| [0, 0.5) | 1 | 100.0% |" in table and "| [0.5, 0.7) | 1 | 0.0% |" in table
    assert "| [0.9, 0.95) | 2 | 0.0% |" in table and "| [0.95, 0.99) | 1 | 100.0% |" in table
    assert "| [0.99, 1] | 0 | - |" in table and "| nan (no pose) | 1 | - |" in table
