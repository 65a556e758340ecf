"""`uareme-fusion simulate`: exit codes and one-line errors."""

import json

from typer.testing import CliRunner

from uareme_fusion.cli import app

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, ["simulate", *args])


def test_simulate_writes_a_sequence_and_refuses_to_overwrite(tmp_path):
    out = tmp_path / "seq"
    result = _run("dropped_frames", "--out", str(out), "--frames", "4", "--size", "48x32", "--seed", "3")
    assert result.exit_code == 0, result.output
    meta = json.loads((out / "scene.json").read_text())
    assert meta["frames"] == 4 and meta["width"] == 48 and meta["seed"] == 3
    assert len(list((out / "rgb").glob("*.png"))) == 4
    again = _run("room", "--out", str(out), "--frames", "2", "--size", "48x32")
    assert again.exit_code == 2 and "--force" in again.output
    forced = _run("room", "--out", str(out), "--frames", "2", "--size", "48x32", "--force")
    assert forced.exit_code == 0
    assert len(list((out / "rgb").glob("*.png"))) == 2  # old frames do not linger


def test_bad_input_gives_one_line_naming_the_option(tmp_path):
    out = str(tmp_path / "x")
    unknown = _run("rooom", "--out", out)
    assert unknown.exit_code == 2 and "room, office, corridor, street, bus" in unknown.output
    for args, option in [(("--size", "3x2"), "--size"), (("--size", "big"), "--size"),
                         (("--frames", "0"), "--frames"), (("--imu-rate", "5"), "--imu-rate"),
                         (("--fov-deg", "150"), "--fov-deg")]:
        result = _run("room", "--out", out, *args)
        assert result.exit_code == 2, args
        assert option in result.output and "Traceback" not in result.output
        assert len(result.output.strip().splitlines()) == 1, result.output


def test_help_lists_scenarios():
    result = runner.invoke(app, ["simulate", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    for name in ("room", "office", "corridor", "street", "bus", "shake", "dropped_frames"):
        assert name in result.output
