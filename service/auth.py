"""API keys: each belongs to one project; only their SHA-256 is stored.

A key is ``lcv_`` and 43 URL-safe characters (256 random bits), so a plain SHA-256 is a
sufficient one-way store (a slow password hash protects guessable secrets, not these) and
lets a request find its key with one indexed lookup. The first characters are kept as the
key's visible prefix, to tell keys apart when revoking.
"""

from __future__ import annotations

import hashlib
import secrets
from typing import Final

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from loceval.errors import InputError
from service.db import ApiKey, Project, utcnow

__all__ = ["KEY_PREFIX", "authenticate", "bootstrap", "create_key", "hash_key", "revoke_key"]

KEY_PREFIX: Final = "lcv_"
_SHOWN: Final = 12


def hash_key(key: str) -> str:
    """Return the stored form of a key."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def create_key(session: Session, project_name: str) -> str:
    """Create a key for a project (created if new); return the key, shown only now.

    Raises:
        InputError: the project name is empty or too long.
    """
    name = project_name.strip()
    if not name or len(name) > 200:
        msg = f"A project name needs 1 to 200 characters, got {project_name!r}."
        raise InputError(msg)
    project = session.scalar(select(Project).where(Project.name == name))
    if project is None:
        project = Project(name=name)
        session.add(project)
        session.flush()
    key = KEY_PREFIX + secrets.token_urlsafe(32)
    session.add(ApiKey(project_id=project.id, prefix=key[:_SHOWN], key_hash=hash_key(key)))
    session.commit()
    return key


def revoke_key(session: Session, key_or_prefix: str) -> int:
    """Revoke a key given whole or by its visible prefix; return how many were revoked.

    Raises:
        InputError: nothing matches, or a prefix matches several keys.
    """
    text = key_or_prefix.strip()
    if len(text) > _SHOWN:
        condition = ApiKey.key_hash == hash_key(text)
    elif len(text) >= len(KEY_PREFIX) + 4:
        condition = ApiKey.prefix == text
    else:
        msg = f"Give the key or its first {_SHOWN} characters (like lcv_AbCd1234), not {text!r}."
        raise InputError(msg)
    keys = session.scalars(select(ApiKey).where(condition, ApiKey.revoked_at.is_(None))).all()
    if not keys:
        msg = f"No active key matches {text!r}; it is unknown or already revoked."
        raise InputError(msg)
    if len(keys) > 1:
        msg = f"{len(keys)} keys start with {text!r}; give the whole key."
        raise InputError(msg)
    session.execute(update(ApiKey).where(ApiKey.id == keys[0].id).values(revoked_at=utcnow()))
    session.commit()
    return 1


def bootstrap(session: Session) -> str | None:
    """On an empty database, create the project ``default`` and return its first key."""
    if session.scalar(select(func.count()).select_from(Project)):
        return None
    return create_key(session, "default")


def authenticate(session: Session, key: str) -> str | None:
    """Return the project id of an active key, or None."""
    if not key.startswith(KEY_PREFIX) or len(key) > 200:
        return None
    return session.scalar(
        select(ApiKey.project_id).where(
            ApiKey.key_hash == hash_key(key), ApiKey.revoked_at.is_(None)
        )
    )
