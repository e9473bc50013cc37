"""What the resume store (vfcore.inference.memo.CachedMap) costs and saves.

Evaluates the same prior draws of a diagnosis-sized problem (the default 0.55 s simulated, 0.25 s
discarded, coarse mesh, 2,000 frames/s) three ways, one process: the builtin ``map``; through a
new store (every part simulated and written); through the same store again (every part read
back). Prints ms per simulation of each, the store's overhead per part and the bytes it keeps per
simulation, and checks that the read-back log-likelihoods and GAWs equal the simulated ones.

    python benchmarks/bench_resume_store.py [--draws 40] [--chunk 20]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--draws", type=int, default=40)
    ap.add_argument("--chunk", type=int, default=20)
    a = ap.parse_args(argv)

    import numpy as np

    from vfcore.config import SimConfig
    from vfcore.diagnose.defaults import DISCARD_S, DURATION_S
    from vfcore.forward import simulate
    from vfcore.inference import Prior, draw_prior, map_evaluate
    from vfcore.inference.importance import batch_function
    from vfcore.inference.memo import CachedMap
    from vfcore.inference.problem import Problem
    from vfcore.params import TABLE3
    from vfcore.result import HR_OVERSAMPLE

    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=DURATION_S, discard=DISCARD_S)
    run = simulate(TABLE3, cfg)
    y = np.asarray(run.gaw_hr[::HR_OVERSAMPLE][:400])
    pb = Problem(
        y,
        2000.0,
        Prior.default(fixed={k: v for k, v in TABLE3.as_dict().items() if k not in ("E_body", "E_cover", "p_sub")}),
        config=cfg,
        sigma_e=1.0,
    )
    fn = batch_function(pb)
    thetas = draw_prior(pb.prior, a.draws, seed=11)
    map_evaluate(fn, thetas[:2], chunk_size=a.chunk)  # compile and warm the kernels

    def timed(m):
        t0 = time.perf_counter()
        ev = map_evaluate(fn, thetas, map=m, chunk_size=a.chunk)
        return ev, 1e3 * (time.perf_counter() - t0) / a.draws

    root = Path(tempfile.mkdtemp(prefix="vfstore-"))
    try:
        plain, ms_plain = timed(map)
        cold = CachedMap(map, root)
        written, ms_cold = timed(cold)
        warm = CachedMap(map, root)
        read, ms_warm = timed(warm)
        size = sum(p.stat().st_size for p in root.rglob("*.pkl"))
    finally:
        shutil.rmtree(root, ignore_errors=True)
    same = all(
        np.array_equal(getattr(plain, n), getattr(x, n), equal_nan=True)
        for x in (written, read)
        for n in ("loglik", "gaw")
        if getattr(plain, n) is not None
    )
    parts = cold.misses
    print(f"{a.draws} draws in {parts} parts of <= {a.chunk}; compared GAW {y.size} frames")
    print(f"builtin map          {ms_plain:8.2f} ms per simulation")
    print(
        f"store, simulated     {ms_cold:8.2f} ms per simulation "
        f"(overhead {(ms_cold - ms_plain) * a.draws / parts:+.1f} ms per part, "
        f"{100 * (ms_cold / ms_plain - 1):+.1f} %)"
    )
    print(f"store, read back     {ms_warm:8.3f} ms per simulation ({warm.hits} parts read, {warm.misses} simulated)")
    print(f"store size           {size / a.draws / 1024:8.1f} KiB per simulation")
    print(f"read back == simulated (loglik, GAW): {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
