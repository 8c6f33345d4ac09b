"""Whether two kept runs are the same run, bit for bit: their configs (but for file paths), demonstrations
digests, the hosts they trained on, every metric of the training history, the best model and each preference's best actor; where they
differ, the first evaluation that does and the largest difference. This is how a rerun of a committed command
is checked against the committed run.

    PYTHONPATH=. python experiments/compare_runs.py RUN_A RUN_B [--json FILE]

RUN_A and RUN_B are folders that ``moiq_jax.archive.save_result`` wrote (e.g.
``results/mujoco_cpu_recipe_online_penalty/runs/mo-ant-moiq/beta0.5-seed1`` and its ``runs_rerun`` twin).
"""

from __future__ import annotations

import argparse
import json
import pathlib

import jax
import numpy as np
from paper_mujoco import DIGEST_FILE

from moiq_jax.archive import RESULT_FILE, load_result

PATH_FIELDS = ("demos",)  # config fields that name a file, which a rerun from another checkout changes


def _equal(x, y) -> bool:
    x, y = np.asarray(x), np.asarray(y)
    return x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f")


def _largest_difference(x, y) -> float:
    leaves = list(zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(y)))
    return max(float(np.max(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64)), initial=0.0))
               for a, b in leaves)


def _trees_equal(x, y) -> bool:
    if jax.tree_util.tree_structure(x) != jax.tree_util.tree_structure(y):
        return False
    return all(_equal(a, b) for a, b in zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(y)))


def _host(folder: pathlib.Path) -> str | None:
    """The host the run was saved on (``result.json``'s ``host``; runs saved before it was recorded have none)."""
    return json.loads((folder / RESULT_FILE).read_text()).get("host")


def _first_difference(x, y) -> int | None:
    """The first row at which the histories ``x`` and ``y`` of one metric differ (the shorter's length where
    one ends first), or None."""
    for i in range(min(len(x), len(y))):
        if not _equal(x[i], y[i]):
            return i
    return None if len(x) == len(y) else min(len(x), len(y))


def _digest(folder: pathlib.Path) -> str | None:
    path = folder / DIGEST_FILE
    return path.read_text().split()[0] if path.exists() else None


def _metric_difference(x, y) -> dict | None:
    """None where one metric's histories are bit-identical; else the first evaluation at which they differ and
    their largest difference over the evaluations both have."""
    first = _first_difference(x, y)
    if first is None:
        return None
    n = min(len(x), len(y))
    return {"first_evaluation": first, "largest": _largest_difference(np.asarray(x)[:n], np.asarray(y)[:n])}


def compare(a: pathlib.Path, b: pathlib.Path) -> dict:
    """How the runs kept in folders ``a`` and ``b`` differ (see the module's docstring)."""
    run_a, run_b = load_result(a), load_result(b)
    config_a, config_b = run_a.config.to_dict(), run_b.config.to_dict()
    history_a, history_b = run_a.history, run_b.history
    metrics = sorted({*history_a, *history_b})
    shared = [k for k in metrics if k in history_a and k in history_b]
    differing = {k: d for k in shared if (d := _metric_difference(history_a[k], history_b[k])) is not None}
    first = min((d["first_evaluation"] for d in differing.values()), default=None)
    same_shape = jax.tree_util.tree_structure(run_a.best_params) == jax.tree_util.tree_structure(run_b.best_params)
    both_each_best = run_a.best_actor_per_expert is not None and run_b.best_actor_per_expert is not None
    digests = [_digest(a), _digest(b)]
    return {
        "a": str(a), "b": str(b),
        "config_differs_in": sorted(k for k in {*config_a, *config_b}
                                    if k not in PATH_FIELDS and config_a.get(k) != config_b.get(k)),
        "demonstrations_digests": digests,
        "same_demonstrations": digests[0] is not None and digests[0] == digests[1],
        "hosts": [_host(a), _host(b)],
        "evaluations": [len(history_a["env_steps"]), len(history_b["env_steps"])],
        "metrics_kept_by_one_run_only": [k for k in metrics if k not in shared],
        "metrics_identical": [k for k in shared if k not in differing],
        "metrics_differing": differing,
        "first_differing_evaluation": None if first is None else {
            "index": first, "env_steps": int(np.asarray(history_a["env_steps"])[min(first, len(history_a["env_steps"]) - 1)]),
            "mean_scalar_return": [float(np.mean(h["eval_scalar_return"][first])) if first < len(h["eval_scalar_return"])
                                   else None for h in (history_a, history_b)]},
        "best_model_identical": _trees_equal(run_a.best_params, run_b.best_params),
        "best_model_largest_difference": _largest_difference(run_a.best_params, run_b.best_params) if same_shape else None,
        "each_best_identical": _trees_equal(run_a.best_actor_per_expert, run_b.best_actor_per_expert)
        if both_each_best else None,
    }


def report(out: dict) -> str:
    """``compare``'s answer as lines of text."""
    digests = out["demonstrations_digests"]
    lines = [f"A: {out['a']}", f"B: {out['b']}",
             "config: " + ("equal" if not out["config_differs_in"] else "differs in " + ", ".join(out["config_differs_in"]))
             + f" (file paths, {', '.join(PATH_FIELDS)}, not compared)",
             "demonstrations: " + ("the same digest" if out["same_demonstrations"] else f"digests {digests[0]} vs {digests[1]}"),
             "host: " + " vs ".join(dict.fromkeys("not recorded" if h is None else h for h in out["hosts"])),
             f"evaluations: {out['evaluations'][0]} vs {out['evaluations'][1]}",
             "history bit-identical in: " + (", ".join(out["metrics_identical"]) or "no metric")]
    for name, d in out["metrics_differing"].items():
        lines.append(f"history differs in {name}: from evaluation {d['first_evaluation'] + 1}, "
                     f"by up to {d['largest']:.3g}")
    if out["metrics_kept_by_one_run_only"]:
        lines.append("kept by one run only: " + ", ".join(out["metrics_kept_by_one_run_only"]))
    first = out["first_differing_evaluation"]
    if first is not None:
        shown = ["none" if v is None else f"{v:.2f}" for v in first["mean_scalar_return"]]
        lines.append(f"first differing evaluation: {first['index'] + 1} ({first['env_steps']:,} env steps per "
                     f"expert), mean scalarised return {shown[0]} vs {shown[1]}")
    largest = out["best_model_largest_difference"]
    lines.append("best model: " + ("bit-identical" if out["best_model_identical"] else "differs" if largest is None
                                   else f"differs, by up to {largest:.3g}"))
    lines.append("each preference's best actor: " + {None: "not kept by both", True: "bit-identical",
                                                      False: "differs"}[out["each_best_identical"]])
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", type=pathlib.Path, help="a kept run's folder")
    parser.add_argument("b", type=pathlib.Path, help="the other run's folder")
    parser.add_argument("--json", type=pathlib.Path, help="also write the comparison here")
    args = parser.parse_args()
    out = compare(args.a, args.b)
    print(report(out))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
