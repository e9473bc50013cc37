"""Regenerate the README's pictures (docs/img/report_job.png, report_diagnosis.png, api_docs.png): the three
pages that tests/service/test_browser.py opens, taken by the same code (tests/service/browser_pages.py) in the
system's headless Chromium, with the demo's finite-element fit in place of the test's toy job.

    .venv/bin/python scripts/screenshots.py                       # the demo's fit, the tests' sample diagnosis
    .venv/bin/python scripts/screenshots.py --diagnosis DIR       # a `vfinfer diagnose --out DIR` result instead

The demo's fit runs on a local Dask cluster (3 minutes on 2 cores, as `make demo`). The diagnosis page shows
the settings of a ``request`` kept in diagnosis.json (the service keeps one; `vfinfer diagnose` does not, so add
it by hand to show them). Each page must pass the test's
checks (every image loaded, no console error) or nothing is written. The pictures are the top of each page,
reduced to 256 colours so each stays well under 400 KB.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads its BLAS
    os.environ.setdefault(_v, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "service"))  # browser_pages and the helpers it shares with the tests

#: page -> (file in docs/img, height shown in px): the part of each page that says what it is.
PICTURES = {
    "job_report": ("report_job.png", 1900),
    "diagnosis_report": ("report_diagnosis.png", 2300),
    "docs": ("api_docs.png", 1300),
}
MAX_BYTES = 400_000


def blank_cut(rows: np.ndarray, limit: int, gap: int = 12) -> int:
    """The lowest row at most ``limit`` that ends a band of ``gap`` rows of plain background (the page's top-left
    colour) in the image ``rows`` (height, width, 3): a cut there falls between two blocks, never through a figure
    or a table; ``limit`` itself where no such band exists."""
    plain = np.all(rows == rows[0, 0], axis=(1, 2))
    for y in range(min(limit, len(plain)) - 1, gap, -1):
        if plain[y - gap : y + 1].all():
            return y - gap // 2
    return min(limit, len(plain))


def shrink(src: Path, dst: Path, height: int) -> int:
    """The top of the screenshot ``src``, at most ``height`` px and cut between two blocks, in 256 colours, as
    ``dst``; its size in bytes."""
    from PIL import Image

    with Image.open(src) as im:
        im = im.convert("RGB")
        im = im.crop((0, 0, im.width, blank_cut(np.asarray(im), height)))
        im.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(dst, optimize=True)
    return dst.stat().st_size


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img", help="folder of the pictures")
    ap.add_argument("--diagnosis", type=Path, help="a `vfinfer diagnose` output folder (diagnosis.json, .png)")
    ap.add_argument("--particles", type=int, default=80, help="SMC particles of the demo's fit (the demo's own)")
    ap.add_argument("--workers", type=int, default=2, help="Dask worker processes")
    args = ap.parse_args(argv)

    from browser_pages import chromium_path, open_pages, pages_service

    chromium = chromium_path()
    if chromium is None:
        print("error: no Chromium found (apt-get install chromium, or VFINFER_CHROMIUM=PATH)", file=sys.stderr)
        return 2
    diagnosis = png = None
    if args.diagnosis is not None:
        diagnosis = json.loads((args.diagnosis / "diagnosis.json").read_text())
        png = (args.diagnosis / "diagnosis.png").read_bytes()

    from distributed import Client, LocalCluster

    from vfcore.data import DEMO_SMC, demo_spec_dict

    spec = demo_spec_dict(sampler={**DEMO_SMC, "n_particles": args.particles})
    with (
        tempfile.TemporaryDirectory() as tmp,
        LocalCluster(n_workers=args.workers, threads_per_worker=1, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        print(f"fitting the demo GAW ({args.particles} SMC particles, {spec['mesh']} mesh) ...", flush=True)
        with pages_service(Path(tmp) / "data", client, spec, diagnosis, png, job_timeout_s=3600) as site:
            views = open_pages(site.page_urls(), Path(tmp) / "shots", chromium)
        bad = {n: v.problems() for n, v in views.items() if v.problems()}
        if bad:
            print(f"error: the pages did not pass the browser test's checks: {bad}", file=sys.stderr)
            return 1
        args.out.mkdir(parents=True, exist_ok=True)
        for name, (file, height) in PICTURES.items():
            size = shrink(views[name].screenshot, args.out / file, height)
            print(f"{args.out / file}: {size / 1000:.0f} KB")
            if size > MAX_BYTES:
                print(f"error: {file} is {size / 1000:.0f} KB, over {MAX_BYTES / 1000:.0f} KB", file=sys.stderr)
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
