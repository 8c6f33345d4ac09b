"""The host loop of chunked training: jitted chunks, with logging, checkpoints and resume between them.

``run_chunks`` runs a ``Program``: one run (``one_run``) or a sweep's runs vmapped side by side
(``all_runs``). A trainer gives pure ``init(key, setup)`` and ``run_chunk(state, hyper, setup) -> (state,
metrics)``; the state carries everything (parameters, optimiser states, replay buffers, RNG keys) and the
attributes ``best_params`` and ``best_return``. After every chunk the state is checkpointed, so a killed
run resumes from its last chunk and ends with the same result as an uninterrupted one.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class TrainingDiverged(RuntimeError):
    """A chunk produced a NaN or infinite metric; the last good checkpoint is kept."""


class Program(NamedTuple):
    """What ``run_chunks`` runs. init: ``() -> state``; step: ``state -> (state, metrics)``, jitted, the
    state given to it donated; open_log: ``(run_dir, resume_step, progress) -> log`` with ``log(step,
    metrics, summary)`` and ``close()``; run_names: for a sweep, one name per run (state and metrics then
    have a leading run axis), None for one run."""

    init: Callable[[], Any]
    step: Callable[[Any], tuple[Any, dict]]
    num_chunks: int
    steps_per_chunk: int
    label: str
    open_log: Callable
    run_names: tuple[str, ...] | None = None


def one_run(trainer, config) -> Program:
    """The chunks of one run of ``trainer`` (``config``'s seed and swept values)."""
    from moiq_jax.runlog import RunLog  # tensorboardX loads only for runs that log

    hyper = {name: jnp.float32(value) for name, value in trainer.hyper.items()}
    step = jax.jit(trainer.run_chunk, donate_argnums=0)
    total_steps = config.offpolicy.eval_interval * trainer.num_chunks
    return Program(lambda: jax.jit(trainer.init)(jax.random.PRNGKey(config.seed)), lambda state: step(state, hyper),
                   trainer.num_chunks, config.offpolicy.eval_interval,
                   " ".join([config.algo, *(f"{name}={value}" for name, value in trainer.hyper.items())]),
                   lambda run_dir, resume_step, progress: RunLog(run_dir, config, total_steps, resume_step, progress))


def all_runs(trainer, config, keys, hyper, setup, run_names, run_configs) -> Program:
    """The chunks of a sweep: every run's ``trainer.run_chunk`` vmapped over the leading run axis of
    ``keys`` (one PRNG key per run), ``hyper`` and ``setup`` (placed as given, e.g. sharded over the run
    axis by ``runtime.shard_runs``: the state and metrics are then sharded alike), run ``i`` logged to
    ``run_dir/run_names[i]`` under ``run_configs[i]``."""
    from moiq_jax.runlog import RunLogs

    # Every output keeps the runs' sharding (XLA would leave what does not depend on the inputs, such as the
    # empty replay buffers, on one device, and a chunk then runs every run there).
    sharding = keys.sharding if isinstance(keys.sharding, jax.sharding.NamedSharding) else None
    init, step = _vmapped(trainer.init, trainer.run_chunk, sharding)
    total_steps = config.offpolicy.eval_interval * trainer.num_chunks
    return Program(lambda: init(keys, setup), lambda state: step(state, hyper, setup), trainer.num_chunks,
                   config.offpolicy.eval_interval, f"{config.algo} sweep of {len(run_names)} runs",
                   lambda run_dir, resume_step, progress: RunLogs(run_dir, run_names, run_configs, total_steps,
                                                                  resume_step),
                   tuple(run_names))


@functools.lru_cache(maxsize=4)
def _vmapped(init, run_chunk, sharding):
    """``init`` and ``run_chunk`` vmapped over runs and jitted, one pair per trainer and sharding, so that the
    sweeps of one trainer (``train.sweep`` reuses it across a script's sweeps) compile their chunk once."""
    return (jax.jit(jax.vmap(init), out_shardings=sharding),
            jax.jit(jax.vmap(run_chunk), donate_argnums=0, out_shardings=sharding))


def _to_json(metrics: dict) -> dict:
    return {name: np.asarray(value).tolist() for name, value in metrics.items()}


def _from_json(metrics: dict, dtypes: dict) -> dict:
    """Metrics read back from a checkpoint's JSON, in the dtypes they were computed in (JSON keeps numbers only)."""
    return {name: np.asarray(value, dtypes.get(name)) for name, value in metrics.items()}


def _summary(metrics: dict) -> str:
    returns = np.asarray(metrics.get("eval_scalar_return", []), float)
    if returns.ndim == 2:  # a sweep: [runs, experts]
        return "mean scalarised return per run [" + ", ".join(f"{r:.2f}" for r in returns.mean(axis=1)) + "]"
    return "scalarised returns [" + ", ".join(f"{r:.2f}" for r in returns.reshape(-1)) + "]"


def _bad_runs(metrics: dict, bad: list[str], run_names) -> str:
    """`` (runs a, b)``: the runs of a sweep whose ``bad`` metrics are not finite."""
    if run_names is None:
        return ""
    finite = np.all([np.isfinite(np.asarray(metrics[name], float).reshape(len(run_names), -1)).all(axis=1)
                     for name in bad], axis=0)
    return f" (runs {', '.join(name for name, ok in zip(run_names, finite) if not ok)})"


def run_chunks(program: Program, run_dir: str | None = None, resume: bool = False, log=print,
               progress: bool = False, until=None, on_chunk=None):
    """Run every chunk of ``program``, or with ``until`` (metrics -> bool) up to the first chunk whose
    metrics it holds true for; returns ``(state, history list, seconds)``. ``on_chunk(state, history)``
    runs after every chunk (to keep results of a run that may be cut short); the state it is given lives
    until the next chunk, which takes over its buffers (donated, so that a chunk needs no second copy of
    the replay buffers).

    With ``run_dir``: metrics go to ``program.open_log(run_dir, ...)``, the state after each chunk and the
    best parameters to ``run_dir/checkpoints``; ``resume=True`` continues from the newest checkpoint there.
    Raises TrainingDiverged, naming the env step (and a sweep's runs), when a chunk's metrics are not finite.
    """
    start = time.perf_counter()
    state = program.init()
    steps_per_chunk = program.steps_per_chunk
    history, dtypes, first_chunk = [], {}, 0
    checkpoints = runlog = None
    if run_dir is not None:
        from moiq_jax.checkpoint import Checkpoints  # orbax loads only for runs that use it

        checkpoints = Checkpoints(os.path.join(run_dir, "checkpoints"))
        if resume:
            state, meta = checkpoints.restore(state)
            first_chunk, dtypes = meta["chunk"], meta.get("dtypes", {})
            history = [_from_json(m, dtypes) for m in meta["history"]]
        else:
            checkpoints.save(0, state, {"chunk": 0, "history": []})  # so even the first chunk can fail safely
        runlog = program.open_log(run_dir, first_chunk * steps_per_chunk, progress)
    try:
        for chunk in range(first_chunk, program.num_chunks):
            best_before = np.asarray(state.best_return)
            state, metrics = program.step(state)  # the old state's buffers are donated to the new one
            metrics = jax.device_get(metrics)
            dtypes = {name: np.asarray(value).dtype.name for name, value in metrics.items()}
            step = (chunk + 1) * steps_per_chunk
            bad = sorted(name for name, value in metrics.items() if not np.all(np.isfinite(value)))
            if bad:
                kept = f"; the last good checkpoint is at env step {chunk * steps_per_chunk}" if checkpoints else ""
                raise TrainingDiverged(f"non-finite {', '.join(bad)} in the chunk ending at env step {step}"
                                       f"{_bad_runs(metrics, bad, program.run_names)}{kept}")
            improved = bool(np.any(np.asarray(state.best_return) > best_before))
            history.append(metrics)
            # Log before checkpointing: a run killed in between resumes from the previous checkpoint and
            # drops the rows logged after it, so every evaluation is logged exactly once.
            if runlog is not None:
                runlog.log(step, metrics, _summary(metrics))
            if checkpoints is not None:
                checkpoints.save(step, state, {"chunk": chunk + 1, "history": [_to_json(m) for m in history],
                                               "dtypes": dtypes})
                if improved:
                    checkpoints.save_best(step, state.best_params,
                                          {"best_return": np.asarray(state.best_return).tolist()})
            if log is not None:
                log(f"[{program.label}] steps {step}: {_summary(metrics)} "
                    f"({time.perf_counter() - start:.0f}s)")
            if on_chunk is not None:
                on_chunk(state, history)
            if until is not None and until(metrics):
                break
    finally:
        if runlog is not None:
            runlog.close()
        if checkpoints is not None:
            checkpoints.close()
    return state, history, time.perf_counter() - start
