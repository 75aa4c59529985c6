"""Drawing a cluster: satellites, taut, slack and broken cables, thrust arrows (matplotlib, headless-safe).

The figure, its 3-D axes and every artist are built once; a frame only moves the artists. Off
screen (``rgb_array``), the axes themselves (panes, grid, ticks, labels), which take most of a
full matplotlib draw, are drawn once into a cached background, and a frame pastes that
background back and draws only the cables, satellites, arrows and title over it (blitting).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tether_gym._optional import require
from tether_gym.cluster import Cluster

#: The axis limits follow the cluster's centre of mass in steps of this fraction of the half
#: width (under half a pixel at the figure's size), so that a background drawn once serves
#: until the cluster has drifted by a step, and a frame depends only on the state drawn.
CENTRE_STEP_FRACTION = 1.0 / 200.0

#: Arrow heads as :meth:`mpl_toolkits.mplot3d.axes3d.Axes3D.quiver` draws them by default: two
#: barbs, each this fraction of the arrow's length, turned this angle (rad) off its shaft.
ARROW_HEAD_FRACTION = 0.3
ARROW_HEAD_ANGLE = math.radians(15.0)

TAUT_COLOUR, SLACK_COLOUR, BROKEN_COLOUR, THRUST_COLOUR = "tab:blue", "tab:orange", "0.3", "tab:red"
#: Marker size (points^2) and colour of a tether's beads.
BEAD_SIZE = 4.0
BEAD_COLOUR = "grey"

#: The second line of the title, the key to the colours.
KEY = "blue: taut, orange dashed: slack, grey dotted: broken, red: thrust"


def arrow_segments(tails: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Line segments of 3-D arrows drawn like ``Axes3D.quiver(..., pivot="tail")``.

    Args:
        tails: (k, 3) arrow tails, m.
        vectors: (k, 3) arrow vectors (tip minus tail), m; zero vectors are left out.

    Returns:
        (3 j, 2, 3) segments, m: j shafts (tip to tail), then j left and j right head barbs
        (from the tip), where j is the number of non-zero vectors.
    """
    drawn = np.linalg.norm(vectors, axis=1) > 0
    tails, vectors = tails[drawn], vectors[drawn]
    tips = tails + vectors
    # Barbs: the arrow turned by +-ARROW_HEAD_ANGLE about the horizontal axis perpendicular to
    # it (the rotation quiver uses; about x for a vertical arrow).
    horizontal = np.linalg.norm(vectors[:, :2], axis=1)
    safe = np.where(horizontal > 0, horizontal, 1.0)
    ux = np.where(horizontal > 0, vectors[:, 1] / safe, 0.0)
    uy = np.where(horizontal > 0, -vectors[:, 0] / safe, 1.0)
    c, s = math.cos(ARROW_HEAD_ANGLE), math.sin(ARROW_HEAD_ANGLE)
    rotation = np.empty((vectors.shape[0], 3, 3))
    rotation[:, 0] = np.stack([c + ux**2 * (1 - c), ux * uy * (1 - c), uy * s], axis=1)
    rotation[:, 1] = np.stack([ux * uy * (1 - c), c + uy**2 * (1 - c), -ux * s], axis=1)
    rotation[:, 2] = np.stack([-uy * s, ux * s, np.full_like(ux, c)], axis=1)
    opposite = rotation.copy()
    opposite[:, [0, 1, 2, 2], [2, 2, 0, 1]] *= -1.0  # the sine terms: the turn the other way
    barbs = [np.einsum("kij,kj->ki", r, vectors) for r in (rotation, opposite)]
    shafts = np.stack([tips, tails], axis=1)
    heads = [np.stack([tips, tips - ARROW_HEAD_FRACTION * barb], axis=1) for barb in barbs]
    return np.concatenate([shafts, *heads])


