"""Every command refuses bad input the same way: exit 2, exactly one line on stderr that starts with
``error:`` and names the problem, no traceback anywhere, and no output left behind.

Each command has a table of at least 20 bad inputs. Nothing expensive may run: the simulator, the
sampler, the diagnosis, the reach ensemble builder and the web server are replaced by stand-ins that
fail the test if they are ever reached. Client commands talk to a port where nothing listens."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from svc_helpers import toy_spec
from typer.testing import CliRunner

from service.cli import app

DEAD_URL = "http://127.0.0.1:1"
JOB = "A" * 32
TOY = [
    "--model",
    "toy",
    "--sampler",
    "is",
    "--n",
    "40",
    "--duration",
    "0.35",
    "--discard",
    "0.2",
    "--sigma-e",
    "10",
    "--prior",
    "E_cover=450:850",
    "--prior",
    "p_sub=700:1300",
    "--fix",
    "E_body=12.15",
    "--fix",
    "E_lig=1.808",
    "--fix",
    "rho=1051",
    "--fix",
    "eta=3.079",
    "--fix",
    "x0=8.4",
]


# ------------------------------------------------------------------------------------ inputs
@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Bad (and one good) input files, made once."""
    from vfvideo.io import write_gaw_csv

    d = tmp_path_factory.mktemp("inputs")
    areas = np.array(toy_spec()["gaw"]["areas"])
    t = np.arange(areas.size) / 4000.0
    write_gaw_csv(d / "good.csv", t, areas, 4000.0)
    (d / "empty.csv").write_text("")
    (d / "binary.csv").write_bytes(bytes(range(256)) * 4)
    (d / "text.csv").write_text("hello world\nthis is not a GAW\n")
    (d / "nan.csv").write_text(
        "time_s,area_mm2\n" + "".join(f"{k / 4000},{'nan' if k == 5 else 1.0 + k % 7}\n" for k in range(40))
    )
    (d / "inf.csv").write_text(
        "time_s,area_mm2\n" + "".join(f"{k / 4000},{'inf' if k == 5 else 1.0 + k % 7}\n" for k in range(40))
    )
    write_gaw_csv(d / "negative.csv", t, areas - 5.0, 4000.0)  # a baseline error, not noise
    np.savetxt(d / "nofps.csv", areas[:400])  # one column, no fps anywhere
    (d / "short.csv").write_text("time_s,area_mm2\n0,1.0\n")
    (d / "nonuniform.csv").write_text("time_s,area_mm2\n0,1\n0.001,2\n0.0015,3\n0.004,1\n0.0045,2\n")
    (d / "ragged.csv").write_text("time_s,area_mm2\n0,1\n0.001,2,7\n0.002,3\n")
    write_gaw_csv(d / "constant.csv", t, np.full_like(areas, 3.0), 4000.0)
    np.save(d / "stack.npy", np.zeros((3, 4, 5)))
    np.save(d / "flat.npy", np.full((30, 40, 40), 200, dtype=np.uint8))  # a video without a glottis
    np.save(d / "image.npy", np.zeros((40, 40)))
    (d / "empty.avi").write_bytes(b"")
    (d / "text.avi").write_text("not a video")
    (d / "folder").mkdir()
    (d / "afile.txt").write_text("x")
    (d / "other").mkdir()
    (d / "other" / "keep.txt").write_text("a folder of the user's, not a vfinfer output")
    (d / "earlier").mkdir()
    (d / "earlier" / "posterior.json").write_text("{}")
    return d


