"""The CUDA ensemble backend (vfcore.gpu, vfcore.solver._cuda_kernels) against the CPU lock-step kernel.

Without a GPU the kernel runs on numba's CUDA simulator, which must be switched on before numba.cuda is first
imported: those checks run in a subprocess with NUMBA_ENABLE_CUDASIM=1. The simulator runs each thread's
integrate_ws as CPU code, so it checks the kernel's thread mapping, interleaved layout, launch and assembly;
test_kernel_compiles_for_the_gpu checks that numba's CUDA target compiles that same code (NVVM, no GPU needed).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
#: The simulator check compiles run_sample for strided arrays on a cold cache (~30 s on the 2-core CI machine);
#: past this the machine is too slow or too busy for it to say anything, and it skips saying so.
SIM_TIMEOUT_S = 150

# Prior draws of test_batch (seed 2) and Table 3, coarse mesh, a few tens of ms: both contact laws, both flow loads, the
# per-row extensions (separation ratio, epithelium, subglottal modes), trajectories and the settled-response
# stop, each against simulate_many on the CPU.
_SIM_SCRIPT = r"""
import json, time
import numpy as np
from vfcore import Params, SimConfig, TABLE3
from vfcore.batch import simulate_many
from vfcore.gpu import cuda_status

LO = np.array([9.0, 250.0, 0.5, 400.0, 950.0, 1.0, 7.4]); HI = np.array([15.0, 950.0, 3.0, 1800.0, 1200.0, 7.0, 8.4])
rng = np.random.default_rng(2)
rows = np.array([Params.from_array(r).as_array() for r in LO + (HI - LO) * rng.random((6, 7))] + [TABLE3.as_array()])
N = len(rows)
base = SimConfig(mesh="coarse", duration=0.04, discard=0.0, early_stop=False)
ext = [base.replace(sep_ratio=1.5), base.replace(epithelium_E_kpa=30.0),
       base.replace(subglottal_modes=((500.0, 0.1, 1e5), (1400.0, 0.05, 5e4))), base]
cases = {
    "projection": [base.replace(contact="projection", flow="paper")] * N,
    "layer": [base.replace(contact="layer", flow="paper")] * N,
    "continuous": [base.replace(contact="layer", flow="continuous")] * N,
    "extensions": [ext[i % 4].replace(keep_trajectories=True) for i in range(N)],
    # long enough for closed draws to settle and for row 4 to diverge (ok=False on both devices)
    "early_stop": [base.replace(duration=0.4, discard=0.1, early_stop=True)] * N,
}
out = {"status": cuda_status()[1], "cases": {}}
fields = ("gaw", "gaw_hr", "width", "flow", "contact_pressure", "contact_force", "p_in", "trajectories")
t_all = time.perf_counter()
for name, cfgs in cases.items():
    cpu = simulate_many(rows, block=N, configs=cfgs)
    t = time.perf_counter()
    gpu = simulate_many(rows, configs=cfgs, device="cuda")
    dt = time.perf_counter() - t
    d_abs, d_rel, same_ok, same_msg, identical = 0.0, 0.0, True, True, True
    for a, b in zip(cpu, gpu):
        same_ok &= a.ok == b.ok
        same_msg &= a.message == b.message
        if not (a.ok and b.ok):
            continue
        d = float(np.max(np.abs(a.gaw - b.gaw)))
        d_abs = max(d_abs, d)
        d_rel = max(d_rel, d / max(float(np.max(np.abs(a.gaw))), 1e-300))
        for f in fields:
            x, y = getattr(a, f), getattr(b, f)
            identical &= (x is None and y is None) or np.array_equal(x, y)
        identical &= a.settled_at == b.settled_at
        for f in ("period", "contact_impulse", "contact_pressure_in_contact"):
            identical &= np.array_equal(getattr(a.cycles, f), getattr(b.cycles, f))
    out["cases"][name] = dict(n_ok=sum(r.ok for r in cpu), same_ok=bool(same_ok), same_message=bool(same_msg),
                              max_abs_gaw=d_abs, max_rel_gaw=d_rel, identical=bool(identical),
                              oscillating=sum(1 for r in cpu if r.ok and np.ptp(r.gaw) > 1e-3),
                              touching=sum(1 for r in cpu if r.ok and r.contact_force.max() > 0),
                              settled=sum(1 for r in cpu if r.ok and r.settled_at > 0),
                              failed=sum(1 for r in cpu if not r.ok), cuda_s=dt)

