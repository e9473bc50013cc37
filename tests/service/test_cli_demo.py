"""``vfinfer demo`` (what ``make demo`` runs) ends by printing the path of the report it wrote, so a newcomer
knows what to open. The fit itself is replaced by a stand-in that writes the folder, since the real one takes
minutes (the FE fit is checked in test_fe_end_to_end.py)."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner


def _fake_run_local(spec, out: Path, workers: int, job_id: str = "local") -> dict:
    out.mkdir(parents=True, exist_ok=True)
    (out / "index.html").write_text("<!doctype html><title>demo</title>")
    (out / "samples.csv").write_text("E_cover,p_sub\n636.2,989.9\n")
    rows = [
        {"name": n, "unit": "Pa", "mean": m, "sd": 5.0, "pct": 0.8, "q05": m - 9, "q95": m + 9}
        for n, m in (("E_cover", 636.0), ("p_sub", 990.0))
    ]
    return {
        "table": rows,
        "method": "smc",
        "n_simulations": 35,
        "n_failed": 0,
        "ess": 40.0,
        "log_evidence": -1.0,
        "log_evidence_se": 0.1,
    }


def test_demo_ends_with_the_path_of_its_index_html(tmp_path, monkeypatch):
    import service.cli as cli

    monkeypatch.setattr(cli, "run_local", _fake_run_local)
    monkeypatch.setattr(cli, "_corner_with_truth", lambda folder: None)  # it needs the real posterior
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(cli.app, ["demo", "--out", "demo_output", "--particles", "10"], env={"COLUMNS": "60"})
    assert r.exit_code == 0, r.output
    last = r.stdout.rstrip("\n").splitlines()[-1]
    assert last.startswith("report: ") and last.endswith("index.html"), r.stdout[-500:]
    page = Path(last.removeprefix("report: "))
    assert page.is_absolute() and page.is_file() and page == (tmp_path / "demo_output" / "index.html").resolve()
