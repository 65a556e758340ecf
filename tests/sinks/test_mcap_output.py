"""`run ... --mcap FILE.mcap`: a Foxglove recording that reads back with the mcap library, one message
per frame on each topic, the estimates as the trajectory has them, and whole frames after a stop."""

import json

import numpy as np
import pytest

pytest.importorskip("mcap", reason="the 'ros' extra (mcap) is not installed")

from mcap.reader import NonSeekingReader, make_reader  # noqa: E402

from helpers import WalkSource, cli, error_lines  # noqa: E402
from uareme_fusion.overlay.horizon import horizon_line  # noqa: E402
from uareme_fusion.pipeline import RunConfig  # noqa: E402
from uareme_fusion.types import FrameResult  # noqa: E402
from uareme_fusion.types import Estimate  # noqa: E402
from uareme_fusion.sinks.mcap_file import TOPICS, McapSink, up_arrow_px  # noqa: E402
from uareme_fusion.pipeline.session import run_source  # noqa: E402
from uareme_fusion.sim.dataset import SequenceOptions, write_sequence  # noqa: E402

FRAMES = 8


def _messages(path, **options) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(**options):
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            assert schema.name == TOPICS[channel.topic]
            out.setdefault(channel.topic, []).append({"log_time": message.log_time, **json.loads(message.data)})
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    root = tmp_path_factory.mktemp("mcap")
    write_sequence("room", root / "sim", SequenceOptions(frames=FRAMES, width=64, height=48, fps=10.0, seed=2))
    proc = cli("run", root / "sim", "--out", root / "out", "--normals", "depth", "--mcap", root / "run.mcap")
    assert proc.returncode == 0, proc.stderr
    return root


def test_every_topic_has_one_message_per_frame(recorded):
    messages = _messages(recorded / "run.mcap")
    assert sorted(messages) == sorted(TOPICS) and all(len(m) == FRAMES for m in messages.values())
    with open(recorded / "run.mcap", "rb") as fh:
        summary = make_reader(fh).get_summary()  # indexed: the run ended normally
    assert summary.statistics.message_count == FRAMES * len(TOPICS)
    doc = json.loads((recorded / "out" / "summary.json").read_text())
    assert doc["mcap"] == {"path": str(recorded / "run.mcap"), "frames": FRAMES, "indexed": True}


def test_transforms_and_estimates_are_the_trajectorys(recorded):
    messages = _messages(recorded / "run.mcap")
    trajectory = np.loadtxt(recorded / "out" / "trajectory.tum")
    transforms = messages["/tf"]
    assert all(m["parent_frame_id"] == "world" and m["child_frame_id"] == "camera" for m in transforms)
    quats = np.array([[m["rotation"][a] for a in "xyzw"] for m in transforms])
    np.testing.assert_allclose(quats, trajectory[:, 4:], atol=1e-8)
    np.testing.assert_array_equal([m["log_time"] for m in transforms], np.round(trajectory[:, 0] * 1e9).astype(int))
    csv = np.genfromtxt(recorded / "out" / "estimates.csv", delimiter=",", names=True, dtype=None, encoding=None)
    for row, est in zip(csv, messages["/estimate"]):
        cov = np.array([row[f"cov_{i}{j}_rad2"] for i in range(3) for j in range(3)])
        np.testing.assert_allclose(est["cov_rad2"], cov, rtol=1e-5)
        assert est["status"] == row["status"] and "|".join(est["status_flags"]) == (row["status_flags"] or "")
        np.testing.assert_allclose([est["up_c"][a] for a in "xyz"], [row["up_x"], row["up_y"], row["up_z"]], atol=1e-8)


def test_images_calibration_and_annotations(recorded):
    import base64

    import cv2

    messages = _messages(recorded / "run.mcap")
    scene_K = np.array(json.loads((recorded / "sim" / "scene.json").read_text())["K"])
    for image, calib, notes, est in zip(messages["/camera/image"], messages["/camera/calibration"],
                                        messages["/camera/annotations"], messages["/estimate"]):
        assert image["format"] == "jpeg" and image["frame_id"] == "camera"
        decoded = cv2.imdecode(np.frombuffer(base64.b64decode(image["data"]), np.uint8), cv2.IMREAD_COLOR)
        assert decoded.shape == (48, 64, 3)
        K = np.array(calib["K"]).reshape(3, 3)
        np.testing.assert_allclose(K, scene_K)
        up_c = np.array([est["up_c"][a] for a in "xyz"])
        horizon, arrow = notes["points"]
        line = horizon_line(up_c, K)
        for p in horizon["points"]:  # Foxglove pixels: OpenCV's plus 0.5
            assert abs(line @ [p["x"] - 0.5, p["y"] - 0.5, 1.0]) < 1e-6
        tip = arrow["points"][1]
        expected_tip = up_arrow_px(up_c, K, 48, 64)[0][1]
        assert (tip["x"] - 0.5, tip["y"] - 0.5) == pytest.approx(expected_tip)
        assert line @ [*expected_tip, 1.0] > 0  # the arrow points to the sky side of the horizon
        assert notes["texts"][0]["text"].startswith("roll ")


def test_a_stopped_run_keeps_whole_frames(tmp_path):
    source = WalkSource(seconds=2.0, fps=10.0, interrupt_at=12)  # Ctrl-C at frame 12: the sink is closed
    summary = run_source(source, tmp_path, RunConfig(normals="source"), extra_sinks=[McapSink(tmp_path / "c.mcap")])
    assert summary["stopped"] == "interrupted" and summary["estimates"] == 12
    messages = _messages(tmp_path / "c.mcap")
    assert len(messages["/tf"]) == len(messages["/estimate"]) == 12 and "/camera/image" not in messages
    sink = McapSink(tmp_path / "k.mcap")  # killed: never closed, the file ends after its last whole frame
    for k in range(5):
        sink.write(FrameResult(0.1 * k, Estimate(0.1 * k, np.eye(3), np.eye(3) * 1e-4)))
    with open(tmp_path / "k.mcap", "rb") as fh:
        count = 0
        try:
            for _ in NonSeekingReader(fh).iter_messages(log_time_order=False):
                count += 1
        except Exception:  # the missing footer ends the stream
            pass
    assert count == 5 * 2


def test_mcap_path_is_checked(tmp_path, recorded):
    proc = cli("run", recorded / "run.mcap", "--out", tmp_path / "o", "--mcap", recorded / "run.mcap")
    assert proc.returncode == 2 and "is the input" in error_lines(proc)[0]
    proc = cli("run", "sim:room", "--max-frames", "2", "--out", tmp_path / "o2", "--mcap", tmp_path / "run.txt")
    assert proc.returncode == 2 and error_lines(proc) == [f"error: --mcap {tmp_path / 'run.txt'}: an MCAP recording is "
                                                          "a .mcap file"]
    (tmp_path / "link.mcap").symlink_to(tmp_path / "elsewhere.mcap")
    proc = cli("run", "sim:room", "--max-frames", "2", "--out", tmp_path / "o3", "--mcap", tmp_path / "link.mcap")
    assert proc.returncode == 2 and "symbolic link" in error_lines(proc)[0]
    assert not (tmp_path / "elsewhere.mcap").exists()


def test_messages_follow_the_schemas_their_channels_declare(recorded):
    jsonschema = pytest.importorskip("jsonschema")
    with open(recorded / "run.mcap", "rb") as fh:
        for schema, _channel, message in make_reader(fh).iter_messages():
            declared = json.loads(schema.data)
            assert declared["title"] == schema.name
            jsonschema.validate(json.loads(message.data), declared)
