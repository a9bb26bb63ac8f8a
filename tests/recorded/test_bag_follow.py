"""``handeye-drake session --bag BAG --follow`` on a ROS 2 bag being written by the rosbags
Writer in a background thread (sqlite3 and MCAP storage): samples arrive while it is recorded,
the session stops before the recording ends; ``BagFollower`` pairing and bad inputs."""

import json
import threading
import time

import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.estimation.se3 import rotation_angle
from handeye_drake.recorded.bag_follow import BagFollower
from handeye_drake.recorded.example_bag import BagWriter
from tests.calibration.test_session import X_EC, samples

HOLD_NS = 100_000_000          # each robot pose is held 0.1 s (recorded time)


class Recorder(threading.Thread):
    """Writes ``n`` stop-and-go samples: /tf (base_link → tool0) at 0 and 50 ms of each hold,
    the camera pose (X_CT, PoseStamped) at 30 ms; makes each hold visible to readers (sqlite3:
    commit, as rosbag2 commits as it records; MCAP: a complete chunk) and waits ``gap_s``."""

    def __init__(self, path, storage, n, gap_s, stop_when=None):
        super().__init__(daemon=True)
        self.bag = BagWriter(path, storage)
        self.storage, self.n, self.gap_s = storage, n, gap_s
        self.data = samples(n, seed=4)
        self.written = 0
        self.stop_flag = threading.Event()
        self.error = None

    def run(self):
        try:
            self._run()
        except BaseException as e:  # reported by the test
            self.error = e

    def _run(self):
        b = self.bag
        w = b.writer
        w.open()
        tf = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=b.store)
        cam = w.add_connection("/camera/target_pose", "geometry_msgs/msg/PoseStamped",
                               typestore=b.store)
        for k, (X_BE, X_CT) in enumerate(self.data):
            if self.stop_flag.is_set():
                break
            t0 = (k + 1) * HOLD_NS
            for dt in (0, 50_000_000):
                msg = b.tf([b.transform(t0 + dt, "base_link", "tool0", X_BE)])
                w.write(tf, t0 + dt, b.store.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))
            msg = b.pose(t0 + 30_000_000, "camera", X_CT)
            w.write(cam, t0 + 30_000_000,
                    b.store.serialize_cdr(msg, "geometry_msgs/msg/PoseStamped"))
            if self.storage == "sqlite3":
                w.storage.conn.commit()
            else:
                w.storage.close_chunk()
                w.storage.bio.flush()
            self.written = k + 1
            time.sleep(self.gap_s)
        w.close()


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_session_follows_a_bag_being_recorded(tmp_path, capsys, storage):
    path = tmp_path / "calib_bag"
    rec = Recorder(path, storage, n=60, gap_s=0.05)
    rec.start()
    out = tmp_path / "out"
    code = main(["session", "--bag", str(path), "--follow", "--camera-topic",
                 "/camera/target_pose", "--target-sigma", "0.2,1.0", "--robot-accuracy",
                 "0.02,0.1", "--poll-s", "0.05", "--timeout-s", "5", "--out", str(out)])
    written_at_stop = rec.written
    recording = rec.is_alive() and not (path / "metadata.yaml").exists()
    rec.stop_flag.set()
    rec.join(10)
    captured = capsys.readouterr()
    text = captured.out
    assert rec.error is None, rec.error
    assert code == 0, text + captured.err
    # It stopped while the bag was still being recorded, on the samples that had arrived.
    assert recording and written_at_stop < rec.n
    lines = [x for x in text.splitlines() if x.startswith("[")]
    n = int(lines[-1][1:4])
    assert "stop: σ" in lines[-1] and 4 < n <= written_at_stop
    # One line per poll that brought samples (samples arriving together are fitted once).
    counts = [int(x[1:4]) for x in lines]
    assert counts == sorted(set(counts)) and counts[0] >= 1
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["verdict"]["status"] == "OK"
    X = np.array(doc["X_EC"]["matrix"])
    assert np.linalg.norm(X[:3, 3] - X_EC[:3, 3]) < 0.003
    assert rotation_angle(X[:3, :3].T @ X_EC[:3, :3]) < np.radians(0.5)


