"""The caller's pose prior (prior.py, issue 41): its checks, the gate and seeds, the CLI's
--initial-pose / --region, the API (Localizer(prior=...), set_initial_pose at any time),
a symmetric building whose ambiguity the prior resolves, and a wrong prior that is said,
not obeyed."""

import json
import math

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.errors import InputError, ZflocError
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.prior import Prior, inside_polygon
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.sim import build_scene
from zfloc_stream.sim.simulator import SimSettings, simulate
from zfloc_stream.sim.trajectory import trajectory_through
from zfloc_stream.tools.cli import main
from localizer_helpers import odometry_jumped


# --- the prior itself -------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, fragment", [
    ({}, "give a pose, a region or both"),
    ({"pose": (0, 0)}, "3 numbers"),
    ({"pose": (0, 0, float("nan"))}, "finite"),
    ({"pose": (0, 0, 0), "sigma_xy": 0.0}, "sigma_xy must be positive"),
    ({"region": [[0, 0], [1, 1], [2, 2]]}, "no area"),
    ({"region": [[0, 0], [1, 1]]}, "at least 3 vertices"),
])
def test_bad_priors_are_one_input_error(kwargs, fragment):
    with pytest.raises(InputError, match=fragment):
        Prior(**kwargs)


def test_gate_and_seeds_agree():
    prior = Prior.at(10.0, -4.0, math.radians(90), 1.0, math.radians(15)).bind((3.0, 2.0, 0.5), Settings().prior)
    seeds = prior.seeds(1.0)
    assert len(seeds) > 100 and prior.inside(seeds).all()
    xy, heading = prior.implied(seeds)
    assert np.hypot(*(xy - [10.0, -4.0]).T).max() <= 2.5 + 1e-9
    # the same alignment seen from 10 m away, or turned by 60 deg, is outside
    far = seeds[:1].copy()
    far[0, 0] += 10.0
    turned = seeds[:1].copy()
    turned[0, 2] += math.radians(60)
    assert not prior.inside(far)[0] and not prior.inside(turned)[0]


def test_region_box_and_polygon():
    box = Prior.within((0, 0, 4, 2))
    assert inside_polygon([[1, 1], [5, 1], [-1, 1]], box.region).tolist() == [True, False, False]
    closed = Prior.within([[0, 0], [4, 0], [4, 2], [0, 2], [0, 0]])  # a GeoJSON ring repeats its first vertex
    assert len(closed.region) == 4
    assert Prior.from_settings(Settings(prior={"region": closed.region.tolist()}).prior).region.shape == (4, 2)
    assert Prior.from_settings(Settings().prior) is None


# --- the CLI ----------------------------------------------------------------------------
@pytest.mark.parametrize("option, fragment", [
    (["--initial-pose", "1,2"], "expected 3 or 5 comma-separated numbers"),
    (["--initial-pose", "1,2,east"], "expected 3 or 5"),
    (["--initial-pose", "1,2,90,0,15"], "must be positive"),
    (["--initial-pose", "1,2,inf"], "finite"),
    (["--region", "5,0,1,1"], "X0 < X1"),
    (["--region", "1,2,3"], "expected 4"),
    (["--region", "missing.geojson"], "no such file"),
])
def test_cli_bad_prior_is_one_line_exit_2(tmp_path, capsys, option, fragment):
    code = main(["run", "--input", str(tmp_path / "in.mcap"), "--out", str(tmp_path / "out"), "--no-progress", *option])
    err = capsys.readouterr().err
    assert code == 2
    assert fragment in err and "Traceback" not in err
    assert len([line for line in err.splitlines() if line.strip()]) == 1, err


def _args(**kw):
    from types import SimpleNamespace

    return SimpleNamespace(**{"initial_pose": None, "region": None, **kw})


def test_cli_prior_options_become_settings(tmp_path):
    from zfloc_stream.tools.prior_options import prior_overrides

    assert prior_overrides(_args()) is None
    assert prior_overrides(_args(initial_pose="1,2,90")) == {"pose": [1.0, 2.0, 90.0], "sigma_xy": 1.0, "sigma_theta_deg": 15.0}
    assert prior_overrides(_args(initial_pose="1,2,90,3,30"))["sigma_xy"] == 3.0
    assert prior_overrides(_args(region="0,0,4,2"))["region"] == [[0, 0], [4, 0], [4, 2], [0, 2]]
    geo = tmp_path / "wing.geojson"
    geo.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [6, 0], [6, 3], [0, 0]]]}}]}))
    assert prior_overrides(_args(region=str(geo)))["region"] == [[0, 0], [6, 0], [6, 3]]
    table = tmp_path / "wing.csv"
    table.write_text("x,y\n0,0\n6,0\n6,3\n")
    assert prior_overrides(_args(region=str(table)))["region"] == [[0, 0], [6, 0], [6, 3]]
    table.write_text("x,y\n0,0\n6,zero\n6,3\n")
    with pytest.raises(InputError, match="row 3"):
        prior_overrides(_args(region=str(table)))


