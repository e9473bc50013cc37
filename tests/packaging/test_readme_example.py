"""The README's Python example runs as written and recovers the truth it was simulated at (a README command
that does not run is a bug)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_the_readme_python_example_runs_and_its_intervals_hold_the_truth(capsys):
    code = re.search(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S).group(1)
    scope = {}
    exec(compile(code, "README.md", "exec"), scope)
    post, truth = scope["post"], scope["TABLE3"]
    assert "E_cover" in capsys.readouterr().out
    for j, name in enumerate(post.names):
        assert abs(post.mean[j] - getattr(truth, name)) < 5 * post.sd[j] + 0.01 * getattr(truth, name), name
