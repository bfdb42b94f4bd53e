"""Issue 41, for a robot user: nothing silent (each case one warning line or a one-line
error with exit 2), the summary at the end of `run`, and the small slips (overlay jumps,
study labels, replay --check wording, help examples, docstrings)."""

import dataclasses
import re

import ezdxf
import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.io.session import SessionWriter
from zfloc_stream.sim import build_scene, simulate_laser
from zfloc_stream.tools.cli import main
from zfloc_stream.io.tum import read_tum, tum_line

N = 20


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """A laser walk on `rooms`: a session with its own ground truth, one without (a robot's
    log), its truth as TUM, and the plan as map.yaml beside a session carrying none."""
    tmp = tmp_path_factory.mktemp("walk")
    scene = build_scene("rooms", seed=0)
    seq = simulate_laser(scene, seed=0, n_frames=N)
    with SessionWriter(tmp / "own.mcap", Settings(), scene.floorplan) as log:
        for i, frame in enumerate(seq.frames):
            log.write_frame(i, frame)
    with SessionWriter(tmp / "bare.mcap", Settings(), scene.floorplan) as log:
        for i, frame in enumerate(seq.frames):
            log.write_frame(i, dataclasses.replace(frame, ground_truth=None))
    plain = tmp / "noplan"
    plain.mkdir()
    with SessionWriter(plain / "session.mcap", Settings()) as log:
        for i, frame in enumerate(seq.frames):
            log.write_frame(i, frame)
    scene.floorplan.write_ros(plain, "map")
    (tmp / "gt.tum").write_text("".join(tum_line(f.timestamp, *f.ground_truth) for f in seq.frames))
    (tmp / "late.tum").write_text("".join(tum_line(f.timestamp + 1000.0, *f.ground_truth) for f in seq.frames))
    (tmp / "short.csv").write_text("x,y,theta\n" + "".join(f"{x:.17g},{y:.17g},{t:.17g}\n" for x, y, t in (f.ground_truth for f in seq.frames[:12])))
    return tmp, scene, seq


def run(capsys, *args):
    code = main(["run", *map(str, args), "--no-progress"])
    out, err = capsys.readouterr()
    return code, out, err


# --- nothing silent ---------------------------------------------------------------------------
def test_groundtruth_that_misses_the_input_is_said_and_the_inputs_own_is_kept(walk, tmp_path, capsys):
    tmp, scene, seq = walk
    code, out, err = run(capsys, "--input", tmp / "own.mcap", "--groundtruth", tmp / "late.tum", "--out", tmp_path / "o")
    assert code == 0, err
    line = [w for w in err.splitlines() if "late.tum" in w]
    assert len(line) == 1 and line[0].startswith("warning: ground truth late.tum: no pose for any of the 20 frames"), err
    t0, t1 = seq.frames[0].timestamp, seq.frames[-1].timestamp
    assert f"(its stamps span {t0 + 1000:.3f}-{t1 + 1000:.3f} s, the input's {t0:.3f}-{t1:.3f} s); not used: the input's own ground truth kept (20 frames)" in line[0]
    assert "position error over" in out and "success@1m" in out  # the session's own truth still gives the figures
    _, truth = read_tum(tmp_path / "o" / "groundtruth.tum")
    np.testing.assert_allclose(truth[:, :2], [f.ground_truth[:2] for f in seq.frames], atol=1e-9)


def test_groundtruth_for_part_of_the_frames_is_said_and_what_can_be_computed_is_printed(walk, tmp_path, capsys):
    tmp, scene, seq = walk
    code, out, err = run(capsys, "--input", tmp / "bare.mcap", "--groundtruth", tmp / "short.csv", "--out", tmp_path / "o")
    assert code == 0, err
    assert re.search(r"^warning: ground truth short.csv: a pose for 12 of the 20 frames \(its rows cover frames 0-11, "
                     r"the input's frames 0-19\); the errors and success figures cover only frames with ground truth$", err, re.M), err
    assert "position error over" in out
    assert re.search(r"success@1m: not computed: it needs ground truth on each of the last 10 frames, 2 of them have it; "
                     r"last frame with ground truth: 11, error ([\d.]+ m|- \(no pose\))", out), out
    # a session with its own truth keeps it where the file has none, and says so
    code, out, err = run(capsys, "--input", tmp / "own.mcap", "--groundtruth", tmp / "short.csv", "--out", tmp_path / "own")
    assert code == 0 and "a pose for 12 of the 20 frames" in err and "the input's own ground truth kept on 8 other frames" in err, err
    assert "success@1m: not computed" not in out and "final position error" in out
    # the file covering every frame is not worth a word
    code, out, err = run(capsys, "--input", tmp / "bare.mcap", "--groundtruth", tmp / "gt.tum", "--out", tmp_path / "full")
    assert code == 0 and "warning" not in err, err


