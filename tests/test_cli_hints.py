"""Every error a user can cause is one line on stderr with exit code 2, and every command
an error, a warning or a hint suggests exists and works: each case below makes the
mistake, reads the suggestion out of the message, runs it, and expects it to succeed
(issue 28)."""

import re
import shlex
from pathlib import Path

import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.io.session import SessionWriter, record_session
from zfloc_stream.sim import build_scene, simulate_laser
from zfloc_stream.tools import cli, replay_cli, study_cli

FIXED = ["--set", "estimator.scale_mode=fixed"]


def call(capsys, main, *args):
    """(exit code, stdout, stderr) of a CLI called in this process."""
    try:
        rc = main([str(a) for a in args])
    except SystemExit as exit_:  # argparse: usage errors and --help
        rc = exit_.code
    out, err = capsys.readouterr()
    return rc, out, err


def one_line_error(rc, err) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "np.float64" not in err
    return lines[0]


def known_options(command: str | None) -> set[str]:
    parser = cli.build_parser()
    if command is not None:
        parser = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction").choices[command]
    return {s for a in parser._actions for s in a.option_strings}


def assert_options_exist(message: str, command: str) -> None:
    """Every --option a message names is one the command has."""
    named = set(re.findall(r"(--[a-z][a-z-]*)", message))
    assert named <= known_options(command), (named - known_options(command), message)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hints")
    scene = build_scene("rooms", seed=0)
    frames = simulate_laser(scene, seed=0, n_frames=10).frames
    session_dir = tmp / "belgioioso-like"
    session_dir.mkdir()
    record_session(session_dir / "session.mcap", scene.floorplan, frames, Settings().model_copy(
        update={"estimator": Settings().estimator.model_copy(update={"scale_mode": "fixed"})}))
    yaml_path = scene.floorplan.write_ros(tmp / "plan", "map")
    return tmp, scene, frames, session_dir, yaml_path


def test_png_floorplan_hint_uses_the_real_option_syntax(made, tmp_path, capsys):
    tmp, scene, frames, session_dir, yaml_path = made
    png = yaml_path.with_suffix(".png")
    rc, _, err = call(capsys, cli.main, "run", "--floorplan", png, "--input", session_dir / "session.mcap", "--out", tmp_path / "a")
    line = one_line_error(rc, err)
    assert_options_exist(line, "run")
    hint = re.search(r"(--resolution \S+ --origin X Y)", line)[1]
    x0, y0 = scene.floorplan.origin
    args = shlex.split(hint.replace("X Y", f"{float(x0)!r} {float(y0)!r}"))
    rc, out, err = call(capsys, cli.main, "run", "--floorplan", png, *args, "--input", session_dir / "session.mcap",
                        "--out", tmp_path / "b", "--no-progress")
    assert rc == 0, err


def test_session_folder_as_input_points_at_its_mcap(made, tmp_path, capsys):
    tmp, scene, frames, session_dir, yaml_path = made
    rc, _, err = call(capsys, cli.main, "run", "--input", session_dir, "--out", tmp_path / "a")
    line = one_line_error(rc, err)
    assert "Gibson" not in line
    suggested = re.search(r"--input (\S+)", line)[1]
    assert suggested == str(session_dir / "session.mcap")
    rc, out, err = call(capsys, cli.main, "run", "--input", suggested, "--out", tmp_path / "b", "--no-progress")
    assert rc == 0, err


def test_unknown_floorplan_format_lists_every_format(made, tmp_path, capsys):
    bad = tmp_path / "plan.txt"
    bad.write_text("walls")
    rc, _, err = call(capsys, cli.main, "demo", "--floorplan", bad, "--out", tmp_path / "a")
    line = one_line_error(rc, err)
    for name in ("yaml", "png", "DXF", "SVG", "GeoJSON", "--resolution", "--origin"):
        assert name in line


