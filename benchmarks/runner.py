"""One way to run the lasting benchmarks: ``python -m benchmarks NAME [ARGS...] [--table PATH]``.

Each benchmark stays a script with its own options (``python -m benchmarks NAME -h`` shows them); the runner
runs it unchanged in a fresh interpreter, echoes its output, and writes one Markdown results table: the
command, the machine, the code's commit, the wall time, then the script's own Markdown tables (or its whole
output where it prints none). ``python -m benchmarks list`` prints the index below.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


@dataclass(frozen=True)
class Benchmark:
    script: str  # file under benchmarks/
    what: str  # what it measures
    cost: str  # order of its wall time at the defaults on the 2-core machine
    page: str  # the docs label of the page that reports it


#: The lasting benchmarks, by the name the runner takes. One-off studies live in ``benchmarks/studies/``.
BENCHMARKS = {
    "forward": Benchmark(
        "bench_forward.py",
        "ms per forward simulation (Table 3, medium mesh) and batch throughput",
        "~2 min",
        "validation-model",
    ),
    "batch": Benchmark(
        "bench_batch.py", "lock-step kernel at block sizes 1-16 against the scalar kernel", "~3 min", "validation-model"
    ),
    "contact": Benchmark(
        "bench_contact.py",
        "contact products against time step and mesh, both contact laws",
        "~15 min",
        "validation-model",
    ),
    "convergence": Benchmark(
        "bench_convergence.py",
        "f0 and peak area against time step and mesh, observed orders",
        "~10 min",
        "validation-model",
    ),
    "element-convergence": Benchmark(
        "bench_element_convergence.py",
        "eigenfrequencies and limit cycle under refinement, P1 and anp elements",
        "~20 min",
        "validation-model",
    ),
    "mesh-refinement": Benchmark(
        "bench_mesh_refinement.py", "limit cycle on six meshes up to 15,000 triangles", "~1 h", "validation-model"
    ),
    "oscillation-map": Benchmark(
        "bench_oscillation_map.py", "where each mesh self-oscillates (p_sub x E_cover)", "~1 h", "validation-model"
    ),
    "early-stop": Benchmark(
        "bench_early_stop.py", "what stopping settled simulations saves and changes", "~10 min", "model-numerics"
    ),
    "calibration": Benchmark(
        "bench_calibration.py",
        "coverage of the credible intervals over many twins",
        "hours",
        "validation-inference-calibration",
    ),
    "inference": Benchmark(
        "bench_inference.py", "twin experiment: prior importance sampling against SMC", "hours", "validation-inference"
    ),
    "paper-fit": Benchmark(
        "bench_paper_fit.py",
        "the paper's experiment as a user runs it (twin at Table 3)",
        "~1 h",
        "validation-inference",
    ),
    "smoothness": Benchmark(
        "bench_smoothness.py",
        "smoothness of the six-parameter log-likelihood",
        "~30 min",
        "validation-inference-roughness",
    ),
    "flow-rules": Benchmark(
        "bench_flow_rules.py",
        "the paper's flow load against the continuous one: Table 3 on three meshes and ms per simulation",
        "~3 min",
        "validation-continuous-model",
    ),
    "rough-flag": Benchmark(
        "bench_rough_flag.py",
        "how often the rough flag fires at the twins' truths and over prior draws, per flow rule",
        "~15 min",
        "validation-continuous-model",
    ),
    "regularity": Benchmark(
        "bench_regularity.py",
        "where the fold's vibration is irregular over the prior",
        "~30 min",
        "validation-inference-roughness",
    ),
    "probe": Benchmark(
        "bench_probe.py", "how well the timed probe predicts a run's cost", "~10 min", "inference-samplers"
    ),
    "resume-store": Benchmark(
        "bench_resume_store.py",
        "what the resume store costs and saves",
        "~5 min",
        "inference-samplers-resuming-an-interrupted-ensemble",
    ),
    "diagnose": Benchmark(
        "bench_diagnose.py",
        "concealed-effect suites: the diagnosis run blind, then scored",
        "hours a case",
        "validation-diagnose",
    ),
    "service": Benchmark(
        "bench_service.py",
        "the service's overhead over the same simulations run directly",
        "~5 min",
        "validation-service",
    ),
    "real-example": Benchmark(
        "real_example.py", "a real clip end to end: video, GAW, reach, fit", "~30 min", "validation-video"
    ),
    "gpu": Benchmark(
        "bench_gpu.py",
        "CUDA backend against the CPU lock-step kernel on the same machine",
        "~5 min on one H100",
        "validation-gpu",
    ),
}


def index_markdown() -> str:
    rows = ["| name | script | what it measures | cost | reported on |", "|---|---|---|---|---|"]
    rows += [f"| `{n}` | `{b.script}` | {b.what} | {b.cost} | `{b.page}` |" for n, b in BENCHMARKS.items()]
    return "\n".join(rows)


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def results_tables(output: str) -> str:
    """The Markdown tables the script printed (runs of lines starting with ``|``), or all of its output."""
    blocks, block = [], []
    for line in output.splitlines():
        if line.lstrip().startswith("|"):
            block.append(line.strip())
        elif block:
            blocks.append(block)
            block = []
    if block:
        blocks.append(block)
    tables = ["\n".join(b) for b in blocks if len(b) >= 2]
    return "\n\n".join(tables) if tables else "```text\n" + output.rstrip() + "\n```"


def run(name: str, args: list[str], table: Path) -> int:
    bench = BENCHMARKS[name]
    cmd = [sys.executable, str(HERE / bench.script), *args]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:
        sys.stdout.write(line)
        lines.append(line)
    rc = proc.wait()
    wall = time.perf_counter() - t0
    shown = " ".join(["python -m benchmarks", name, *args])
    head = [
        f"# {name}: {bench.what}",
        "",
        f"- command: `{shown}` (runs `benchmarks/{bench.script}`)",
        f"- machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"{platform.system()}",
        f"- code: {_commit()}; wall time {wall:.0f} s; exit status {rc}",
        f"- reported on the docs page `{bench.page}`",
        "",
    ]
    table.parent.mkdir(parents=True, exist_ok=True)
    table.write_text("\n".join(head) + "\n" + results_tables("".join(lines)) + "\n")
    print(f"results table: {table}", file=sys.stderr)
    return rc


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("list", "-h", "--help"):
        print(__doc__.strip() + "\n\n" + index_markdown())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in BENCHMARKS:
        print(f"error: no benchmark {name!r}; `python -m benchmarks list` shows them", file=sys.stderr)
        return 2
    table = Path("bench_results") / f"{name}.md"
    if "--table" in rest:
        i = rest.index("--table")
        if i + 1 >= len(rest):
            print("error: --table needs a path", file=sys.stderr)
            return 2
        table = Path(rest[i + 1])
        rest = rest[:i] + rest[i + 2 :]
    return run(name, rest, table)