def test_odometry_noise_on_a_recorded_session_is_refused(walk, tmp_path, capsys):
    tmp, _, _ = walk
    code, out, err = run(capsys, "--input", tmp / "own.mcap", "--odometry-noise", "0.05", "--out", tmp_path / "o")
    assert code == 2 and err.count("\n") == 1, err
    assert "error: --odometry-noise applies to Carmen logs and Gibson(t) scenes" in err and "own.mcap" in err
    assert not (tmp_path / "o").exists()


def test_the_map_yaml_taken_beside_a_session_is_named(walk, tmp_path, capsys):
    tmp, _, _ = walk
    code, out, err = run(capsys, "--input", tmp / "noplan" / "session.mcap", "--out", tmp_path / "o")
    assert code == 0, err
    assert f"floorplan: {tmp / 'noplan' / 'map.yaml'}, beside the input (the session carries none" in out
    code, out, err = run(capsys, "--input", tmp / "own.mcap", "--out", tmp_path / "p")
    assert "floorplan: the one the session carries" in out


@pytest.fixture()
def layered_dxf(tmp_path):
    """Walls and a table on layers the DXF's LAYER table does not list (ezdxf audits it clean)."""
    doc = ezdxf.new(units=6)  # metres
    msp = doc.modelspace()
    for a, b in (((0, 0), (10, 0)), ((10, 0), (10, 8)), ((10, 8), (0, 8)), ((0, 8), (0, 0)), ((5, 0), (5, 3))):
        msp.add_line(a, b, dxfattribs={"layer": "WALLS"})
    msp.add_line((2, 5), (3, 5), dxfattribs={"layer": "FURNITURE"})
    for name in ("WALLS", "FURNITURE"):
        if name in doc.layers:
            doc.layers.remove(name)
    path = tmp_path / "plan.dxf"
    doc.saveas(path)
    doc = ezdxf.readfile(path)
    assert {layer.dxf.name for layer in doc.layers} == {"0", "Defpoints"} and not doc.audit().has_errors
    return path


def test_dxf_layers_used_by_entities_count_and_a_misspelt_layer_is_refused(layered_dxf, tmp_path, capsys):
    from zfloc_stream.plans.vector import load_vector_floorplan

    walls = load_vector_floorplan(layered_dxf, layers=["WALLS"])
    every = load_vector_floorplan(layered_dxf)
    assert 0 < walls.occupied.sum() < every.occupied.sum()
    assert load_vector_floorplan(layered_dxf, skip_layers=["furniture"]).occupied.sum() == walls.occupied.sum()
    for option in ("--skip-layers", "--layers"):
        code = main(["demo", "--floorplan", str(layered_dxf), option, "FURNITUR", "--frames", "2", "--out", str(tmp_path / "o"),
                     "--no-progress"])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, err
        assert f"no layer(s) furnitur ({option}); its layers: 0, Defpoints, FURNITURE, WALLS" in err


# --- the summary ----------------------------------------------------------------------------
def test_the_summary_says_how_the_run_went_how_fast_and_rmse_as_evo(walk, tmp_path, capsys):
    tmp, _, _ = walk
    code, out, err = run(capsys, "--input", tmp / "bare.mcap", "--groundtruth", tmp / "gt.tum", "--out", tmp_path / "o")
    assert code == 0, err
    m = re.search(r"final status: (\w+), confidence ([\d.]+), score (-?[\d.]+) \(of 1 = every wall seen on a plan wall", out)
    assert m, out
    counts = re.search(r"frames by status: initializing (\d+), tracking (\d+), ambiguous (\d+), lost (\d+); "
                       r"(never tracking|first tracking at frame (\d+) \((\d+) frames into the run, t = [\d.]+ s\))", out)
    assert counts and sum(int(counts[i]) for i in range(1, 5)) == N, out
    rows = [line.split(",") for line in (tmp_path / "o" / "trajectory.csv").read_text().splitlines()[1:]]
    statuses = [r[8] for r in rows]
    assert [statuses.count(s) for s in ("initializing", "tracking", "ambiguous", "lost")] == [int(counts[i]) for i in range(1, 5)]
    if "tracking" in statuses:
        assert int(counts[6]) == statuses.index("tracking") and int(counts[7]) == statuses.index("tracking") + 1
    assert statuses[-1] == m[1]
    assert re.search(rf"speed: {N} frames in [\d.]+ s = [\d.]+ frames/s \(reading and writing included\); "
                     r"push latency p50 [\d.]+ ms, p99 [\d.]+ ms", out), out
    # RMSE as evo_ape computes it (translation, no alignment) from the two TUM files written
    rmse = float(re.search(r"posed frames with ground truth: RMSE ([\d.]+) m, mean", out)[1])
    stamps, truth = read_tum(tmp_path / "o" / "groundtruth.tum")
    est_stamps, est = read_tum(tmp_path / "o" / "trajectory.tum")
    err = np.linalg.norm(est[:, :2] - truth[np.searchsorted(stamps, est_stamps), :2], axis=1)  # both at z = 0
    assert rmse == pytest.approx(np.sqrt(np.mean(err**2)), abs=0.006)


