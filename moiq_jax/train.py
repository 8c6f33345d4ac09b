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

from moiq_jax.algos import gail, iq_learn, moiq, moiq_preference_inference, preference_inference, sac
from moiq_jax.algos.offpolicy import Algorithm, make_trainer
from moiq_jax.config import Config
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.loading import load_demonstrations, match_preferences, take_experts
from moiq_jax.preferences import check_preferences
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
    if config.algo == "moiq" and config.infer_preferences:  # MOIQ in an outer loop that infers the preferences
        return moiq_preference_inference.ALGORITHM
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
        if demos is not None:
            raise ValueError(f"{config.algo}{' inferring preferences' if config.infer_preferences else ''} reads its "
                             "demonstrations from config.demos (a file) or the oracle experts, not a demos argument")
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


def preference_sets(sets, reward_dim: int, demos=None) -> tuple[list[np.ndarray], list]:
    """``sets`` (each a list of preferences) checked to have one size, and ``demos`` matched to them: None
    (each set's oracle demonstrations), or one ``Demonstrations`` or file path per set."""
    checked = [check_preferences(s, reward_dim, what=f"preference set {i}") for i, s in enumerate(sets)]
    if not checked:
        raise ValueError("preferences=[...]: give at least one preference set")
    sizes = [len(s) for s in checked]
    if len(set(sizes)) != 1:
        raise ValueError(f"every preference set of one sweep needs the same number of experts (they train as one "
                         f"program), got sizes {sizes}; sweep sets of each size separately")
    if demos is None or isinstance(demos, (Demonstrations, str)):
        if demos is not None and len(checked) > 1:
            raise ValueError(f"{len(checked)} preference sets need one demonstrations file each, got one")
        demos = [demos] * len(checked)
    if len(demos) != len(checked):
        raise ValueError(f"{len(checked)} preference sets need one demonstrations file each, got {len(demos)}")
    return checked, list(demos)


def sweep(config: Config, demos=None, **values) -> Result:
    """Train every combination of the given values (``seed=[...]``, and the algorithm's hyperparameters,
    e.g. ``beta=[...]`` for moiq; the config's value for those not given) as one vmapped, compiled program,
    sharded over the run axis when several devices are present and they divide the number of runs (on
    CPU, ``runtime.split_cpu_into_devices`` makes the devices). Returns a ``Result`` with a run axis.

    ``preferences=[set_1, set_2, ...]`` also sweeps preference sets of one size (each set's demonstrations
    and preferences are inputs of the program, not constants); ``demos`` is then one ``Demonstrations`` or
    file path per set (None: the env's oracle experts), and ``runs`` holds each run's ``set`` index and its
    ``preferences``, in the order given, as ``Result.preferences`` ``[runs, E, d]`` does."""
    algorithm = algorithm_of(config)
    validate(config)
    known = swept_names(config)
    sets = values.pop("preferences", None)
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise ValueError(f"a sweep of {config.algo} varies {', '.join(known)}; got {unknown} "
                         "(and preference sets, as preferences=[set, ...])")
    if not isinstance(algorithm, Algorithm):
        if sets is not None:
            raise ValueError(f"a sweep of {config.algo} varies seed only; train each preference set separately")
        return algorithm.train_seeds(config, [config.seed] if values.get("seed") is None else values["seed"])
    start = time.perf_counter()
    swept_sets = sets is not None
    if sets is None:
        trainer = make_trainer(config, algorithm, demos)
        setups, sets = [trainer.setup], [trainer.preferences]
        given = sets
    else:
        raw = sets
        sets, set_demos = preference_sets(sets, config.make_env().reward_dim, demos)
        given = [np.asarray(s, np.float64) for s in raw]  # the labels as given, not rounded to float32
        as_config = lambda s: tuple(map(tuple, s.tolist()))
        trainer = make_trainer(config.replace(preferences=as_config(sets[0])), algorithm,
                               set_demos_of(config, sets[0], set_demos[0], 0))
        setups = [trainer.setup] + [trainer.make_setup(s, set_demos_of(config, s, d, i + 1))
                                    for i, (s, d) in enumerate(zip(sets[1:], set_demos[1:]))]
    defaults = {**trainer.hyper, "seed": config.seed}
    grid = {name: [defaults[name]] if values.get(name) is None else values[name] for name in known}
    runs = run_grid({**{k: v for k, v in grid.items() if k != "seed"}, "set": range(len(sets)), "seed": grid["seed"]})
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(runs["seed"], jnp.uint32))
    hyper = {name: jnp.asarray(runs[name], jnp.float32) for name in trainer.hyper}
    setup = jax.tree_util.tree_map(lambda *x: jnp.stack(x)[runs["set"]], *setups)
    keys, hyper, setup = shard_runs(keys, hyper, setup)

    def one(key, hyper, setup):
        state, history = trainer.train_with(key, hyper, setup)
        return (trainer.to_config_order(state.learner.params, 0, setup["back"]),
                trainer.to_config_order(state.best_params, 0, setup["back"]), state.best_return, history)

    final, best, best_return, history = jax.jit(jax.vmap(one))(keys, hyper, setup)
    runs = {name: np.asarray(v, np.float32) if name in hyper else v for name, v in runs.items()}
    preferences = np.stack(given)[runs["set"]]
    if swept_sets:
        runs["preferences"] = preferences
    else:
        runs.pop("set")
        preferences = trainer.preferences
    return Result(config, preferences, jax.device_get(history), final, best, np.asarray(best_return),
                  time.perf_counter() - start, runs=runs)


def set_demos_of(config: Config, preferences, demos, index: int) -> Demonstrations | None:
    """Preference set ``index``'s demonstrations in its order: ``demos`` (matched to the set by their
    preferences), or loaded from a file path (matched too), or None (the oracle experts, loaded by the trainer)."""
    if demos is None:
        return None
    try:
        if isinstance(demos, str):
            return load_demonstrations(config.replace(preferences=tuple(map(tuple, preferences.tolist())), demos=demos))
        if getattr(demos, "preferences", None) is None:
            raise ValueError("the demos given carry no preferences to match to the set")
        return take_experts(demos, match_preferences(demos.preferences, preferences, "the demos given"))
    except ValueError as err:
        raise ValueError(f"preference set {index}: {err}") from None
