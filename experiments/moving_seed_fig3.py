"""Seed 002 Fig. 3 reproduction: the observer's ω_n error against time (simulated).

Drifts (4, 6, 9)·10⁻⁶ s⁻¹ (~1 °/h, panel a) and ·10⁻⁷ s⁻¹ (~0.1 °/h, panel b), K = 50, the
stable form (solid) and the printed form (16) (dashed, until it diverges and leaves the plot),
from :func:`selfnav.moving.seed_example`.

    python experiments/moving_seed_fig3.py docs/img/moving_fig3.png
"""
from __future__ import annotations

import sys

import numpy as np

from selfnav.moving import seed_example


def plot_seed_fig3(path, *, gain=50.0, t_end=8.0, dt=1e-3):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for ax, scale, lab in zip(axes, (1e-6, 1e-7), ("a) drift (4, 6, 9)·1e-6 s⁻¹ (~1 °/h)",
                                                   "b) drift (4, 6, 9)·1e-7 s⁻¹ (~0.1 °/h)")):
        drift = np.array([4.0, 6.0, 9.0]) * scale
        t, e, _ = seed_example(drift, gain=gain, t_end=t_end, dt=dt)
        tp, ep, _ = seed_example(drift, gain=gain, form="printed", t_end=t_end, dt=dt)
        for j in range(3):
            ax.plot(t, e[:, j], lw=1.2, label=f"stable, δω_{'ξηζ'[j]}", color=f"C{j}")
            ax.plot(tp, np.clip(ep[:, j], -1e3, 1e3), lw=0.8, ls="--", color=f"C{j}",
                    label=f"printed (16), δω_{'ξηζ'[j]}")
        lim = 2.5 * np.linalg.norm(drift)
        ax.set_ylim(-lim, lim)
        ax.set_ylabel("ω_n error, s⁻¹")
        ax.set_title(f"{lab}, K = {gain:g}", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2, loc="lower left")
    axes[1].set_xlabel("t, s (simulated; printed form leaves the plot when it diverges)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(plot_seed_fig3(sys.argv[1] if len(sys.argv) > 1 else "moving_fig3.png"))
