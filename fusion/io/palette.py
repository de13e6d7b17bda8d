"""One colour per role, used by every view of a recording (trajectories and time series alike),
so a colour means the same thing everywhere. RGBA, 0-255."""

from __future__ import annotations

ROLE_COLOURS: dict[str, tuple[int, int, int, int]] = {
    "truth": (40, 170, 70, 255),  # green
    "measurement": (120, 120, 120, 255),  # grey: a measurement nobody used
    "associated": (255, 140, 0, 255),  # orange: the measurement that updated a track
    "clutter": (190, 190, 190, 110),  # faint grey: unassigned / unexplained returns
    "estimate": (30, 110, 255, 255),  # blue: the posterior
    "prediction": (150, 190, 255, 255),  # light blue: the prior, before the update
    "tentative": (170, 170, 170, 120),  # faint grey: not yet confirmed
    "covariance": (30, 110, 255, 160),  # the estimate's 2-sigma ellipse
    "trail": (30, 110, 255, 70),  # the faint 2-sigma ellipses of earlier steps
    "smoothed": (0, 160, 150, 255),  # teal: the RTS smoother's estimate (fusion replay --smooth)
    "smoothed_bound": (110, 200, 190, 255),  # its +-2 sigma band
    "bound": (90, 90, 90, 255),  # dark grey: +-2 sigma bands, chi-square bounds
    "nis": (150, 60, 200, 255),  # purple
    "nees": (220, 50, 50, 255),  # red
    "start": (25, 25, 25, 255),  # near black: not the truth's green (a start marker read as the truth)
    "end": (220, 50, 50, 255),
}
# Several components of one quantity (x, vx, y, ...; IMM models): distinct, in a fixed order.
SERIES_COLOURS: tuple[tuple[int, int, int, int], ...] = (
    (31, 119, 180, 255), (255, 127, 14, 255), (44, 160, 44, 255), (214, 39, 40, 255), (148, 103, 189, 255),
    (140, 86, 75, 255), (227, 119, 194, 255), (127, 127, 127, 255), (188, 189, 34, 255), (23, 190, 207, 255),
)


def colour(role: str) -> tuple[int, int, int, int]:
    """The colour of `role` (KeyError for an unknown role: every role is in the table)."""
    return ROLE_COLOURS[role]


def series_colours(n: int) -> list[tuple[int, int, int, int]]:
    """n distinct colours for the components of one quantity (repeating past ten)."""
    return [SERIES_COLOURS[i % len(SERIES_COLOURS)] for i in range(n)]
