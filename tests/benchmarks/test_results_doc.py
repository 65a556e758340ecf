"""docs/results.md written by the benchmarks (`bench WHAT --results FILE`): one section replaced, the
rest of the document kept, the command and date written with the figures."""

from __future__ import annotations

import datetime
import os
import sys

import pytest
import typer
from typer.testing import CliRunner

from uareme_fusion.benchmarks.results_doc import capture_stdout, invoked_command, write_section
from uareme_fusion.cli import app
from uareme_fusion.errors import InputError

DAY = datetime.date(2026, 1, 2)


def test_a_section_is_replaced_and_the_prose_kept(tmp_path):
    doc = tmp_path / "results.md"
    doc.write_text("# Results\n\nProse before.\n")
    write_section(doc, "solver", "old figure 1.0 ms\n", "uareme-fusion bench solver", DAY)
    write_section(doc, "mekf", "tilt 0.27 deg\n", "uareme-fusion bench mekf --quick", DAY)
    text = doc.read_text()
    doc.write_text(text.replace("## bench mekf", "Prose between.\n\n## bench mekf"))
    write_section(doc, "solver", "\x1b[1mnew figure 0.8 ms\x1b[0m\n", "uareme-fusion bench solver --repeats 5", DAY)
    text = doc.read_text()
    assert "old figure" not in text and "new figure 0.8 ms" in text and "\x1b" not in text
    assert "`uareme-fusion bench solver --repeats 5`, 2026-01-02:" in text
    assert text.startswith("# Results\n\nProse before.\n") and "Prose between." in text
    assert text.index("new figure") < text.index("Prose between.") < text.index("tilt 0.27 deg")
    assert text.count("<!-- results:solver -->") == 1 and text.count("<!-- /results:mekf -->") == 1


def test_a_missing_file_is_started(tmp_path):
    write_section(tmp_path / "results.md", "broad", "ratio 0.97\n", "uareme-fusion bench broad", DAY)
    assert (tmp_path / "results.md").read_text().startswith("# Results\n\n## bench broad\n<!-- results:broad -->")


def test_unpaired_markers_and_unwritable_paths_are_refused(tmp_path):
    doc = tmp_path / "results.md"
    doc.write_text("<!-- /results:solver -->\n<!-- results:solver -->\n")
    with pytest.raises(InputError, match="unpaired or out of order"):
        write_section(doc, "solver", "x", "cmd", DAY)
    with pytest.raises(InputError, match="cannot write a file there"):
        capture_stdout(tmp_path / "no_such_folder" / "results.md")


def test_the_tee_keeps_what_was_printed_and_restores_stdout(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    before = sys.stdout
    tee = capture_stdout(tmp_path / "results.md")
    print("figure 1.5 ms")
    assert os.environ["COLUMNS"] == "120"  # rich tables as wide as a results page, not a terminal's 80
    assert tee.stop() == "figure 1.5 ms\n" and sys.stdout is before and "COLUMNS" not in os.environ
    assert capsys.readouterr().out == "figure 1.5 ms\n"  # still printed


def test_the_command_names_its_argument_and_changed_options_only():
    demo = typer.Typer()
    seen = []

    @demo.command()
    def bench(ctx: typer.Context, what: str = typer.Argument("solver"), repeats: int = typer.Option(100, "--repeats"),
              quick: bool = typer.Option(False, "--quick"), results: str = typer.Option(None, "--results")):
        seen.append(invoked_command(ctx))

    @demo.command()
    def other():  # two commands: a group, as the real application
        pass

    CliRunner().invoke(demo, ["bench", "mekf", "--quick", "--results", "x.md"], prog_name="uareme-fusion")
    assert seen == ["uareme-fusion bench mekf --quick"]


def test_bench_refuses_an_unwritable_results_file_before_running(tmp_path):
    result = CliRunner().invoke(app, ["bench", "solver", "--results", str(tmp_path / "nowhere" / "r.md")])
    assert result.exit_code == 2 and "--results" in result.output and "cannot write a file there" in result.output