GAW_FILES = [
    ("missing", "{d}/missing.csv", "no such file"),
    ("empty", "{d}/empty.csv", "no data rows"),
    ("binary", "{d}/binary.csv", "binary.csv"),
    ("text", "{d}/text.csv", "non-numeric"),
    ("nan", "{d}/nan.csv", "nan"),
    ("inf", "{d}/inf.csv", "infinite"),
    ("negative", "{d}/negative.csv", "negative"),
    ("nofps", "{d}/nofps.csv", "fps"),
    ("short", "{d}/short.csv", "fewer than two"),
    ("nonuniform", "{d}/nonuniform.csv", "non-uniform"),
    ("ragged", "{d}/ragged.csv", "columns"),
    ("stack", "{d}/stack.npy", "shape"),
    ("folder", "{d}/folder", "folder"),
]
GENERIC = [
    ("unknown-option", ["--bogus"], "no such option"),
    ("extra-argument", ["surplus", "extra"], "unexpected"),
    ("short-unknown", ["-x"], "no such option"),
]


def _client(cmd: list[str], job: bool) -> list[tuple]:
    """Bad inputs every client command shares (the service is never reached)."""
    j = [JOB] if job else []
    cases = [
        ("no-token", [*cmd, *j, "--token", ""], "token"),
        ("blank-token", [*cmd, *j, "--token", "   "], "token"),
        ("ftp-url", [*cmd, *j, "--url", "ftp://host"], "--url"),
        ("no-scheme-url", [*cmd, *j, "--url", "localhost:8000"], "--url"),
        ("empty-host-url", [*cmd, *j, "--url", "http://"], "--url"),
        ("empty-url", [*cmd, *j, "--url", ""], "--url"),
        ("unreachable", [*cmd, *j], "cannot reach"),
        ("token-no-value", [*cmd, *j, "--token"], "requires an argument"),
        ("url-no-value", [*cmd, *j, "--url"], "requires an argument"),
    ]
    cases += [(n, [*cmd, *j, *a], nd) for n, a, nd in GENERIC]
    if job:
        cases += [
            ("short-id", [*cmd, "abc"], "not a job id"),
            ("long-id", [*cmd, "A" * 33], "not a job id"),
            ("path-id", [*cmd, "../../etc/passwd"], "not a job id"),
            ("space-id", [*cmd, "A" * 15 + " " + "A" * 16], "not a job id"),
            ("unicode-id", [*cmd, "Ä" * 32], "not a job id"),
            ("dot-id", [*cmd, "." * 32], "not a job id"),
            ("missing-id", [*cmd], "missing argument"),
        ]
    return cases