# the device evaluator (what a worker maps for a job with device "cuda") scores as the CPU ProblemEvaluator does
from vfcore.inference import Prior, Problem, ProblemEvaluator
from vfcore.inference.device_eval import DeviceEvaluator
cfg = SimConfig(mesh="coarse", duration=0.12, discard=0.02)
obs = simulate_many(rows[-1:], cfg)[0].gaw[:80]
prior = Prior({"E_cover": (250.0, 950.0), "p_sub": (400.0, 1800.0)})
pb = Problem(obs + 0.01, 2000.0, prior, sigma_e=0.05, config=cfg)
th = np.array([[636.2, 989.9], [500.0, 1200.0], [900.0, 700.0], [-5.0, 800.0]])     # the last is invalid
e_cpu = ProblemEvaluator(pb)(th)
e_gpu = DeviceEvaluator(pb, "cuda")(th)
out["evaluator"] = dict(ok=e_cpu.ok.tolist(), same_ok=bool(np.array_equal(e_cpu.ok, e_gpu.ok)),
                        same_loglik=bool(np.array_equal(e_cpu.loglik, e_gpu.loglik)))
# the device-side zero fill (the simulator path of _zeros copies zeros instead)
from numba import cuda
from vfcore.solver._cuda_kernels import fill_zero
x = cuda.to_device(np.ones(300))
fill_zero[2, 64](x)
out["fill_zero"] = bool(np.all(x.copy_to_host() == 0.0))
out["total_s"] = time.perf_counter() - t_all
print("RESULT " + json.dumps(out))
"""


def _run_script(code: str, timeout: float, **env_extra) -> tuple[dict, float]:
    env = dict(
        os.environ,
        OMP_NUM_THREADS="1",
        OPENBLAS_NUM_THREADS="1",
        NUMBA_NUM_THREADS="1",
        MPLBACKEND="Agg",
        PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
        **env_extra,
    )
    t = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        pytest.skip(
            f"the CUDA-simulator run took over {timeout:.0f} s on this machine (compiling the kernel's "
            "thread body for strided arrays dominates); too slow here to check anything"
        )
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise AssertionError(f"subprocess failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-8000:]}")
    if "SKIP " in proc.stdout:
        pytest.skip(proc.stdout.split("SKIP ", 1)[1].strip().splitlines()[0])
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :]), wall


@pytest.fixture(scope="module")
def simulated():
    return _run_script(_SIM_SCRIPT, SIM_TIMEOUT_S, NUMBA_ENABLE_CUDASIM="1")


@pytest.mark.slow  # half a minute compiling the kernel for the simulator
def test_simulator_matches_the_cpu_lockstep_kernel(simulated):
    """On the simulator each thread runs the CPU's integrate_ws on its columns of the interleaved arrays: the
    results equal the CPU lock-step kernel's bit for bit (flags, messages, GAW, contact, p_in, trajectories,
    per-cycle products, settle step), for both contact laws, the extensions and the early stop."""
    res, wall = simulated
    assert "simulator" in res["status"]
    c = res["cases"]
    assert c["projection"]["oscillating"] >= 1 and c["projection"]["touching"] >= 1
    assert c["layer"]["touching"] >= 1
    assert c["early_stop"]["settled"] >= 1 and c["early_stop"]["failed"] >= 1
    for name, r in c.items():
        assert r["same_ok"] and r["same_message"], name
        assert r["max_rel_gaw"] <= 1e-10 and r["max_abs_gaw"] <= 1e-10, (name, r)
        assert r["identical"], (name, r)


@pytest.mark.slow  # half a minute compiling the kernel for the simulator
def test_device_zero_fill(simulated):
    assert simulated[0]["fill_zero"]


@pytest.mark.slow  # half a minute compiling the kernel for the simulator
def test_device_evaluator_scores_as_the_cpu_evaluator(simulated):
    res, _ = simulated
    ev = res["evaluator"]
    assert ev["same_ok"] and ev["same_loglik"]
    assert ev["ok"][:3] == [True, True, True] and ev["ok"][3] is False


def test_worker_passes_a_jobs_device_through():
    """A job whose spec names a device gets the device evaluator and GPU-sized chunks; a spec without the
    field (a JobSpec made before it existed) runs on the CPU as before."""
    from types import SimpleNamespace

    from vfcore.inference.device_eval import DeviceEvaluator
    from vfcore.inference.problem import ProblemEvaluator
    from worker.run import GPU_CHUNK, evaluator_for, job_device

    assert job_device(SimpleNamespace(model="fe")) == "cpu"
    ev = evaluator_for(SimpleNamespace(model="fe", device="cuda"), problem=None)
    assert isinstance(ev, DeviceEvaluator) and ev.device == "cuda"
    assert type(evaluator_for(SimpleNamespace(model="fe", device="cpu"), problem=None)) is ProblemEvaluator
    assert GPU_CHUNK >= 4096


def test_cuda_without_a_gpu_is_one_clear_error():
    from vfcore.gpu import CudaUnavailable, cuda_status, resolve_device

    assert resolve_device("cpu") == "cpu"
    with pytest.raises(ValueError, match="device must be one of"):
        resolve_device("gpu")
    ok, what = cuda_status()
    if ok:
        pytest.skip(f"a CUDA device is usable here ({what})")
    assert resolve_device("auto") == "cpu"
    with pytest.raises(CudaUnavailable, match=r"device='cuda' cannot run here: .*use device='cpu'") as err:
        resolve_device("cuda")
    assert "\n" not in str(err.value)
    from vfcore import TABLE3, SimConfig
    from vfcore.batch import simulate_many

    with pytest.raises(CudaUnavailable):
        simulate_many(
            np.array([TABLE3.as_array()]), SimConfig(mesh="coarse", duration=0.001, discard=0.0), device="cuda"
        )


_PTX_SCRIPT = r"""
import re, time
from numba import cuda, typeof, types
from numba.cuda.cudadrv import nvvm
if not nvvm.is_available():
    print("SKIP the CUDA toolkit's NVVM is not installed here (CUDA_HOME or a system toolkit)"); raise SystemExit
