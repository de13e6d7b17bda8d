"""Asking a running service: its status and its snapshot of confirmed tracks (Zenoh queries).

The service answers on `fusion/<ns>/status` (ServiceStatus) and `fusion/<ns>/snapshot`
(Snapshot, the latest estimate of every confirmed track); see fusion.service. Both come back
msgpack-encoded; a reply that does not decode raises MessageError, no reply within the timeout
raises NoAnswerError.
"""

from __future__ import annotations

from typing import Any

from fusion import messages as m
from fusion.errors import FusionError


class NoAnswerError(FusionError):
    """No service answered the query within the timeout."""


def _ask(session: Any, key: str, timeout_s: float) -> bytes:
    replies = session.get(key, timeout=timeout_s)
    errors = []
    for reply in replies:
        if reply.ok is not None:
            return bytes(reply.ok.payload.to_bytes())
        errors.append(reply.err.payload.to_string())
    if errors:
        raise NoAnswerError(f"{key}: the service replied with an error: {errors[0]}")
    raise NoAnswerError(f"no fusion service answered on {key} within {timeout_s:g} s")


def query_status(session: Any, namespace: str, *, timeout_s: float = 2.0) -> m.ServiceStatus:
    """The status of the service on `namespace`."""
    return m.decode_status(_ask(session, m.status_key(namespace), timeout_s))


def query_snapshot(session: Any, namespace: str, *, timeout_s: float = 2.0) -> m.Snapshot:
    """The latest estimate of every confirmed track of the service on `namespace`."""
    return m.decode_snapshot(_ask(session, m.snapshot_key(namespace), timeout_s))
