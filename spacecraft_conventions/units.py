"""Angle units. Internally everything is SI (rad, rad/s, m, N m, s).

Two names, one direction each, so a reader never has to guess which way a
``_DEG`` constant converts.
"""

from __future__ import annotations

import math

__all__ = ["DEG_PER_RAD", "RAD_PER_DEG"]

#: Radians in one degree: ``angle_rad = angle_deg * RAD_PER_DEG``.
RAD_PER_DEG: float = math.pi / 180.0
#: Degrees in one radian: ``angle_deg = angle_rad * DEG_PER_RAD``.
DEG_PER_RAD: float = 180.0 / math.pi
