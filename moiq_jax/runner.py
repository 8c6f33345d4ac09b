"""The host loop of a chunked training run: jitted chunks, with logging, checkpoints and resume between them.

A trainer gives pure ``init(key) -> state`` and ``run_chunk(state, hyper) -> (state, metrics)`` and the
config's swept values ``hyper``; the state
carries everything (parameters, optimiser states, replay buffers, RNG keys) and the attributes
``best_params`` and ``best_return``. After every chunk the state is checkpointed, so a killed run resumes
from its last chunk and ends with the same result as an uninterrupted one.
"""

from __future__ import annotations

import os
import time

import jax
import jax.numpy as jnp
import numpy as np


class TrainingDiverged(RuntimeError):
    """A chunk produced a NaN or infinite metric; the last good checkpoint is kept."""


def _to_json(metrics: dict) -> dict:
    return {name: np.asarray(value).tolist() for name, value in metrics.items()}


def _summary(metrics: dict) -> str:
    returns = np.asarray(metrics.get("eval_scalar_return", []), float).reshape(-1)
    return "scalarised returns [" + ", ".join(f"{r:.2f}" for r in returns) + "]"


def run_chunks(trainer, config, run_dir: str | None = None, resume: bool = False, log=print,
               progress: bool = False, until=None, on_chunk=None):
    """Run every chunk of ``trainer`` for ``config``, or with ``until`` (metrics -> bool) up to the first
    chunk whose metrics it holds true for; returns ``(state, history list, seconds)``. ``on_chunk(state,
    history)`` runs after every chunk (to keep results of a run that may be cut short).

    With ``run_dir``: metrics go to ``run_dir`` (RunLog), the state after each chunk and the best
    parameters to ``run_dir/checkpoints``; ``resume=True`` continues from the newest checkpoint there.
    Raises TrainingDiverged, naming the env step, when a chunk's metrics are not finite.
    """
    start = time.perf_counter()
    state = jax.jit(trainer.init)(jax.random.PRNGKey(config.seed))
    run_chunk = jax.jit(trainer.run_chunk)
    hyper = {name: jnp.float32(value) for name, value in trainer.hyper.items()}
    label = " ".join([config.algo, *(f"{name}={value}" for name, value in trainer.hyper.items())])
    steps_per_chunk = config.offpolicy.eval_interval
    total_steps = steps_per_chunk * trainer.num_chunks
    history, first_chunk = [], 0
    checkpoints = runlog = None
    if run_dir is not None:
        from moiq_jax.checkpoint import Checkpoints  # orbax and tensorboardX load only for runs that use them
        from moiq_jax.runlog import RunLog

        checkpoints = Checkpoints(os.path.join(run_dir, "checkpoints"))
        if resume:
            state, meta = checkpoints.restore(state)
            first_chunk = meta["chunk"]
            history = [{k: np.asarray(v) for k, v in m.items()} for m in meta["history"]]
        else:
            checkpoints.save(0, state, {"chunk": 0, "history": []})  # so even the first chunk can fail safely
        runlog = RunLog(run_dir, config, total_steps, resume_step=first_chunk * steps_per_chunk, progress=progress)
    try:
        for chunk in range(first_chunk, trainer.num_chunks):
            new_state, metrics = run_chunk(state, hyper)
            metrics = jax.device_get(metrics)
            step = (chunk + 1) * steps_per_chunk
            bad = sorted(name for name, value in metrics.items() if not np.all(np.isfinite(value)))
            if bad:
                kept = f"; the last good checkpoint is at env step {chunk * steps_per_chunk}" if checkpoints else ""
                raise TrainingDiverged(f"non-finite {', '.join(bad)} in the chunk ending at env step {step}{kept}")
            improved = bool(np.any(np.asarray(new_state.best_return) > np.asarray(state.best_return)))
            state = new_state
            history.append(metrics)
            # Log before checkpointing: a run killed in between resumes from the previous checkpoint and
            # drops the rows logged after it, so every evaluation is logged exactly once.
            if runlog is not None:
                runlog.log(step, metrics, _summary(metrics))
            if checkpoints is not None:
                checkpoints.save(step, state, {"chunk": chunk + 1, "history": [_to_json(m) for m in history]})
                if improved:
                    checkpoints.save_best(step, state.best_params,
                                          {"best_return": np.asarray(state.best_return).tolist()})
            if log is not None:
                log(f"[{label}] steps {step}: {_summary(metrics)} "
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
