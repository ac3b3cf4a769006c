"""Pictures of the environments, drawn with plain NumPy, and the matplotlib window of "human".

Internal: the environments call `point_mass_frame` or `state_bars_frame` for ``"rgb_array"``
and show the same frames in a `HumanViewer` for ``"human"``. Nothing here imports matplotlib
until a ``"human"`` environment is built.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

import fuzzyq

Frame = npt.NDArray[np.uint8]
Colour = tuple[int, int, int]

#: The render modes of every fuzzyq environment.
RENDER_MODES = ["human", "rgb_array", "ansi"]

#: Side of the square point-mass picture, in pixels (even, as video encoders want).
FRAME_SIZE = 400
#: Blank border around the arena, in pixels.
MARGIN = 20
#: Radius of an agent's disc, in pixels.
AGENT_RADIUS = 7
#: Length of the velocity tick at full speed (``velocity_limit``), beyond the disc, in pixels.
TICK_LENGTH = 18
#: Smallest radius of the drawn goal region, in pixels (the paper's 0.1 m is ~3 px).
MIN_GOAL_RADIUS = 5

BACKGROUND: Colour = (255, 255, 255)
ARENA: Colour = (244, 244, 244)
ARENA_BORDER: Colour = (60, 60, 60)
AXES: Colour = (222, 222, 222)
GOAL: Colour = (190, 235, 190)
GOAL_BORDER: Colour = (44, 160, 44)
TRACK: Colour = (170, 170, 170)
TERMINAL_BORDER: Colour = (255, 0, 0)

#: Agent colours (matplotlib's tab10 without its green, which marks the goal); agents beyond
#: the ninth reuse them.
AGENT_COLOURS: list[Colour] = [
    (31, 119, 180),
    (255, 127, 14),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
]


def agent_colour(i: int) -> Colour:
    """The fill colour of agent `i`."""
    return AGENT_COLOURS[i % len(AGENT_COLOURS)]


def tick_colour(i: int) -> Colour:
    """The colour of agent `i`'s velocity tick: its fill colour, darkened."""
    r, g, b = agent_colour(i)
    return (r // 2, g // 2, b // 2)


# --- raster primitives (all clip to the image) --------------------------------------------------


def fill_rect(img: Frame, r0: int, r1: int, c0: int, c1: int, colour: Colour) -> None:
    """Fills rows ``r0..r1`` and columns ``c0..c1`` (inclusive)."""
    h, w = img.shape[:2]
    r0, r1, c0, c1 = max(r0, 0), min(r1, h - 1), max(c0, 0), min(c1, w - 1)
    if r0 <= r1 and c0 <= c1:
        img[r0 : r1 + 1, c0 : c1 + 1] = colour


def fill_disc(
    img: Frame, row: float, col: float, radius: float, colour: Colour, inner: float = -1.0
) -> None:
    """Fills the pixels whose centres lie within `radius` of (row, col) and beyond `inner`."""
    h, w = img.shape[:2]
    r0, r1 = max(int(np.floor(row - radius)), 0), min(int(np.ceil(row + radius)), h - 1)
    c0, c1 = max(int(np.floor(col - radius)), 0), min(int(np.ceil(col + radius)), w - 1)
    if r0 > r1 or c0 > c1:
        return
    rows, cols = np.ogrid[r0 : r1 + 1, c0 : c1 + 1]
    d2 = (rows - row) ** 2 + (cols - col) ** 2
    mask = d2 <= radius**2
    if inner >= 0.0:
        mask &= d2 > inner**2
    img[r0 : r1 + 1, c0 : c1 + 1][mask] = colour


def draw_line(
    img: Frame, p0: tuple[float, float], p1: tuple[float, float], colour: Colour, width: float
) -> None:
    """A segment from `p0` to `p1` ((row, col) pairs) of about `width` pixels."""
    n = int(np.ceil(max(abs(p1[0] - p0[0]), abs(p1[1] - p0[1])))) + 1
    for t in np.linspace(0.0, 1.0, n):
        fill_disc(img, p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]), width / 2, colour)


def blank(height: int, width: int) -> Frame:
    """A new white image."""
    img = np.empty((height, width, 3), dtype=np.uint8)
    img[:] = BACKGROUND
    return img


# --- the point-mass arena -----------------------------------------------------------------------


def arena_to_pixel(
    x: float, y: float, position_limit: float, size: int = FRAME_SIZE
) -> tuple[float, float]:
    """The (row, col) pixel of arena point (x, y): the arena ``[-limit, limit]^2`` fills the
    picture but for a `MARGIN`, with y pointing up."""
    scale = (size - 1 - 2 * MARGIN) / (2.0 * position_limit)
    return MARGIN + (position_limit - y) * scale, MARGIN + (x + position_limit) * scale


