"""What every ``vfinfer`` command shares: one-line errors on stderr (exit 2 for a user error), checked
option types, GAW input with its clipping rule, output folders that appear whole or not at all, and
human-readable times."""

from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
import threading
import time
import warnings
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path

import typer
from typer.core import TyperGroup

#: Exit status of a user error (bad option, unreadable input, refused request); 1 is left for failures
#: of the run itself.
USAGE_EXIT = 2


def _one_line(msg: str) -> str:
    return " ".join(str(msg).split())


def error_line(msg: str) -> None:
    """``error: <msg>`` as one line on stderr (newlines folded: a message must never become two)."""
    typer.echo(f"error: {_one_line(msg)}", err=True)


def warn(msg: str) -> None:
    """``warning: <msg>`` as one line on stderr."""
    typer.echo(f"warning: {_one_line(msg)}", err=True)


@contextmanager
def warnings_in_words(echo: bool = True):
    """Inside, a Python warning is one ``warning: <message>`` line on stderr, like every other warning of the
    command line: no file, line number or source line, which say nothing to a user. Yields the list of the
    warnings' texts (each once), for a report to list; ``echo`` False only collects them, for a command that
    prints its report's warnings itself. The previous handler comes back on exit."""
    shown: list[str] = []

    def show(message, category, filename, lineno, file=None, line=None):
        text = _one_line(message)
        if text not in shown:
            shown.append(text)
            if echo:
                warn(text)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield shown


def fail(msg: str, code: int = USAGE_EXIT) -> typer.Exit:
    """Print the error line and return the ``typer.Exit`` to raise (``raise fail(...)``)."""
    error_line(msg)
    return typer.Exit(code)


# recent typer releases carry their own copy of click: take the exception classes of whichever click it uses
_click_exc = sys.modules[typer.BadParameter.__module__]
ClickException, UsageError = _click_exc.ClickException, _click_exc.UsageError


class VfinferGroup(TyperGroup):
    """The command group: click's usage errors become one ``error:`` line (click prints a usage box),
    an unexpected exception becomes one line too, not a traceback (``VFINFER_DEBUG=1`` shows it), and a Python
    warning a ``warning:`` line (:func:`warnings_in_words`)."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        try:
            with warnings_in_words():
                rv = super().main(
                    args=args, prog_name=prog_name, complete_var=complete_var, standalone_mode=False, **extra
                )
        except UsageError as exc:
            if type(exc).__name__.startswith("NoArgsIsHelp") and exc.ctx is not None:
                typer.echo(exc.ctx.get_help())
                rv = 0
            else:
                hint = f" (see '{exc.ctx.command_path} --help')" if exc.ctx is not None else ""
                error_line(exc.format_message() + hint)
                rv = USAGE_EXIT
        except ClickException as exc:
            error_line(exc.format_message())
            rv = USAGE_EXIT
        except (typer.Abort, KeyboardInterrupt):
            error_line("interrupted")
            rv = 130
        except Exception as exc:  # noqa: BLE001 - the last line of defence against a traceback
            if os.environ.get("VFINFER_DEBUG"):
                raise
            error_line(f"internal error: {type(exc).__name__}: {exc} (VFINFER_DEBUG=1 shows the traceback)")
            rv = 1
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


# ------------------------------------------------------------------------------------ option parsers
def finite(lo: float | None = None, lo_open: bool = False, hi: float | None = None):
    """A parser (``typer.Option(parser=...)``) of a finite float, optionally bounded: ``lo < x`` (``lo_open``)
    or ``lo <= x``, and ``x <= hi``. click's FloatRange lets NaN through, this does not."""

    def parse(value) -> float:
        try:
            x = float(str(value).strip())
        except ValueError:
            raise typer.BadParameter(f"{value!r} is not a number") from None
        if not math.isfinite(x):
            raise typer.BadParameter(f"{value!r} is not a finite number")
        if lo is not None and (x <= lo if lo_open else x < lo):
            raise typer.BadParameter(f"{x:g} must be {'>' if lo_open else '>='} {lo:g}")
        if hi is not None and x > hi:
            raise typer.BadParameter(f"{x:g} must be <= {hi:g}")
        return x

    return parse


def choice(*values: str):
    """A parser of one of ``values`` (portable across typer releases, unlike click types or Literal)."""

    def parse(value) -> str:
        v = str(value).strip()
        if v not in values:
            raise typer.BadParameter(f"{value!r} is not one of {', '.join(repr(c) for c in values)}")
        return v

    return parse


POSITIVE = finite(0.0, lo_open=True)
NON_NEGATIVE = finite(0.0)


# ------------------------------------------------------------------------------------ GAW input
def load_gaw(path: Path, fps: float | None):
    """Read a GAW file (vfcore.gawio.read_gaw) for a command: any unreadable input is a user error; negative
    samples within ``NEGATIVE_NOISE_SDS`` noise sds of zero are noise around a closed glottis and are kept
    (the likelihood expects them), deeper ones are refused (``vfcore.gawio.check_negative``). Returns the
    ``GawData``."""
    from vfcore.gawio import check_negative, read_gaw

    if path.is_dir():
        raise fail(f"GAW file {path} is a folder, not a file")
    try:
        g = read_gaw(path, fps=fps, allow_negative=True)
    except UnicodeDecodeError:
        raise fail(f"GAW file {path}: not a text CSV (binary content); expected CSV, NPY or NPZ") from None
    except (ValueError, OSError) as exc:  # GawFileError is a ValueError; its message names the file
        raise fail(str(exc) if str(path) in str(exc) else f"GAW file {path}: {exc}") from None
    why = check_negative(g.area)
    if why is not None:
        raise fail(f"GAW file {path}: {why}")
    return g


