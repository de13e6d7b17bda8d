"""Human forms shared by the recording, `fusion inspect` and the CLI's text output: short track
labels and the reading of sensor times (no rerun import here).

Track ids are 63-bit hashes (fusion.tracking.trackset.track_id_for), unreadable at 19 digits.
A label is the id's top 30 bits in Crockford base 32: six characters, stable (a function of the
id alone), and with 1000 live tracks two share a label with probability about 1000^2 / 2^31
= 0.05 %. The full id stays in every record next to its label.
"""

from __future__ import annotations

from functools import lru_cache

_CROCKFORD = "0123456789abcdefghjkmnpqrstvwxyz"
EPOCH_NS = 10**17  # sensor times from about 1973 on are epoch times; below are stream-relative


@lru_cache(maxsize=65536)
def short_id(track_id: int) -> str:
    """Six base-32 characters of the id's top 30 bits (of 63): 'k3x9qa'."""
    v = (int(track_id) >> 33) & ((1 << 30) - 1)
    return "".join(_CROCKFORD[(v >> s) & 31] for s in (25, 20, 15, 10, 5, 0))


def is_epoch(t_ns: int) -> bool:
    """True for epoch times (real dates), False for stream-relative times (seconds from a start)."""
    return int(t_ns) >= EPOCH_NS
