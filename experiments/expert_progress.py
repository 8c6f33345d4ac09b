"""How an expert run is going, from its run directory's metrics.csv (``train_experts.py --run-dir``): each
expert's scalarised evaluation return at every evaluation, every expert scored under every preference (its
evaluation's vector return scalarised by that preference), and where one expert continued from another
(``--adopt-margin``). Prints markdown; ``--out FILE`` also writes it.

    PYTHONPATH=. python experiments/expert_progress.py RUN_DIR [--from STEPS] [--out progress.md]
"""

from __future__ import annotations

import argparse
import csv
import pathlib
from collections import defaultdict

import numpy as np


def read_evaluations(run_dir: pathlib.Path, first_step: int = 0):
    """``(steps, labels, vectors [step, expert, d], adopted [step, expert])`` from ``metrics.csv``; ``adopted``:
    the expert each one continued from after that evaluation, -1 for none, NaN where the run did not record it."""
    path = run_dir / "metrics.csv"
    if not path.exists():
        raise FileNotFoundError(f"{run_dir} has no metrics.csv (is it a --run-dir of train_experts.py?)")
    rows = [r for r in csv.DictReader(path.open(newline="")) if int(r["env_steps"]) >= first_step]
    if not rows:
        raise ValueError(f"{path} has no evaluation at or after step {first_step}")
    objectives = sorted((k for k in rows[0] if k.startswith("eval_return_")), key=lambda k: int(k.rsplit("_", 1)[1]))
    by_step, labels = defaultdict(dict), {}
    for r in rows:
        expert = int(r["expert"])
        labels[expert] = tuple(float(w) for w in r["preference"].split())
        by_step[int(r["env_steps"])][expert] = r
    steps, experts = sorted(by_step), sorted(labels)
    vectors = np.array([[[float(by_step[s][e][k]) for k in objectives] for e in experts] for s in steps])
    adopted = np.array([[float(by_step[s][e].get("adopted_from") or "nan") for e in experts] for s in steps])
    return steps, [labels[e] for e in experts], vectors, adopted


def progress_markdown(steps, labels, vectors, adopted) -> str:
    preferences = np.asarray(labels)
    scores = np.einsum("id,sjd->sij", preferences, vectors)  # [step, preference i, expert j]
    own = np.einsum("sii->si", scores)
    name = lambda w: "[" + ", ".join(f"{x:g}" for x in w) + "]"
    head = "| steps | " + " | ".join(f"{s // 1000}K" if s >= 1000 else str(s) for s in steps) + " |\n"
    rule = "|---|" + "---|" * len(steps) + "\n"
    lines = ["Scalarised evaluation return of each expert:\n\n", head + rule
             + "".join(f"| {name(w)} | " + " | ".join(f"{own[t, i]:,.0f}" for t in range(len(steps))) + " |\n"
                       for i, w in enumerate(labels))]
    lines.append("\nThe best expert under each preference (its evaluation vector scalarised by that preference), "
                 "where it is another:\n\n")
    cells = []
    for i, w in enumerate(labels):
        row = []
        for t in range(len(steps)):
            j = int(np.argmax(scores[t, i]))
            row.append("" if j == i else f"{name(labels[j])} {scores[t, i, j]:,.0f}")
        cells.append(f"| {name(w)} | " + " | ".join(row) + " |\n")
    lines.append(head + rule + "".join(cells))
    moves = [f"- after {s:,} steps: {name(labels[i])} continued from {name(labels[int(adopted[t, i])])}\n"
             for t, s in enumerate(steps) for i in range(len(labels)) if adopted[t, i] >= 0]
    if moves:
        lines.append("\nAdoptions (the expert continued from the other's learner and replay after that evaluation):\n\n")
        lines += moves
    return "".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=pathlib.Path)
    parser.add_argument("--from", dest="first_step", type=int, default=0, help="the first evaluation step to show")
    parser.add_argument("--out", type=pathlib.Path, help="also write the markdown here")
    args = parser.parse_args()
    try:
        text = progress_markdown(*read_evaluations(args.run_dir, args.first_step))
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    print(text, end="")
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