def point_mass_frame(model: fuzzyq.PointMass, state: npt.NDArray[np.float64]) -> Frame:
    """The ``"rgb_array"`` picture of a point-mass state: a ``(400, 400, 3)`` uint8 image.

    The arena (the position limits) is the grey square, the goal region the green disc at the
    origin (drawn at least `MIN_GOAL_RADIUS` pixels wide), and agent `i` a disc of colour
    ``AGENT_COLOURS[i]`` with a darker tick pointing along its velocity, longer the faster it
    moves (`TICK_LENGTH` pixels beyond the disc at ``velocity_limit``).
    """
    size, limit = FRAME_SIZE, model.position_limit
    img = blank(size, size)
    lo, hi = MARGIN, size - 1 - MARGIN
    fill_rect(img, lo - 2, hi + 2, lo - 2, hi + 2, ARENA_BORDER)
    fill_rect(img, lo, hi, lo, hi, ARENA)
    centre_row, centre_col = arena_to_pixel(0.0, 0.0, limit)
    fill_rect(img, round(centre_row), round(centre_row), lo, hi, AXES)
    fill_rect(img, lo, hi, round(centre_col), round(centre_col), AXES)
    scale = (size - 1 - 2 * MARGIN) / (2.0 * limit)
    goal = max(model.goal_radius * scale, MIN_GOAL_RADIUS)
    fill_disc(img, centre_row, centre_col, goal, GOAL)
    fill_disc(img, centre_row, centre_col, goal, GOAL_BORDER, inner=goal - 1.5)
    for i, (sx, sy, vx, vy) in enumerate(np.asarray(state, dtype=np.float64).reshape(-1, 4)):
        row, col = arena_to_pixel(float(sx), float(sy), limit)
        speed = float(np.hypot(vx, vy))
        if speed > 0.0:  # the tick: from the centre, so that the disc hides its root
            # Image rows grow downwards: a positive vy points up.
            d_row, d_col = -vy / speed, vx / speed
            length = AGENT_RADIUS + TICK_LENGTH * min(speed / model.velocity_limit, 1.0)
            end = (row + d_row * length, col + d_col * length)
            draw_line(img, (row, col), end, tick_colour(i), 3.0)
        fill_disc(img, row, col, AGENT_RADIUS, agent_colour(i))
    return img


# --- the Khepera arena ---------------------------------------------------------------------------

#: Colour of the arena's obstacles.
OBSTACLE: Colour = (120, 120, 120)


