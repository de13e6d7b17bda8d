"""Time: integer nanoseconds everywhere, turned into seconds here and only here."""

from __future__ import annotations

from fusion.errors import TimeError

NS_PER_S = 1_000_000_000


def dt_seconds(t_from_ns: int, t_to_ns: int) -> float:
    """dt_s = (t_to_ns - t_from_ns) / 1e9, refused when negative.

    The difference is taken in integers first, so epoch-sized timestamps lose no precision.
    """
    d = int(t_to_ns) - int(t_from_ns)
    if d < 0:
        raise TimeError(
            f"negative time step: from t_ns={t_from_ns} to t_ns={t_to_ns} ({d} ns); "
            "a filter never goes back in time"
        )
    return d / NS_PER_S


def seconds_to_ns(t_s: float) -> int:
    """Round seconds to the nearest integer nanosecond."""
    return round(t_s * NS_PER_S)