# device functions compile for the current device's compute capability; with no GPU here, name the H100's
import numba.cuda.dispatcher as disp
class _H100:
    compute_capability = (9, 0)
disp.get_current_device = lambda: _H100()
import numpy as np
from vfcore.solver import _cuda_kernels as ck
from vfcore.solver.system import get_system
s = get_system("coarse", 0.4995, "p1")
f8, i8 = types.float64, types.int64
def arr(nd, dt=f8):
    return types.Array(dt, nd, "C")
sig = ([i8, i8, f8, f8, f8, f8, f8, f8, f8, f8, i8, f8, f8, types.boolean, i8, i8, f8, f8]
       + [typeof(getattr(s, k)) for k in ("indptr", "indices", "Lp", "Lj", "sdx", "sdz", "sX", "sZ")]
       + [arr(3), arr(2), arr(3), arr(3), arr(2), arr(3), arr(3), arr(3), arr(3), arr(2, types.boolean), arr(2, i8),
          arr(3), arr(3), arr(2), arr(2), arr(3), arr(3), arr(2), arr(3), arr(3), arr(1, i8), arr(1, i8)])
t = time.perf_counter()
with ck._no_fma_contraction() as patched:
    ptx, _ = cuda.compile_ptx(ck.integrate_kernel, tuple(sig), cc=(9, 0))
cuda.compile_ptx(ck.fill_zero.py_func, (arr(1),), cc=(9, 0))
print("RESULT " + __import__("json").dumps(dict(
    patched=patched, chars=len(ptx), fma=len(re.findall(r"\bfma\.rn\.f64", ptx)), mul_rn=ptx.count("mul.rn.f64"),
    sqrt_rn=ptx.count("sqrt.rn.f64"), div_rn=ptx.count("div.rn.f64"), seconds=time.perf_counter() - t)))
"""


def test_kernel_compiles_for_the_gpu_without_fma_contraction():
    """numba's CUDA target compiles the kernel, with integrate_ws and every physics helper it calls as device
    functions, to PTX for an H100 (sm_90); with NVVM's contraction off there is no fused multiply-add, and the
    square roots and divisions are the correctly rounded ones, as on the CPU."""
    res, _ = _run_script(_PTX_SCRIPT, 300)
    assert res["patched"]
    assert res["fma"] == 0 and res["mul_rn"] > 100
    assert res["sqrt_rn"] >= 1 and res["div_rn"] >= 1


def _real_gpu() -> bool:
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return False
    from vfcore.gpu import cuda_status

    return cuda_status()[0]


@pytest.mark.skipif(
    not _real_gpu(),
    reason="no usable NVIDIA GPU (numba.cuda.is_available() is false, or NVVM is "
    "missing); the kernel's logic is checked on the simulator above",
)
def test_real_gpu_matches_the_cpu_lockstep_kernel():
    """On a GPU: the medium mesh, prior draws and Table 3 over 100 ms, both contact laws and flow loads; with FMA contraction
    off the GPU's arithmetic is the CPU's, so the GAWs agree to 1e-10 relative (bit for bit expected)."""
    from vfcore import TABLE3, Params, SimConfig
    from vfcore.batch import simulate_many

    lo = np.array([9.0, 250.0, 0.5, 400.0, 950.0, 1.0, 7.4])
    hi = np.array([15.0, 950.0, 3.0, 1800.0, 1200.0, 7.0, 8.4])
    rng = np.random.default_rng(2)
    rows = np.array(
        [Params.from_array(r).as_array() for r in lo + (hi - lo) * rng.random((15, 7))] + [TABLE3.as_array()]
    )
    for contact, flow in (("projection", "paper"), ("layer", "paper"), ("layer", "continuous")):
        cfg = SimConfig(duration=0.1, discard=0.02, contact=contact, flow=flow)
        cpu = simulate_many(rows, cfg, block=16)
        gpu = simulate_many(rows, cfg, device="cuda")
        for a, b in zip(cpu, gpu):
            assert a.ok == b.ok and a.message == b.message
            if a.ok:
                scale = max(float(np.max(np.abs(a.gaw))), 1e-12)
                assert np.max(np.abs(a.gaw - b.gaw)) <= 1e-10 * scale, contact
