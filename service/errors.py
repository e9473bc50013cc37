"""422 responses that name the field and never echo the (possibly huge or non-JSON) input."""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse


def _loc(loc) -> str:
    parts = [str(p) for p in loc if p not in ("body",)]
    return ".".join(parts) or "body"


async def validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    detail = []
    for e in exc.errors():
        loc = [p if isinstance(p, (int, str)) else str(p) for p in e.get("loc", ())]
        detail.append({"loc": loc, "field": _loc(loc), "msg": str(e.get("msg", "")), "type": str(e.get("type", ""))})
    message = "; ".join(f"{d['field']}: {d['msg']}" for d in detail[:10])
    return JSONResponse(status_code=422, content={"message": message, "detail": detail[:50]})


def install(app: FastAPI) -> None:
    app.add_exception_handler(RequestValidationError, validation_error)
