"""PNG plots (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from datagen.approach import trace_approach  # noqa: E402
from datagen.config import Config  # noqa: E402
from datagen.files import atomic_path  # noqa: E402

__all__ = ["plot_approaches"]


def plot_approaches(config: Config, path: Path, approaches: int = 5, seed: int | None = None) -> None:
    """Distance over time and trajectories in the drogue-centred frame for a few approaches."""
    seed = config.dataset.seed if seed is None else seed
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8), constrained_layout=True)
    for a in range(approaches):
        tr = trace_approach(config, seed, a)
        label = f"approach {a} ({tr['time_s'][-1]:.0f} s)"
        axes[0].plot(tr["time_s"], tr["distance_m"], label=label)
        pos = tr["probe_drogue_m"]
        axes[1].plot(pos[:, 0], pos[:, 1])
        axes[2].plot(pos[:, 0], pos[:, 2])
        for ax, j in ((axes[1], 1), (axes[2], 2)):
            ax.plot(pos[0, 0], pos[0, j], "o", color=ax.lines[-1].get_color(), ms=4)
    axes[0].set(xlabel="time since start (s)", ylabel="probe-to-drogue distance (m)",
                title="PtD distance (contact < 1 cm)", yscale="log")
    axes[0].legend(fontsize=8)
    axes[1].set(xlabel="x, tanker forward (m)", ylabel="y, left (m)", title="top view, drogue-centred frame")
    axes[2].set(xlabel="x, tanker forward (m)", ylabel="z, up (m)", title="side view, drogue-centred frame")
    for ax in axes[1:]:
        ax.plot(0, 0, "k+", ms=12)
        ax.grid(True, alpha=0.3)
    axes[0].grid(True, alpha=0.3)
    fig.suptitle(f"{config.name}: {approaches} Monte Carlo approaches (seed {seed}, start markers o, drogue +)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
