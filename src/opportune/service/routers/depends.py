"""What the HTTP service's routers share: who is asking, the run id in a path, the ``Idempotency-Key``
header as the OpenAPI document states it, and answers that a retry gets again byte for byte."""

from __future__ import annotations

from typing import Callable, Optional

from fastapi import Depends, Path as PathParam
from fastapi.responses import Response
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from opportune.limits import MAX_KEY
from opportune.service import idempotency as idem
from opportune.service.auth import Authenticator, Principal
from opportune.service.errors import unauthorized

__all__ = ["IDEMPOTENCY_KEY", "REPLAYED", "RUN_ID", "links", "principal_dependency", "replayable"]

RUN_ID = PathParam(..., ge=1, le=2**62, description="The run's id")

# The Idempotency-Key header as the OpenAPI states it: required.  The route itself reads it as optional, so
# that a request without it gets the service's own 428 (which says what to send), not a validation error.
IDEMPOTENCY_KEY = {"parameters": [{
    "name": idem.HEADER, "in": "header", "required": True,
    "description": "A fresh random string (e.g. a UUID) for every new request, reused when retrying it: a retry "
                   "gets the stored answer, byte for byte, and changes nothing",
    "schema": {"type": "string", "minLength": 1, "maxLength": MAX_KEY, "pattern": idem.KEY_PATTERN}}]}

REPLAYED = {"Idempotent-Replayed": {"description": "`true` when this is the stored answer of an earlier request "
                                                   "with the same key", "schema": {"type": "string", "enum": ["true"]}}}


def links(run_id: str, *op_ids: str) -> dict:
    """OpenAPI links: the run an answer names (``run_id``, a runtime expression) to the operations on it."""
    return {op: {"operationId": op, "parameters": {"run_id": run_id}} for op in op_ids}


def principal_dependency(auth: Authenticator, bearer: HTTPBearer) -> Callable[..., Principal]:
    """The dependency that reads the bearer token and answers who is asking (401 for no token or an
    unknown one)."""

    def principal(creds: Optional[HTTPAuthorizationCredentials] = Depends(bearer)) -> Principal:
        p = auth.token(creds.credentials) if creds and creds.credentials else None
        if p is None:
            raise unauthorized()
        return p

    return principal


def replayable(status: int, text: str, replayed: bool) -> Response:
    """The stored answer of a request that changed a run: the same bytes the first time and on every
    retry (the stored answer is this JSON text), marked ``Idempotent-Replayed`` on a retry."""
    return Response(text, status_code=status, media_type="application/json",
                    headers={"Idempotent-Replayed": "true"} if replayed else None)
