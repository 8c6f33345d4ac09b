"""Plots of runs: learning curves (mean and spread over seeds) and preference transfer against the true
Pareto front. Figures are written as PNG with matplotlib's Agg backend (no display needed)."""

from __future__ import annotations

import csv
import json
import os
from typing import NamedTuple

import numpy as np


class RunMetrics(NamedTuple):
    """A run's metrics.csv: ``steps[T]`` (the first column, named ``step_name``), preference ``labels[E]``
    and ``values``: name -> ``[T, E]``."""

    step_name: str
    steps: np.ndarray
    labels: list[str]
    values: dict[str, np.ndarray]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_metrics(run_dir: str) -> RunMetrics:
    """A run's metrics.csv; the step is its first column (env steps, or ADMM rounds)."""
    path = os.path.join(run_dir, "metrics.csv")
    if not os.path.exists(path):
        raise FileNotFoundError(f"{run_dir!r} has no metrics.csv; is it a run directory of `moiq train`?")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path} holds no evaluations yet")
    step_name = next(iter(rows[0]))
    steps = sorted({int(r[step_name]) for r in rows})
    labels = list(dict.fromkeys(r["preference"] for r in rows))
    names = [k for k in rows[0] if k not in (step_name, "expert", "preference")]
    values = {name: np.full((len(steps), len(labels)), np.nan) for name in names}
    for r in rows:
        t, e = steps.index(int(r[step_name])), labels.index(r["preference"])
        for name in names:
            values[name][t, e] = float(r[name])
    return RunMetrics(step_name, np.array(steps), labels, values)


def learning_curves(run_dirs: list[str], out: str, metric: str = "eval_scalar_return",
                    expert_returns: np.ndarray | None = None) -> str:
    """One line per preference: the mean over ``run_dirs`` (seeds) of ``metric`` against env steps, with
    the min-max band; dashed lines at the experts' returns when given. Returns the PNG path."""
    runs = [read_metrics(d) for d in run_dirs]
    steps, labels = runs[0].steps, runs[0].labels
    for d, run in zip(run_dirs, runs):
        if not np.array_equal(run.steps, steps) or run.labels != labels:
            raise ValueError(f"{d!r} has other evaluation steps or preferences than {run_dirs[0]!r}")
        if metric not in run.values:
            raise ValueError(f"{d!r} has no metric {metric!r}; it has {', '.join(sorted(run.values))}")
    values = np.stack([r.values[metric] for r in runs])  # [runs, T, E]
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for e, label in enumerate(labels):
        line = ax.plot(steps, values[:, :, e].mean(0), marker="o", ms=3, label=f"w=[{label.replace(' ', ', ')}]")[0]
        ax.fill_between(steps, values[:, :, e].min(0), values[:, :, e].max(0), alpha=0.2, color=line.get_color())
        if expert_returns is not None:
            ax.axhline(expert_returns[e], ls="--", lw=1, color=line.get_color())
    ax.set_xlabel("env steps per expert" if runs[0].step_name == "env_steps" else runs[0].step_name)
    ax.set_ylabel(metric.replace("_", " "))
    ax.set_title(f"{len(run_dirs)} run(s); mean and min-max" + ("; dashed: experts" if expert_returns is not None else ""))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def transfer(returns: np.ndarray, preferences: np.ndarray, out: str, front: np.ndarray | None = None,
             title: str = "", traced: np.ndarray | None = None) -> str:
    """Vector returns ``[P, 2]`` reached for each of ``preferences`` (coloured by the first weight), beside
    the true Pareto front and the front the returns trace (``traced``), when given. Returns the PNG path."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    if front is not None:
        ax.plot(front[:, 1], front[:, 0], "k--", marker="s", ms=5, mfc="none", label="true Pareto front")
    if traced is not None and len(traced):
        traced = traced[np.argsort(traced[:, 1])]
        ax.step(traced[:, 1], traced[:, 0], "C3-", where="post", alpha=0.6, label="front the policy traces")
    points = ax.scatter(returns[:, 1], returns[:, 0], c=preferences[:, 0], cmap="viridis", zorder=3,
                        label="policy, per preference")
    fig.colorbar(points, ax=ax, label="weight of objective 1")
    ax.set_xlabel("objective 2 return")
    ax.set_ylabel("objective 1 return")
    ax.set_title(title or "preference transfer")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def read_transfer(run_dir: str) -> dict | None:
    """A run's transfer.json (written by `moiq eval`) as arrays: ``preferences`` and ``returns`` ``[P, d]``,
    and, when written, ``front`` (the traced one), ``hypervolume``, ``regret``, ``mean_regret``..."""
    path = os.path.join(run_dir, "transfer.json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        data = json.load(f)
    return {k: np.asarray(v) if k in ("preferences", "returns", "front") else v for k, v in data.items()}