def _fit_options(cmd: str) -> list[tuple]:
    """Bad options of infer and submit, each on an otherwise valid toy job."""
    g = "{d}/good.csv"
    base = [cmd, g, *TOY]
    opts = [
        ("sampler-mcmc", ["--sampler", "mcmc"], "'mcmc' is not one of"),
        ("mesh", ["--mesh", "huge"], "mesh"),
        ("noise", ["--noise", "loud"], "noise"),
        ("fps-neg", ["--fps", "-5"], "fps"),
        ("fps-zero", ["--fps", "0"], "fps"),
        ("fps-nan", ["--fps", "nan"], "fps"),
        ("fps-disagrees", ["--fps", "1000"], "disagrees"),
        ("dt-zero", ["--dt", "0"], "--dt"),
        ("dt-text", ["--dt", "abc"], "--dt"),
        ("dt-coarse", ["--dt", "1e-3"], "--dt"),
        ("duration-zero", ["--duration", "0"], "--duration"),
        ("discard-neg", ["--discard", "-0.1"], "--discard"),
        ("discard-long", ["--discard", "0.4"], "--discard"),
        ("sigma-zero", ["--sigma-e", "0"], "--sigma-e"),
        ("sigma-inf", ["--sigma-e", "inf"], "--sigma-e"),
        ("n-zero", ["--n", "0"], "--n"),
        ("particles-few", ["--sampler", "smc", "--particles", "5"], "--particles"),
        ("seed-neg", ["--seed", "-1"], "--seed"),
        ("fix-text", ["--fix", "E_cover=abc"], "not a number"),
        ("fix-unknown", ["--fix", "colour=1"], "unknown parameter"),
        ("fix-no-eq", ["--fix", "x0"], "name=value"),
        ("fix-twice", ["--fix", "x0=8"], "twice"),
        ("prior-reversed", ["--prior", "E_body=15:9"], "must be <"),
        ("prior-text", ["--prior", "E_body=a:9"], "not a number"),
        ("prior-unknown", ["--prior", "colour=1:2"], "unknown parameter"),
        ("prior-and-fix", ["--prior", "x0=8:9"], "both"),
        ("measure", ["--measure", "p_sub=1000:0"], "measure"),
        ("model", ["--model", "cfd"], "model"),
        ("screen-mesh", ["--screen", "huge"], "--screen"),
        ("screen-dt", ["--screen", "coarse:abc"], "not a number"),
        ("screen-dt-range", ["--screen", "coarse:0.01"], "time step"),
        ("screen-with-is", ["--sampler", "is", "--screen", "coarse"], "--sampler smc"),
        ("runs-with-is", ["--sampler", "is", "--runs", "2"], "--runs needs --sampler smc"),
        ("runs-zero", ["--runs", "0"], "--runs"),
        ("runs-many", ["--runs", "9"], "--runs"),
        ("area-scale-text", ["--area-scale", "a:2"], "not a number"),
        ("area-scale-one", ["--area-scale", "2"], "LO:HI"),
        ("area-scale-reversed", ["--area-scale", "4:0.25"], "0 < LO < HI"),
        ("area-scale-zero", ["--area-scale", "0:4"], "0 < LO < HI"),
        ("area-scale-negative", ["--area-scale", "-1:4"], "0 < LO < HI"),
        ("area-scale-inf", ["--area-scale", "1:inf"], "finite"),
        ("area-scale-and-uncalibrated", ["--area-scale", "1:2", "--uncalibrated"], "not both"),
        ("contact", ["--contact", "rigid"], "'rigid' is not one of"),
        ("contact-layer-thick", ["--contact", "layer", "--contact-layer-mm", "1.5"], "contact_layer_mm"),
        ("contact-layer-zero", ["--contact-layer-mm", "0"], "--contact-layer-mm"),
    ]
    cases = [(n, [*base, *a], nd) for n, a, nd in opts]
    cases += [(f"gaw-{n}", [cmd, f, *TOY], nd) for n, f, nd in GAW_FILES]
    cases += [("gaw-constant", [cmd, "{d}/constant.csv", *TOY], "gaw")]
    cases += [(n, [*base, *a], nd) for n, a, nd in GENERIC]
    cases += [("missing-gaw", [cmd], "missing argument")]
    return cases