def test_did_you_mean_for_settings_options_and_commands(made, tmp_path, capsys):
    tmp, scene, frames, session_dir, yaml_path = made
    rc, _, err = call(capsys, cli.main, "config", "--set", "estimator.ransac.iteratons=50")
    key = re.search(r"did you mean '([^']+)'", one_line_error(rc, err))[1]
    rc, out, err = call(capsys, cli.main, "config", "--set", f"{key}=50")
    assert rc == 0 and "iterations: 50" in out
    rc, _, err = call(capsys, cli.main, "run", "--flooplan", yaml_path, "--input", session_dir / "session.mcap", "--out", tmp_path / "a")
    option = re.search(r"did you mean (--[a-z-]+)\?", one_line_error(rc, err))[1]
    rc, out, err = call(capsys, cli.main, "run", option, yaml_path, "--input", session_dir / "session.mcap", "--out", tmp_path / "a", "--no-progress")
    assert rc == 0, err
    rc, _, err = call(capsys, cli.main, "confg")
    command = re.search(r"did you mean ([a-z-]+)\?", one_line_error(rc, err))[1]
    assert call(capsys, cli.main, command)[0] == 0
    rc, _, err = call(capsys, replay_cli.main, session_dir / "session.mcap", "--chek")
    assert "did you mean --check?" in one_line_error(rc, err)
    rc, _, err = call(capsys, study_cli.main, "--dataset", "sim:rooms", "--out", tmp_path / "s", "--seedz", "1")
    assert "did you mean --seeds?" in one_line_error(rc, err)


def test_out_naming_an_existing_file(made, tmp_path, capsys):
    tmp, scene, frames, session_dir, yaml_path = made
    taken = tmp_path / "taken"
    taken.write_text("mine")
    for main, args in ((cli.main, ["demo", "--frames", "2"]), (cli.main, ["run", "--input", session_dir / "session.mcap"]),
                       (study_cli.main, ["--dataset", "sim:rooms"])):
        rc, _, err = call(capsys, main, *args, "--out", taken)
        assert "is a file, not a folder" in one_line_error(rc, err)
    assert taken.read_text() == "mine"
    assert call(capsys, cli.main, "demo", "--frames", "2", "--out", tmp_path / "folder", "--no-progress")[0] == 0


def _plan_in_half_metres(path):
    """Two 4 x 4 m rooms joined by a 1 m door, drawn at half size with the header saying
    metres: every opening reads 0.5 m wide."""
    import ezdxf

    doc = ezdxf.new(units=6)
    msp = doc.modelspace()
    for a, b in [((0, 0), (8, 0)), ((8, 0), (8, 4)), ((8, 4), (0, 4)), ((0, 4), (0, 0)), ((4, 0), (4, 1.5)), ((4, 2.5), (4, 4))]:
        msp.add_line((a[0] / 2, a[1] / 2), (b[0] / 2, b[1] / 2))
    doc.saveas(path)


def test_narrow_openings_say_the_clear_width_and_the_scale_hint_works(tmp_path, capsys):
    plan = tmp_path / "half.dxf"
    _plan_in_half_metres(plan)
    rc, _, err = call(capsys, cli.main, "demo", "--floorplan", plan, "--frames", "3", "--out", tmp_path / "a")
    line = one_line_error(rc, err)
    assert re.search(r"no walkable path from \(-?[\d.]+, -?[\d.]+\) to \(-?[\d.]+, -?[\d.]+\)", line), line
    assert "clear width of at least 0.6 m" in line
    assert_options_exist(line, "demo")
    assert "--scale" in line
    rc, out, err = call(capsys, cli.main, "demo", "--floorplan", plan, "--scale", "2", "--frames", "3", "--out", tmp_path / "b", "--no-progress")
    assert rc == 0, err


def test_carmen_self_test_warning_recipe_runs(tmp_path, capsys):
    from laser_helpers import laser_run, write_carmen

    scene, seq = laser_run("rooms", 24)
    log = tmp_path / "robot.log"
    write_carmen(log, seq, stamp_digits=12)
    rc, out, err = call(capsys, cli.main, "run", "--input", log, "--out", tmp_path / "self", "--no-progress")
    assert rc == 0, err
    warning = [line for line in err.splitlines() if line.startswith("warning: ")]
    assert len(warning) == 1 and "self-test" in warning[0], err
    recipe = re.search(r"(zfloc-stream map-from-log LOG --exclude A:B --out DIR), then (run --scans A:B)", warning[0])
    assert recipe, warning[0]
    first = shlex.split(recipe[1].replace("LOG", str(log)).replace("A:B", "8:16").replace("DIR", str(tmp_path / "held")))[1:]
    rc, out, err = call(capsys, cli.main, *first)
    assert rc == 0, err
    second = shlex.split(recipe[2].replace("A:B", "8:16"))
    rc, out, err = call(capsys, cli.main, *second, "--input", log, "--floorplan", tmp_path / "held" / "map.yaml",
                        "--out", tmp_path / "held-run", "--no-progress")
    assert rc == 0, err
    assert "frames 8-15 of 24" in out and "position error over" in out  # the log's own poses are the truth


