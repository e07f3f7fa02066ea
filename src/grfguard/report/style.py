"""Colours and labels shared by the matplotlib figures and the HTML report.

One colour per *signal type*, the same in every figure (Okabe-Ito palette, readable
by colour-blind readers and in greyscale print).
"""

from __future__ import annotations

__all__ = ["SIGNAL_COLORS", "SIGNAL_LABELS", "FAULT_SHADE", "CONTACT_SHADE", "ALARM_COLOR"]

#: Line colour of each signal type.
SIGNAL_COLORS: dict[str, str] = {
    "measured": "#E69F00",  # orange: what the sensor says
    "true": "#000000",  # black: simulation truth
    "vfs": "#0072B2",  # blue: virtual force sensor
    "recovered": "#009E73",  # green: recovered signal
    "eta": "#D55E00",  # vermilion: estimated fault (filtered)
    "residual": "#F0B27A",  # light orange: unfiltered fault estimate
    "fault": "#000000",  # black dashed: injected fault truth
    "flag": "#AA3377",  # purple: detection flag
}

#: Legend label of each signal type.
SIGNAL_LABELS: dict[str, str] = {
    "measured": "measured",
    "true": "true",
    "vfs": "VFS",
    "recovered": "recovered",
    "eta": "estimated fault",
    "residual": "unfiltered estimate",
    "fault": "true fault",
    "flag": "flag",
}

#: Fill colour of injected fault windows (RGBA hex with alpha).
FAULT_SHADE = "rgba(213, 94, 0, 0.13)"
#: Fill colour of planned stance (foot contact) phases.
CONTACT_SHADE = "rgba(86, 180, 233, 0.45)"
#: Colour of alarm onset marks.
ALARM_COLOR = "#CC3311"


def rgba_to_mpl(rgba: str) -> tuple[float, float, float, float]:
    """Convert ``"rgba(r, g, b, a)"`` (0-255, alpha 0-1) to a matplotlib RGBA tuple."""
    inner = rgba[rgba.index("(") + 1 : rgba.index(")")]
    r, g, b, a = (float(v) for v in inner.split(","))
    return (r / 255.0, g / 255.0, b / 255.0, a)
