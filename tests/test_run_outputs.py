"""What `zfloc-stream run` tells and writes (issue 28): ground truth from a file for any
input with the error summary, a window of the input, ROS 2 messages that evo reads with
the same numbers as ours, and the live Foxglove view over a loopback WebSocket."""

import dataclasses
import importlib.util
import json
import re
import struct
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.io.session import SessionWriter, record_session
from zfloc_stream.sim import build_scene, simulate_laser
from zfloc_stream.tools.cli import main
from zfloc_stream.io.tum import read_tum, tum_line

N = 16


@pytest.fixture(scope="module")
def laser(tmp_path_factory):
    """A laser walk: its floorplan, a session holding its inputs without ground truth, and
    the truth apart, as TUM and as CSV (the layout of the shared sessions' gt.csv)."""
    tmp = tmp_path_factory.mktemp("laser")
    scene = build_scene("rooms", seed=0)
    seq = simulate_laser(scene, seed=0, n_frames=N)
    truth = np.array([f.ground_truth for f in seq.frames])
    with SessionWriter(tmp / "inputs.mcap", Settings(), scene.floorplan) as log:  # a robot's log: no truth in it
        for i, frame in enumerate(seq.frames):
            log.write_frame(i, dataclasses.replace(frame, ground_truth=None))
    (tmp / "gt.tum").write_text("".join(tum_line(f.timestamp, *f.ground_truth) for f in seq.frames))
    (tmp / "gt.csv").write_text("x,y,theta\n" + "".join(f"{x:.17g},{y:.17g},{t:.17g}\n" for x, y, t in truth))
    return tmp, scene, seq, truth


def _summary(stdout: str) -> dict:
    m = re.search(r"position error over (\d+) posed frames with ground truth: RMSE [\d.]+ m, mean ([\d.]+) m, median ([\d.]+) m, "
                  r"max ([\d.]+) m; (\d+) frames more than 1 m off", stdout)
    assert m, stdout
    return {"posed": int(m[1]), "mean": float(m[2]), "median": float(m[3]), "max": float(m[4]), "off": int(m[5])}


