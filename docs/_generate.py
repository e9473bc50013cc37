"""Writes the generated reference pages' sources: the command line (from the typer app) and the REST API
(the OpenAPI document of ``create_app()``), into ``docs/_generated/`` (not committed)."""

import contextlib
import io
import json
import os
from pathlib import Path


def _help(cmd, ctx) -> str:
    """A command's help text: typer's rich formatter prints it rather than returning it."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        text = cmd.get_help(ctx)
    return (buf.getvalue() + text).rstrip()


def cli_markdown() -> str:
    """Every command's ``--help`` text, as the command line prints it at 100 columns."""
    os.environ["COLUMNS"] = "100"
    import click
    import typer

    from service.cli import app

    root = typer.main.get_command(app)
    out = []
    with click.Context(root, info_name="vfinfer") as ctx:
        out += ["## vfinfer", "", "```text", _help(root, ctx), "```", ""]
        for name in sorted(root.list_commands(ctx)):
            cmd = root.get_command(ctx, name)
            with click.Context(cmd, parent=ctx, info_name=name) as sub:
                out += [f"## vfinfer {name}", "", "```text", _help(cmd, sub), "```", ""]
    return "\n".join(out)


def openapi() -> dict:
    from service.main import create_app

    return create_app().openapi()


def rest_markdown(doc: dict) -> str:
    """One row a route: method, path and summary, from the OpenAPI document."""
    rows = ["| method | path | what |", "|---|---|---|"]
    for path, ops in sorted(doc["paths"].items()):
        for method, op in ops.items():
            what = (op.get("summary") or op.get("description") or "").split("\n")[0].replace("|", "\\|")
            rows.append(f"| {method.upper()} | `{path}` | {what} |")
    return "\n".join(rows) + "\n"


def write_all(folder: Path) -> None:
    folder.mkdir(exist_ok=True)
    doc = openapi()
    (folder / "openapi.json").write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    (folder / "rest.md").write_text(rest_markdown(doc))
    (folder / "cli.md").write_text(cli_markdown())
