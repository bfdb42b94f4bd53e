"""zfloc-replay on sessions recorded with the real engine: --check, ranges, overrides,
divergence reports and clean failures on bad input."""

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from session_helpers import record_laser_session

from zfloc_stream.session import read_session
from zfloc_stream.session import schemas as S
from zfloc_stream.tools.replay_cli import main

INTEL = Path("/work/shared/data/sessions/intel-camera-30")
if not INTEL.exists():
    INTEL = Path(__file__).resolve().parents[1] / "data" / "sessions" / "intel-camera-30"
N = 30


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "walk.mcap"
    estimates = record_laser_session(path, N)
    assert estimates[-1].pose is not None  # the engine localized: there is something to compare
    return path


def _rewrite(src: Path, dst: Path, edit_status) -> None:
    """Copy an MCAP record by record, passing each status JSON through edit_status."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out)
        w.start()
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for a in reader.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {
            cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], c.metadata) for cid, c in summary.channels.items()
        }
        f.seek(0)
        for _schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            data = msg.data
            if channel.topic == S.TOPIC_STATUS:
                data = json.dumps(edit_status(json.loads(data))).encode()
            w.add_message(channel_ids[channel.id], msg.log_time, data, msg.publish_time, msg.sequence)
        w.finish()


def test_replay_check_is_identical(recorded, capsys):
    # the run logged its BEV (every logging.bev_every_n_frames frames): the check covers it
    grids = [r.outputs.bev_grid for r in read_session(recorded).records() if r.outputs.bev is not None]
    assert len(grids) == N // 10 and all(g.values.size > 100 and g.resolution > 0 for g in grids)
    assert main([str(recorded), "--check", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert f"identical: {N} frames checked (0-{N - 1})" in out


def test_replay_check_of_a_range_warms_up_first(recorded, capsys):
    assert main([str(recorded), "--check", "--from", "12", "--to", "20"]) == 0
    assert "identical: 8 frames checked (12-19)" in capsys.readouterr().out


def test_divergence_is_reported_with_frame_topic_and_values(recorded, tmp_path, capsys):
    def edit(status):
        if status["frame"] == 17 and status["score"] is not None:
            status["score"] += 1e-9
        return status

    _rewrite(recorded, tmp_path / "tampered.mcap", edit)
    assert main([str(tmp_path / "tampered.mcap"), "--check"]) == 1
    out = capsys.readouterr().out
    assert "DIVERGED at frame 17, /zfloc/status: score: logged" in out and "replay" in out
    # timings are measurements: changing them is not a divergence
    _rewrite(recorded, tmp_path / "timings.mcap", lambda s: {**s, "timings": {"fusion": 123.0}})
    assert main([str(tmp_path / "timings.mcap"), "--check"]) == 0


def test_overrides_write_a_new_session_with_a_side_by_side_summary(recorded, tmp_path, capsys):
    out_path = tmp_path / "fewer.mcap"
    assert main([str(recorded), "--set", "estimator.ransac.iterations=60", "--out", str(out_path)]) == 0
    out = capsys.readouterr().out
    assert "logged" in out and "replay" in out and "success (last frames within 1 m)" in out
    assert "mean position error" in out and "mean time per frame" in out and f"wrote {out_path}" in out
    session = read_session(out_path)
    assert session.settings.estimator.ransac.iterations == 60 and session.info["replay_of"] == str(recorded)
    assert len(list(session.frames())) == N
    # the new session is itself an exact record of its run
    assert main([str(out_path), "--check"]) == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["{missing}"], "session file not found"),
        (["{text}"], "not an MCAP file"),
        (["{rec}", "--set", "estimator.nope=1"], "unknown setting 'estimator.nope'"),
        (["{rec}", "--set", "estimator"], "must look like dotted.key=value"),
        (["{rec}", "--from", "500"], "no frame in the requested range"),
        (["{rec}", "--from", "5", "--to", "3"], "empty frame range"),
        (["{rec}", "--config", "{missing}"], "config file not found"),
        (["{rec}", "--out", "{rec}"], "would overwrite"),
        (["{intel}"], "carries no floorplan: pass --floorplan"),
        (["{rec}", "--bogus"], "unrecognized arguments"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(recorded, tmp_path, capsys, args, message):
    (tmp_path / "text.mcap").write_text("not mcap")
    names = {"missing": tmp_path / "nope.mcap", "text": tmp_path / "text.mcap", "rec": recorded, "intel": INTEL / "session.mcap"}
    with pytest.raises(SystemExit) if "--bogus" in args else _no_raise():
        code = main([a.format(**{k: str(v) for k, v in names.items()}) for a in args])
        assert code == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if not line.startswith("note:")]
    assert len(lines) == 1 and message in lines[0], err


class _no_raise:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "--check" in out and "--salvage" in out


def test_session_of_another_tool_replays_with_a_floorplan(tmp_path, capsys):
    """intel-camera-30 (camera frames, real building) through the engine, then --check
    of the session it wrote."""
    out_path = tmp_path / "intel.mcap"
    fast = ["--set", "estimator.ransac.iterations=60", "--set", "estimator.ransac.tracking_iterations=30"]
    code = main([str(INTEL / "session.mcap"), "--floorplan", str(INTEL / "map.yaml"), "--to", "10", *fast, "--out", str(out_path)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "carries no settings" in captured.err and "final position error" in captured.out
    assert main([str(INTEL / "session.mcap"), "--floorplan", str(INTEL / "map.yaml"), "--check"]) == 2
    assert "nothing to check" in capsys.readouterr().err
    assert main([str(out_path), "--check"]) == 0
    assert "identical: 10 frames checked" in capsys.readouterr().out


def test_floorplan_built_with_other_settings_still_replays(tmp_path, capsys):
    """The floorplan of a built-in scene has the default settings while the run uses
    seed 5: its settings are logged so the replay rebuilds the same primitives."""
    from zfloc_stream.config import load_settings

    path = tmp_path / "seed5.mcap"
    record_laser_session(path, 12, settings=load_settings(overrides=["seed=5"]))
    session = read_session(path)
    assert session.settings.seed == 5 and session.floorplan_settings.seed == 0
    assert main([str(path), "--check"]) == 0
    assert "identical: 12 frames checked" in capsys.readouterr().out


def test_segment_replay_starts_fresh_and_default_out_lands_in_cwd(recorded, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main([str(recorded), "--from", "10", "--to", "18", "--set", "estimator.ransac.iterations=80"]) == 0
    out_path = tmp_path / "walk-replay.mcap"
    assert f"wrote {out_path.name}" in capsys.readouterr().out
    records = list(read_session(out_path).records())
    assert len(records) == 8 and records[0].outputs.estimate.frame == 0  # a fresh engine at frame 10
    assert records[0].frame.timestamp == next(read_session(recorded).frames(10, 11)).timestamp
