"""A run directory: the resolved config, metrics as CSV and TensorBoard events, and a progress bar."""

from __future__ import annotations

import csv
import json
import os
import time

import numpy as np


def per_expert_rows(step: int, metrics: dict, preferences, step_name: str = "env_steps") -> list[dict]:
    """One CSV row per expert: a metric of shape ``[E]`` gives one column, ``[E, d]`` gives ``d`` columns
    (``name_0``...), a scalar repeats on every row."""
    rows = []
    for e, preference in enumerate(np.asarray(preferences)):
        row = {step_name: step, "expert": e, "preference": " ".join(f"{w:g}" for w in preference)}
        for name, value in sorted(metrics.items()):
            if name in row:  # the step and the expert come from the caller
                continue
            value = np.asarray(value)
            if value.ndim == 0:
                row[name] = float(value)
            elif value.shape[0] == len(preferences) and value.ndim == 1:
                row[name] = float(value[e])
            elif value.shape[0] == len(preferences) and value.ndim == 2:
                row.update({f"{name}_{k}": float(v) for k, v in enumerate(value[e])})
        rows.append(row)
    return rows


class RunLog:
    """Writes ``config.json``, appends ``metrics.csv`` and TensorBoard scalars, and shows progress.

    ``labels`` name each expert's rows (default: the config's preferences; a run that infers the
    preferences labels its experts by the inferred ones). Non-finite values go to the CSV only.
    Reopening a directory (``resume``) appends to the same files; rows past the resumed step are dropped
    first, so the CSV holds each evaluation once.
    """

    def __init__(self, run_dir: str | os.PathLike, config, total_steps: int, resume_step: int = 0,
                 progress: bool = True, step_name: str = "env_steps", labels=None):
        from tensorboardX import SummaryWriter
        from tqdm import tqdm

        self.run_dir = os.fspath(run_dir)
        self.step_name = step_name
        os.makedirs(self.run_dir, exist_ok=True)
        with open(os.path.join(self.run_dir, "config.json"), "w") as f:
            json.dump(config.to_dict(), f, indent=2)
        self.csv_path = os.path.join(self.run_dir, "metrics.csv")
        self._truncate_csv(resume_step)
        self.writer = SummaryWriter(os.path.join(self.run_dir, "tensorboard"))
        self.preferences = config.preferences if labels is None else labels  # each expert's row label
        self.bar = tqdm(total=total_steps, initial=resume_step, unit="step", disable=not progress,
                        dynamic_ncols=True, mininterval=1.0)
        self.start = time.perf_counter()

    def _truncate_csv(self, resume_step: int) -> None:
        if not os.path.exists(self.csv_path):
            return
        with open(self.csv_path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if int(r[self.step_name]) <= resume_step]
        self._write_rows(rows, mode="w")

    def _write_rows(self, rows: list[dict], mode: str = "a") -> None:
        if not rows:
            if mode == "w":
                open(self.csv_path, "w").close()
            return
        new = mode == "w" or not os.path.exists(self.csv_path) or os.path.getsize(self.csv_path) == 0
        fields = list(rows[0])
        if not new:  # append under the file's header; a metric it lacks (a resumed run's) rewrites it once
            with open(self.csv_path, newline="") as f:
                header = next(csv.reader(f), [])
            added = [name for name in fields if name not in header]
            fields = header + added
            if added:
                with open(self.csv_path, newline="") as f:
                    rows, mode, new = list(csv.DictReader(f)) + rows, "w", True
        with open(self.csv_path, mode, newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields, restval="")
            if new:
                writer.writeheader()
            writer.writerows(rows)

    def log(self, step: int, metrics: dict, summary: str = "") -> None:
        """Record the metrics of one evaluation at ``step`` env steps and advance the progress bar."""
        rows = per_expert_rows(step, metrics, self.preferences, self.step_name)
        self._write_rows(rows)
        for row in rows:
            for name, value in row.items():
                if name not in (self.step_name, "expert", "preference") and np.isfinite(value):
                    self.writer.add_scalar(f"preference {row['preference']}/{name}", value, step)
        self.writer.flush()
        self.bar.update(step - self.bar.n)
        if summary:
            self.bar.set_postfix_str(summary, refresh=True)

    def close(self) -> None:
        self.bar.close()
        self.writer.close()


class RunLogs:
    """The run directories of a sweep, ``run_dir/<name>`` per run, each a ``RunLog`` under its run's config;
    ``log`` takes metrics with a leading run axis and gives each run its own."""

    def __init__(self, run_dir: str | os.PathLike, names, configs, total_steps: int, resume_step: int = 0):
        self.logs = [RunLog(os.path.join(os.fspath(run_dir), name), config, total_steps, resume_step, progress=False)
                     for name, config in zip(names, configs)]

    def log(self, step: int, metrics: dict, summary: str = "") -> None:
        for run, log in enumerate(self.logs):
            log.log(step, {name: np.asarray(value)[run] for name, value in metrics.items()})

    def close(self) -> None:
        for log in self.logs:
            log.close()
