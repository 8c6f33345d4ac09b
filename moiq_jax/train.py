"""``train(config)`` and ``sweep(config, ...)``: run the configured algorithm, one run or a vmapped grid.

``ALGORITHMS`` is the registry, name -> the algorithm's object: an ``offpolicy.Algorithm`` (run by the
one off-policy loop) or ADMM's tabular program. Both return a ``Result``.
"""

from __future__ import annotations

import itertools
import time

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax.algos import gail, iq_learn, moiq, preference_inference, sac
from moiq_jax.algos.offpolicy import Algorithm, make_trainer
from moiq_jax.config import Config
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.result import Result
from moiq_jax.runner import run_chunks
from moiq_jax.runtime import shard_runs

ALGORITHMS = {
    "moiq": moiq.ALGORITHM,
    "iq_learn": iq_learn.ALGORITHM,
    "sac": sac.ALGORITHM,
    "gail": gail.ALGORITHM,
    "admm": preference_inference.ALGORITHM,  # consensus ADMM, inferring the preferences with infer_preferences
}


def algorithm_of(config: Config):
    """The registered algorithm ``config.algo``; unknown names raise, listing the known ones."""
    if config.algo not in ALGORITHMS:
        raise ValueError(f"unknown algo {config.algo!r}; known algorithms: {', '.join(ALGORITHMS)}")
    return ALGORITHMS[config.algo]


def validate(config: Config, env=None) -> Config:
    """``config``'s common fields and the sections its algorithm reads; raises ValueError naming a bad field."""
    return config.validate(env, sections=algorithm_of(config).sections)


def swept_names(config: Config) -> tuple[str, ...]:
    """What a sweep of ``config``'s algorithm may vary: its hyperparameters, then ``seed``."""
    algorithm = algorithm_of(config)
    return (*algorithm.hyper(config), "seed") if isinstance(algorithm, Algorithm) else ("seed",)


def train(config: Config, demos: Demonstrations | None = None, log=print, run_dir: str | None = None,
          resume: bool = False, progress: bool = False, until=None, on_chunk=None) -> Result:
    """Run ``config``'s algorithm. The off-policy ones run jitted chunks of ``eval_interval`` env steps,
    logged in between; with ``run_dir``, also checkpointed after every chunk and resumable (see
    ``moiq_jax.runner``); with ``until``, stopped after the first evaluation whose metrics (a dict of
    arrays) it holds true for; ``on_chunk(state, history)`` is called after every evaluation (the state's
parameters in the config's expert order). ``demos``
    (in the config's preference order) replaces the configured ones."""
    algorithm = algorithm_of(config)
    validate(config)
    if not isinstance(algorithm, Algorithm):
        return algorithm.train_seeds(config, [config.seed]).run(0)
    trainer = make_trainer(config, algorithm, demos)

    def in_config_order(state):
        return state.replace(best_params=trainer.to_config_order(state.best_params),
                             learner=state.learner.replace(params=trainer.to_config_order(state.learner.params)))

    hook = None if on_chunk is None else (lambda state, history: on_chunk(in_config_order(state), history))
    state, history, seconds = run_chunks(trainer, config, run_dir=run_dir, resume=resume, log=log, progress=progress,
                                         until=until, on_chunk=hook)
    stacked = {k: np.stack([h[k] for h in history]) for k in history[0]}
    state = in_config_order(state)
    return Result(config, trainer.preferences, stacked, state.learner.params, state.best_params,
                  np.asarray(state.best_return), seconds)


def run_grid(values: dict) -> dict[str, np.ndarray]:
    """Every combination of ``values`` (name -> list), the first name outermost: name -> value per run."""
    names = list(values)
    grid = list(itertools.product(*(list(values[name]) for name in names)))
    return {name: np.asarray([run[i] for run in grid]) for i, name in enumerate(names)}


def sweep(config: Config, demos: Demonstrations | None = None, **values) -> Result:
    """Train every combination of the given values (``seed=[...]``, and the algorithm's hyperparameters,
    e.g. ``beta=[...]`` for moiq; the config's value for those not given) as one vmapped, compiled program,
    sharded over the run axis when several devices are present and they divide the number of runs (on
    CPU, ``runtime.split_cpu_into_devices`` makes the devices). Returns a ``Result`` with a run axis."""
    algorithm = algorithm_of(config)
    validate(config)
    known = swept_names(config)
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise ValueError(f"a sweep of {config.algo} varies {', '.join(known)}; got {unknown}")
    if not isinstance(algorithm, Algorithm):
        return algorithm.train_seeds(config, [config.seed] if values.get("seed") is None else values["seed"])
    start = time.perf_counter()
    trainer = make_trainer(config, algorithm, demos)
    defaults = {**trainer.hyper, "seed": config.seed}
    runs = run_grid({name: [defaults[name]] if values.get(name) is None else values[name] for name in known})
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(runs["seed"], jnp.uint32))
    hyper = {name: jnp.asarray(runs[name], jnp.float32) for name in trainer.hyper}
    keys, hyper = shard_runs(keys, hyper)
    state, history = jax.jit(jax.vmap(trainer.train))(keys, hyper)
    runs = {name: np.asarray(v, np.float32) if name in hyper else v for name, v in runs.items()}
    return Result(config, trainer.preferences, jax.device_get(history),
                  trainer.to_config_order(state.learner.params, axis=1), trainer.to_config_order(state.best_params, axis=1),
                  np.asarray(state.best_return), time.perf_counter() - start, runs=runs)
