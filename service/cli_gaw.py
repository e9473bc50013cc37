"""``vfinfer gaw VIDEO``: high-speed video (or frame stack) -> GAW CSV + figure."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

console = Console()


def gaw(video: Annotated[Path, typer.Argument(help="video file, frame folder, multi-page TIFF or .npy stack")],
        fps: Annotated[float, typer.Option(help="capture frame rate, frames/s (containers often store playback rates)")],
        px_per_mm: Annotated[float, typer.Option("--px-per-mm", help="spatial calibration, pixels per mm")],
        out: Annotated[Path, typer.Option("-o", "--out", help="GAW CSV to write")] = Path("gaw.csv"),
        segment_s: Annotated[float, typer.Option(help="length of the stable segment, s")] = 0.3,
        figure: Annotated[Optional[Path], typer.Option(help="PNG with contours and the GAW")] = None,
        fmax: Annotated[float, typer.Option(help="highest f0 considered, Hz")] = 600.0) -> None:
    """Segment the glottis in every frame and write the calibrated GAW (mm^2) of the stable segment."""
    from vfvideo import extract_gaw, plot_extraction

    try:
        ex = extract_gaw(video, fps=fps, px_per_mm=px_per_mm, segment_s=segment_s, fmax=fmax)
    except ValueError as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None
    ex.write_csv(out)
    fig_path = figure or out.with_suffix(".png")
    plot_extraction(ex, fig_path)
    t = Table(title=f"GAW of {video.name}: frames {ex.segment[0]}-{ex.segment[1]} of {ex.area.size}")
    t.add_column("measure")
    t.add_column("value", justify="right")
    t.add_row("f0 (Hz)", f"{ex.f0:.2f}")
    for k, v in ex.measures.items():
        if isinstance(v, float):
            t.add_row(k, f"{v:.4g}")
    t.add_row("flagged frames", str(int((~ex.ok).sum())))
    console.print(t)
    console.print(f"wrote {out} and {fig_path}")
