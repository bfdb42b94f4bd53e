"""F3Loc success rate / RMSE against hand-made trajectories."""

import numpy as np
import pytest

from zfloc_stream.errors import InputError
from zfloc_stream.metrics import evaluate_run, is_success, position_errors, run_rmse, summarize


def _walk(n=20):
    """Truth on integer coordinates so offsets give exact distances."""
    return np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])


def _estimates(truth, offsets_x):
    est = truth.copy()
    est[:, 0] += offsets_x
    return [row for row in est]


def test_success_when_all_last_ten_frames_are_within_threshold():
    truth = _walk()
    offsets = np.full(20, 0.3)
    offsets[:10] = 50.0  # early frames do not count
    errors = position_errors(_estimates(truth, offsets), truth)
    assert is_success(errors, 1.0) and is_success(errors, 0.5)
    assert not is_success(errors, 0.2)
    assert run_rmse(errors) == pytest.approx(0.3)


def test_failure_by_one_frame():
    truth = _walk()
    offsets = np.full(20, 0.2)
    offsets[14] = 1.01  # one of the last ten frames just outside
    errors = position_errors(_estimates(truth, offsets), truth)
    assert not is_success(errors, 1.0)
    assert is_success(errors[:14], 1.0)  # without that frame it would succeed


def test_distance_exactly_on_the_threshold_counts_as_success():
    truth = _walk()
    errors = position_errors(_estimates(truth, np.full(20, 1.0)), truth)
    assert np.all(errors[-10:] == 1.0)  # exactly representable
    assert is_success(errors, 1.0)
    half = position_errors(_estimates(truth, np.full(20, 0.5)), truth)
    assert is_success(half, 0.5)
    assert not is_success(np.nextafter(half, 2.0), 0.5)


def test_missing_pose_is_a_failure_with_infinite_error():
    truth = _walk()
    est = _estimates(truth, np.zeros(20))
    est[17] = None
    errors = position_errors(est, truth)
    assert errors[17] == np.inf
    run = evaluate_run(errors, (1.0, 0.5))
    assert run.success == {1.0: False, 0.5: False}
    assert run.rmse == np.inf
    # NaN rows are missing poses too
    est[17] = np.array([np.nan, np.nan, np.nan])
    assert position_errors(est, truth)[17] == np.inf


def test_summary_over_runs():
    runs = [
        ({1.0: True, 0.5: True}, 0.2),
        ({1.0: True, 0.5: False}, 0.6),
        ({1.0: False, 0.5: False}, 3.0),
        ({1.0: False, 0.5: False}, np.inf),  # a pose missing at the end
    ]
    s = summarize([r[0] for r in runs], [r[1] for r in runs], (1.0, 0.5))
    assert s.n_runs == 4
    assert s.success_rate == {1.0: 0.5, 0.5: 0.25}
    assert s.rmse_succ == pytest.approx(0.4)  # mean of the successful runs' RMSEs
    assert s.rmse_all == pytest.approx((0.2 + 0.6 + 3.0) / 3)  # runs with a pose throughout
    assert s.n_no_pose == 1


def test_bad_inputs_raise_input_errors():
    with pytest.raises(InputError, match="one truth"):
        position_errors([np.zeros(3)], np.zeros((2, 3)))
    with pytest.raises(InputError, match="NaN"):
        is_success([0.1, np.nan], 1.0)
    with pytest.raises(InputError, match="no frame"):
        run_rmse([])