def test_groundtruth_from_tum_or_csv_gives_the_summary_for_an_input_without_truth(laser, tmp_path, capsys):
    tmp, scene, seq, truth = laser
    assert main(["run", "--input", str(tmp / "inputs.mcap"), "--out", str(tmp_path / "none"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "position error" not in out and "input: MCAP session" in out and "/scan" in out  # names the topics it read
    summaries = []
    for gt in ("gt.tum", "gt.csv"):
        assert main(["run", "--input", str(tmp / "inputs.mcap"), "--groundtruth", str(tmp / gt), "--out", str(tmp_path / gt),
                     "--no-progress"]) == 0
        out = capsys.readouterr().out
        summaries.append(_summary(out))
        assert re.search(r"frames within 1 m by status: .*tracking \d+/\d+", out), out
        # the reference written beside the estimate holds the truth at the same stamps
        stamps, poses = read_tum(tmp_path / gt / "groundtruth.tum")
        np.testing.assert_allclose(poses[:, :2], truth[:, :2], atol=1e-9)
        est_stamps, est = read_tum(tmp_path / gt / "trajectory.tum")
        assert set(est_stamps) <= set(stamps) and len(est) == summaries[-1]["posed"]
        # and the summary is the error of trajectory.tum against it
        err = np.linalg.norm(est[:, :2] - poses[np.searchsorted(stamps, est_stamps), :2], axis=1)
        assert summaries[-1]["mean"] == pytest.approx(err.mean(), abs=0.006)
        assert summaries[-1]["off"] == int((err > 1.0).sum())
    assert summaries[0] == summaries[1]


def test_scans_takes_a_window_and_csv_rows_follow_input_frame_numbers(laser, tmp_path, capsys):
    tmp, scene, seq, truth = laser
    assert main(["run", "--input", str(tmp / "inputs.mcap"), "--groundtruth", str(tmp / "gt.csv"), "--scans", "4:14",
                 "--out", str(tmp_path / "w"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "frames 4-13 of 16" in out
    rows = (tmp_path / "w" / "trajectory.csv").read_text().splitlines()
    assert len(rows) == 1 + 10
    stamps, poses = read_tum(tmp_path / "w" / "groundtruth.tum")
    np.testing.assert_allclose(poses[:, :2], truth[4:14, :2], atol=1e-9)  # frame 4's truth for the window's first frame
    assert main(["run", "--input", str(tmp / "inputs.mcap"), "--scans", "20:30", "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert "has only 16 frames" in capsys.readouterr().err


def _evo_ape(*args) -> dict:
    exe = Path(sys.executable).with_name("evo_ape")
    proc = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {k: float(v) for k, v in re.findall(r"^\s*(max|mean|median|min|rmse)\s+([\d.eE+-]+)\s*$", proc.stdout, re.M)}


@pytest.mark.skipif(importlib.util.find_spec("evo") is None, reason="evo not installed (the [eval] extra)")
def test_ros2_messages_and_tum_read_by_evo_agree_with_our_error_figures(laser, tmp_path, capsys):
    tmp, scene, seq, truth = laser
    out = tmp_path / "r"
    assert main(["run", "--input", str(tmp / "inputs.mcap"), "--groundtruth", str(tmp / "gt.tum"), "--ros2",
                 "--out", str(out), "--no-progress"]) == 0
    ours = _summary(capsys.readouterr().out)
    tum = _evo_ape("tum", str(out / "groundtruth.tum"), str(out / "trajectory.tum"))
    bag = _evo_ape("bag2", str(out / "ros2.mcap"), "/zfloc/groundtruth", "/zfloc/pose")
    for figures in (tum, bag):
        assert figures["mean"] == pytest.approx(ours["mean"], abs=0.006)
        assert figures["median"] == pytest.approx(ours["median"], abs=0.006)
        assert figures["max"] == pytest.approx(ours["max"], abs=0.006)
    # the map -> odom transform carries each frame's odometry-plane pose onto its estimate
    from mcap_ros2.reader import read_ros2_messages

    msgs = {}
    for m in read_ros2_messages(str(out / "ros2.mcap")):
        msgs.setdefault(m.channel.topic, []).append(m.ros_msg)
    grid = msgs["/zfloc/floorplan"][0]
    assert (grid.info.width, grid.info.height) == scene.floorplan.occupied.shape[::-1]
    assert np.array_equal(np.array(grid.data).reshape(grid.info.height, grid.info.width) == 100, scene.floorplan.occupied)
    assert len(msgs["/tf"]) == len(msgs["/zfloc/pose"]) == ours["posed"]
    assert len(msgs["/zfloc/pose"][-1].pose.covariance) == 36  # PoseWithCovarianceStamped, as AMCL: evo reads it too
    tf = msgs["/tf"][-1].transforms
    assert [(t.header.frame_id, t.child_frame_id) for t in tf] == [("map", "odom"), ("odom", "base_link")]


def _foxglove_client(url, received, ready, done):
    """A Foxglove WebSocket client (the protocol Foxglove itself speaks): subscribe to every
    channel advertised, collect (topic, payload) of the message data frames."""
    from websockets.sync.client import connect

    channels, next_id, subs = {}, 1, {}
    with connect(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], open_timeout=10, max_size=None) as ws:
        ready.set()
        while not done.is_set() or subs and len(received) == 0:
            try:
                msg = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:  # noqa: BLE001 - the server went away at the end of the run
                return
            if isinstance(msg, str):
                op = json.loads(msg)
                wanted = []
                if op.get("op") == "advertise":
                    for ch in op["channels"]:
                        channels[ch["id"]] = ch
                        wanted.append(ch["id"])
                elif op.get("op") == "status" and "unknown channel" in op.get("message", "").lower():
                    # foxglove-sdk 0.30 can answer a subscription sent right after an
                    # advertisement with "unknown channel" (a race on its side): ask again
                    wanted = [int(op["message"].rsplit(":", 1)[1])]
                new = []
                for channel_id in wanted:
                    subs[next_id] = channel_id
                    new.append({"id": next_id, "channelId": channel_id})
                    next_id += 1
                if new:
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif msg[0] == 1:  # MessageData: opcode, subscription id, log time, payload
                sub, log_time = struct.unpack_from("<IQ", msg, 1)
                ch = channels[subs[sub]]
                received.append((ch["topic"], ch["schemaName"], log_time, bytes(msg[13:])))


@pytest.mark.skipif(importlib.util.find_spec("foxglove") is None or importlib.util.find_spec("websockets") is None,
                    reason="needs foxglove-sdk (the [live] extra) and websockets (the [test] extra)")
def test_live_view_serves_floorplan_bev_and_poses_to_a_websocket_client(laser, tmp_path):
    from zfloc_stream.io.session import schemas as S
    from zfloc_stream.tools.live import LiveServer
    from zfloc_stream.tools.session_runner import run_session
    from zfloc_stream.io.trajectory_csv import read_trajectory_csv

    tmp, scene, seq, truth = laser
    settings = Settings().model_copy(update={"logging": Settings().logging.model_copy(update={"bev_every_n_frames": 2})})
    settings = settings.model_copy(update={"estimator": settings.estimator.model_copy(update={"scale_mode": "fixed"})})
    server = LiveServer(0)  # port 0: a free one
    assert server.url.startswith("ws://127.0.0.1:")
    received, ready, done = [], threading.Event(), threading.Event()
    client = threading.Thread(target=_foxglove_client, args=(server.url, received, ready, done), daemon=True)
    client.start()
    assert ready.wait(10)
    try:
        run_session(scene.floorplan, iter(seq.frames), settings, tmp_path / "live", progress=False, live=server)
    finally:
        done.set()
        client.join(10)
        server.close()
    topics = {t for t, *_ in received}
    assert {S.TOPIC_FLOORPLAN, S.TOPIC_BEV, S.TOPIC_POSE, S.TOPIC_STATUS, S.TOPIC_SCAN} <= topics, topics
    # the bytes are those of the session log: the last pose is the last estimate
    last = [p for t, _, _, p in received if t == S.TOPIC_POSE][-1]
    pose = S.PoseInFrame.FromString(last).pose.position
    row = [r for r in read_trajectory_csv(tmp_path / "live" / "trajectory.csv") if r["x"]][-1]
    assert (pose.x, pose.y) == pytest.approx((float(row["x"]), float(row["y"])), abs=1e-9)
    grid = [p for t, _, _, p in received if t == S.TOPIC_FLOORPLAN][0]
    assert len(grid) > 100  # the floorplan, re-sent to this late subscriber


def test_overlay_marks_the_start_colours_the_path_by_status_and_names_every_marker():
    import matplotlib.pyplot as plt

    from zfloc_stream.io.overlay import STATUS_COLOURS, overlay_figure

    plan = build_scene("rooms", seed=0).floorplan
    est = np.array([[np.nan] * 3, [1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [3.0, 1.5, 0.5], [3.5, 2.0, 1.0]])
    truth = est + 0.1
    truth[0] = [0.9, 0.9, 0.0]
    fig = overlay_figure(plan, est, truth, statuses=["initializing", "initializing", "tracking", "ambiguous", "tracking"])
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)
    assert labels == ["ground truth", "ground truth start", "ground truth end",
                      "estimate (tracking)", "estimate (ambiguous)", "estimate start (first pose)", "final estimated pose and heading"]
    segments = ax.collections[-1]
    colours = [tuple(c) for c in segments.get_colors()]
    from matplotlib.colors import to_rgba

    assert colours == [to_rgba(STATUS_COLOURS[s]) for s in ("tracking", "ambiguous", "tracking")]


def test_a_ros2_bag_gets_ground_truth_from_a_tum_file_and_run_names_its_topics(laser, tmp_path, capsys):
    """A robot's bag carries no truth: --groundtruth gives it, matched by the scans' stamps."""
    from ros2_bag import mount, write_sensor_bag

    tmp, scene, seq, truth = laser
    bag = tmp_path / "robot.mcap"
    stamps = write_sensor_bag(bag, seq.frames, mount(0.0, 0.0, 0.3), sensor_hz=10, odom_hz=40)
    (tmp_path / "gt.tum").write_text("".join(tum_line(ns / 1e9, *t) for ns, t in zip(stamps, truth)))
    plan = scene.floorplan.write_ros(tmp_path / "plan")
    assert main(["run", "--floorplan", str(plan), "--input", str(bag), "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "input: ROS 2 bag" in out and "scan=/scan" in out and "position error" not in out
    assert main(["run", "--floorplan", str(plan), "--input", str(bag), "--groundtruth", str(tmp_path / "gt.tum"),
                 "--out", str(tmp_path / "g"), "--no-progress"]) == 0
    summary = _summary(capsys.readouterr().out)
    assert summary["posed"] >= N - 4 and summary["mean"] < 0.5