INFER = _fit_options("infer") + [
    ("workers-zero", ["infer", "{d}/good.csv", *TOY, "--workers", "0"], "--workers"),
    ("out-is-file", ["infer", "{d}/good.csv", *TOY, "--out", "{d}/afile.txt"], "not a folder"),
    ("out-foreign", ["infer", "{d}/good.csv", *TOY, "--out", "{d}/other", "--overwrite"], "refusing"),
    ("out-exists", ["infer", "{d}/good.csv", *TOY, "--out", "{d}/earlier"], "--overwrite"),
    ("out-no-parent", ["infer", "{d}/good.csv", *TOY, "--out", "{d}/nowhere/o"], "does not exist"),
]
SUBMIT = _fit_options("submit") + _client(["submit", "{d}/good.csv", *TOY], job=False)
SIMULATE = [
    (n, ["simulate", *a, "-o", "{out}.csv"], nd)
    for n, a, nd in [
        ("param-text", ["--param", "p_sub=abc"], "not a number"),
        ("param-unknown", ["--param", "foo=1"], "unknown"),
        ("param-no-eq", ["--param", "p_sub"], "name=value"),
        ("param-neg-E", ["--param", "E_body=-5"], "e_body"),
        ("param-neg-p", ["--param", "p_sub=-1"], "p_sub"),
        ("param-nan", ["--param", "x0=nan"], "finite"),
        ("param-inf", ["--param", "p_sub=inf"], "finite"),
        ("param-twice", ["--param", "x0=8", "--param", "x0=9"], "twice"),
        ("mesh", ["--mesh", "huge"], "mesh"),
        ("dt-zero", ["--dt", "0"], "--dt"),
        ("dt-text", ["--dt", "abc"], "--dt"),
        ("duration-neg", ["--duration", "-1"], "--duration"),
        ("discard-long", ["--discard", "1"], "--discard"),
        ("fps-zero", ["--fps", "0"], "--fps"),
        ("fps-fast", ["--fps", "1e6"], "--fps"),
        ("fps-nan", ["--fps", "nan"], "--fps"),
        ("contact", ["--contact", "rigid"], "'rigid' is not one of"),
        ("contact-layer-thick", ["--contact", "layer", "--contact-layer-mm", "2"], "contact_layer_mm"),
        *GENERIC,
    ]
] + [
    ("out-folder", ["simulate", "-o", "{d}/folder"], "folder"),
    ("out-no-parent", ["simulate", "-o", "{d}/nowhere/g.csv"], "does not exist"),
    ("out-no-value", ["simulate", "-o"], "requires an argument"),
]
GAW_CMD = [
    (n, ["gaw", *a], nd)
    for n, a, nd in [
        ("missing-video", ["{d}/missing.avi", "--fps", "2000", "--px-per-mm", "20", "-o", "{out}.csv"], "missing.avi"),
        ("flat-video", ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "-o", "{out}.csv"], "flat.npy"),
        ("one-image", ["{d}/image.npy", "--fps", "2000", "--px-per-mm", "20", "-o", "{out}.csv"], "image.npy"),
        ("empty-video", ["{d}/empty.avi", "--fps", "2000", "--px-per-mm", "20", "-o", "{out}.csv"], "empty"),
        ("text-video", ["{d}/text.avi", "--fps", "2000", "--px-per-mm", "20", "-o", "{out}.csv"], "text.avi"),
        ("no-fps", ["{d}/flat.npy", "--px-per-mm", "20", "-o", "{out}.csv"], "--fps"),
        ("no-px", ["{d}/flat.npy", "--fps", "2000", "-o", "{out}.csv"], "--px-per-mm"),
        ("fps-zero", ["{d}/flat.npy", "--fps", "0", "--px-per-mm", "20", "-o", "{out}.csv"], "--fps"),
        ("fps-text", ["{d}/flat.npy", "--fps", "abc", "--px-per-mm", "20", "-o", "{out}.csv"], "--fps"),
        ("fps-nan", ["{d}/flat.npy", "--fps", "nan", "--px-per-mm", "20", "-o", "{out}.csv"], "--fps"),
        ("px-zero", ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "0", "-o", "{out}.csv"], "--px-per-mm"),
        ("px-neg", ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "-3", "-o", "{out}.csv"], "--px-per-mm"),
        (
            "segment-zero",
            ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "--segment-s", "0", "-o", "{out}.csv"],
            "--segment-s",
        ),
        (
            "segment-inf",
            ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "--segment-s", "inf", "-o", "{out}.csv"],
            "--segment-s",
        ),
        (
            "fmax-zero",
            ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "--fmax", "0", "-o", "{out}.csv"],
            "--fmax",
        ),
        ("out-folder", ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "-o", "{d}/folder"], "folder"),
        (
            "out-no-parent",
            ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "-o", "{d}/nowhere/g.csv"],
            "does not exist",
        ),
        (
            "figure-folder",
            ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", "-o", "{out}.csv", "--figure", "{d}/folder"],
            "folder",
        ),
        ("missing-video-arg", [], "missing argument"),
        *[(n, ["{d}/flat.npy", "--fps", "2000", "--px-per-mm", "20", *a], nd) for n, a, nd in GENERIC],
    ]
]
DIAGNOSE = (
    [(f"gaw-{n}", ["diagnose", f, "--out", "{out}"], nd) for n, f, nd in GAW_FILES]
    + [
        (n, ["diagnose", "{d}/good.csv", "--out", "{out}", *a], nd)
        for n, a, nd in [
            ("estimate-unknown", ["--estimate", "E_cover,stiffness"], "stiffness"),
            ("estimate-empty", ["--estimate", ","], "no parameter"),
            ("fix-unknown", ["--fix", "colour=1"], "colour"),
            ("fix-estimated", ["--estimate", "E_cover", "--fix", "E_cover=600"], "also in --estimate"),
            ("fix-text", ["--fix", "x0=abc"], "not a number"),
            ("candidates", ["--candidates", "warp_drive"], "warp_drive"),
            ("particles", ["--particles", "3"], "--particles"),
            ("refit-particles", ["--refit-particles", "2"], "--refit"),
            ("max-refits", ["--max-refits", "-1"], "--max-refits"),
            ("workers", ["--workers", "0"], "--workers"),
            ("mesh", ["--mesh", "huge"], "mesh"),
            ("noise", ["--noise", "loud"], "noise"),
            ("dt", ["--dt", "0"], "--dt"),
            ("discard", ["--discard", "-1"], "--discard"),
            ("sigma", ["--sigma-e", "0"], "--sigma-e"),
            ("seed", ["--seed", "-1"], "--seed"),
            ("base-missing", ["--base", "{d}/nothing.nc"], "--base"),
            ("base-not-netcdf", ["--base", "{d}/good.csv"], "not a vfinfer posterior"),
            ("prior-set", ["--prior-set", "martian"], "prior-set"),
            ("area-scale-reversed", ["--area-scale", "4:0.25"], "0 < LO < HI"),
            ("area-scale-and-uncalibrated", ["--area-scale", "1:2", "--uncalibrated"], "not both"),
            ("contact", ["--contact", "rigid"], "'rigid' is not one of"),
            ("contact-layer-thick", ["--contact", "layer", "--contact-layer-mm", "2"], "contact_layer_mm"),
            *GENERIC,
        ]
    ]
    + [
        ("out-is-file", ["diagnose", "{d}/good.csv", "--out", "{d}/afile.txt"], "not a folder"),
        ("no-out", ["diagnose", "{d}/good.csv"], "--out"),
    ]
)
REACH = [
    (n, ["reach", *a], nd)
    for n, a, nd in [
        ("n-zero", ["--n", "0"], "--n"),
        ("n-text", ["--n", "abc"], "--n"),
        ("seed-neg", ["--seed", "-1"], "--seed"),
        ("mesh", ["--mesh", "huge"], "mesh"),
        ("dt-zero", ["--dt", "0"], "--dt"),
        ("duration", ["--duration", "0"], "--duration"),
        ("discard", ["--discard", "1"], "--discard"),
        ("prior-reversed", ["--prior", "E_body=15:9"], "must be <"),
        ("prior-unknown", ["--prior", "colour=1:2"], "unknown"),
        ("prior-text", ["--prior", "E_body=a:b"], "not a number"),
        ("fix-unknown", ["--fix", "colour=1"], "unknown"),
        ("fix-text", ["--fix", "x0=abc"], "not a number"),
        ("fps-zero", ["--fps", "0", "--check", "{d}/good.csv"], "--fps"),
        ("contact", ["--contact", "rigid"], "'rigid' is not one of"),
        ("contact-layer-thick", ["--contact", "layer", "--contact-layer-mm", "2"], "contact_layer_mm"),
        ("element", ["--element", "q2"], "'q2' is not one of"),
        *[(f"check-{n}", ["--check", f], nd) for n, f, nd in GAW_FILES],
        *GENERIC,
    ]
]
SERVE = [
    (n, ["serve", *a], nd)
    for n, a, nd in [
        ("port-big", ["--port", "70000"], "--port"),
        ("port-text", ["--port", "abc"], "--port"),
        ("port-neg", ["--port", "-1"], "--port"),
        ("port-float", ["--port", "80.5"], "--port"),
        ("port-empty", ["--port", ""], "--port"),
        ("port-in-use", ["--port", "{busy_port}"], "in use"),
        ("workers-zero", ["--workers", "0"], "--workers"),
        ("workers-text", ["--workers", "abc"], "--workers"),
        ("workers-neg", ["--workers", "-2"], "--workers"),
        ("host-empty", ["--host", ""], "--host"),
        ("host-blank", ["--host", "  "], "--host"),
        ("port-no-value", ["--port"], "requires an argument"),
        ("host-no-value", ["--host"], "requires an argument"),
        ("workers-no-value", ["--workers"], "requires an argument"),
        ("port-nan", ["--port", "nan"], "--port"),
        ("port-hex", ["--port", "0x50"], "--port"),
        ("workers-float", ["--workers", "1.5"], "--workers"),
        *GENERIC,
    ]
]
DEMO = [
    (n, ["demo", *a], nd)
    for n, a, nd in [
        ("particles-few", ["--particles", "5"], "--particles"),
        ("particles-text", ["--particles", "abc"], "--particles"),
        ("particles-neg", ["--particles", "-1"], "--particles"),
        ("particles-nan", ["--particles", "nan"], "--particles"),
        ("particles-float", ["--particles", "1.5"], "--particles"),
        ("workers-zero", ["--workers", "0"], "--workers"),
        ("workers-text", ["--workers", "x"], "--workers"),
        ("workers-neg", ["--workers", "-3"], "--workers"),
        ("out-is-file", ["--out", "{d}/afile.txt"], "not a folder"),
        ("out-foreign", ["--out", "{d}/other"], "refusing"),
        ("out-earlier-no-overwrite", ["--out", "{d}/earlier", "--no-overwrite"], "--overwrite"),
        ("out-no-parent", ["--out", "{d}/nowhere/o"], "does not exist"),
        ("particles-no-value", ["--particles"], "requires an argument"),
        ("workers-no-value", ["--workers"], "requires an argument"),
        ("out-no-value", ["--out"], "requires an argument"),
        ("particles-empty", ["--particles", ""], "--particles"),
        ("workers-empty", ["--workers", ""], "--workers"),
        ("overwrite-value", ["--overwrite=yes"], "does not take a value"),
        *GENERIC,
    ]
]
STATUS = _client(["status"], job=True) + [("wait-value", ["status", JOB, "--wait=3"], "does not take a value")]
LIST = (
    _client(["list"], job=False)
    + [
        (n, ["list", "--state", s], "--state")
        for n, s in [
            ("state-bogus", "bogus"),
            ("state-empty", ""),
            ("state-upper", "DONE"),
            ("state-two", "done,failed"),
            ("state-space", " "),
            ("state-number", "1"),
            ("state-prefix", "don"),
        ]
    ]
    + [("state-no-value", ["list", "--state"], "requires an argument")]
)
CANCEL = _client(["cancel"], job=True) + [
    ("all-flag", ["cancel", JOB, "--all"], "no such option"),
    ("two-ids", ["cancel", JOB, JOB], "unexpected"),
]
FETCH = _client(["fetch"], job=True) + [
    ("out-is-file", ["fetch", JOB, "--out", "{d}/afile.txt"], "not a folder"),
    ("out-foreign", ["fetch", JOB, "--out", "{d}/other", "--overwrite"], "refusing"),
    ("out-exists", ["fetch", JOB, "--out", "{d}/earlier"], "--overwrite"),
    ("out-no-parent", ["fetch", JOB, "--out", "{d}/nowhere/o"], "does not exist"),
]
DIAGNOSIS = _client(["diagnosis"], job=True) + [
    (n, ["diagnosis", JOB, *a], nd)
    for n, a, nd in [
        ("start-and-cancel", ["--start", "--cancel"], "exclude"),
        ("settings-without-start", ["--particles", "12"], "--start"),
        ("candidates-without-start", ["--candidates", "leak"], "--start"),
        ("particles-few", ["--start", "--particles", "2"], "--particles"),
        ("refit-few", ["--start", "--refit-particles", "1"], "--refit-particles"),
        ("max-refits-neg", ["--start", "--max-refits", "-1"], "--max-refits"),
        ("seed-neg", ["--start", "--seed", "-5"], "--seed"),
        ("out-is-file", ["--out", "{d}/afile.txt"], "not a folder"),
    ]
]
# JOB_ID is optional here (without one the link is to the jobs page), so no "missing-id" case
REPORT = [c for c in _client(["report"], job=True) if c[0] != "missing-id"] + [
    ("open-value", ["report", JOB, "--open=yes"], "does not take a value"),
    ("two-ids", ["report", JOB, JOB], "unexpected"),
    ("no-id-unreachable", ["report"], "cannot reach"),
    ("no-id-ftp-url", ["report", "--url", "ftp://host"], "--url"),
    ("no-id-blank-token", ["report", "--token", " "], "token"),
]

