"""Dependencies of the routes: the runtime and the caller's project."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request, Security
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.auth import authenticate
from service.errors import AuthenticationError
from service.runtime import Runtime
from service.schemas.base import NO_NUL

__all__ = ["PathText", "ProjectDep", "RuntimeDep", "get_runtime"]

PathText = Annotated[str, Path(json_schema_extra={"pattern": NO_NUL})]
"""A path parameter (an id, an artifact's name): declared NUL-free, as the server holds it.

:class:`~service.api.middleware.ApiKeyMiddleware` refuses a NUL (``%00``) in any path with
a 422 before a route runs; the pattern says so in the schema, and no route checks it again.
"""

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
