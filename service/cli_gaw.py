"""``vfinfer gaw VIDEO``: high-speed video (or frame stack) -> GAW CSV + figure."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console

from .cli_common import POSITIVE, fail
from rich.table import Table

console = Console()


def gaw(
    video: Annotated[Path, typer.Argument(help="video file, frame folder, multi-page TIFF or .npy stack")],
    fps: Annotated[
        float,
        typer.Option(parser=POSITIVE, help="capture frame rate, frames/s (containers often store playback rates)"),
    ],
    px_per_mm: Annotated[
        float, typer.Option("--px-per-mm", parser=POSITIVE, help="spatial calibration, pixels per mm")
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="GAW CSV to write")] = Path("gaw.csv"),
    segment_s: Annotated[float, typer.Option(parser=POSITIVE, help="length of the stable segment, s")] = 0.3,
    figure: Annotated[Optional[Path], typer.Option(help="PNG with contours and the GAW")] = None,
    fmax: Annotated[float, typer.Option(parser=POSITIVE, help="highest f0 considered, Hz")] = 600.0,
) -> None:
    """Segment the glottis in every frame and write the calibrated GAW (mm^2) of the stable segment."""
    import os
    import tempfile

    from vfvideo import extract_gaw, plot_extraction

    fig_path = figure or out.with_suffix(".png")
    for what, p in (("-o/--out", out), ("--figure", fig_path)):
        if p.is_dir():
            raise fail(f"{what} {p} is a folder; give a file name")
        if not p.resolve().parent.is_dir():
            raise fail(f"{what} {p}: the folder {p.resolve().parent} does not exist")
    if not video.exists():
        raise fail(f"cannot read {video}: no such file or folder")
    try:
        ex = extract_gaw(video, fps=fps, px_per_mm=px_per_mm, segment_s=segment_s, fmax=fmax)
    except ValueError as exc:
        raise fail(str(exc) if str(video) in str(exc) else f"{video}: {exc}") from None
    # both files appear together or not at all
    tmps = []
    try:
        for p in (out, fig_path):
            fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=p.suffix, dir=p.resolve().parent)
            os.close(fd)
            tmps.append(tmp)
        ex.write_csv(tmps[0])
        plot_extraction(ex, tmps[1])
        os.replace(tmps[0], out)
        os.replace(tmps[1], fig_path)
    finally:
        for tmp in tmps:
            if os.path.exists(tmp):
                os.unlink(tmp)
    t = Table(title=f"GAW of {video.name}: frames {ex.segment[0]}-{ex.segment[1]} of {ex.area.size}")
    t.add_column("measure")
    t.add_column("value", justify="right")
    t.add_row("f0 (Hz)", f"{ex.f0:.2f}")
    for k, v in ex.measures.items():
        if isinstance(v, float) and k != "f0":
            t.add_row(k, f"{v:.4g}")
    t.add_row("flagged frames", str(int((~ex.ok).sum())))
    console.print(t)
    console.print(f"wrote {out} and {fig_path}")