# --- the API and the built-in symmetric scene ------------------------------------------------
@pytest.fixture(scope="module")
def symmetric():
    scene = build_scene("symmetric", seed=0)
    wp = scene.waypoints
    path = trajectory_through(scene, [wp["symmetric_start"], wp["symmetric_end"], wp["distinguishing"]],
                              make_rng(0, "test", "symmetric"))
    seq = simulate(scene, SimSettings(), seed=0, trajectory=path)
    return scene, list(seq)[:30], seq.poses[:30]


def _errors(estimates, poses):
    return np.array([np.inf if e.pose is None else np.linalg.norm(e.pose[:2] - p[:2]) for e, p in zip(estimates, poses)])


def test_prior_resolves_the_symmetric_ambiguity(symmetric):
    scene, frames, poses = symmetric
    with Localizer(scene.floorplan, Settings()) as loc:
        plain = [loc.push(f) for f in frames]
    assert "tracking" not in [e.status for e in plain]  # the halves look alike: ambiguous
    assert "ambiguous" in [e.status for e in plain]
    prior = Prior.at(*poses[0], 1.0, math.radians(15))
    with Localizer(scene.floorplan, Settings(), prior=prior) as loc:
        assert loc.settings.prior.pose == pytest.approx([*poses[0][:2], math.degrees(poses[0][2])])  # recorded
        est = [loc.push(f) for f in frames]
    errors = _errors(est, poses)
    tracking = [k for k, e in enumerate(est) if e.status == "tracking"]
    assert tracking and tracking[0] <= 10, [e.status for e in est]
    assert (errors[tracking] < 1.0).all()
    assert tracking[-1] == len(est) - 1 and est[-1].prior == "active"


def test_wrong_prior_is_dropped_and_never_tracked_at(symmetric):
    """A prior 10 m off (sigma 3 m): the frames are clearly better explained elsewhere."""
    scene, frames, poses = symmetric
    x, y, theta = poses[0]
    prior = Prior.at(x + 10.0, y, theta, 3.0, math.radians(30))
    with Localizer(scene.floorplan, Settings(), prior=prior) as loc:
        est = [loc.push(f) for f in frames]
    assert est[-1].prior == "contradicted"
    near_prior = [e.pose is not None and np.hypot(e.pose[0] - x - 10.0, e.pose[1] - y) < 7.5 for e in est]
    errors = _errors(est, poses)
    assert not any(e.status == "tracking" and n and err >= 1.0 for e, n, err in zip(est, near_prior, errors))


def test_set_initial_pose_at_any_time_restarts_from_it(symmetric):
    scene, frames, poses = symmetric
    with Localizer(scene.floorplan, Settings()) as loc:
        est = [loc.push(f) for f in frames[:12]]
        assert est[-1].prior is None and est[-1].status != "tracking"
        loc.set_initial_pose(*poses[12], sigma_xy=1.0, sigma_theta=math.radians(15))
        assert loc.prior == "pending" and loc.tracker.best is None
        est = [loc.push(f) for f in frames[12:]]
    assert est[0].prior == "active"
    tracking = [k for k, e in enumerate(est) if e.status == "tracking"]
    assert tracking and (_errors(est, poses[12:])[tracking] < 1.0).all()
    with pytest.raises(ZflocError, match="Prior"):
        Localizer(scene.floorplan, Settings(), prior=(1, 2, 3))


def test_odometry_jump_releases_an_active_prior(symmetric):
    """The prior was bound in the map an odometry jump clears: it is let go, not carried
    into the new map frame (where the same numbers name another place)."""
    scene, frames, poses = symmetric
    jumped = odometry_jumped(frames, 15, shift=(10.0, 0.0))
    with Localizer(scene.floorplan, Settings(), prior=Prior.at(*poses[0], 1.0, math.radians(15))) as loc:
        est = [loc.push(f) for f in jumped]
        assert loc.odometry_jumps > 0
    assert est[14].prior == "active" and est[-1].prior == "released"
    errors = _errors(est, poses)
    assert not any(e.status == "tracking" and err >= 1.0 for e, err in zip(est[15:], errors[15:]))


def test_settings_prior_is_the_constructions(symmetric):
    """A run recorded with a prior in its settings (a session log) replays with it."""
    scene, frames, poses = symmetric
    settings = Settings(prior={"pose": [*poses[0][:2], math.degrees(poses[0][2])]})
    with Localizer(scene.floorplan, settings) as loc:
        a = [loc.push(f) for f in frames[:8]]
    with Localizer(scene.floorplan, Settings(), prior=Prior.at(*poses[0])) as loc:
        b = [loc.push(f) for f in frames[:8]]
    assert [e.status for e in a] == [e.status for e in b] and a[-1].prior == "active"
    assert all((x.pose is None and y.pose is None) or np.array_equal(x.pose, y.pose) for x, y in zip(a, b))


