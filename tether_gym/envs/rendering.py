"""Drawing a cluster: satellites, taut and slack cables, thrust arrows (matplotlib, headless-safe)."""

from __future__ import annotations

from typing import Any

import numpy as np

from tether_gym.cluster import Cluster


class ClusterRenderer:
    """A 3-D view of one cluster, returned as an RGB array or shown in a window.

    Args:
        cluster: the cluster (for its cables and nominal size).
        max_thrust: thrust drawn as a full-length arrow, N.
        human: open a window (``plt.show`` mode) instead of drawing off-screen.
        exaggeration: factor applied to each satellite's displacement from its nominal place
            (in the centre-of-mass frame) so that centimetre vibrations of 100 m cables show.
    """

    def __init__(self, cluster: Cluster, max_thrust: float, human: bool = False, exaggeration: float = 1.0) -> None:
        import matplotlib

        if not human:
            matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        self._plt = plt
        self.cluster = cluster
        self.max_thrust = max_thrust
        self.human = human
        self.exaggeration = exaggeration
        self.nominal = cluster.positions - cluster.positions.mean(axis=0)
        self.figure = plt.figure(figsize=(5, 5), dpi=96) if human else matplotlib.figure.Figure(figsize=(5, 5), dpi=96)
        if not human:
            FigureCanvasAgg(self.figure)
        self.axes = self.figure.add_subplot(projection="3d")
        centre = cluster.positions.mean(axis=0)
        self.half_width = 0.75 * float(np.ptp(cluster.positions, axis=0).max()) + 1.0
        self.centre = centre

    def draw(self, positions: np.ndarray, slack: np.ndarray, thrust: np.ndarray, time: float) -> np.ndarray | None:
        """Draw positions (n, 3) m, slack flags (m,), thrust (n, 3) N at ``time`` s."""
        ax = self.axes
        ax.cla()
        centre = positions.mean(axis=0)
        positions = centre + self.nominal + self.exaggeration * (positions - centre - self.nominal)
        for c, (i, j) in enumerate(self.cluster.cables):
            segment = positions[[i, j]]
            if slack[c]:
                ax.plot(*segment.T, color="tab:orange", linestyle="--", linewidth=1.0)
            else:
                ax.plot(*segment.T, color="tab:blue", linewidth=1.8)
        ax.scatter(
            *positions.T,
            s=40 * self.cluster.masses / self.cluster.masses.min() ** 1.0 / 2 + 20,
            color="black",
            depthshade=False,
        )
        arrow_length = 0.25 * self.half_width / max(self.max_thrust, 1e-12)
        if np.any(thrust):
            ax.quiver(*positions.T, *(thrust * arrow_length).T, color="tab:red", linewidth=1.5)
        for axis, setter in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
            setter(centre[axis] - self.half_width, centre[axis] + self.half_width)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.set_title(
            f"{self.cluster.name}  t = {time:6.2f} s   slack {int(slack.sum())}/{slack.size}"
            f"   displacements x{self.exaggeration:g}\n"
            "blue: taut, orange dashed: slack, red: thrust",
            fontsize=9,
        )
        self.figure.canvas.draw()
        if self.human:
            self._plt.pause(1e-3)
            return None
        canvas: Any = self.figure.canvas  # an Agg canvas (off screen), which the base class does not declare
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        if self.human:
            self._plt.close(self.figure)
