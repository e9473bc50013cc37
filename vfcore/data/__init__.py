"""Data shipped with the package: a demo glottal area waveform.

``demo_gaw.csv`` was made by ``make_demo_gaw()``: the vfcore forward model at the Table 3 silicone
values (Hadwin et al. 2019) on the *medium* mesh with dt = 5e-5 s, observed at 2000 frames/s,
plus Gaussian noise with sd 0.5 mm^2 (seed 2019). Its header records exactly that.

The demo inference (``demo_spec_dict``) uses the *same* numerics (medium mesh, dt = 5e-5 s,
0.4 s with 0.25 s discarded) and assumes sigma_e = 1 mm^2: a cheaper model is not usable here,
because the discretisation error is larger than the noise (coarse mesh: peak area 19.8 vs
27.1 mm^2, f0 67 vs 64 Hz; medium mesh at dt = 1e-4: rms misfit 0.7-2.8 mm^2 depending on
the window), which would bias the posterior well away from the truth. The demo is therefore a
check of the inference machinery with the truth inside the model (only the noise differs from
what is assumed), stated as such in :ref:`inference`.
"""

from __future__ import annotations

from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
DEMO_GAW = DATA_DIR / "demo_gaw.csv"

#: How the demo GAW was made (also written into its header).
DEMO_TRUTH = {
    "mesh": "medium",
    "dt": 5e-5,
    "duration": 0.4,
    "discard": 0.25,
    "fps": 2000.0,
    "noise_sd_mm2": 0.5,
    "noise_seed": 2019,
}


def make_demo_gaw(path: Path = DEMO_GAW) -> Path:
    """Regenerate ``demo_gaw.csv`` (needs the FE model; takes seconds)."""
    import json

    import numpy as np

    from vfcore.config import SimConfig
    from vfcore.forward import simulate
    from vfcore.gawio import write_gaw_csv
    from vfcore.params import TABLE3

    d = DEMO_TRUTH
    r = simulate(
        TABLE3, SimConfig(mesh=d["mesh"], dt=d["dt"], duration=d["duration"], discard=d["discard"], fps=d["fps"])
    )
    if not r.ok:
        raise RuntimeError(f"demo simulation failed: {r.message}")
    noisy = r.gaw + np.random.default_rng(d["noise_seed"]).normal(0.0, d["noise_sd_mm2"], r.gaw.size)
    noisy = np.maximum(noisy, 0.0)
    return write_gaw_csv(
        path,
        r.t,
        noisy,
        r.fps,
        meta={
            "source": "vfcore.data.make_demo_gaw (synthetic: FE model + noise)",
            "params": json.dumps(TABLE3.as_dict()),
            **{k: str(v) for k, v in d.items()},
        },
    )


#: The demo sampler: SMC over (E_cover, p_sub), ~2500-3000 simulations (~3 min on 2 cores).
DEMO_SMC = {"kind": "smc", "n_particles": 80, "ess_fraction": 0.5, "min_moves": 2, "max_moves": 4}


def demo_spec_dict(n: int = 240, path: Path = DEMO_GAW, sampler: dict | None = None, **overrides) -> dict:
    """A JobSpec body (dict) for the demo GAW over E_cover and p_sub, the rest fixed at Table 3.

    ``sampler``: a JobSpec sampler body; default IS with ``n`` prior draws (the tests use it,
    with a cheaper mesh in ``overrides``); ``make demo`` passes ``DEMO_SMC``.
    """
    from vfcore.gawio import read_gaw

    g = read_gaw(path)
    spec = {
        "model": "fe",
        "gaw": {"areas": [float(a) for a in g.area], "fps": float(g.fps), "units": "mm2"},
        "priors": {"E_cover": [400.0, 900.0], "p_sub": [700.0, 1300.0]},
        "fixed": {"E_body": 12.15, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
        "sampler": dict(sampler) if sampler else {"kind": "is", "n_samples": int(n)},
        "mesh": DEMO_TRUTH["mesh"],
        "dt": DEMO_TRUTH["dt"],
        "duration": DEMO_TRUTH["duration"],
        "discard": DEMO_TRUTH["discard"],
        "sigma_e": 1.0,
        "seed": 2019,
    }
    spec.update(overrides)
    return spec
