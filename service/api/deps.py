"""Dependencies of the routes: the runtime and the caller's project."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request, Security
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.auth import authenticate
from service.errors import AuthenticationError
from service.runtime import Runtime

__all__ = ["ProjectDep", "RuntimeDep", "get_runtime"]

_bearer = HTTPBearer(
    auto_error=False,
    scheme_name="ApiKey",
    description="An API key: `loceval keys create --project NAME` prints one.",
)


def get_runtime(request: Request) -> Runtime:
    """Return the process's runtime (database, blobs, queue)."""
    runtime: Runtime = request.app.state.runtime
    return runtime


RuntimeDep = Annotated[Runtime, Depends(get_runtime)]


def current_project(
    request: Request,
    runtime: RuntimeDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)],
) -> str:
    """Return the project id of the request's API key.

    Raises:
        AuthenticationError: no Bearer key, or one that is unknown or revoked.
    """
    known = getattr(request.state, "project_id", None)
    if isinstance(known, str):
        return known  # checked by ApiKeyMiddleware before the body was read
    if credentials is None:
        msg = (
            "This endpoint needs an API key: send the header 'Authorization: Bearer KEY' "
            "(loceval keys create --project NAME prints one)."
        )
        raise AuthenticationError(msg)
    with runtime.sessions() as session:
        project_id = authenticate(session, credentials.credentials)
    if project_id is None:
        msg = "The API key is unknown or revoked; ask your administrator for a new one."
        raise AuthenticationError(msg)
    return project_id


ProjectDep = Annotated[str, Depends(current_project)]
