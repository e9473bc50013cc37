"""The install is what was tested: the committed lock satisfies pyproject.toml's ranges, and the
library's core does not pull in the service or video stacks."""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[2]


def _pyproject():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _lock():
    """``{name: [(version, marker or None), ...]}`` of requirements.lock, and its hash count."""
    text = (ROOT / "requirements.lock").read_text()
    pins, n_hash = {}, 0
    for line in text.splitlines():
        if line.lstrip().startswith("--hash=sha256:"):
            n_hash += 1
        m = re.match(r"^([A-Za-z0-9_.\-]+)==([^\s;\\]+)\s*(?:;\s*([^\\]+?))?\s*\\?$", line)
        if m:
            marker = Marker(m.group(3)) if m.group(3) else None
            pins.setdefault(canonicalize_name(m.group(1)), []).append((Version(m.group(2)), marker))
    return pins, n_hash


def _direct_requirements():
    proj = _pyproject()["project"]
    reqs = [Requirement(r) for r in proj["dependencies"]]
    for items in proj["optional-dependencies"].values():
        reqs += [r for r in map(Requirement, items) if canonicalize_name(r.name) != "vfinfer"]
    return reqs


def test_the_lock_pins_every_direct_dependency_inside_its_range():
    pins, n_hash = _lock()
    env = {
        "python_version": "3.11",
        "python_full_version": "3.11.7",
        "sys_platform": "linux",
        "platform_system": "Linux",
        "platform_machine": "x86_64",
        "implementation_name": "cpython",
        "platform_python_implementation": "CPython",
        "os_name": "posix",
        "extra": "",
    }
    for req in _direct_requirements():
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} is in pyproject.toml but not in requirements.lock: run `make lock`"
        chosen = [v for v, marker in pins[name] if marker is None or marker.evaluate(env)]
        assert len(chosen) == 1, f"{req.name}: {len(chosen)} pins apply on CPython 3.11 / Linux"
        assert req.specifier.contains(chosen[0], prereleases=True), (
            f"requirements.lock pins {req.name}=={chosen[0]} outside pyproject.toml's {req.specifier}: run `make lock`"
        )
        for extra in req.extras:  # dask[distributed] -> distributed pinned too
            if extra == "distributed":
                assert "distributed" in pins
    # every pin carries hashes (pip --require-hashes refuses anything else)
    assert n_hash >= sum(len(v) for v in pins.values())


def test_the_lock_is_what_make_lock_writes():
    """The lock's header records the command that made it; `make lock` runs the same one."""
    header = (ROOT / "requirements.lock").read_text().splitlines()[1]
    make = (ROOT / "Makefile").read_text()
    cmd = re.search(r"^LOCK_CMD := (.+)$", make, re.M).group(1)
    # uv drops the index URL from the header it writes
    want = re.sub(r"\s--index-url \S+", "", cmd)
    assert header.strip("# ").strip() == want


def test_the_core_library_imports_without_the_service_and_video_stacks(tmp_path):
    """`pip install vfinfer` (no extras) must give a working vfcore: importing it and running a
    forward model or reading a GAW file must not touch dask, zarr, fastapi, imageio, scikit-image or the
    video package. The check blocks those packages at import time in a fresh interpreter, so it holds in
    the full dev install too."""
    code = r"""
import sys, importlib.abc
BLOCKED = {"dask", "distributed", "zarr", "fastapi", "starlette", "uvicorn", "imageio", "imageio_ffmpeg",
           "skimage", "typer", "rich", "httpx", "vfvideo"}
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"blocked: {name}")
        return None
sys.meta_path.insert(0, Block())
import vfcore
import vfcore.batch, vfcore.inference, vfcore.diagnose, vfcore.measures, vfcore.data, vfcore.gawio
assert len(vfcore.data.demo_spec_dict()["gaw"]["areas"]) > 0
from vfcore import SimConfig, TABLE3, simulate
r = simulate(TABLE3, SimConfig(mesh="coarse", dt=1e-4, duration=0.12, discard=0.02))
assert r.gaw.size > 0
print(sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]"


@pytest.mark.parametrize(
    "extra,modules", [("service", ["fastapi", "dask.distributed", "zarr", "typer"]), ("video", ["skimage", "imageio"])]
)
def test_each_extra_is_declared(extra, modules):
    """The optional stacks a user opts into are the ones the code imports."""
    names = {canonicalize_name(Requirement(r).name) for r in _pyproject()["project"]["optional-dependencies"][extra]}
    dist = {
        "fastapi": "fastapi",
        "dask.distributed": "dask",
        "zarr": "zarr",
        "typer": "typer",
        "skimage": "scikit-image",
        "imageio": "imageio",
    }
    for m in modules:
        assert canonicalize_name(dist[m]) in names
