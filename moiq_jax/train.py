"""``train(config)`` and ``sweep(config, ...)``: run the configured algorithm, one run or a vmapped grid.

``ALGORITHMS`` is the registry, name -> the algorithm's object: an ``offpolicy.Algorithm`` (run by the
one off-policy loop) or ADMM's tabular program. Both return a ``Result``.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import os
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
from moiq_jax.runner import all_runs, one_run, run_chunks
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
                             learner=state.learner.replace(params=trainer.to_config_order(state.learner.params)),
                             **per_expert_in_order(state, trainer.setup["back"]))

    hook = None if on_chunk is None else (lambda state, history: on_chunk(in_config_order(state), history))
    state, history, seconds = run_chunks(one_run(trainer, config), run_dir=run_dir, resume=resume, log=log,
                                         progress=progress, until=until, on_chunk=hook)
    stacked = {k: np.stack([h[k] for h in history]) for k in history[0]}
    state = in_config_order(state)
    return Result(config, trainer.preferences, stacked, state.learner.params, state.best_params,
                  np.asarray(state.best_return), seconds,
                  **as_result_fields({"best_actor_per_expert": state.best_actor_per_expert,
                                      "best_return_per_expert": state.best_return_per_expert}))


def per_expert_in_order(state, back) -> dict:
    """A one-model trainer state's per-expert best actors and returns with their experts put in the order
    ``back`` gives (canonical -> config order); nothing for one model per expert."""
    if state.best_actor_per_expert is None:
        return {}
    take = lambda x: jnp.take(x, back, axis=0)
    return {"best_actor_per_expert": jax.tree_util.tree_map(take, state.best_actor_per_expert),
            "best_return_per_expert": take(state.best_return_per_expert)}


def as_result_fields(per_expert: dict) -> dict:
    """Per-expert best actors and returns (a dict possibly empty or None-valued, experts in the config's order)
    as ``Result`` keyword arguments."""
    if per_expert.get("best_return_per_expert") is None:
        return {}
    return {"best_actor_per_expert": per_expert["best_actor_per_expert"],
            "best_return_per_expert": np.asarray(per_expert["best_return_per_expert"])}


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


def sweep(config: Config, demos=None, run_dir: str | None = None, resume: bool = False, log=print,
          **values) -> Result:
    """Train every combination of the given values (``seed=[...]``, and the algorithm's hyperparameters,
    e.g. ``beta=[...]`` for moiq; the config's value for those not given) as one vmapped program, sharded
    over the run axis when several devices are present and they divide the number of runs (on CPU,
    ``runtime.split_cpu_into_devices`` makes the devices). Returns a ``Result`` with a run axis.

    Without ``run_dir`` the whole training is one compiled program (the fastest; nothing to resume). With
    ``run_dir`` it runs chunk by chunk (``eval_interval`` env steps each, logged by ``log``): the sweep's
    config and values go to ``run_dir/sweep.json``, each run's config and metrics to
    ``run_dir/<name><value>-...`` (``run_dir_names``), the state of all runs to ``run_dir/checkpoints``
    after every chunk; ``resume=True`` continues a sweep cut there (given the same config, values and
    demos), ending with the same result as an uninterrupted checkpointed one. (The two shapes compile to
    different programs, so their float results are not bit-identical.)

    ``preferences=[set_1, set_2, ...]`` also sweeps preference sets of one size (each set's demonstrations
    and preferences are inputs of the program, not constants); ``demos`` is then one ``Demonstrations`` or
    file path per set (None: the env's oracle experts), and ``runs`` holds each run's ``set`` index and its
    ``preferences``, in the order given, as ``Result.preferences`` ``[runs, E, d]`` does."""
    algorithm = algorithm_of(config)
    validate(config)
    known = swept_names(config)
    values = {name: value for name, value in values.items() if value is not None}
    given_values = dict(values)
    sets = values.pop("preferences", None)
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise ValueError(f"a sweep of {config.algo} varies {', '.join(known)}; got {unknown} "
                         "(and preference sets, as preferences=[set, ...])")
    if resume and run_dir is None:
        raise ValueError("resume=True continues the sweep saved in run_dir; give run_dir")
    if not isinstance(algorithm, Algorithm):
        if sets is not None:
            raise ValueError(f"a sweep of {config.algo} varies seed only; train each preference set separately")
        if run_dir is not None:
            raise ValueError(f"a sweep of {config.algo} is one program of seconds, not checkpointed; drop run_dir")
        return algorithm.train_seeds(config, [config.seed] if values.get("seed") is None else values["seed"])
    start = time.perf_counter()
    swept_sets = sets is not None
    if sets is None:
        trainer = make_trainer(config, algorithm, demos) if demos is not None else _config_trainer(config)
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
    runs = {name: np.asarray(v, np.float32) if name in hyper else v for name, v in runs.items()}
    preferences = np.stack(given)[runs["set"]]
    if swept_sets:
        runs["preferences"] = preferences
    else:
        runs.pop("set")
        preferences = trainer.preferences
    def final_and_best(state, back):
        """One run's final and best parameters and per-expert bests, their experts in the config's order."""
        return (trainer.to_config_order(state.learner.params, 0, back),
                trainer.to_config_order(state.best_params, 0, back), per_expert_in_order(state, back))

    if run_dir is None:
        def one(key, hyper, setup):
            state, history = trainer.train_with(key, hyper, setup)
            return (*final_and_best(state, setup["back"]), state.best_return, history)

        final, best, per_expert, best_return, history = jax.jit(jax.vmap(one))(keys, hyper, setup)
        return Result(config, preferences, jax.device_get(history), final, best, np.asarray(best_return),
                      time.perf_counter() - start, runs=runs, **as_result_fields(per_expert))
    names = run_dir_names(runs)
    each = Result(config, preferences, {}, None, None, np.zeros(len(names)), runs=runs)  # for each run's config
    _record_sweep(run_dir, config, given_values, demos, _digest(setups), resume)
    state, history, _ = run_chunks(all_runs(trainer, config, keys, hyper, setup, names,
                                            [each.run(i).config for i in range(len(names))]),
                                   run_dir=run_dir, resume=resume, log=log)
    final, best, per_expert = jax.jit(jax.vmap(final_and_best))(state, setup["back"])
    history = {name: np.stack([h[name] for h in history], axis=1) for name in history[0]}
    return Result(config, preferences, history, final, best, np.asarray(state.best_return),
                  time.perf_counter() - start, runs=runs, **as_result_fields(per_expert))


def _config_trainer(config: Config):
    """``make_trainer`` of ``config`` with the demonstrations it names, kept for the next sweep of the same
    config (and demonstrations file, unchanged) in this process: sweeps that differ only in their swept
    values (a script's beta after beta) then run one compiled chunk. A MuJoCo chunk steps its simulator by a
    host callback, which JAX's persistent compilation cache cannot keep, so each new trainer compiles anew."""
    stamp = None
    if config.demos is not None and os.path.exists(config.demos):
        stat = os.stat(config.demos)
        stamp = (stat.st_mtime_ns, stat.st_size)
    return _trainer_of(config, stamp)


@functools.lru_cache(maxsize=2)
def _trainer_of(config: Config, demos_stamp):
    return make_trainer(config, algorithm_of(config))


def run_dir_names(runs: dict) -> list[str]:
    """Each run's directory name in a sweep directory, its swept values: ``beta0.5-set1-seed0``."""
    swept = {name: v for name, v in runs.items() if name != "preferences"}
    return ["-".join(f"{name}{v[run].item():g}" for name, v in swept.items()) for run in range(len(runs["seed"]))]


SWEEP_FILE = "sweep.json"  # in a sweep's run_dir: the config, swept values and demos it was started with


def _as_json(value):
    return json.loads(json.dumps(value, default=lambda x: np.asarray(x).tolist()))


def _digest(setups) -> str:
    """A fingerprint of the preference sets' inputs (demonstrations, preferences), to check a resumed sweep's."""
    digest = hashlib.sha256()
    for leaf in jax.tree_util.tree_leaves(jax.device_get(setups)):
        digest.update(np.ascontiguousarray(leaf).tobytes())
    return digest.hexdigest()


def _record_sweep(run_dir: str, config: Config, values: dict, demos, digest: str, resume: bool) -> None:
    """Write ``run_dir/sweep.json``; on ``resume``, check that the saved one is this sweep's."""
    path = os.path.join(run_dir, SWEEP_FILE)
    paths = demos is None or isinstance(demos, str) or (
        isinstance(demos, (list, tuple)) and all(d is None or isinstance(d, str) for d in demos))
    record = _as_json({"config": config.to_dict(), "values": values, "demos": demos if paths else None,
                       "inputs": digest})
    if not resume:
        if os.path.exists(path) or os.path.exists(os.path.join(run_dir, "checkpoints")):
            raise ValueError(f"{run_dir!r} already holds a sweep; continue it with resume=True (`moiq sweep --resume "
                             f"{run_dir}`) or choose another directory")
        os.makedirs(run_dir, exist_ok=True)
        with open(path, "w") as f:
            json.dump(record, f, indent=1)
        return
    saved = _read_sweep(run_dir)
    # Where the demonstrations file lies may change (another checkout of it); its contents are the inputs' digest.
    for part in (saved, record):
        part["config"] = {name: value for name, value in part["config"].items() if name != "demos"}
    for what, key in (("config", "config"), ("swept values", "values"), ("demonstrations", "inputs")):
        if saved[key] != record[key]:
            if key == "config":
                given, kept = record[key], saved[key]
                differ = sorted(name for name in {*given, *kept} if given.get(name) != kept.get(name))
                detail = "; ".join(f"{name}: saved {kept.get(name)!r}, given {given.get(name)!r}" for name in differ)
            elif key == "values":
                detail = f"saved {saved[key]}, given {record[key]}"
            else:
                detail = "the preference sets' demonstrations or preferences differ"
            raise ValueError(f"{run_dir!r} holds a sweep of other {what} ({detail}); resume it with the saved "
                             "ones (`moiq sweep --resume` reads them)")


def _read_sweep(run_dir: str) -> dict:
    path = os.path.join(run_dir, SWEEP_FILE)
    if not os.path.exists(path):
        raise ValueError(f"{run_dir!r} is not a sweep directory (no {SWEEP_FILE}; `moiq sweep` and sweep(..., "
                         "run_dir=...) write one)")
    with open(path) as f:
        return json.load(f)


def saved_sweep(run_dir: str) -> tuple[Config, dict, object]:
    """``(config, values, demos)`` a sweep directory was started with: ``sweep(config, demos, run_dir,
    resume=True, **values)`` continues it."""
    saved = _read_sweep(run_dir)
    return Config(**saved["config"]), saved["values"], saved["demos"]


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
