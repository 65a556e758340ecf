"""Small things a new user meets (issue 16): help text, progress length of IMU files, threads."""

from __future__ import annotations

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from uareme_fusion.cli import app
from uareme_fusion.drivers.interleave import count_spans, split_by_span

COMMANDS = ("run", "eval", "horizon", "ground", "compare", "demo", "simulate", "image", "normals", "bench", "solve")


@pytest.mark.parametrize("command", COMMANDS)
def test_help_shows_no_bool_type_on_flags(command):
    result = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "160"})
    assert result.exit_code == 0
    assert "<bool>" not in result.output
    assert re.search(r"--help\s+Show this message", result.output)


def test_preset_help_lists_imu_only():
    result = CliRunner().invoke(app, ["run", "--help"], env={"COLUMNS": "200"})
    line = next(line for line in result.output.splitlines() if "--preset" in line)
    for name in ("building", "handheld", "vehicle", "imu_only"):
        assert name in line


@pytest.mark.parametrize("command", ["run", "eval", "horizon", "ground", "compare", "demo", "normals", "bench"])
def test_threads_on_every_command_that_runs_the_network(command):
    result = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "200"})
    assert "--threads" in result.output


@pytest.mark.parametrize("command", ["run", "eval", "horizon", "ground", "compare"])
def test_imu_geometry_options_on_every_command_that_merges_an_imu(command):
    result = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "200"})
    for option in ("--imu-rotation", "--imu-time-offset-s"):
        assert option in result.output, (command, option)


@pytest.mark.parametrize("n, rate_hz", [(0, 200.0), (1, 200.0), (5515, 200.0), (997, 333.0)])
def test_count_spans_is_the_number_of_batches(n, rate_hz):
    t = np.arange(n) / rate_hz + 12.3
    zeros = np.zeros((n, 3))
    assert count_spans(t) == sum(1 for _ in split_by_span(t, zeros, zeros))


def test_threads_config_reaches_torch(tmp_path):
    torch = pytest.importorskip("torch")
    from uareme_fusion.drivers.base import SourceInfo
    from uareme_fusion.pipeline.stages import make_normal_estimator

    before = torch.get_num_threads()
    try:
        make_normal_estimator("learned", SourceInfo(name="x"), threads=2)
        assert torch.get_num_threads() == 2
        make_normal_estimator("learned", SourceInfo(name="x"))
        assert torch.get_num_threads() == 1  # the default: one thread
    finally:
        torch.set_num_threads(before)
