"""What the MuJoCo experiment scripts (table1-3.py, figure2-4.py) share: the paper's numbers, the configs
per task, the sweeps over beta and seeds kept run by run, and the evaluation of their best models.

A task's MOIQ sweep (betas 5, 0 and 0.5 x seeds) serves Tables 1-3 and Figures 2 and 3; GAIL (Figure 2) and
the one-demonstration runs (Figure 4) have sweeps of their own. Each finished run is kept in
``<archive>/<env>-<name>/<run>`` (``moiq_jax.save_result``: small files, committed, with the digest of the
demonstrations it learnt from), so a sweep can be trained over several sessions (``experiments/train_runs.py``)
and the scripts read it without retraining. ``--quick`` runs tiny sweeps (CI smoke size) under ``<cache>/quick``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import json
import os
import pathlib
import shlex
import subprocess
import sys
import time

import jax
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import moiq_jax
from moiq_jax.archive import RESULT_FILE, load_result, save_result, stack_results
from moiq_jax.config import Config, tuned
from moiq_jax.result import Result
from moiq_jax.runtime import host_description, split_cpu_into_devices, use_compilation_cache
from moiq_jax.train import SWEEP_FILE, run_dir_names, run_grid

ENVS = ("mo-halfcheetah", "mo-hopper", "mo-walker2d", "mo-ant")  # the paper's four tasks: the scripts' default
# mo-halfcheetah-v4: the halfcheetah with MO-Gymnasium v4's cost scale (-0.1 |a|^2), the scale the paper's
# halfcheetah returns fit (experiments/demos/README.md); its rows are the paper's halfcheetah rows.
PAPER_SCALE_TWINS = {"mo-halfcheetah-v4": "mo-halfcheetah"}
TASKS = ENVS + tuple(PAPER_SCALE_TWINS)  # every task the scripts take
ROOT = pathlib.Path(__file__).resolve().parents[1]
DEMOS = ROOT / "experiments" / "demos"
PAPER_BETA = 5.0
# The consensus weight this project's penalty needs (its scale is the batch mean of per-sample reward distances,
# the paper does not state its own): chosen on cdst (results/cdst_moiq/README.md) and in the MuJoCo pilots
# (results/mujoco_cpu/README.md), where beta = 5 kept the hopper from learning to hop.
PROJECT_BETA = 0.5
MOIQ_BETAS = (PAPER_BETA, PROJECT_BETA)  # MOIQ's rows in Tables 1 and 3 and Figures 2-4
BETAS = (PAPER_BETA, 0.0, PROJECT_BETA)  # a task's sweep: MOIQ_BETAS and the ablation's beta = 0 (Table 2)

# The paper's Table 1 (MOIQ beta = 5, best model), Table 2 (EWMA return at 500K steps, beta 0 and 5) and
# Table 3 (Pearson correlation of learned and true scalarised reward), per preference of tuned(env).
PAPER_TABLE1 = {"mo-halfcheetah": (4377, 2261, 315), "mo-hopper": (2055, 2283, 896), "mo-walker2d": (3577, 1735, 879),
                "mo-ant": (2475, 1039, 463)}
PAPER_TABLE2 = {"mo-halfcheetah": ((3578, 3654), (2152, 2160), (341, 347)),
                "mo-hopper": ((1118, 1268), (1081, 1189), (638, 707)),
                "mo-walker2d": ((2386, 2636), (1560, 1326), (714, 738)),
                "mo-ant": ((2265, 2249), (926, 911), (295, 281))}
PAPER_TABLE3 = {"mo-halfcheetah": (0.63, 0.52, 0.19), "mo-hopper": (0.91, 0.1, 0.93), "mo-walker2d": (0.96, 0.96, 0.98),
                "mo-ant": (0.92, 0.95, 0.86)}
for _table in (PAPER_TABLE1, PAPER_TABLE2, PAPER_TABLE3):
    _table.update({twin: _table[env] for twin, env in PAPER_SCALE_TWINS.items()})


# The protocols of DESIGN.md ("Backends and protocols"), and the CI smoke size. All keep the paper's Table 5
# (critic lr 3e-4, tau 0.005, one update per env step per expert; actor lr 3e-5 but see "cpu") and IQ-Learn's own
# defaults, which the paper's code builds on and does not override: a fixed temperature 0.01 and V(s') from
# the online critic. "paper": 500K env steps per expert, 256x256, batch 256, for an accelerator. "cpu": sized
# so that one MOIQ run of a task fits about 30 minutes of the 2 CPU cores (128x128, batch 128, 100K steps),
# with IQ-Learn's actor learning rate for 1M steps (3e-5) raised to 3e-4 for 100K. "cpu_recipe": the cpu
# sizes for 300K steps with IQ-Learn's MuJoCo critic recipe (one critic, V(s') from the target critic, actor lr
# 3e-5) and the chi^2 regulariser at both the rows' and the policy's actions, which keeps that recipe from
# running away; about an hour of one core per run. "cpu_recipe_online_penalty": cpu_recipe with the consensus
# penalty's V(s') from the online critic (``penalty_online``), which keeps the penalty from climbing with the
# target critic. "cpu_recipe_fast_actor": cpu_recipe_online_penalty with the actor learning rate 3e-4, which
# held the mo-hopper's standing expert where 3e-5 lost it but slowed the halfcheetah; "cpu_recipe_mid_actor":
# the actor learning rate between them (1e-4), one rate for every task. "cpu_recipe_long":
# cpu_recipe_online_penalty for the paper's 500K env steps per expert (about 1.7x its time). The pilots that
# chose them are in results/mujoco_<protocol>/README.md.
IQ_LEARN_DEFAULTS = {"learn_alpha": False, "init_alpha": 0.01, "use_target": False}
_CPU_SIZES = {"hidden_sizes": (128, 128), "batch_size": 128, "num_envs": 8, "updates_per_step": 8,
              "learning_starts": 5_000, "eval_interval": 5_000, "eval_episodes": 5}
_CPU_RECIPE = {**_CPU_SIZES, "total_steps": 300_000, "buffer_size": 300_000, "actor_lr": 3e-5, "num_critics": 1,
               "use_target": True, "regulariser": "both"}
_CPU_RECIPE_ONLINE_PENALTY = {**_CPU_RECIPE, "penalty_online": True}
PROTOCOLS = {
    "paper": {"total_steps": 499_200, "num_envs": 16, "updates_per_step": 16, "learning_starts": 4_992,
              "eval_interval": 4_992, "eval_episodes": 10, "buffer_size": 499_200},
    "cpu": {**_CPU_SIZES, "total_steps": 100_000, "buffer_size": 100_000, "actor_lr": 3e-4},
    "cpu_recipe": _CPU_RECIPE,
    "cpu_recipe_online_penalty": _CPU_RECIPE_ONLINE_PENALTY,
    "cpu_recipe_fast_actor": {**_CPU_RECIPE_ONLINE_PENALTY, "actor_lr": 3e-4},
    "cpu_recipe_mid_actor": {**_CPU_RECIPE_ONLINE_PENALTY, "actor_lr": 1e-4},
    "cpu_recipe_long": {**_CPU_RECIPE_ONLINE_PENALTY, "total_steps": 500_000, "buffer_size": 500_000},
    "quick": {"total_steps": 64, "num_envs": 16, "updates_per_step": 1, "learning_starts": 16, "eval_interval": 64,
              "eval_episodes": 1, "buffer_size": 64, "hidden_sizes": (16, 16), "batch_size": 16},
}
EWMA_ALPHA = 0.1  # the paper's smoothing of learning curves (Table 2, Figures 2 and 4)
LAST_WINDOW = 0.2  # Table 2 beside the EWMA: the mean return over the evaluations of the last 20% of training
DIGEST_FILE = "demos.sha256"  # beside each kept run: the demonstrations file it learnt from


def protocol_of(args) -> str:
    """The protocol the command line asks for (``--quick`` is the CI smoke size)."""
    return "quick" if args.quick else args.protocol


def moiq_config(env: str, protocol: str = "cpu", **changes) -> Config:
    """MOIQ on ``env`` from its committed SAC demonstrations under ``protocol`` (``PROTOCOLS``), then
    ``changes``."""
    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; choose one of {', '.join(PROTOCOLS)}")
    return tuned(env, demos=str(DEMOS / f"{env}.npz"), **protocol_settings(protocol)).replace(**changes)


def protocol_settings(protocol: str) -> dict:
    """The Config fields ``protocol`` sets: IQ-Learn's defaults, then the protocol's own."""
    return {**IQ_LEARN_DEFAULTS, **PROTOCOLS[protocol]}


def gail_config(env: str, protocol: str = "cpu") -> Config:
    """GAIL with the paper's Table 4 settings (SAC generator: learning rate 3e-4, tau 0.05, batch 256 under
    the paper's protocol, learnt temperature), one model per preference, on the same demonstrations and env
    steps as MOIQ. GAIL has no consensus penalty, so protocols that differ in MOIQ's penalty alone give it one
    config and can share its runs (``figure2.py --gail-protocol``)."""
    return moiq_config(env, protocol, algo="gail", actor_lr=3e-4, critic_lr=3e-4, disc_lr=3e-4, tau=0.05,
                       use_target=True, learn_alpha=True, beta=0.0, num_critics=2, penalty_online=False)


# Every sweep the scripts read: what it is for. Its config and betas: ``sweep_of``.
SWEEPS = {"moiq": "MOIQ, 10 demonstrations per preference (Tables 1-3, Figures 2 and 3)",
          "gail": "GAIL, one model per preference (Figure 2)",
          "moiq-1demo": "MOIQ from 1 demonstration per preference (Figure 4)",
          "iq_learn-1demo": "IQ-Learn, one model per preference, from 1 demonstration per preference (Figure 4)"}


def sweep_of(env: str, protocol: str, name: str) -> tuple[Config, tuple | None]:
    """Sweep ``name`` (``SWEEPS``) of ``env`` under ``protocol``: its config and betas (None: the algorithm has
    no beta)."""
    if name == "moiq":
        return moiq_config(env, protocol), BETAS
    if name == "gail":
        return gail_config(env, protocol), None
    one_demo = moiq_config(env, protocol, num_demos=1)
    if name == "moiq-1demo":
        return one_demo, MOIQ_BETAS
    if name == "iq_learn-1demo":
        return one_demo.replace(algo="iq_learn", beta=0.0), None
    raise ValueError(f"unknown sweep {name!r}; choose one of {', '.join(SWEEPS)}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--envs", nargs="+", default=list(ENVS), choices=TASKS)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--protocol", default="cpu", choices=[p for p in PROTOCOLS if p != "quick"],
                        help="cpu: sized for the 2-core CPU machine; cpu_recipe: 3x its steps with IQ-Learn's "
                             "MuJoCo critic recipe; cpu_recipe_online_penalty: that with the consensus "
                             "penalty on the online critic; cpu_recipe_fast_actor / _mid_actor: that with actor lr "
                             "3e-4 / 1e-4; cpu_recipe_long: that for 500K steps; paper: the paper's (for an accelerator)")
    parser.add_argument("--quick", action="store_true", help="a tiny run of every step (CI smoke test)")
    parser.add_argument("--cache", default="results/mujoco/sweeps",
                        help="where the sweeps are trained (checkpointed, resumable), per protocol")
    parser.add_argument("--archive", help="where finished runs are kept; default results/mujoco_<protocol>/runs")
    parser.add_argument("--no-train", action="store_true",
                        help="read the kept runs only; a run not kept is an error naming the command that trains it")


def add_betas_argument(parser: argparse.ArgumentParser) -> None:
    """``--betas``: the MOIQ rows of a table, reading (or training) only their runs (``row_and_sweep_betas``)."""
    parser.add_argument("--betas", type=float, nargs="+",
                        help="MOIQ's rows, reading (or training) only their runs; default: the paper's beta and this "
                             "project's, from the task's whole sweep (which the other tables share)")


def row_and_sweep_betas(args) -> tuple[tuple, tuple]:
    """``(the betas of a table's MOIQ rows, the betas of the sweep to read)``: ``MOIQ_BETAS`` from the whole
    sweep ``BETAS``, or ``--betas`` from their runs alone."""
    return (MOIQ_BETAS, BETAS) if args.betas is None else (tuple(args.betas), tuple(args.betas))


def out_dir(args, name: str) -> pathlib.Path:
    """The output folder of experiment ``name``: ``--out``, else ``results/mujoco_<protocol>/<name>``."""
    out = pathlib.Path(args.out or f"results/mujoco_{protocol_of(args)}/{name}")
    out.mkdir(parents=True, exist_ok=True)
    return out


def archive_of(args) -> pathlib.Path:
    """Where a protocol's finished runs are kept (small files, committed): ``--archive``, else
    ``results/mujoco_<protocol>/runs``; the CI smoke size keeps its runs under ``<cache>/quick/runs``."""
    if args.archive:
        return pathlib.Path(args.archive)
    protocol = protocol_of(args)
    return pathlib.Path(args.cache) / "quick" / "runs" if protocol == "quick" else pathlib.Path(f"results/mujoco_{protocol}/runs")


def run_configs(config: Config, betas, seeds) -> dict[str, Config]:
    """Each run of a ``betas`` (None: the algorithm has no beta) x ``seeds`` grid, beta outermost, by its name
    (``beta5-seed0``): ``config`` with the run's swept values."""
    grid = run_grid({"seed": list(seeds)} if betas is None else {"beta": list(betas), "seed": list(seeds)})
    return {run: config.replace(**{k: v[i].item() for k, v in grid.items()}) for i, run in enumerate(run_dir_names(grid))}


def set_up_host(seeds) -> None:
    """Before JAX's first computation: each seed's runs on a CPU device of their own, and the persistent
    compilation cache (each seed's evaluation, and every rerun, loads the same programs)."""
    split_cpu_into_devices(len(seeds))
    use_compilation_cache()


def demos_digest(config: Config) -> str:
    """The SHA-256 of ``config``'s demonstrations file: a kept run is valid only for the demos it learnt from."""
    return hashlib.sha256(pathlib.Path(config.demos).read_bytes()).hexdigest()


def load_run(folder: pathlib.Path, config: Config) -> Result | None:
    """The run kept in ``folder`` (None if there is none), checked to be ``config``'s (``config`` with the run's
    swept values) and trained on the same demonstrations file, whose path is set to this checkout's."""
    if not (folder / RESULT_FILE).exists():
        return None
    run = load_result(folder)
    run = dataclasses.replace(run, config=run.config.replace(demos=config.demos))
    if run.config != config:
        given, kept = config.to_dict(), run.config.to_dict()
        differ = sorted(k for k in given if given[k] != kept.get(k))
        raise ValueError(f"{folder} holds a run of another config ({', '.join(differ)}); move it away to retrain")
    if (folder / DIGEST_FILE).read_text().strip() != demos_digest(config):
        raise ValueError(f"{folder} holds a run trained on other demonstrations than {config.demos}; move it away "
                         "to retrain")
    return run


def train_runs(env: str, args, name: str, config: Config, betas, seeds) -> list[str]:
    """Train the runs of ``env``'s sweep ``name`` (``betas`` x ``seeds``; betas None: an algorithm without one)
    that the archive (``archive_of``) does not hold yet, one checkpointed sweep per beta in
    ``<cache>/<protocol>/<env>-<name>-beta<b>-seeds<s1-s2..>`` (the same call after a crash resumes it there),
    and keep each run in ``<archive>/<env>-<name>/<run>`` when its sweep ends. Returns the runs trained."""
    set_up_host(seeds)
    kept = archive_of(args) / f"{env}-{name}"
    trained = []
    for beta in [None] if betas is None else betas:
        swept = {} if beta is None else {"beta": [beta]}
        wanted = run_configs(config, swept.get("beta"), seeds)
        missing = [run for run, c in wanted.items() if load_run(kept / run, c) is None]
        if not missing:
            continue
        missing_seeds = [wanted[run].seed for run in missing]
        label = "-".join([env, name, *([f"beta{beta:g}"] if swept else []), "seeds" + "-".join(map(str, missing_seeds))])
        run_dir = pathlib.Path(args.cache) / protocol_of(args) / label
        resumed = (run_dir / SWEEP_FILE).exists()
        result = moiq_jax.sweep(config, run_dir=str(run_dir), resume=resumed, **swept, seed=missing_seeds)
        digest = demos_digest(config)
        for i, run in enumerate(missing):
            (kept / run).mkdir(parents=True, exist_ok=True)  # the digest first: save_result's record comes last
            (kept / run / DIGEST_FILE).write_text(digest + "\n")
            save_result(jax.device_get(result.run(i)), kept / run)
            trained.append(run)
        print(f"{env}: trained {name} ({protocol_of(args)} protocol) {', '.join(missing)} "
              f"({result.seconds:.0f}s in this call{', which resumed a cut sweep' if resumed else ''}; kept in {kept})")
    return trained


def task_sweep(env: str, args, name: str = "moiq", betas: tuple | None = None) -> Result:
    """Sweep ``name`` (``sweep_of``) of ``env`` under the command line's protocol, at ``betas`` (default: all
    the sweep's) x seeds, from the runs kept in the archive; those not kept yet are trained first
    (``train_runs``), so a sweep longer than a session is trained in parts (``experiments/train_runs.py``) and
    the scripts read it without retraining."""
    seeds = list(range(2 if args.quick else args.seeds))
    set_up_host(seeds)
    config, sweep_betas = sweep_of(env, protocol_of(args), name)
    betas = sweep_betas if betas is None else tuple(betas)
    kept = archive_of(args) / f"{env}-{name}"
    wanted = run_configs(config, betas, seeds)
    runs = {run: load_run(kept / run, c) for run, c in wanted.items()}
    missing = [run for run, result in runs.items() if result is None]
    if missing:
        if args.no_train:
            raise SystemExit(f"{kept} does not hold the runs {', '.join(missing)} (--no-train); "
                             f"`PYTHONPATH=. python experiments/train_runs.py --env {env} --sweep {name} "
                             f"{'--quick' if args.quick else '--protocol ' + args.protocol}"
                             f"{' --betas ...' if betas else ''} --seed-list ...` trains them")
        train_runs(env, args, name, config, betas, seeds)
        runs.update({run: load_run(kept / run, wanted[run]) for run in missing})
    return stack_results(list(runs.values()))


def near_expert(value: float, expert: float) -> bool:
    """Whether a return is within 10% of the expert's, ``value >= expert - 0.1 |expert|`` (the 90% line of
    Table 1, judged on the difference so that negative expert returns are judged right)."""
    return bool(value >= expert - 0.1 * abs(expert))


def evaluation_returns(result: Result, beta: float | None) -> tuple[np.ndarray, np.ndarray]:
    """``(env steps per expert [evals], scalarised evaluation returns [seeds, evals, E])`` of the ``beta`` runs
    of a sweep (one model, or one per expert: the steps are the same)."""
    steps = np.asarray(result.history["env_steps"])[0]
    steps = steps if steps.ndim == 1 else steps[:, 0]
    return steps, np.asarray(result.history["eval_scalar_return"])[runs_of(result, beta)]


def runs_of(result: Result, beta: float | None) -> np.ndarray:
    """The runs of a sweep with consensus weight ``beta`` (None: every run, for algorithms without one)."""
    if beta is None:
        return np.arange(len(result.runs["seed"]))
    return np.flatnonzero(np.isclose(result.runs["beta"], beta))


def best_model_returns(result: Result, beta: float, episodes: int) -> np.ndarray:
    """``[seeds, E, d]`` mean vector returns over ``episodes`` of each ``beta`` run's best model at the
    experts' preferences."""
    config = result.config
    return np.stack([moiq_jax.evaluate(result.run(r).best_params, config.env, config.preferences, episodes=episodes)
                     for r in runs_of(result, beta)])


def each_preferences_best_returns(result: Result, beta: float, episodes: int) -> np.ndarray | None:
    """``[seeds, E, d]`` mean vector returns over ``episodes`` of each ``beta`` run's best actor *of each
    preference* (``Result.best_actor_per_expert``: the model a per-preference reading of "the best model" takes),
    each at its own preference; None when the runs kept no such actors (trained before they were kept)."""
    if result.best_actor_per_expert is None:
        return None
    config = result.config
    rows = []
    for run in map(result.run, runs_of(result, beta)):
        rows.append([moiq_jax.evaluate(run.expert_best_params(e), config.env, [w], episodes=episodes)[0]
                     for e, w in enumerate(config.preferences)])
    return np.asarray(rows)


def best_model_correlations(result: Result, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """``([seeds, E], [seeds, E, d])`` the recovered reward's Pearson correlations with the true one on the
    demonstrations (scalarised, and per objective) at each ``beta`` run's best model
    (``moiq_jax.reward_correlations``)."""
    per_run = [moiq_jax.reward_correlations(run.best_params, run.config)
               for run in map(result.run, runs_of(result, beta))]
    return (np.stack([c["reward_correlation"] for c in per_run]),
            np.stack([c["reward_correlation_objectives"] for c in per_run]))


def best_model_rollout_correlations(result: Result, beta: float, episodes: int) -> dict[str, np.ndarray]:
    """``moiq_jax.rollout_reward_correlations`` at each ``beta`` run's best model, stacked over seeds: the
    recovered and true returns' correlation across the policy's own ``episodes`` (IQ-Learn's code's measure),
    ``episode_reward_correlation`` ``[seeds, E]`` and the others."""
    per_run = [moiq_jax.rollout_reward_correlations(run.best_params, run.config, episodes)
               for run in map(result.run, runs_of(result, beta))]
    return {k: np.stack([c[k] for c in per_run]) for k in per_run[0]}


def expert_returns(env: str) -> np.ndarray:
    """``[E, d]`` the committed demonstrations' mean vector returns."""
    return moiq_jax.Demonstrations.load(DEMOS / f"{env}.npz").mean_returns()


def last_window_mean(steps: np.ndarray, returns: np.ndarray, axis: int = 1) -> np.ndarray:
    """The mean of ``returns`` over its evaluations (along ``axis``, made at ``steps``) after ``1 - LAST_WINDOW``
    of the last step: what a run ends at, without the weight the EWMA of a short run keeps on its start."""
    return np.compress(steps > (1 - LAST_WINDOW) * steps[-1], returns, axis=axis).mean(axis)


def ewma(values: np.ndarray, alpha: float = EWMA_ALPHA, axis: int = 0) -> np.ndarray:
    """Exponentially weighted moving average along ``axis`` (the paper's smoothing, alpha = 0.1)."""
    values = np.moveaxis(np.asarray(values, np.float64), axis, 0)
    smoothed = np.empty_like(values)
    smoothed[0] = values[0]
    for t in range(1, len(values)):
        smoothed[t] = alpha * values[t] + (1 - alpha) * smoothed[t - 1]
    return np.moveaxis(smoothed, 0, axis)


def curves_figure(envs, methods_of, path: pathlib.Path, note: str = "") -> dict[str, dict]:
    """One row of learning-curve panels per env, one panel per expert preference: the mean and spread over
    seeds of each method's EWMA-smoothed evaluation returns (``methods_of(env)`` -> {method: (steps, returns
    [seeds, evals, E])}, as ``evaluation_returns``) with the expert's return; saved to ``path``. Returns, per env,
    preference and method (means over seeds), the first evaluation's return (where training starts from), the
    final EWMA return and the ``last_window_mean``, keyed by the names the figures' JSON gives them."""
    first, final, last = {}, {}, {}
    fig, axes = plt.subplots(len(envs), 3, figsize=(13, 3.2 * len(envs)), layout="constrained", squeeze=False)
    for row, env in zip(axes, envs):
        methods = methods_of(env)
        preferences = moiq_config(env).preferences
        expert = (expert_returns(env) * np.asarray(preferences)).sum(-1)
        for e, ax in enumerate(row):
            key = str(list(preferences[e]))
            for method, (steps, returns) in methods.items():
                curves = ewma(returns[:, :, e], axis=1)
                mean, std = curves.mean(0), curves.std(0)
                ax.plot(steps, mean, label=method)
                ax.fill_between(steps, mean - std, mean + std, alpha=0.2)
                first.setdefault(env, {}).setdefault(key, {})[method] = round(float(returns[:, 0, e].mean()), 2)
                final.setdefault(env, {}).setdefault(key, {})[method] = round(float(mean[-1]), 2)
                last.setdefault(env, {}).setdefault(key, {})[method] = round(
                    float(last_window_mean(steps, returns[:, :, e]).mean()), 2)
            ax.axhline(expert[e], color="k", linestyle="--", label="expert")
            ax.set_title(f"{env} {list(preferences[e])}{note}", fontsize=9)
            ax.set_xlabel("env steps per expert")
            ax.xaxis.set_major_formatter(lambda steps, _: f"{steps / 1000:g}K")
        row[0].set_ylabel("EWMA scalarised return")
    axes[0][0].legend(fontsize=7)
    fig.savefig(path, dpi=120)
    return {"first_evaluation_return": first, "final_ewma_return": final, "final_last_window_return": last}


def protocol_record(args) -> dict:
    """What every output file names: the protocol, its settings and the seeds."""
    protocol = protocol_of(args)
    return {"protocol": protocol, "protocol_settings": protocol_settings(protocol),
            "seeds": 2 if args.quick else args.seeds}


def process_wall_seconds() -> float | None:
    """Wall seconds since this process started (from Linux's /proc; None where there is none)."""
    try:
        start_ticks = int(pathlib.Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime = float(pathlib.Path("/proc/uptime").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return round(uptime - start_ticks / os.sysconf("SC_CLK_TCK"), 1)


def provenance() -> dict:
    """How an output was made: the command line, the code's commit (and whether moiq_jax/ or experiments/ had
    uncommitted changes; None outside a git checkout), the machine, and the script's wall seconds so far."""
    def git(*command: str) -> str | None:
        try:
            done = subprocess.run(["git", "-C", str(ROOT), *command], capture_output=True, text=True, timeout=30,
                                  check=False)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    changes = git("status", "--porcelain", "--", "moiq_jax", "experiments") if commit else None
    return {"command": shlex.join(["python", *sys.argv]), "commit": commit,
            "uncommitted_changes": None if changes is None else bool(changes),
            "machine": f"{host_description()}, jax {jax.__version__} on {jax.devices()[0].platform}",
            "wall_seconds": process_wall_seconds(),
            "written": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def write_outputs(out: pathlib.Path, name: str, args, rows: list[dict] | None, **summary) -> None:
    """``out/<name>.csv`` (``rows``, dicts with the same keys, each with the protocol's name; None: no CSV)
    and ``out/<name>.json`` (the protocol record, ``summary``, the rows and the ``provenance``)."""
    record = {**protocol_record(args), "provenance": provenance()}
    if rows:
        with open(out / f"{name}.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[*rows[0], "protocol"])
            writer.writeheader()
            writer.writerows({**row, "protocol": record["protocol"]} for row in rows)
    (out / f"{name}.json").write_text(json.dumps({**record, **summary, **({"rows": rows} if rows else {})}, indent=1))
