"""The benchmark runner (benchmarks/runner.py) and the index (benchmarks/README.md) agree with the folder."""

import sys
from pathlib import Path

from benchmarks.runner import BENCHMARKS, main, results_tables

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
SUPPORT = {"__init__.py", "__main__.py", "runner.py", "scoring.py", "suite.py"}


def test_every_script_is_run_by_the_runner_or_is_a_study_and_the_index_lists_it():
    readme = (BENCH / "README.md").read_text()
    registered = {b.script for b in BENCHMARKS.values()}
    top = {p.name for p in BENCH.glob("*.py")} - SUPPORT
    assert top == registered, "a script in benchmarks/ is neither a lasting benchmark nor moved to studies/"
    studies = {p.name for p in (BENCH / "studies").glob("*.py")} - {"__init__.py"}
    for name in registered | studies:
        assert f"`{name}`" in readme, f"{name} is missing from benchmarks/README.md"


def test_the_table_keeps_the_script_s_markdown_tables_or_its_whole_output():
    out = "header\n| a | b |\n|---|---|\n| 1 | 2 |\ntrailer\n"
    assert results_tables(out) == "| a | b |\n|---|---|\n| 1 | 2 |"
    assert results_tables("no table\n") == "```text\nno table\n```"


def test_a_run_writes_its_results_table(tmp_path, capsys):
    table = tmp_path / "t.md"
    assert main(["forward", "-h", "--table", str(table)]) == 0
    text = table.read_text()
    assert "python -m benchmarks forward -h" in text and "bench_forward.py" in text and sys.version.split()[0] in text
    assert main(["no-such-benchmark"]) == 2