TABLES = {
    "infer": INFER,
    "submit": SUBMIT,
    "simulate": SIMULATE,
    "gaw": GAW_CMD,
    "diagnose": DIAGNOSE,
    "reach": REACH,
    "serve": SERVE,
    "demo": DEMO,
    "status": STATUS,
    "list": LIST,
    "cancel": CANCEL,
    "fetch": FETCH,
    "diagnosis": DIAGNOSIS,
    "report": REPORT,
}
CASES = [
    pytest.param(cmd, args, needle, id=f"{cmd}-{name}") for cmd, table in TABLES.items() for name, args, needle in table
]


def test_every_command_has_twenty_bad_inputs():
    small = {cmd: len(t) for cmd, t in TABLES.items() if len(t) < 20}
    assert not small, small
    names = {c.name or c.callback.__name__ for c in app.registered_commands}
    assert set(TABLES) == names, "a command without a bad-input table"


# ------------------------------------------------------------------------------------ the walk
def _never(*a, **k):
    raise AssertionError("reached past input validation")


@pytest.fixture
def guarded(monkeypatch, tmp_path):
    """Replace everything expensive by ``_never`` (an unexpected pass is an ``internal error`` line, exit 1)."""
    import uvicorn

    import service.cli as cli
    import vfcore.diagnose.pipeline as pipeline
    import vfcore.forward as forward
    from vfcore.inference import reach

    monkeypatch.setattr(cli, "run_local", _never)
    monkeypatch.setattr(forward, "simulate", _never)
    monkeypatch.setattr(pipeline, "diagnose", _never)
    monkeypatch.setattr(reach, "build_ensemble", _never)
    monkeypatch.setattr(uvicorn, "run", _never)
    monkeypatch.setattr(uvicorn, "Server", _never)
    monkeypatch.setenv("VFINFER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("VFINFER_DEBUG", raising=False)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        yield busy.getsockname()[1]


def _snapshot(d) -> set:
    return {str(p.relative_to(d)) for p in d.rglob("*")}


@pytest.mark.parametrize("cmd, args, needle", CASES)
def test_bad_input_is_one_error_line(files, guarded, tmp_path, cmd, args, needle):
    out = tmp_path / "out"
    argv = [a.format(d=files, out=out, busy_port=guarded) for a in args]
    before = _snapshot(files)
    r = CliRunner().invoke(app, argv, env={"COLUMNS": "200", "VFINFER_URL": DEAD_URL, "VFINFER_TOKEN": "t"})
    err = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in r.output and r.exception is None or isinstance(r.exception, SystemExit), r.output
    assert r.exit_code == 2, (argv, r.output)
    assert len(err) == 1 and err[0].startswith("error: "), (argv, r.stderr)
    assert needle.lower() in err[0].lower(), (needle, err[0])
    assert not any(p.name.startswith("out") for p in tmp_path.iterdir()), list(tmp_path.iterdir())
    assert _snapshot(files) == before, "an input folder changed"
