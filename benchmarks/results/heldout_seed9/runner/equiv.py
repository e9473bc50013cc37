"""Stop 35: does main's diagnosis code give the same result as the seed-9 code (wt9d)? A small blind
diagnosis (recording 10 % too large, continuation on), several entries; prints the report minus wall times."""
import json, sys, warnings
import numpy as np
from vfcore.config import SimConfig
from vfcore.diagnose.pipeline import diagnose
from vfcore.forward import simulate
from vfcore.inference import Prior
from vfcore.inference.problem import Problem
from vfcore.params import PARAM_NAMES, TABLE3
from vfcore.result import HR_OVERSAMPLE
warnings.simplefilter("ignore")
cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)
run = simulate(TABLE3, cfg)
y = 1.1 * np.asarray(run.gaw_hr[29::HR_OVERSAMPLE][:200]) + 0.3 * np.random.default_rng(3).standard_normal(200)
prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in ("E_cover", "P_sub")})
pb = Problem(y, 2000.0, prior, config=cfg, sigma_e=0.3)
small = {"n_design": 4, "n_keep": 1, "maxfev0": 6, "maxfev_step": 3}
rep = diagnose(pb, n_particles=16, refit_particles=12, seed=3, candidates=["scale", "leak", "frame_rate"], base_runs=1,
               continuation=True, continuation_options=small)
d = rep.to_dict()
def strip(x):
    if isinstance(x, dict):
        return {k: strip(v) for k, v in x.items() if k not in ("wall_s", "cost", "progress")}
    return [strip(v) for v in x] if isinstance(x, (list, tuple)) else x
print("verdict:", rep.verdict)
print("winner:", d.get("winner"), "sims:", rep.n_simulations)
for r in d["ranking"]:
    print(r["name"], round(r["delta"], 9), round(r["rms_gain"], 9), r["found"])
print("base logZ", d["base"]["log_evidence"])
json.dump(strip(d), open(sys.argv[1], "w"), sort_keys=True, indent=1, default=float)