def test_follower_pairs_camera_stamps_with_the_robot_pose(tmp_path):
    path = tmp_path / "bag"
    rec = Recorder(path, "sqlite3", n=6, gap_s=0.0)
    rec.run()
    f = BagFollower(path, "base_link:tool0", camera_topic="/camera/target_pose")
    got = f.poll()
    assert len(got) == 6 and f.poll() == []          # each message once
    for s, (X_BE, X_CT) in zip(got, rec.data):
        assert rotation_angle(s["X_BE"][:3, :3].T @ X_BE[:3, :3]) < 1e-6
        assert np.allclose(s["X_BE"][:3, 3], X_BE[:3, 3], atol=1e-9)
        assert np.allclose(s["X_CT"], X_CT, atol=1e-6)
    assert [round(s["stamp"], 3) for s in got] == [round(0.13 + 0.1 * k, 3) for k in range(6)]


def test_a_read_that_meets_a_transaction_being_written_is_retried(tmp_path, monkeypatch):
    """SQLite can report a page the recorder is writing as corrupt ("database disk image is
    malformed"): the poll returns nothing, says it is waiting and why, and the next poll reads."""
    import apsw

    from handeye_drake.recorded import bags

    path = tmp_path / "bag"
    rec = Recorder(path, "sqlite3", n=4, gap_s=0.0)
    rec.run()
    f = BagFollower(path, "base_link:tool0", camera_topic="/camera/target_pose")
    original, calls = bags._read, []

    def torn_once(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise apsw.CorruptError("database disk image is malformed")
        return original(*args, **kwargs)

    monkeypatch.setattr(bags, "_read", torn_once)
    assert f.poll() == [] and f.waiting
    assert "unreadable while being written" in f.last_error and "malformed" in f.last_error
    assert len(f.poll()) == 4 and not f.waiting

def test_bag_bad_inputs_are_one_line(tmp_path, capsys):
    path = tmp_path / "bag"
    Recorder(path, "sqlite3", n=3, gap_s=0.0).run()
    cases = [
        (["--bag", str(tmp_path / "nope"), "--camera-topic", "/x"], "no such file"),
        (["--bag", str(path)], "one camera source"),
        (["--bag", str(path), "--camera-topic", "/nope"], "no topic '/nope'"),
        (["--bag", str(path), "--samples", "x", "--camera-topic", "/x"], "one source"),
        (["--bag", str(path), "--camera-topic", "/camera/target_pose", "--robot-frames",
          "base_link:flange"], "flange"),
    ]
    for k, (argv, what) in enumerate(cases):
        code = main(["session", *argv, "--out", str(tmp_path / f"o{k}")])
        err = capsys.readouterr().err
        assert code == 2 and what in err and err.count("\n") == 1, (argv, err)


def test_a_live_follower_waits_for_a_bag_not_created_yet(tmp_path):
    """A session started before ``ros2 bag record`` has created the bag waits for it
    (must_exist=False, what ``session --follow`` passes); without --follow it is an error."""
    path = tmp_path / "calib_bag"
    with pytest.raises(ValueError, match="no such file or directory"):
        BagFollower(path, "base_link:tool0", camera_topic="/camera/target_pose")
    f = BagFollower(path, "base_link:tool0", camera_topic="/camera/target_pose",
                    must_exist=False)
    assert f.poll() == [] and f.waiting and "not there yet" in f.last_error
    rec = Recorder(path, "sqlite3", n=6, gap_s=0.0)
    rec.run()                       # in this thread: the whole bag, then closed
    assert rec.error is None and rec.written == 6
    got = f.poll()
    assert len(got) == 6 and not f.waiting
    X_CT = np.array([s["X_CT"] for s in got])
    assert np.allclose(X_CT, np.array([x for _, x in rec.data]), atol=1e-9)
