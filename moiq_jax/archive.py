"""A ``Result`` kept as a folder of small files, and read back; runs kept one by one joined into one sweep.

A saved result is what tables and figures read, not a run to resume: ``result.json`` (config, preferences,
swept values per run, best returns, seconds), ``history.npz`` (the metrics of every evaluation) and
``best_params.npz`` (the best model's parameters; for one model of all experts, also
``best_actor_per_expert.npz``: each expert's best actor). The final parameters and the training state are left
out, so a run is a few hundred kilobytes and can be committed: runs trained in different sessions or on
different machines are saved as they finish and joined with ``stack_results``.
"""

from __future__ import annotations

import json
import os

import jax
import numpy as np
from flax import serialization, traverse_util

from moiq_jax.config import Config
from moiq_jax.networks import Params
from moiq_jax.result import Result
from moiq_jax.runtime import host_description
from moiq_jax.train import algorithm_of

RESULT_FILE, HISTORY_FILE, PARAMS_FILE = "result.json", "history.npz", "best_params.npz"
PER_EXPERT_FILE = "best_actor_per_expert.npz"


def save_result(result: Result, directory: str | os.PathLike) -> None:
    """Write ``result`` (one run, or a sweep with its run axis) of an off-policy algorithm to ``directory``.
    The parameters are written first and ``result.json`` last, so a folder with ``result.json`` is whole."""
    if not isinstance(result.best_params, Params):
        raise TypeError(f"save_result keeps the off-policy algorithms' results (moiq, iq_learn, sac, gail); "
                         f"{result.config.algo}'s has no network parameters to keep")
    os.makedirs(directory, exist_ok=True)
    flat = traverse_util.flatten_dict(serialization.to_state_dict(jax.device_get(result.best_params)), sep="/")
    _write_npz(os.path.join(directory, PARAMS_FILE), flat)
    if result.best_actor_per_expert is not None:
        _write_npz(os.path.join(directory, PER_EXPERT_FILE),
                   traverse_util.flatten_dict(jax.device_get(result.best_actor_per_expert), sep="/"))
    _write_npz(os.path.join(directory, HISTORY_FILE), result.history)
    record = {"config": result.config.to_dict(), "preferences": np.asarray(result.preferences).tolist(),
              "best_return": np.asarray(result.best_return).tolist(), "seconds": float(result.seconds),
              "runs": None if result.runs is None else {k: np.asarray(v).tolist() for k, v in result.runs.items()},
              "action_scale": result.best_params.action_scale,
              "best_return_per_expert": None if result.best_return_per_expert is None
              else np.asarray(result.best_return_per_expert).tolist(),
              "host": host_description()}  # where it is saved, which is where it trained
    tmp = os.path.join(directory, RESULT_FILE + ".tmp")
    with open(tmp, "w") as f:
        json.dump(record, f, indent=1, default=lambda x: np.asarray(x).tolist())
    os.replace(tmp, os.path.join(directory, RESULT_FILE))


def load_result(directory: str | os.PathLike) -> Result:
    """The ``Result`` that ``save_result`` wrote to ``directory`` (``final_params`` None)."""
    path = os.path.join(directory, RESULT_FILE)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{os.fspath(directory)!r} holds no saved result (no {RESULT_FILE}; save_result "
                                "writes one)")
    with open(path) as f:
        record = json.load(f)
    with np.load(os.path.join(directory, PARAMS_FILE)) as data:
        tree = traverse_util.unflatten_dict({k: data[k] for k in data.files}, sep="/")
    params = Params(critic=tree["critic"], target_critic=tree["target_critic"], actor=tree["actor"],
                    log_alpha=tree["log_alpha"], action_scale=record["action_scale"])
    with np.load(os.path.join(directory, HISTORY_FILE)) as data:
        history = {k: data[k] for k in data.files}
    runs = None if record["runs"] is None else {k: np.asarray(v) for k, v in record["runs"].items()}
    per_expert = {}
    if record.get("best_return_per_expert") is not None:  # runs saved before it was kept have none
        with np.load(os.path.join(directory, PER_EXPERT_FILE)) as data:
            per_expert = {"best_actor_per_expert": traverse_util.unflatten_dict({k: data[k] for k in data.files}, sep="/"),
                          "best_return_per_expert": np.asarray(record["best_return_per_expert"])}
    return Result(Config(**record["config"]), np.asarray(record["preferences"]), history, None, params,
                  np.asarray(record["best_return"]), record["seconds"], runs=runs, **per_expert)


def swept_values(config: Config) -> dict:
    """The values a sweep of ``config``'s algorithm varies, as this config has them: its hyperparameters
    (e.g. moiq's ``beta``), then ``seed``."""
    return {**algorithm_of(config).hyper(config), "seed": config.seed}


def stack_results(results: list[Result]) -> Result:
    """Single runs of one sweep (configs equal but for the swept values, ``swept_values``) joined into one
    sweep result with a leading run axis, in the order given; ``runs`` holds each run's swept values."""
    if not results:
        raise ValueError("stack_results needs at least one result")
    if any(r.runs is not None for r in results):
        raise ValueError("stack_results joins single runs; take a sweep's runs with Result.run(i) first")
    base = results[0].config
    values = [swept_values(r.config) for r in results]
    for i, (result, own) in enumerate(zip(results, values)):
        if result.config.replace(**values[0]) != base:
            given, kept = result.config.to_dict(), base.to_dict()
            differ = sorted(k for k in {*given, *kept} if k not in own and given.get(k) != kept.get(k))
            raise ValueError(f"run {i} is not of the same sweep as run 0: its config differs in {', '.join(differ)}")
        if not np.array_equal(result.preferences, results[0].preferences):
            raise ValueError(f"run {i} has other preferences than run 0")
        lengths = {k: np.shape(v)[0] for k, v in result.history.items()}
        if lengths != {k: np.shape(v)[0] for k, v in results[0].history.items()}:
            raise ValueError(f"run {i} has other evaluations than run 0 ({lengths} vs run 0's); join finished runs")
    stack = lambda *x: np.stack(x)
    per_expert = {}
    if all(r.best_return_per_expert is not None for r in results):  # else a per-preference reading has gaps
        per_expert = {name: jax.tree_util.tree_map(stack, *[getattr(r, name) for r in results])
                      for name in ("best_actor_per_expert", "best_return_per_expert")}
    return Result(base, results[0].preferences, jax.tree_util.tree_map(stack, *[r.history for r in results]),
                  None, jax.tree_util.tree_map(stack, *[r.best_params for r in results]),
                  np.asarray([r.best_return for r in results]), float(sum(r.seconds for r in results)),
                  runs={name: np.asarray([v[name] for v in values]) for name in values[0]}, **per_expert)


def _write_npz(path: str, arrays: dict) -> None:
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, **{k: np.asarray(v) for k, v in arrays.items()})
    os.replace(tmp, path)
