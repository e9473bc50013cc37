"""Short-lived signed links: how a browser opens the HTML pages of a service whose API takes bearer tokens.

A browser cannot send an ``Authorization`` header on a plain link, so a bearer-authenticated request
(``POST /jobs/{id}/report-link``, ``POST /page-link``) asks for a link that carries its own proof:
``?exp=<epoch s>&sig=<HMAC-SHA256>``. The MAC covers a fixed prefix, the *scope* (the one page the link
opens: ``report/<job id>`` or ``jobs/<user>``) and the expiry, under a server secret
(``VFINFER_LINK_SECRET``; a random one per process when unset, so links then die with a restart). A link
therefore opens exactly one page, for a few minutes, and no edit of its job id, user or expiry survives
verification; signatures are compared with ``hmac.compare_digest``. A link cannot be revoked before it
expires except by changing the secret, which is why it is short-lived.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Annotated
from urllib.parse import urlencode

from fastapi import Depends, HTTPException, Query, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .api_models import LinkOut
from .deps import get_settings, get_user
from .settings import Settings

#: Bound into every MAC, so a signature made for anything else with the same secret never verifies here.
_PREFIX = b"vfinfer-link-v1\n"
#: base64url of a 32-byte SHA-256 MAC, unpadded.
_SIG_RE = re.compile(r"^[A-Za-z0-9_-]{43}$")


class LinkError(Exception):
    """A signed link that does not open its page; the message is one line meant for the person holding it."""


def _b64(raw: bytes) -> str:
    return base64.urlsafe_b64encode(raw).rstrip(b"=").decode("ascii")


def _utc(epoch: float) -> str:
    return datetime.fromtimestamp(epoch, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


@dataclass(frozen=True)
class SignedLink:
    path: str  # relative to the service, query included
    expires: int  # epoch seconds
    ttl_s: int


class Signer:
    """Makes and checks signed links under one secret; ``ttl_s`` is how long a new link stays valid."""

    def __init__(self, secret: bytes, ttl_s: int = 300):
        if len(secret) < 16:
            raise ValueError("the link secret must have at least 16 bytes")
        self._key = secret
        self.ttl_s = int(ttl_s)

    @classmethod
    def from_settings(cls, s: Settings) -> Signer:
        """The configured secret, or 32 random bytes when none is (links then hold until a restart)."""
        configured = s.link_secret.get_secret_value().encode() if s.link_secret is not None else None
        return cls(configured or secrets.token_bytes(32), s.link_ttl_s)

    def _mac(self, scope: str, exp: int) -> str:
        return _b64(hmac.new(self._key, _PREFIX + f"{scope}\n{exp}".encode(), hashlib.sha256).digest())

    def sign(self, scope: str, path: str, extra: dict[str, str] | None = None, now: float | None = None) -> SignedLink:
        """A link to ``path`` (whose own query is ``extra``) that opens the page of ``scope`` until ``now + ttl``."""
        exp = int(time.time() if now is None else now) + self.ttl_s
        query = urlencode({**(extra or {}), "exp": exp, "sig": self._mac(scope, exp)})
        return SignedLink(path=f"{path}?{query}", expires=exp, ttl_s=self.ttl_s)

    def verify(self, scope: str, exp: int | None, sig: str | None, now: float | None = None) -> None:
        """Nothing when ``sig`` is this server's signature of ``scope`` until ``exp`` and ``exp`` lies ahead;
        :class:`LinkError` otherwise. The signature is checked first, so an edited expiry reads as tampering."""
        if exp is None or sig is None:
            raise LinkError("incomplete signed link: it needs both exp and sig; ask for a new link")
        if not _SIG_RE.match(sig) or not hmac.compare_digest(sig.encode(), self._mac(scope, exp).encode()):
            raise LinkError(
                "invalid link signature: the link was altered or was made for another page; ask for a new link"
            )
        if exp <= int(time.time() if now is None else now):
            raise LinkError(f"link expired at {_utc(exp)}; ask for a new link")


def report_scope(job_id: str) -> str:
    return f"report/{job_id}"


def jobs_scope(user: str) -> str:
    return f"jobs/{user}"


# ------------------------------------------------------------------------------------ FastAPI dependencies
def get_signer(request: Request) -> Signer:
    return request.app.state.signer


#: The same scheme as every API endpoint's, but optional: a page also opens with a signed link.
_optional_bearer = HTTPBearer(auto_error=False, description="per-user bearer token (VFINFER_TOKENS)")
SignerDep = Annotated[Signer, Depends(get_signer)]
Exp = Annotated[
    int | None,
    Query(ge=0, le=2**40, description="signed link: expiry, epoch seconds (with sig, instead of a bearer token)"),
]
Sig = Annotated[
    str | None,
    Query(
        max_length=64,
        description="signed link: HMAC-SHA256 of the page and exp "
        "(from POST /jobs/{id}/report-link or POST /page-link)",
    ),
]


def bearer_user(
    settings: Annotated[Settings, Depends(get_settings)],
    cred: Annotated[HTTPAuthorizationCredentials | None, Depends(_optional_bearer)],
) -> str | None:
    """The token's user when an ``Authorization`` header is sent (401 if it is wrong), else None."""
    return None if cred is None else get_user(settings, cred)


OptionalUserDep = Annotated[str | None, Depends(bearer_user)]


def link_refused(exc: LinkError) -> HTTPException:
    return HTTPException(status.HTTP_403_FORBIDDEN, str(exc))


def link_out(request: Request, link: SignedLink) -> LinkOut:
    return LinkOut(
        url=link.path,
        absolute_url=str(request.base_url).rstrip("/") + link.path,
        expires=link.expires,
        expires_in_s=link.ttl_s,
    )