# --- small slips ----------------------------------------------------------------------------------
def test_replay_check_of_a_session_cut_before_its_last_outputs_counts_what_it_checked(walk, tmp_path, capsys):
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.tools.replay_cli import main as replay

    tmp, scene, seq = walk
    settings = Settings()
    path = tmp_path / "cut.mcap"
    with Localizer(scene.floorplan, settings) as loc, SessionWriter(path, settings, scene.floorplan) as log:
        for i, frame in enumerate(seq.frames[:12]):
            est = loc.push(log.write_frame(i, frame))
            if i < 11:  # the run stopped after logging frame 11's input, before its outputs
                log.write_estimate(est, loc)
    assert replay([str(path), "--check", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "11 frames checked (0-10); frame 11 replayed but not checked: the file ends before their logged outputs" in out, out


def test_overlay_breaks_the_path_where_the_estimate_jumps_to_another_place():
    import matplotlib.pyplot as plt

    from zfloc_stream.io.overlay import jumps, overlay_figure
    from zfloc_stream.geometry.sim2 import Sim2

    plane = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [1.5, 0.0, 0.0], [2.0, 0.0, 0.0]])
    here = Sim2(1.0, 0.0, np.array([1.0, 1.0]))
    there = Sim2(1.0, 0.0, np.array([1.0, 7.0]))  # another mode, 6 m away
    nudged = Sim2(1.0, 0.02, np.array([1.05, 1.0]))  # the same mode, refined
    alignments = [here, here, there, there, nudged]
    # frame 4 is reported by `nudged` but follows `there`: a jump back of ~6 m
    est = np.array([np.array(a.apply_pose(*p)) for a, p in zip(alignments, plane)])
    np.testing.assert_array_equal(jumps(est, alignments), [False, False, True, False, True])
    smooth = [here, here, nudged, nudged, nudged]
    est_smooth = np.array([np.array(a.apply_pose(*p)) for a, p in zip(smooth, plane)])
    assert not jumps(est_smooth, smooth).any()
    fig = overlay_figure(build_scene("rooms", seed=0).floorplan, est, statuses=["tracking"] * 5, alignments=alignments)
    ax = fig.axes[0]
    segments = [s for c in ax.collections for s in c.get_segments()]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)
    assert len(segments) == 2  # 0-1 and 2-3; no line into frames 2 and 4
    assert any(label.startswith("estimate jumped here (2x") for label in labels)


def test_study_tables_tell_two_sessions_named_alike_apart():
    from zfloc_stream.study.report import dataset_labels, markdown_table

    specs = ["mcap:/data/fhw/session.mcap", "mcap:/data/aces/session.mcap", "carmen:/logs/intel.log.gz"]
    labels = dataset_labels(specs)
    assert labels == {specs[0]: "mcap:fhw/session.mcap", specs[1]: "mcap:aces/session.mcap", specs[2]: "carmen:intel.log.gz"}
    stat = {"mean": 0.5, "std": float("nan")}
    summary = [{"dataset": d, "length": 15, "n_runs": 1, "n_errors": 0, "n_no_pose": 0, "success_rate": {"1": stat},
                "rmse_succ": stat, "rmse_all": stat} for d in specs]
    table = markdown_table(summary, [15], [1.0])
    assert "| mcap:fhw/session.mcap |" in table and "| mcap:aces/session.mcap |" in table


def test_every_command_help_has_examples(capsys):
    from zfloc_stream.tools.cli import build_parser
    from zfloc_stream.tools.cli_support import _subparsers
    from zfloc_stream.tools.replay_cli import main as replay
    from zfloc_stream.tools.study_cli import main as study

    commands = [(main, [name, "--help"]) for name in _subparsers(build_parser())] + [(main, ["--help"]), (replay, ["--help"]), (study, ["--help"])]
    assert len(commands) >= 8
    for entry, argv in commands:
        with pytest.raises(SystemExit) as exit_info:
            entry(argv)
        assert exit_info.value.code == 0
        text = capsys.readouterr().out
        assert "\nexamples:\n  zfloc-" in text, (argv, text)


def test_the_public_classes_say_what_they_are_and_what_each_field_means():
    from zfloc_stream.estimate import Estimate
    from zfloc_stream.stream.localizer import Localizer

    assert "push(frame)" in Localizer.__doc__ and "Estimate" in Localizer.__doc__
    doc = Estimate.__doc__
    for name in [f.name for f in dataclasses.fields(Estimate)] + ["scale", "n_hypotheses"]:
        assert re.search(rf"^    {name}: \S", doc, re.M), name
    assert "1 is a perfect match" in doc