def test_truncated_session_hint_names_an_option_run_has(made, tmp_path, capsys):
    tmp, scene, frames, session_dir, yaml_path = made
    data = (session_dir / "session.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    rc, _, err = call(capsys, cli.main, "run", "--input", cut, "--out", tmp_path / "a", "--no-progress")
    line = one_line_error(rc, err)
    assert "--salvage" in line, line
    assert_options_exist(line, "run")
    rc, out, err = call(capsys, cli.main, "run", "--input", cut, "--salvage", "--out", tmp_path / "b", "--no-progress")
    assert rc == 0, err


def test_export_of_inputs_only_says_to_run_first_and_that_works(made, tmp_path, capsys):
    tmp, scene, frames, session_dir, yaml_path = made
    inputs = tmp_path / "inputs.mcap"
    with SessionWriter(inputs, Settings(), scene.floorplan) as log:
        for i, frame in enumerate(frames):
            log.write_frame(i, frame)
    rc, _, err = call(capsys, cli.main, "export", inputs, "--tum", tmp_path / "t.tum")
    line = one_line_error(rc, err)
    command = re.search(r"with (zfloc-stream \S+)", line)[1].split()[1:]
    rc, out, err = call(capsys, cli.main, *command, "--input", inputs, *FIXED, "--out", tmp_path / "r", "--no-progress")
    assert rc == 0, err
    rc, out, err = call(capsys, cli.main, "export", tmp_path / "r" / "session.mcap", "--tum", tmp_path / "t.tum")
    assert rc == 0 and "poses" in out, err


def test_replay_help_states_the_tolerances_the_settings_have(capsys):
    rc, out, _ = call(capsys, replay_cli.main, "--help")
    assert rc == 0
    replay = Settings().replay
    rtol, atol = re.search(r"\(defaults (\S+) / (\S+)\)", out).groups()
    assert (float(rtol), float(atol)) == (replay.rtol, replay.atol)
    looser = float(re.search(r"--set replay.rtol=(\S+)\s+# a looser tolerance", out)[1])
    assert looser > replay.rtol


def test_short_run_says_no_pose_yet(tmp_path, capsys):
    rc, out, err = call(capsys, cli.main, "demo", "--frames", "3", "--out", tmp_path / "d", "--no-progress")
    assert rc == 0, err
    assert "no pose yet" in out and "nan" not in out and "inf" not in out


def test_progress_off_a_terminal_is_plain_periodic_lines():
    import io

    from zfloc_stream.tools.cli_support import Progress

    stream = io.StringIO()  # a log file: not a terminal, so no bar and no carriage returns
    with Progress(4, "run x", "frame", stream=stream, every=0.0) as bar:
        for _ in range(4):
            bar.update()
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue()
    assert lines[0].startswith("run x: 1/4 frames") and lines[3].startswith("run x: 4/4 frames")
    quiet = io.StringIO()
    with Progress(4, "run x", stream=quiet, enabled=False) as bar:  # --no-progress
        bar.update(4)
    assert quiet.getvalue() == ""


@pytest.mark.parametrize("prog, build", [("zfloc-stream", cli.build_parser), ("zfloc-replay", replay_cli.build_parser),
                                         ("zfloc-study", study_cli.build_parser)])
def test_every_help_example_parses(prog, build, capsys):
    """The example lines of every --help (top level and each command) are commands the
    parser accepts as written: no option that does not exist, no missing argument."""
    parser = build()
    helps = [parser.format_help()]
    for action in parser._actions:
        if action.__class__.__name__ == "_SubParsersAction":
            helps += [sub.format_help() for sub in action.choices.values()]
    examples = []
    for text in helps:
        joined = re.sub(r"\\\n\s*", " ", text)  # continued example lines
        examples += [re.split(r" [>|] ", line.split("#")[0])[0].strip()  # the command, not the shell around it
                     for line in joined.splitlines() if line.strip().startswith(prog + " ")]
    assert len(examples) >= 3
    for example in examples:
        try:
            build().parse_args(shlex.split(example)[1:])
        except SystemExit as exit_:
            pytest.fail(f"{example!r}: {capsys.readouterr().err.strip()} (exit {exit_.code})")
