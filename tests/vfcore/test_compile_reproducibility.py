"""A kernel compiled cold gives the same bits as the same kernel loaded from numba's cache.

Regression test for a reproducibility bug: with fast-math reassociation the
time loop compiled in a fresh process produced other GAWs (up to 22 mm^2 apart on a sensitive
case) than the cached machine code used by every later run. Each subprocess below gets its own
empty NUMBA_CACHE_DIR for the first (cold) run, which the second run then loads.
"""

import os
import subprocess
import sys
from pathlib import Path

SCRIPT = r"""
import hashlib, numpy as np
from vfcore import TABLE3, SimConfig, simulate
from vfcore.batch import simulate_many
cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.12, discard=0.06)
rows = np.array([TABLE3.as_array(), TABLE3.replace(p_sub=700.0, E_cover=500.0).as_array()])
h = hashlib.sha256()
for r in rows:
    h.update(simulate(r, cfg).contact_pressure.tobytes())
for x in simulate_many(rows, cfg, block=2):
    h.update(x.contact_pressure.tobytes())
print(h.hexdigest())
"""


def _run(cache_dir: Path) -> str:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), OMP_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()[-1]


def test_cold_compile_equals_cached(tmp_path):
    cold = _run(tmp_path)  # empty cache: every kernel compiled here
    assert any(tmp_path.rglob("*.nbi"))  # ... and written to the cache
    warm = _run(tmp_path)  # loaded from the cache
    assert cold == warm
