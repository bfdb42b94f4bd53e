"""Valid but unusual session files read right, or refused in one line (issue 44):
messages out of log-time order, a damaged first chunk under --salvage, depth in
millimetres, lens distortion, huge log times and poses."""

import warnings

import numpy as np
import pytest
from mcap.writer import Writer
from session_helpers import camera_frames, laser_frames, write_fake_session
from session_hostile import ORDERS, frame_messages, ordered, write_messages

from zfloc_stream.config import Settings, load_settings
from zfloc_stream.errors import SessionLogError
from zfloc_stream.session import read_session


def _same_frames(got, frames):
    assert len(got) == len(frames)
    for rec, fr in zip(got, frames, strict=True):
        assert rec.frame.timestamp == pytest.approx(fr.timestamp)
        if hasattr(fr, "depth"):
            assert np.array_equal(np.nan_to_num(rec.frame.depth), np.nan_to_num(fr.depth))
            assert np.array_equal(rec.frame.labels, fr.labels)
            np.testing.assert_allclose(rec.frame.T_odom_cam, fr.T_odom_cam, atol=1e-9)
        else:
            np.testing.assert_allclose(rec.frame.ranges, fr.ranges)
        d = np.asarray(rec.frame.ground_truth) - fr.ground_truth
        d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(d, 0, atol=1e-9)


# --- message order ----------------------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_messages_out_of_log_time_order_lose_no_frame(tmp_path, order):
    """Issue 44: grouped by topic or shuffled, 49 of 50 frames were lost (read in file order)."""
    frames = camera_frames(50, seed=3, shape=(12, 16))
    path = tmp_path / f"{order}.mcap"
    write_messages(path, ordered(frame_messages(frames), order, np.random.default_rng(1)))
    session = read_session(path)
    got = list(session.records())
    _same_frames(got, frames)
    assert session.problems == []
    index = session.frame_index()  # the seek index groups the same way
    assert len(index) == 50 and index.problems == []
    _same_frames(list(session.records(17, 20)), frames[17:20])


def test_laser_topics_grouped_read_every_frame(tmp_path):
    frames = laser_frames(30, seed=2, beams=40)
    write_messages(tmp_path / "l.mcap", ordered(frame_messages(frames), "reversed-topic"))
    _same_frames(list(read_session(tmp_path / "l.mcap").records()), frames)


def test_our_own_files_read_exactly_as_in_file_order(tmp_path):
    """A file in log-time order reads message for message as before (ties in file order)."""
    from zfloc_stream.session.decoding import messages
    from zfloc_stream.session.mcap_file import file_records

    path = tmp_path / "ours.mcap"
    write_fake_session(path, camera_frames(12, seed=4, shape=(6, 8)), load_settings(overrides=["logging.chunk_max_frames=2"]))
    session = read_session(path)
    in_order = [(t, s) for t, s, _, _ in session._messages(())]
    in_file = [(t, s) for t, s, _, _ in messages(session, file_records(path, False, []))]
    assert in_order == in_file and len(in_order) > 12 * 4


def test_a_merge_beyond_the_memory_limit_is_refused_naming_the_setting(tmp_path):
    frames = camera_frames(30, seed=3, shape=(120, 160))  # 3 MB
    path = tmp_path / "shuffled.mcap"
    write_messages(path, ordered(frame_messages(frames), "shuffled", np.random.default_rng(2)), chunk_size=200_000)
    tight = load_settings(overrides=["logging.reorder_max_mb=1"])
    with pytest.raises(SessionLogError, match=r"shuffled\.mcap: .*out of log-time order.*logging\.reorder_max_mb") as err:
        list(read_session(path, settings=tight).records())
    assert "\n" not in str(err.value)
    assert len(list(read_session(path).records())) == 30  # the default limit (2 GiB) reads it


def test_a_file_without_chunk_index_out_of_order_warns(tmp_path):
    frames = camera_frames(10, seed=3, shape=(6, 8))
    msgs = ordered(frame_messages(frames), "topic")
    path = tmp_path / "flat.mcap"
    with open(path, "wb") as f:  # messages outside chunks: no index to read them in order by
        w = Writer(f, use_chunking=False)
        w.start()
        from session_hostile import CLASSES
        from mcap_protobuf.schema import build_file_descriptor_set

        ids = {}
        for topic, t, m in msgs:
            if topic not in ids:
                cls = CLASSES[topic]
                sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
                ids[topic] = w.register_channel(topic, "protobuf", sid)
            w.add_message(ids[topic], log_time=t, data=m.SerializeToString(), publish_time=t)
        w.finish()
    session = read_session(path)
    list(session.records())
    notes = [p for p in session.problems if "not in log-time order" in p]
    assert len(notes) == 1 and "no chunk index" in notes[0] and "dropped" in notes[0]


# --- salvage -----------------------------------------------------------------------------------
def _damage_first_chunk(path, how: str) -> None:
    session = read_session(path)
    c0 = min(session.summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(path.read_bytes())
    if how == "all":
        for i in range(c0.chunk_start_offset, c0.chunk_start_offset + c0.chunk_length):
            data[i] = (data[i] * 7 + 13) & 255
    else:
        data[c0.chunk_start_offset + {"opcode": 0, "length": 3, "middle": c0.chunk_length // 2}[how]] ^= 0x5A
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["opcode", "length", "middle", "all"])
def test_salvage_reads_the_chunks_after_a_damaged_first_one(tmp_path, how):
    """Issue 44: a damaged first chunk (4 intact ones and the summary remain) salvaged
    nothing: the scan stopped there, or the channels defined in it were unknown after it."""
    frames = camera_frames(15, seed=2, shape=(12, 16))
    path = tmp_path / "five.mcap"
    write_fake_session(path, frames, load_settings(overrides=["logging.chunk_max_frames=3"]))
    _damage_first_chunk(path, how)
    with pytest.raises(SessionLogError, match="five.mcap"):
        list(read_session(path).records())
    session = read_session(path, salvage=True)
    got = list(session.records())
    assert [r.index for r in got] == list(range(12))
    _same_frames(got, [f for f in write_fake_session(tmp_path / "again.mcap", frames)][3:])
    assert len(session.problems) == 1 and session.problems[0].startswith("chunk skipped: damaged chunk at byte")
    assert session.settings is not None and session.info["source"] == "test"