def _obstacle_mask(
    obstacle: dict[str, Any], x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """Which arena points (x, y) lie inside `obstacle` (a ``box`` or a ``disc``)."""
    cx, cy = obstacle["center"]
    if obstacle["shape"] == "disc":
        return np.asarray((x - cx) ** 2 + (y - cy) ** 2 <= obstacle["radius"] ** 2)
    a = np.radians(obstacle.get("angle_deg", 0.0))
    u = (x - cx) * np.cos(a) + (y - cy) * np.sin(a)
    v = -(x - cx) * np.sin(a) + (y - cy) * np.cos(a)
    hx, hy = obstacle["half_extents"]
    return np.asarray((np.abs(u) <= hx) & (np.abs(v) <= hy))


def khepera_frame(params: dict[str, Any], poses: npt.NDArray[np.float64]) -> Frame:
    """The ``"rgb_array"`` picture of the Khepera robots: a ``(400, 400, 3)`` uint8 image.

    The arena (walls at ``params["arena"]``'s ``x`` and ``y``, square pixels) is grey with its
    obstacles darker, the reward region the green disc at the origin, and robot `i` a disc of
    its true radius (at least `AGENT_RADIUS` pixels) in ``AGENT_COLOURS[i]`` with a darker
    tick along its heading.
    """
    arena = params["arena"]
    (x0, x1), (y0, y1) = arena["x"], arena["y"]
    size = FRAME_SIZE
    scale = (size - 1 - 2 * MARGIN) / max(x1 - x0, y1 - y0)
    img = blank(size, size)

    def pixel(x: float, y: float) -> tuple[float, float]:
        return MARGIN + (y1 - y) * scale, MARGIN + (x - x0) * scale

    top, left = pixel(x0, y1)
    bottom, right = pixel(x1, y0)
    fill_rect(img, round(top) - 2, round(bottom) + 2, round(left) - 2, round(right) + 2, ARENA_BORDER)
    fill_rect(img, round(top), round(bottom), round(left), round(right), ARENA)
    rows, cols = np.mgrid[0:size, 0:size]
    ax, ay = x0 + (cols - MARGIN) / scale, y1 - (rows - MARGIN) / scale
    for obstacle in arena.get("obstacle", []):
        img[_obstacle_mask(obstacle, ax, ay)] = OBSTACLE
    centre = pixel(0.0, 0.0)
    goal = max(params["goal_radius"] * scale, MIN_GOAL_RADIUS)
    fill_disc(img, *centre, goal, GOAL)
    fill_disc(img, *centre, goal, GOAL_BORDER, inner=goal - 1.5)
    radius = max(params["radius"] * scale, AGENT_RADIUS)
    for i, (x, y, heading) in enumerate(np.asarray(poses, dtype=np.float64).reshape(-1, 3)):
        row, col = pixel(float(x), float(y))
        fill_disc(img, row, col, radius, agent_colour(i))
        tip = (row - np.sin(heading) * radius, col + np.cos(heading) * radius)
        draw_line(img, (row, col), tip, tick_colour(i), 3.0)
    return img


# --- any other model: one gauge per state variable ------------------------------------------------

#: Height of one state variable's gauge, in pixels.
GAUGE_HEIGHT = 40
#: Radius of a gauge's marker, in pixels.
MARKER_RADIUS = 8


def gauge_fraction(value: float, low: float, high: float) -> float:
    """Where `value` sits on its gauge, in [0, 1]: linear in ``[low, high]`` when both are
    finite, else ``(1 + tanh(value)) / 2`` (0.5 at zero)."""
    if np.isfinite(low) and np.isfinite(high) and high > low:
        return float(np.clip((value - low) / (high - low), 0.0, 1.0))
    return float((1.0 + np.tanh(value)) / 2.0)


def state_bars_frame(
    state: npt.NDArray[np.float64], low: Sequence[float], high: Sequence[float], done: bool
) -> Frame:
    """The ``"rgb_array"`` picture of any model's state: a ``(40 * state_dim + 20, 400, 3)``
    uint8 image with one horizontal gauge per state variable.

    Variable `d` is a marker of colour ``AGENT_COLOURS[d]`` on a grey track spanning its
    bounds (a short dark notch marks zero when it lies within them); an unbounded variable
    sits at ``(1 + tanh(x_d)) / 2`` of its track. The border turns red in a terminal state.
    """
    width, dims = FRAME_SIZE, len(state)
    height = GAUGE_HEIGHT * dims + 2 * (MARGIN // 2)
    img = blank(height, width)
    if done:
        fill_rect(img, 0, height - 1, 0, width - 1, TERMINAL_BORDER)
        fill_rect(img, 4, height - 5, 4, width - 5, BACKGROUND)
    lo_col, hi_col = MARGIN, width - 1 - MARGIN
    for d, value in enumerate(state):
        row = MARGIN // 2 + GAUGE_HEIGHT * d + GAUGE_HEIGHT // 2
        fill_rect(img, row - 1, row + 1, lo_col, hi_col, TRACK)
        zero = gauge_fraction(0.0, low[d], high[d])
        if low[d] <= 0.0 <= high[d] or not (np.isfinite(low[d]) and np.isfinite(high[d])):
            zc = round(lo_col + zero * (hi_col - lo_col))
            fill_rect(img, row - 6, row + 6, zc - 1, zc + 1, ARENA_BORDER)
        frac = gauge_fraction(float(value), low[d], high[d])
        fill_disc(img, row, lo_col + frac * (hi_col - lo_col), MARKER_RADIUS, agent_colour(d))
    return img


# --- "human": a matplotlib window ---------------------------------------------------------------


def require_matplotlib() -> None:
    """Raises a clear ImportError when matplotlib (needed by ``"human"``) is not installed."""
    if importlib.util.find_spec("matplotlib") is None:
        raise ImportError(
            "render_mode='human' needs matplotlib, which is not installed: "
            "pip install matplotlib (or use render_mode='rgb_array')"
        )


class HumanViewer:
    """Shows frames in one matplotlib window, paced at the environment's ``render_fps``."""

    def __init__(self, title: str) -> None:
        require_matplotlib()
        import matplotlib.pyplot as plt

        self._plt: Any = plt
        self._title = title
        self._fig: Any = None
        self._image: Any = None

    def show(self, frame: Frame, fps: float) -> None:
        """Draws `frame`; on an interactive backend waits ``1 / fps`` seconds."""
        plt = self._plt
        if self._fig is None or not plt.fignum_exists(self._fig.number):
            self._fig, ax = plt.subplots(figsize=(frame.shape[1] / 100, frame.shape[0] / 100))
            ax.set_axis_off()
            self._fig.subplots_adjust(0, 0, 1, 1)
            self._image = ax.imshow(frame)
            manager = self._fig.canvas.manager
            if manager is not None:
                manager.set_window_title(self._title)
        else:
            self._image.set_data(frame)
        if getattr(self._fig.canvas, "required_interactive_framework", None) is None:
            # A non-interactive backend (Agg: no display): nothing to show or wait for.
            self._fig.canvas.draw()
        else:
            plt.pause(1.0 / fps)

    def close(self) -> None:
        """Closes the window (a later `show` opens a new one)."""
        if self._fig is not None:
            self._plt.close(self._fig)
            self._fig = None
            self._image = None
