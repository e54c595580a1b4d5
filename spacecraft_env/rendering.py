"""Frames of the flexible spacecraft for ``render_mode="rgb_array"``/``"human"``.

Two views side by side: looking along roll (y-z plane: hub, the two solar
paddles and their out-of-plane bending, rotated by the roll angle) and
looking along pitch (x-z plane: hub, the two antenna reflectors, rotated by
the pitch angle). Deflections are drawn exaggerated (gain printed on the
frame); docked modules appear above and below the hub. A status strip shows
time, scenario, attitude angles and paddle angle.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from spacecraft_env.dynamics import FlexibleSpacecraftModel
from spacecraft_env.modes import cantilever_mode_shape

__all__ = ["SpacecraftRenderer"]

_W, _H, _STRIP = 720, 400, 70
_BG, _HUB, _PADDLE, _ANTENNA, _MODULE, _TEXT = (
    (12, 16, 32), (190, 190, 200), (70, 120, 230), (230, 180, 60), (150, 110, 200), (230, 230, 230))
#: Height (m) a docked module reaches from the hub's centre: the panels leave room for it.
_MODULE_REACH_M = 4.7


class SpacecraftRenderer:
    """Draws RGB frames of the spacecraft state.

    Parameters
    ----------
    model : FlexibleSpacecraftModel
        The truth model (geometry, mode slices).
    deflection_gain : float
        Exaggeration of appendage deflections in the drawing.
    """

    def __init__(self, model: FlexibleSpacecraftModel, deflection_gain: float = 300.0) -> None:
        self.gain = float(deflection_gain)
        self._xi = np.linspace(0.0, 1.0, 16)
        self._shapes = [cantilever_mode_shape(self._xi, a.n_modes) / np.sqrt(a.mass)
                        for a in model.params.appendages]
        self._window = None

    @staticmethod
    def _rotate(points: np.ndarray, angle: float) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        return points @ np.array([[c, s], [-s, c]])

    def _panel(self, draw: ImageDraw.ImageDraw, origin: tuple[float, float], scale: float,
               angle: float, items: list[tuple[np.ndarray, tuple, int]]) -> None:
        ox, oy = origin
        for pts, color, width in items:
            p = self._rotate(pts, angle) * scale
            xy = [(ox + u, oy - v) for u, v in p]
            if len(xy) == 4 and width == 0:
                draw.polygon(xy, fill=color)
            else:
                draw.line(xy, fill=color, width=width, joint="curve")

    def draw(self, x: np.ndarray, t: float, model: FlexibleSpacecraftModel,
             reference: np.ndarray) -> np.ndarray:
        """Return a ``(400, 720, 3)`` uint8 frame of state ``x`` at time ``t`` (s).

        Returns
        -------
        (400, 720, 3) uint8 ndarray
            The frame.
        """
        img = Image.new("RGB", (_W, _H), _BG)
        draw = ImageDraw.Draw(img)
        cfg = model.configuration(t)
        psi = x[:3]
        hub = np.array([[-1.2, -1.5], [1.2, -1.5], [1.2, 1.5], [-1.2, 1.5]])
        views = {"y": [], "x": []}
        for a, sl, shape in zip(model.params.appendages, model._mode_slices, self._shapes,
                                strict=True):
            w = shape @ x[sl] * self.gain                     # deflection along the span
            span = np.asarray(a.span_axis) * a.length
            root = np.asarray(a.hinge)
            if a.rotates:
                axis, col = "y", _PADDLE
                along = root[1] + self._xi * span[1]
                pts = np.column_stack([along, root[2] + w])
                width = int(4 + 8 * abs(np.sin(cfg.paddle_angle + 0.36)))
            else:
                axis, col = "x", _ANTENNA
                along = root[0] + self._xi * span[0]
                pts = np.column_stack([along, root[2] + w])
                width = 5
            views[axis].append((pts, col, width))
        modules = [np.array([[-1.1, 0], [1.1, 0], [1.1, 0], [-1.1, 0]]) +
                   np.array([0, m.position[2] - 1.5 * np.sign(m.position[2])]) +
                   np.array([[0, 0], [0, 0], [0, 3 * np.sign(m.position[2])],
                             [0, 3 * np.sign(m.position[2])]])
                   for m in cfg.modules]
        panel_w = _W / 2
        scale = (panel_w - 30) / 20.0
        cy = (_H - _STRIP) / 2 + 10
        for i, (axis, angle, title) in enumerate(
                (("y", psi[0], "view along roll (y-z): solar paddles"),
                 ("x", psi[1], "view along pitch (x-z): antennas"))):
            items = [(m, _MODULE, 0) for m in modules] + [(hub, _HUB, 0)] + views[axis]
            # zoom in on the short antennas, but keep a docked module (up to 4.5 m above
            # or below the hub's centre) and the appendages inside the panel
            reach_z = max(_MODULE_REACH_M, *(np.abs(pts[:, 1]).max() for pts, _, _ in items))
            reach_y = max(np.abs(pts[:, 0]).max() for pts, _, _ in items)
            zoom = min(scale * (1.0 if i == 0 else 2.5), (cy - 28) / reach_z,
                       (panel_w / 2 - 12) / reach_y)
            self._panel(draw, (panel_w * (i + 0.5), cy), zoom, angle, items)
            draw.text((panel_w * i + 10, 8), title, fill=_TEXT)
        draw.line([(panel_w, 0), (panel_w, _H - _STRIP)], fill=(60, 60, 80))
        deg = np.rad2deg(psi)
        err = np.rad2deg(psi - reference)
        y0 = _H - _STRIP + 6
        draw.rectangle([(0, _H - _STRIP), (_W, _H)], fill=(25, 30, 50))
        draw.text((10, y0), f"t = {t:6.1f} s   scenario: {model.scenario.name}   "
                            f"docked modules: {len(cfg.modules)}   paddle angle: "
                            f"{np.rad2deg(cfg.paddle_angle):5.1f} deg   deflection x{self.gain:g}",
                  fill=_TEXT)
        draw.text((10, y0 + 20), f"attitude (deg): roll {deg[0]:+7.3f}  pitch {deg[1]:+7.3f}  "
                                 f"yaw {deg[2]:+7.3f}", fill=_TEXT)
        draw.text((10, y0 + 40), f"error    (deg): roll {err[0]:+7.3f}  pitch {err[1]:+7.3f}  "
                                 f"yaw {err[2]:+7.3f}", fill=_TEXT)
        # yaw indicator: a needle in the strip
        cx, cyy, r = _W - 40, _H - _STRIP / 2, 25
        draw.ellipse([(cx - r, cyy - r), (cx + r, cyy + r)], outline=_TEXT)
        ang = psi[2] * 10.0  # x10 so degrees are visible
        draw.line([(cx, cyy), (cx + r * np.sin(ang), cyy - r * np.cos(ang))], fill=_PADDLE,
                  width=3)
        draw.text((cx - 34, cyy - r - 12), "yaw x10", fill=_TEXT)
        return np.asarray(img)

    def show(self, frame: np.ndarray, fps: float) -> None:
        """Display ``frame`` in a matplotlib window (``render_mode="human"``)."""
        import matplotlib.pyplot as plt

        if self._window is None:
            plt.ion()
            fig, ax = plt.subplots(figsize=(7.2, 4.0))
            ax.set_axis_off()
            self._window = (fig, ax.imshow(frame))
        else:
            self._window[1].set_data(frame)
        self._window[0].canvas.draw_idle()
        plt.pause(1.0 / fps)

    def close(self) -> None:
        """Close the human-mode window, if any."""
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