class ClusterRenderer:
    """A 3-D view of one cluster, returned as an RGB array or shown in a window.

    Args:
        cluster: the cluster (for its cables, masses and nominal size).
        max_thrust: thrust drawn as an arrow a quarter of the view's half width long, N.
        human: open a window (``plt.show`` mode) instead of drawing off-screen.
        exaggeration: factor applied to each satellite's displacement from its nominal place
            (in the centre-of-mass frame) so that centimetre vibrations of 100 m cables show.

    Raises:
        MissingExtraError: matplotlib is not installed (the ``plots`` extra).
    """

    def __init__(self, cluster: Cluster, max_thrust: float, human: bool = False, exaggeration: float = 1.0) -> None:
        purpose = f"drawing the env (render_mode={'human' if human else 'rgb_array'!r})"
        matplotlib = require("matplotlib", "plots", purpose)
        if not human:
            matplotlib.use("Agg", force=False)
        self._plt = require("matplotlib.pyplot", "plots", purpose)
        art3d = require("mpl_toolkits.mplot3d.art3d", "plots", purpose)
        agg = require("matplotlib.backends.backend_agg", "plots", purpose)
        figure_module = require("matplotlib.figure", "plots", purpose)

        self.cluster = cluster
        self.max_thrust = max_thrust
        self.human = human
        self.exaggeration = exaggeration
        self.nominal = cluster.positions - cluster.positions.mean(axis=0)
        self.half_width = 0.75 * float(np.ptp(cluster.positions, axis=0).max()) + 1.0
        self.centre = cluster.positions.mean(axis=0)
        self._centre_step = CENTRE_STEP_FRACTION * self.half_width
        self._arrow_scale = 0.25 * self.half_width / max(self.max_thrust, 1e-12)  # m per N
        self._cables = np.asarray(cluster.cables, dtype=np.int64).reshape(-1, 2)

        self.figure = (
            self._plt.figure(figsize=(5, 5), dpi=96) if human else figure_module.Figure(figsize=(5, 5), dpi=96)
        )
        self._canvas: Any = self.figure.canvas if human else agg.FigureCanvasAgg(self.figure)
        ax: Any = self.figure.add_subplot(projection="3d")
        self.axes = ax
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.set_autoscale_on(False)

        # Off screen the moving artists are "animated": a full draw (the background) leaves them out.
        animated = not human

        def lines(**style: Any) -> Any:  # an mplot3d Line3DCollection (mplot3d is untyped)
            collection = art3d.Line3DCollection(np.empty((0, 2, 3)), animated=animated, **style)
            ax.add_collection(collection, autolim=False)
            return collection

        # As the axes drew them before: cables as lines (projecting caps when solid) under the
        # satellites and arrows.
        self._taut = lines(colors=TAUT_COLOUR, linewidths=1.8, capstyle="projecting")
        self._slack = lines(colors=SLACK_COLOUR, linewidths=1.0, linestyles="--")
        self._broken = lines(colors=BROKEN_COLOUR, linewidths=1.5, linestyles=":")
        self._thrust = lines(colors=THRUST_COLOUR, linewidths=1.5)
        start = self.centre + self.nominal
        # Satellites are sized by their mass ratio among the satellites; a tether's beads are
        # small grey points along its line, so that heavy satellites do not hide the figure.
        satellite_masses = cluster.masses[: cluster.num_satellites]
        sizes = np.full(cluster.num_nodes, BEAD_SIZE)
        sizes[: cluster.num_satellites] = 20.0 * satellite_masses / satellite_masses.min() + 20.0
        colours: Any = "black" if not cluster.num_beads else np.where(cluster.is_bead, BEAD_COLOUR, "black").tolist()
        self._satellites: Any = ax.scatter(
            *start.T,
            s=sizes,
            color=colours,
            depthshade=False,
            animated=animated,
        )
        # The title's two lines. Off screen the key, which never changes, is drawn with the axes
        # (as the second line of the axes' title), and the status line above it, which changes
        # every frame, is a text of the same font and place whose second line is blank: text is
        # most of what a blitted frame costs, so only the line that changes is drawn each time.
        self._key = ax.set_title(" \n" + KEY, fontsize=9)
        self._status = self.figure.text(
            0.5, 1.0, "", fontsize=9, ha="center", va="baseline", transform=self._key.get_transform()
        )
        self._status.set_animated(animated)
        self._background: Any = None
        self._background_key: tuple[int, int, int] | None = None
        self._limits_key: tuple[int, int, int] = (0, 0, 0)
        self._set_limits(self._centre_key(self.centre))

    # ------------------------------------------------------------------ limits
    def _centre_key(self, centre: np.ndarray) -> tuple[int, int, int]:
        """The centre as whole steps of ``_centre_step`` (the last one for a non-finite centre)."""
        if not np.all(np.isfinite(centre)) or np.any(np.abs(centre) > 1e12 * self._centre_step):
            return self._limits_key  # numerics diverged: keep the last view rather than fail to draw
        x, y, z = (int(round(float(value) / self._centre_step)) for value in centre)
        return x, y, z

    def _set_limits(self, key: tuple[int, int, int]) -> None:
        for axis, setter in enumerate((self.axes.set_xlim, self.axes.set_ylim, self.axes.set_zlim)):
            middle = key[axis] * self._centre_step
            setter(middle - self.half_width, middle + self.half_width)
        self._limits_key = key

    # ------------------------------------------------------------------ drawing
    def draw(
        self,
        positions: np.ndarray,
        slack: np.ndarray,
        thrust: np.ndarray,
        time: float,
        broken: np.ndarray | None = None,
    ) -> np.ndarray | None:
        """Draw one state.

        Args:
            positions: (n, 3) satellite positions, m.
            slack: (m,) bool, cables carrying no tension (broken ones included).
            thrust: (n, 3) thrust per satellite, N (red arrows; zero ones are not drawn).
            time: simulation time, s (in the title).
            broken: (m,) bool, cables that broke (drawn grey dotted), or None: none broke.

        Returns:
            The frame as an (H, W, 3) uint8 array (480 x 480), or None in ``human`` mode.
        """
        slack = np.asarray(slack, dtype=bool)
        broken = np.zeros_like(slack) if broken is None else np.asarray(broken, dtype=bool)
        positions = np.asarray(positions, dtype=float)
        with np.errstate(invalid="ignore", over="ignore"):  # diverged numerics draw what is finite
            centre = positions.mean(axis=0)
            shown = centre + self.nominal + self.exaggeration * (positions - centre - self.nominal)
        segments = shown[self._cables]  # (m, 2, 3)
        loose = slack & ~broken
        self._taut.set_segments(segments[~slack & ~broken])
        self._slack.set_segments(segments[loose])
        self._broken.set_segments(segments[broken])
        self._thrust.set_segments(arrow_segments(shown, self._arrow_scale * np.asarray(thrust, dtype=float)))
        # Setting the 3-D offsets directly: set_3d_properties would take the depth-sorted sizes
        # of the last projection as the satellites' own.
        self._satellites._offsets3d = tuple(shown.T)
        cut = f"   broken {int(broken.sum())}" if broken.any() else ""
        status = (
            f"{self.cluster.name}  t = {time:6.2f} s   slack {int(loose.sum())}/{slack.size}{cut}"
            f"   displacements x{self.exaggeration:g}"
        )
        key = self._centre_key(centre)
        if key != self._limits_key:
            self._set_limits(key)
        if self.human:  # every draw is a full one: the title holds both lines
            self._key.set_text(f"{status}\n{KEY}")
            self._canvas.draw_idle()
            self._plt.pause(1e-3)
            return None
        if self._background is None or self._background_key != key:
            self._canvas.draw()  # the axes alone: the moving artists are animated
            self._status.set_position(self._key.get_position())  # where the axes placed their title
            self._background = self._canvas.copy_from_bbox(self.figure.bbox)
            self._background_key = key
        else:
            self._canvas.restore_region(self._background)
        self._status.set_text(f"{status}\n ")
        self._draw_moving_artists()
        return np.asarray(self._canvas.buffer_rgba())[..., :3].copy()

    def _draw_moving_artists(self) -> None:
        """Project and draw the cables, then satellites and arrows (the nearer of the two last,
        as the axes order collections), then the title, over the background."""
        renderer = self._canvas.get_renderer()
        cables = (self._taut, self._slack, self._broken)
        for collection in cables:
            collection.do_3d_projection()
            collection.draw(renderer)
        depth = {artist: artist.do_3d_projection() for artist in (self._satellites, self._thrust)}
        # Axes3D draws collections farthest first (largest projected minimum depth); an empty
        # one (NaN depth) has nothing to draw.
        for artist in sorted(depth, key=lambda a: -depth[a] if np.isfinite(depth[a]) else 0.0):
            artist.draw(renderer)
        self._status.draw(renderer)

    def close(self) -> None:
        """Close the window (``human`` mode); an off-screen figure is simply dropped."""
        if self.human:
            self._plt.close(self.figure)