def test_head_start_confirms_at_birth():
    """PRIOR_HEAD_START: with confirm_rounds - 1 extra hits a mode is tracked in its first
    round; without, it waits for a second."""
    from zfloc_stream.geometry.sim2 import Sim2
    from zfloc_stream.tracking.filter_bank import HypothesisTracker
    from zfloc_stream.tracking.policy import birth_hits

    class Hyp:
        def __init__(self, alignment, score):
            self.alignment, self.score = alignment, score

    hyps = [Hyp(Sim2(1.0, 0.3, (2.0, 1.0)), 0.8)]
    settings = Settings().tracking
    plain, helped = HypothesisTracker(settings), HypothesisTracker(settings)
    plain.update(hyps, (0.0, 0.0), 0)
    helped.update(hyps, (0.0, 0.0), 0, head_start=[settings.confirm_rounds - 1])
    assert plain.status == "initializing" and helped.status == "tracking"
    assert birth_hits(0) == 1 and birth_hits(-3) == 1 and birth_hits(2) == 3


def test_cli_wrong_prior_warns_once_and_the_session_replays_with_it(tmp_path, capsys):
    """run --initial-pose far from the truth: one warning line, the run falls back to the
    global search, and the session log records the prior so a replay reproduces the run."""
    from pathlib import Path

    from zfloc_stream.io.session import read_session
    from zfloc_stream.tools.replay_cli import main as replay

    sample = Path(__file__).resolve().parents[1] / "replay" / "office-laser.mcap"
    out = tmp_path / "out"
    assert main(["run", "--input", str(sample), "--scans", "0:25", "--initial-pose", "0,0,0,1,10", "--out", str(out),
                 "--no-progress"]) == 0
    captured = capsys.readouterr()
    warnings = [line for line in (captured.out + captured.err).splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "contradict the initial pose" in warnings[0], warnings
    assert "success@1m: yes" in captured.out
    logged = read_session(out / "session.mcap").settings.prior
    assert logged.pose == [0.0, 0.0, 0.0] and logged.sigma_theta_deg == 10.0
    assert replay([str(out / "session.mcap"), "--check", "--no-progress"]) == 0


def test_region_prior_resolves_the_symmetric_ambiguity(symmetric):
    """ "Somewhere in this wing": the half of the building the walk starts in."""
    scene, frames, poses = symmetric
    centre = np.asarray(scene.info["symmetry_center"])
    assert poses[0][0] < centre[0]  # the walk starts in the west half
    with Localizer(scene.floorplan, Settings(), prior=Prior.within((centre[0] - 30, centre[1] - 30, centre[0], centre[1] + 30))) as loc:
        est = [loc.push(f) for f in frames]
    tracking = [k for k, e in enumerate(est) if e.status == "tracking"]
    assert tracking and tracking[0] <= 10, [e.status for e in est]
    assert (_errors(est, poses)[tracking] < 1.0).all()


def test_the_priors_own_pose_stands_in_where_no_place_is_found(symmetric):
    """Before the first round, and on a map that lacks what the frames see, the prior's own
    pose (carried by odometry) is the estimate: `initializing`, rule PRIOR_POSE, the prior's
    covariance, a confidence that never reaches 0.5; without a prior no pose at all."""
    from zfloc_stream.prior import PRIOR_POSE_MAX_CONFIDENCE
    from zfloc_stream.tracking.status import Rule

    scene, frames, poses = symmetric
    prior = Prior.at(*poses[0], 2.0, math.radians(20))
    with Localizer(scene.floorplan, Settings(), prior=prior) as loc:
        first = loc.push(frames[0])
        assert loc.last_rule is Rule.PRIOR_POSE
    assert first.status == "initializing" and first.pose is not None
    assert np.linalg.norm(first.pose[:2] - poses[0][:2]) < 0.05
    assert np.allclose(np.diag(first.covariance), [4.0, 4.0, math.radians(20) ** 2])
    assert first.confidence == pytest.approx(1 - math.exp(-0.5 / 4.0)) and first.confidence < PRIOR_POSE_MAX_CONFIDENCE
    with Localizer(scene.floorplan, Settings()) as loc:
        assert loc.push(frames[0]).pose is None

    # a floorplan with no wall near the walk: no place explains the frames, the prior's pose
    # follows the odometry (within the simulator's drift), never `tracking`
    from zfloc_stream.plans.floorplan import Floorplan

    occupied = np.zeros((60, 60), dtype=bool)
    occupied[30, 10:50] = True  # one 4 m wall, 400 m from the walk
    far = Floorplan.from_occupancy(occupied, 0.1, (400.0, 400.0))
    with Localizer(far, Settings(), prior=prior) as loc:
        est = [loc.push(f) for f in frames[:20]]
    assert all(e.status != "tracking" for e in est)
    assert (_errors(est, poses[:20]) < 1.0).all()