# ------------------------------------------------------------------------------------ output folders
def _looks_like_output(path: Path) -> bool:
    names = {p.name for p in path.iterdir()}
    return bool(names & {"posterior.json", "index.html", "diagnosis.json", "timings.json"}) or any(
        n.endswith(".zarr") for n in names
    )


def check_out(out: Path, overwrite: bool) -> None:
    """Refuse an output folder that exists (unless ``overwrite`` and it holds an earlier vfinfer output);
    called before any work so that a refusal costs nothing."""
    if out.exists() and not out.is_dir():
        raise fail(f"--out {out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise fail(f"--out {out} already exists; pass --overwrite to replace it, or choose another folder")
        if not _looks_like_output(out):
            raise fail(f"--out {out} is not empty and holds no vfinfer output; refusing to replace it")
    parent = out.resolve().parent
    if not parent.is_dir():
        raise fail(f"--out {out}: the folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise fail(f"--out {out}: cannot write into {parent}")


@contextmanager
def staged_output(out: Path):
    """Yield a fresh folder beside ``out`` to write into; on success it replaces ``out`` in one rename,
    on any failure it is removed, so ``out`` is never left half-written."""
    out = Path(out)
    parent = out.resolve().parent
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    stage.chmod(0o777 & ~umask)  # mkdtemp's 0700 would outlive the rename
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=parent))
        out.rename(old / "x")
        stage.rename(out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        stage.rename(out)


# ------------------------------------------------------------------------------------ human units
def human_duration(s: float | None) -> str:
    """``3.2 s``, ``4 min 05 s``, ``2 h 03 min``; ``-`` when unknown."""
    if s is None or not math.isfinite(s):
        return "-"
    s = max(0.0, float(s))
    if s < 60:
        return f"{s:.1f} s"
    m, sec = divmod(int(round(s)), 60)
    if m < 60:
        return f"{m} min {sec:02d} s"
    h, m = divmod(m, 60)
    if h < 48:
        return f"{h} h {m:02d} min"
    return f"{h // 24} d {h % 24} h"


def human_time(epoch: float | None, now: float | None = None) -> str:
    """ISO 8601 local time to the second with the time since, e.g. ``2026-11-03 14:02:11+01:00 (5 min 02 s
    ago)``; ``-`` when unknown."""
    if epoch is None or not math.isfinite(epoch):
        return "-"
    now = time.time() if now is None else now
    iso = datetime.fromtimestamp(epoch, tz=timezone.utc).astimezone().isoformat(sep=" ", timespec="seconds")
    ago = now - epoch
    return f"{iso} ({human_duration(ago)} ago)" if ago >= 0 else f"{iso} (in {human_duration(-ago)})"


# ------------------------------------------------------------------------------------ progress in a log file
#: Seconds between two progress lines when stderr is not a terminal (``VFINFER_PROGRESS_INTERVAL`` overrides it;
#: the tests set a fraction of a second).
PROGRESS_INTERVAL_S = 30.0


class ProgressLines:
    """Plain progress lines on stderr for a run whose stderr is not a terminal (a log file, ``nohup``, a batch
    job), where a live bar draws nothing until the end and an hour's run cannot be told from a hang. A thread
    prints the latest state every ``interval`` seconds (``VFINFER_PROGRESS_INTERVAL``, default
    :data:`PROGRESS_INTERVAL_S`), so a line comes even while a long chunk reports nothing; elapsed time moves on
    in each, the simulations only when work is done. On a terminal it prints nothing: the bar is there.

    Use as a context manager; :meth:`update` with the stage, simulations done and expected (None: unknown) and
    the ESS where there is one. A line: ``progress: <stage> · 120/400 simulations · ESS 35.2 · elapsed 1 min
    02 s · about 3 min 05 s left``."""

    def __init__(self, interval: float | None = None, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        if interval is None:
            try:
                interval = float(os.environ.get("VFINFER_PROGRESS_INTERVAL", PROGRESS_INTERVAL_S))
            except ValueError:
                interval = PROGRESS_INTERVAL_S
        self.interval = max(0.05, interval)
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = not (isatty is not None and isatty())
        self.t0 = time.perf_counter()
        self.stage, self.done, self.total, self.ess = "starting", None, None, None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def update(self, stage: str, done: int | None = None, total: int | None = None, ess: float | None = None) -> None:
        self.stage, self.done, self.total, self.ess = stage, done, total, ess

    def line(self) -> str:
        el = time.perf_counter() - self.t0
        parts = [f"progress: {self.stage}"]
        done, total = self.done, self.total
        if done is not None:
            parts.append(f"{done:,}/{total:,} simulations" if total else f"{done:,} simulations")
        if self.ess is not None and self.ess == self.ess:
            parts.append(f"ESS {self.ess:.1f}")
        parts.append(f"elapsed {human_duration(el)}")
        if done and total and total > done:
            parts.append(f"about {human_duration(el / done * (total - done))} left")
        return " · ".join(parts)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            print(self.line(), file=self.stream, flush=True)

    def __enter__(self) -> ProgressLines:
        if self.enabled:
            self._thread = threading.Thread(target=self._run, name="vfinfer-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
