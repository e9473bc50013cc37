"""Diagnoses kept by an earlier release, brought into the job table once, at start-up.

That release ran a diagnosis outside the job table and left its files beside the job's store:
``<job>.diagnosis.json`` and ``.png`` (done), ``.error`` (failed), ``.cancelled``, ``.request.json`` (running
or interrupted: ``{"request", "resumes"}``) and ``.resume/`` (its finished simulations). Each becomes a
diagnosis job with its own store, so nothing of it is lost over the upgrade: a finished one is served as
before, an interrupted one goes on from its simulations (its earlier interruptions counted), and a failed
one's simulations are there for the next request of it.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import time
from pathlib import Path

from pydantic import ValidationError

from . import diagnosis as dg
from .api_models import DiagnoseRequest, DiagnosisSpec
from .db import new_job_id

log = logging.getLogger("vfinfer.manager")

_SUFFIXES = ("json", "png", "error", "cancelled", "request.json", "resume")


def _legacy(stores: Path) -> dict[str, dict[str, Path]]:
    """job id -> {suffix: path} of the legacy files present."""
    found: dict[str, dict[str, Path]] = {}
    for f in stores.glob("*.diagnosis.*"):
        jid, _, rest = f.name.partition(".diagnosis.")
        if len(jid) == 32 and rest in _SUFFIXES:
            found.setdefault(jid, {})[rest] = f
    return found


def _import_one(manager, jid: str, files: dict[str, Path]) -> str | None:
    job = manager.db.get(jid)
    if job is None or job["kind"] != "inference" or manager.db.children(jid):
        return None  # a job that is gone (its diagnosis goes with it), or imported before
    saved, report = {}, None
    try:
        if "request.json" in files:
            saved = json.loads(files["request.json"].read_text())
        if "json" in files:
            report = json.loads(files["json"].read_text())
        request = DiagnoseRequest.model_validate(saved.get("request") or (report or {}).get("request") or {})
    except (OSError, ValueError, ValidationError) as exc:
        log.warning("dropping the unreadable diagnosis of job %s (%s)", jid, exc)
        return None
    diag_id = new_job_id()
    spec = DiagnosisSpec(job=jid, request=request)
    store = manager.store_path(diag_id)
    now = time.time()
    fields: dict = {"started": now}
    if report is not None:
        report.pop("request", None)
        png = files["png"].read_bytes() if "png" in files else None
        clock = dg.write_report(store, diag_id, spec.to_json(), report, png)
        n = int(report.get("n_simulations") or 0)
        fields.update(state="done", finished=now, n_done=n, n_total=n, stats={"clock": clock})
    else:
        from worker.store import create_diagnosis_store

        create_diagnosis_store(store, diag_id, spec.to_json())
        if "resume" in files:
            os.replace(files["resume"], dg.resume_dir(store))
        if "request.json" in files:  # interrupted: goes on, its earlier interruptions counted
            fields.update(state="running", attempts=int(saved.get("resumes", 0)) + 1)
        elif "error" in files:
            fields.update(state="failed", finished=now, error=files["error"].read_text(errors="replace")[:2000])
        else:
            fields.update(state="cancelled", finished=now)
    manager.db.insert(diag_id, job["owner"], spec.to_json(), 0, kind="diagnosis", parent=jid, sampler="smc", model="fe")
    manager.db.update(diag_id, **fields)
    return diag_id


def import_legacy_diagnoses(manager) -> list[str]:
    """Turn every legacy diagnosis beside the stores into a diagnosis job and delete its files; returns the new
    jobs' ids."""
    made = []
    for jid, files in sorted(_legacy(Path(manager.settings.stores_dir)).items()):
        diag_id = _import_one(manager, jid, files)
        if diag_id is not None:
            made.append(diag_id)
        for f in files.values():
            shutil.rmtree(f, ignore_errors=True) if f.is_dir() else f.unlink(missing_ok=True)
    if made:
        log.info("imported %d diagnosis(es) kept by an earlier release", len(made))
    return made
