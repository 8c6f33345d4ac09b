"""The ``moiq`` command."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from moiq_jax.config import Config, field_help, field_types, tuned

FIELDS = Config().to_dict()  # every field's flat name (its flag) and default


def _cmd_envs(args) -> int:
    from moiq_jax import envs

    specs = sorted(envs.registered().items())
    width = max(len("name"), *(len(name) for name, _ in specs))
    print(f"{'name':<{width}} {'obs':>4} {'actions':<13} {'reward_dim':>10} {'episode':>8}  {'backends':<11}  "
          "description")
    for name, env_spec in specs:
        env = envs.make(name)
        actions = f"{env.num_actions} discrete" if env.discrete else f"{env.action_size}-D box"
        backends = ",".join(envs.backends(name)) or "jax"  # the default first
        print(f"{name:<{width}} {env.observation_size:>4} {actions:<13} {env.reward_dim:>10} "
              f"{env_spec.episode_length:>8}  {backends:<11}  {env_spec.description}")
    print(f"backends: the first is the default here ({envs.default_backend()}); choose with --env-backend "
          "(mujoco: MuJoCo's C engine, for CPUs; mjx: MJX, for accelerators)")
    return 0


def _format_preference(w) -> str:
    return "[" + ", ".join(f"{x:g}" for x in np.round(np.asarray(w, float), 4)) + "]"


def _format_vector(v) -> str:
    return "(" + ", ".join(f"{x:8.2f}" for x in np.asarray(v)) + ")"


def _cmd_rollout(args) -> int:
    import jax

    from moiq_jax import envs
    from moiq_jax.evaluate import episode_returns, random_policy

    env = envs.make(args.env)
    key = jax.random.key(args.seed)
    if args.policy == "random":
        out = episode_returns(env, random_policy(env), key, args.episodes)
        returns, lengths = np.asarray(out["returns"]), np.asarray(out["lengths"])
        print(f"{args.episodes} random-policy episodes of {args.env}: vector returns (objective 1, objective 2, ...)")
        for i, (ret, length) in enumerate(zip(returns, lengths)):
            print(f"  episode {i:3d}  return {_format_vector(ret)}  length {length:3d}")
        print(f"  mean         return {_format_vector(returns.mean(0))}  length {lengths.mean():5.1f}")
        return 0
    base = env.unwrapped
    if not hasattr(base, "optimal_policy"):
        print(f"error: env {args.env!r} has no optimal policy; use --policy random", file=sys.stderr)
        return 2
    print(f"optimal policy to each treasure of {args.env}: return (treasure, -steps) vs the exact front")
    front = {tuple(p) for p in base.pareto_front().tolist()}
    for treasure in base.sea_map.treasures():
        policy = base.optimal_policy(treasure)
        out = episode_returns(env, lambda k, obs, p=policy: p(obs), key, 1)
        ret = np.asarray(out["returns"][0])
        tag = "on the front" if tuple(ret.tolist()) in front else "dominated"
        print(f"  treasure at {treasure}: return {_format_vector(ret)}  {tag}")
    return 0


def _parse_vector(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(w) for w in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers like 0.9,0.1, got {text!r}") from None


def add_config_flags(parser: argparse.ArgumentParser, repeated: tuple[str, ...] = ()) -> None:
    """A flag for every Config field (``--beta``, ``--total-steps``...), plus ``--config FILE``; the
    ``repeated`` ones may be given several times (a list).

    Flags default to None so that only the ones given override the file's or Config's values."""
    parser.add_argument("--config", metavar="FILE", help="a JSON or YAML file of Config fields; flags override it")
    helps, types = field_help(), field_types()
    for name, default in FIELDS.items():
        flag = "--" + name.replace("_", "-")
        text = f"{helps[name]} (default: {default})"
        if name == "preferences":
            parser.add_argument(flag, nargs="+", type=_parse_vector, metavar="W1,W2", default=None,
                                help=text + "; one comma-separated vector per expert")
        elif name in repeated:
            parser.add_argument(flag, action="append", default=None, help=text + "; repeat it, one per preference set")
        elif isinstance(default, bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=None, help=text)
        elif isinstance(default, tuple):
            parser.add_argument(flag, nargs="+", type=int, default=None, help=text)
        elif isinstance(default, (int, float)):
            parser.add_argument(flag, type=type(default), default=None, help=text)
        elif default is None and types[name].startswith("float"):
            parser.add_argument(flag, type=float, default=None, help=text)
        else:
            parser.add_argument(flag, type=str, default=None, help=text)


def config_from_args(args: argparse.Namespace) -> Config:
    """The Config of a command: the env's tuned settings (``config.tuned``), then the file given by
    ``--config`` (if any), then the flags given."""
    values = {}
    if args.config:
        values = load_config_file(args.config)
    for name in FIELDS:
        given = getattr(args, name, None)
        if given is not None:
            values[name] = given
    return tuned(values.pop("env", Config.env), **values)


def load_config_file(path: str) -> dict:
    """Config fields from a ``.json`` or ``.yaml``/``.yml`` file, with unknown keys named in the error."""
    if not os.path.exists(path):
        raise ValueError(f"config file {path!r} does not exist")
    with open(path) as f:
        if path.endswith((".yaml", ".yml")):
            import yaml

            values = yaml.safe_load(f) or {}
        else:
            values = json.load(f)
    if not isinstance(values, dict):
        raise ValueError(f"config file {path!r} must hold a mapping of Config fields, got {type(values).__name__}")  # noqa: TRY004 (a user's input error, reported as the others)
    known = set(FIELDS)
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"config file {path!r} has unknown fields {unknown}; known fields: {', '.join(sorted(known))}")
    return values


def _saved_config(run_dir: str) -> Config:
    """The resolved config a run directory of `moiq train` keeps in its config.json."""
    from moiq_jax.train import SWEEP_FILE

    saved = os.path.join(run_dir, "config.json")
    if not os.path.exists(saved) and os.path.exists(os.path.join(run_dir, SWEEP_FILE)):
        raise ValueError(f"{run_dir!r} is a sweep directory (`moiq sweep`, `moiq train --seeds`); continue it with "
                         f"`moiq sweep --resume {run_dir}`")
    if not os.path.exists(saved):
        raise ValueError(f"{run_dir!r} is not a run directory of `moiq train` (no config.json)")
    return Config(**load_config_file(saved))


def _resolve_run(args) -> tuple[Config, str, bool]:
    """The config, run directory and resume flag of ``moiq train``."""
    if args.resume:
        config = _saved_config(args.resume)
        given = [name for name in FIELDS if getattr(args, name, None) is not None]
        if given or args.config:
            raise ValueError(f"--resume continues the run's saved config; drop --config and {given}")
        return config, args.resume, True
    config = config_from_args(args)
    run_dir = args.run_dir or os.path.join("runs", f"{config.env}-{config.algo}-{time.strftime('%Y%m%d-%H%M%S')}")
    if os.path.exists(run_dir) and os.listdir(run_dir):
        raise ValueError(f"run directory {run_dir!r} already exists; continue it with `moiq train --resume "
                         f"{run_dir}` or choose another --run-dir")
    return config, run_dir, False


def _print_returns_against_experts(config: Config, result) -> None:
    """One row per expert, in the config's order and under its own preference."""
    from moiq_jax.experts.loading import load_demonstrations

    try:
        expert = load_demonstrations(config).mean_returns()
    except ValueError:  # SAC experts of an env without oracle experts: nothing to compare with
        expert = [None] * len(result.preferences)
    final = np.asarray(result.history["eval_return"][-1])
    best_step = int(np.argmax(np.asarray(result.history["eval_scalar_return"]).mean(axis=1)))
    best = np.asarray(result.history["eval_return"][best_step])
    print(f"returns per preference (vector, then scalarised); best = evaluation {best_step + 1} of "
          f"{len(result.history['eval_return'])}")
    print(f"  {'preference':<12} {'expert':<26} {'final':<26} {'best':<26}")
    for w, e, f, b in zip(np.asarray(result.preferences), expert, final, best):
        cells = ["-" if v is None else f"{_format_vector(v)} {float(np.dot(w, v)):7.2f}" for v in (e, f, b)]
        print(f"  {_format_preference(w):<12} " + " ".join(f"{c:<26}" for c in cells))


def _run_sweep(config: Config, values: dict, out_dir: str, demos=None, resume: bool = False) -> None:
    """Train every combination of ``values`` (swept name -> list; ``preferences``: a list of preference
    sets) as one vmapped program, one CPU device per run (``runtime.split_cpu_into_devices``), checkpointed
    in ``out_dir`` after every chunk (``resume``: continue it); each run's config.json and metrics.csv go to
    ``out_dir/<name><value>-...`` (e.g. ``beta0.5-set1-seed0``, so `moiq plot` reads them). Prints final
    and best returns per run, one table per preference set."""
    import moiq_jax
    from moiq_jax.runtime import split_cpu_into_devices
    from moiq_jax.train import run_dir_names

    split_cpu_into_devices(int(np.prod([len(v) for v in values.values()])))

    print(f"sweep directory: {out_dir}", flush=True)
    result = moiq_jax.sweep(config, demos=demos, run_dir=out_dir, resume=resume,
                            log=lambda line: print(line, flush=True), **values)
    sets = result.runs.get("set", np.zeros(len(result.runs["seed"]), int))
    print(f"{len(result.runs['seed'])} runs; scalarised returns per preference")
    for run, name in enumerate(run_dir_names(result.runs)):
        run_result = result.run(run)
        if run == 0 or sets[run] != sets[run - 1]:
            set_name = f"set {sets[run]} " if "set" in result.runs else ""
            print(f"{set_name}{[_format_preference(w) for w in run_result.preferences]}")
        swept = {name: v[run].item() for name, v in result.runs.items() if name != "preferences"}
        scalar = np.asarray(run_result.history["eval_scalar_return"])
        best = scalar[int(np.argmax(scalar.mean(axis=1)))]
        shown = " ".join(f"{name} {value:<5g}" if name not in ("seed", "set") else f"{name} {int(value):<3d}"
                         for name, value in swept.items())
        print(f"  {shown} final {_format_vector(scalar[-1])}  best {_format_vector(best)}  -> "
              f"{os.path.join(out_dir, name)}")


def _cmd_sweep(args) -> int:
    from moiq_jax.algos.offpolicy import Algorithm
    from moiq_jax.train import algorithm_of, saved_sweep, swept_names, validate

    if args.resume:
        given = ["--" + name.replace("_", "-") for name in FIELDS if getattr(args, name, None) is not None]
        given += [flag for flag, value in (("--betas", args.betas), ("--preference-sets", args.preference_sets),
                                           ("--seeds", args.seeds), ("--out", args.out), ("--config", args.config))
                  if value is not None]
        if given:
            raise ValueError(f"--resume continues the sweep's saved config and swept values; drop {given}")
        if os.path.exists(os.path.join(args.resume, "config.json")):
            raise ValueError(f"{args.resume!r} is a run of `moiq train`; continue it with `moiq train --resume "
                             f"{args.resume}`")
        config, values, demos = saved_sweep(args.resume)
        _run_sweep(config, values, args.resume, demos, resume=True)
        return 0
    seeds = 1 if args.seeds is None else args.seeds
    demos, args.demos = args.demos, None
    if demos and not args.preference_sets and len(demos) > 1:
        raise ValueError(f"--demos given {len(demos)} times: give one per --preference-sets entry")
    if demos and not args.preference_sets:
        args.demos = demos[0]
    sets = None
    if args.preference_sets:
        if args.preferences:
            raise ValueError("give the experts' preferences either by --preferences or by --preference-sets")
        sets = [[_parse_vector(w) for w in text.replace(";", " ").split()] for text in args.preference_sets]
        args.preferences = sets[0]  # the config's labels: the first set's (validated with the env)
    config = validate(config_from_args(args))
    off_policy = isinstance(algorithm_of(config), Algorithm)
    if not off_policy:
        raise ValueError(f"moiq sweep runs the off-policy algorithms; for {config.algo}, moiq_jax.sweep(config, "
                         "seed=[...]) trains every seed as one program")
    out_dir = args.out or os.path.join("runs", f"sweep-{config.env}-{config.algo}-{time.strftime('%Y%m%d-%H%M%S')}")
    if os.path.exists(out_dir) and os.listdir(out_dir):
        raise ValueError(f"sweep directory {out_dir!r} already exists; continue it with `moiq sweep --resume "
                         f"{out_dir}` or choose another --out")
    values = {"seed": list(range(config.seed, config.seed + seeds))}
    if args.betas:
        if "beta" not in swept_names(config):
            raise ValueError(f"--betas: {config.algo} has no consensus penalty weight to sweep")
        values = {"beta": args.betas, **values}
    if sets is not None:
        values["preferences"] = sets
        demos = demos or None
    else:
        demos = None  # the config's demos file (--demos), as in `moiq train`
    _run_sweep(config, values, out_dir, demos)
    return 0


def _cmd_train(args) -> int:
    import moiq_jax
    from moiq_jax.algos.offpolicy import Algorithm
    from moiq_jax.train import algorithm_of, validate

    config, run_dir, resume = _resolve_run(args)
    validate(config)
    algorithm = algorithm_of(config)
    if config.infer_preferences and config.algo == "moiq":
        return _train_moiq_inferring(config, run_dir, resume, args.seeds)
    if not isinstance(algorithm, Algorithm):  # ADMM: one compiled program of all rounds (seconds), not checkpointed
        result = moiq_jax.train(config)
        rounds = len(result.history["length"])  # with inferred preferences: warm-up rounds too
        _write_history(run_dir, config, result, np.arange(1, rounds + 1), step_name="round")
        last = {name: np.asarray(values)[-1] for name, values in result.history.items()}
        print(f"run directory: {run_dir}")
        if config.infer_preferences:
            _print_inferred_preferences(result, run_dir)
            return 0
        print(f"after {rounds} rounds: returns per expert (vector, scalarised) against the optimum")
        for w, v, s, best in zip(result.preferences, last["vector_return"], last["return"],
                                 result.extras["optimal_return"]):
            print(f"  {_format_preference(w):<12} {_format_vector(v)} {float(s):8.2f}   optimum {float(best):8.2f}")
        return 0
    if args.seeds > 1:  # several seeds train as one vmapped program (`moiq sweep --resume RUN_DIR` continues it)
        _run_sweep(config, {"seed": list(range(config.seed, config.seed + args.seeds))}, run_dir)
        return 0
    print(f"run directory: {run_dir}")
    result = moiq_jax.train(config, run_dir=run_dir, resume=resume, progress=not args.no_progress, log=None)
    _print_returns_against_experts(config, result)
    if not algorithm.learns_from_demos:  # trained experts: save them to record demonstrations
        from moiq_jax.experts import sac

        experts = os.path.join(run_dir, "experts.npz")
        sac.save_experts(experts, config, result.best_params.actor)
        print(f"best experts written to {experts}; record demonstrations with `moiq demos --experts {experts}`")
    return 0


def _write_history(run_dir: str, config: Config, result, steps, step_name: str = "env_steps") -> None:
    """A finished run's history, one row per entry of ``steps``, to ``run_dir``'s metrics.csv and TensorBoard,
    its experts labelled by ``result.preferences``."""
    from moiq_jax.runlog import RunLog

    log = RunLog(run_dir, config, total_steps=int(steps[-1]), progress=False, step_name=step_name,
                 labels=result.preferences)
    for t, step in enumerate(steps):
        log.log(int(step), {name: np.asarray(values)[t] for name, values in result.history.items()})
    log.close()


def _train_moiq_inferring(config: Config, run_dir: str, resume: bool, seeds: int) -> int:
    """`moiq train --algo moiq --infer-preferences`: MOIQ in the preference-inference outer loop, one seed,
    logged per chunk (metrics.csv under the inferred preferences), ``inferred_preferences.json`` written."""
    from moiq_jax.algos import moiq_preference_inference as inference

    if resume or seeds > 1:
        raise ValueError("moiq --infer-preferences trains one seed and is not checkpointed: drop --resume/--seeds "
                         "(several seeds: moiq_jax.sweep(config, seed=[...]))")
    print(f"run directory: {run_dir}")
    result = inference.train_seeds(config, [config.seed], log=print).run(0)
    _write_history(run_dir, config, result, np.asarray(result.history["env_steps"]))
    inference.write_run(result, run_dir)
    print("returns per expert (inferred preference: agent's final vector return, the expert's demonstrated return)")
    for w, agent, demo in zip(result.preferences, result.history["eval_return"][-1], result.extras["demo_return"]):
        print(f"  {_format_preference(w):<12} {_format_vector(agent)}   expert {_format_vector(demo)}")
    return 0


def _print_inferred_preferences(result, run_dir: str) -> None:
    """Per round and at the end, the preferences ADMM inferred (written to ``inferred_preferences.json``), and
    each agent's return against its expert's demonstrations."""
    from moiq_jax.algos.preference_evidence import write_run

    write_run(result.extras["inference"], run_dir, log=print)
    last = {name: np.asarray(values)[-1] for name, values in result.history.items()}
    print("returns per expert (inferred preference: agent's vector return, the expert's demonstrated return)")
    for w, agent, demo in zip(result.preferences, last["vector_return"], result.extras["demo_return"]):
        print(f"  {_format_preference(w):<12} {_format_vector(agent)}   expert {_format_vector(demo)}")


def _print_demos(demos) -> None:
    returns = demos.mean_returns()
    print(f"{demos.num_experts} experts x {demos.num_episodes} demonstrations of {demos.env} "
          f"(obs {demos.obs.shape[-1]}, steps {demos.obs.shape[2]}); mean return per expert (vector, scalarised):")
    for w, ret in zip(np.asarray(demos.preferences), returns):
        print(f"  {_format_preference(w):<12} {_format_vector(ret)} {float(np.dot(w, ret)):8.2f}")


def _cmd_demos(args) -> int:
    from moiq_jax.experts import Demonstrations, oracle_demonstrations

    if args.info:
        _print_demos(Demonstrations.load(args.info))
        return 0
    if args.experts:
        from moiq_jax.experts import sac

        config, actor = sac.load_experts(args.experts)
        demos = sac.record_demonstrations(config, actor, args.num_demos, args.seed)
    elif args.import_iq_learn:
        from moiq_jax.experts import load_iq_learn

        if not args.preferences:
            raise ValueError("--import-iq-learn needs --preferences: one per file, in the same order")
        demos = load_iq_learn(args.import_iq_learn, args.preferences, args.env)
    else:
        preferences = args.preferences or Config().preferences
        demos = oracle_demonstrations(args.env, preferences, args.num_demos, args.seed)
    demos.save(args.out)
    _print_demos(demos)
    print(f"written to {args.out}")
    return 0


def _cmd_plot(args) -> int:
    from moiq_jax import plots

    out_dir = args.out or args.run_dirs[0]
    os.makedirs(out_dir, exist_ok=True)
    config = _saved_config(args.run_dirs[0])
    from moiq_jax.experts.loading import load_demonstrations

    try:
        demos = load_demonstrations(config)
        expert = (demos.mean_returns() * np.asarray(demos.preferences)).sum(-1)
    except ValueError:  # no oracle experts for this env and no demos file: curves without expert lines
        expert = None
    rounds = plots.read_metrics(args.run_dirs[0]).step_name == "round"  # ADMM logs rounds, not env steps
    metric = args.metric or ("return" if rounds else "eval_scalar_return")
    print(plots.learning_curves(args.run_dirs, os.path.join(out_dir, "learning_curves.png"), metric, expert))
    base = config.make_env().unwrapped
    for run_dir in args.run_dirs:
        found = plots.read_transfer(run_dir)
        if found is not None:
            front = base.pareto_front() if hasattr(base, "pareto_front") else None
            name = os.path.basename(os.path.normpath(run_dir))
            start = found.get("swept_from", 0)  # the experts' own preferences are not part of the sweep
            title = name if "hypervolume" not in found else f"{name}: hypervolume {found['hypervolume']:.1f}"
            if found.get("mean_regret") is not None:
                title += f", mean regret {found['mean_regret']:.2f}"
            print(plots.transfer(found["returns"][start:], found["preferences"][start:],
                                 os.path.join(out_dir, f"transfer_{name}.png"), front, title=title,
                                 traced=found.get("front")))
    return 0


def _cmd_eval(args) -> int:
    import jax

    import moiq_jax
    from moiq_jax.algos.offpolicy import Algorithm, make_trainer
    from moiq_jax.checkpoint import Checkpoints
    from moiq_jax.evaluate import transfer_scores
    from moiq_jax.preferences import preference_sweep
    from moiq_jax.train import algorithm_of

    config = _saved_config(args.run_dir)
    algorithm = algorithm_of(config)
    if not isinstance(algorithm, Algorithm) or algorithm.one_model_per_expert:
        raise ValueError(f"moiq eval evaluates one preference-conditioned model (moiq); this run is {config.algo!r}")
    like = jax.jit(make_trainer(config, algorithm).init)(jax.random.PRNGKey(config.seed)).best_params
    checkpoints = Checkpoints(os.path.join(args.run_dir, "checkpoints"))
    try:
        params, meta = checkpoints.restore_best(like)
    finally:
        checkpoints.close()
    experts = np.asarray(config.preferences, np.float32)
    env = config.make_env(absorbing=True)  # as in training, on the run's backend
    if args.preferences is None:  # the experts' preferences, then the paper's 19
        preferences = np.concatenate([experts, preference_sweep()]) if experts.shape[1] == 2 else experts
        num_experts = len(experts)
    else:
        preferences, num_experts = _eval_preferences(args.preferences, env.reward_dim), 0
    returns = moiq_jax.evaluate(params, env, preferences, episodes=args.episodes)  # one vmapped call
    base = env.unwrapped
    front = base.pareto_front() if hasattr(base, "pareto_front") else None
    swept = slice(num_experts, None)
    scores = transfer_scores(returns[swept], preferences[swept], front) if env.reward_dim == 2 else {}
    regret = [None] * num_experts + (scores["regret"].tolist() if "regret" in scores else
                                     [None] * (len(returns) - num_experts))
    optimal = [None] * len(preferences)
    if front is not None:
        optimal = [bool(np.dot(w, r) >= np.max(front @ w) - 1e-3) for w, r in zip(preferences, returns)]
    print(f"best parameters of {args.run_dir} (mean scalarised return {np.mean(meta['best_return']):.2f}); "
          f"vector return per preference over {args.episodes} episode(s):")
    for i, (w, r, ok) in enumerate(zip(preferences, returns, optimal)):
        kind = "expert " if i < num_experts else "sweep  "
        tag = "" if ok is None else ("  Pareto-optimal" if ok else f"  not optimal, regret {regret[i]:.3f}"
                                     if regret[i] is not None else "  not optimal")
        print(f"  {kind}{_format_preference(w):<14} {_format_vector(r)} {float(np.dot(w, r)):8.2f}{tag}")
    record = {"preferences": preferences.tolist(), "returns": np.asarray(returns).tolist(),
              "pareto_optimal": optimal, "regret": regret, "swept_from": num_experts}
    if scores:
        record.update(front=scores["front"].tolist(), hypervolume=scores["hypervolume"],
                      reference=scores["reference"].tolist())
        if front is not None:
            record.update(front_hypervolume=scores["front_hypervolume"], mean_regret=float(scores["regret"].mean()),
                          optimal=int(scores["optimal"].sum()))
            print(f"transfer: {int(scores['optimal'].sum())} of {len(scores['regret'])} swept preferences reach their "
                  f"Pareto-optimal return; mean regret {float(scores['regret'].mean()):.3f}")
        true_front = "" if front is None else f" (the true front's: {scores['front_hypervolume']:.2f})"
        print(f"front: the swept preferences' returns trace {len(scores['front'])} non-dominated point(s), "
              f"hypervolume {scores['hypervolume']:.2f} above {np.round(scores['reference'], 3).tolist()}{true_front}")
    with open(os.path.join(args.run_dir, "transfer.json"), "w") as f:
        json.dump(record, f, indent=1)
    return 0


def _eval_preferences(given: list[str], reward_dim: int) -> np.ndarray:
    """``--preferences N`` (the paper's sweep ``[1 - k / (N + 1), k / (N + 1)]``, two objectives) or a list of
    comma-separated vectors."""
    from moiq_jax.preferences import check_preferences, preference_sweep

    if len(given) == 1 and "," not in given[0]:
        try:
            count = int(given[0])
        except ValueError:
            raise ValueError(f"--preferences: a count like 19 or vectors like 0.9,0.1, got {given[0]!r}") from None
        if count < 1 or reward_dim != 2:
            raise ValueError(f"--preferences {count}: a count of swept preferences (>= 1) needs two objectives; "
                             f"this env has {reward_dim}; give the vectors instead")
        return preference_sweep(count)
    return check_preferences([_parse_vector(w) for w in given], reward_dim, what="--preferences")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="moiq", description="Multi-objective inverse RL from several experts, in JAX.")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("envs", help="list the registered envs with their sizes")
    p.set_defaults(func=_cmd_envs)

    p = sub.add_parser("rollout", help="run a policy in an env and print vector returns")
    p.add_argument("--env", default="cdst", help="registered env name (see `moiq envs`); default: cdst")
    p.add_argument("--policy", choices=["random", "optimal"], default="random",
                   help="random actions, or the exact optimal policy to each treasure (DST-style envs)")
    p.add_argument("--episodes", type=int, default=8, help="episodes run side by side (random policy); default: 8")
    p.add_argument("--seed", type=int, default=0, help="random seed; default: 0")
    p.set_defaults(func=_cmd_rollout)

    p = sub.add_parser("train", help="train an algorithm; every Config field is a flag",
                       description="Train (moiq, iq_learn, gail, admm, or sac experts) and print each preference's return "
                                   "against its expert's. Metrics, config and checkpoints go to the run directory.")
    add_config_flags(p)
    p.add_argument("--run-dir", help="where logs and checkpoints go (default: runs/<env>-<algo>-<time>)")
    p.add_argument("--resume", metavar="RUN_DIR", help="continue a stopped run from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--seeds", type=int, default=1,
                   help="train seeds seed..seed+N-1 as one vmapped program, one sub-directory each (a sweep: "
                        "`moiq sweep --resume RUN_DIR` continues it)")
    p.set_defaults(func=_cmd_train)

    p = sub.add_parser("sweep", help="train every (beta, preference set, seed) combination as one vmapped program",
                       description="Train the product of --betas, --preference-sets and --seeds in one compiled "
                                   "program (moiq, iq_learn), chunk by chunk; each run's config and metrics go to "
                                   "OUT/beta<b>-set<i>-seed<s> (set only with --preference-sets), the state of all "
                                   "runs to OUT/checkpoints after every chunk; --resume OUT continues a stopped sweep.")
    add_config_flags(p, repeated=("demos",))
    p.add_argument("--betas", nargs="+", type=float, help="consensus penalty weights (default: --beta)")
    p.add_argument("--preference-sets", nargs="+", metavar='"W1,W2 W1,W2 ..."',
                   help="expert preference sets, each one quoted argument of space-separated vectors, all of "
                        "one size; demos: the env's oracle experts, or --demos FILE once per set, in order")
    p.add_argument("--seeds", type=int, default=None, help="number of seeds, from --seed on; default: 1")
    p.add_argument("--out", help="sweep directory (default: runs/sweep-<env>-<algo>-<time>)")
    p.add_argument("--resume", metavar="DIR", help="continue a stopped sweep from its last checkpoint, with its "
                                                    "saved config and swept values")
    p.set_defaults(func=_cmd_sweep)

    p = sub.add_parser("eval", help="evaluate a run's best parameters per preference (transfer)",
                       description="Vector returns of a moiq run's best parameters at the experts' preferences and "
                                   "the paper's 19 transfer preferences (or --preferences), in one vmapped call, against the "
                                   "true Pareto front; writes RUN_DIR/transfer.json (drawn by `moiq plot`).")
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run directory of `moiq train`")
    p.add_argument("--episodes", type=int, default=1, help="episodes per preference; default: 1 (cdst is deterministic)")
    p.add_argument("--preferences", nargs="+", metavar="N|W1,W2",
                   help="evaluate at these preferences instead: a count N (the sweep [1 - k/(N+1), k/(N+1)], "
                        "k = 1..N; 19 is the paper's) or comma-separated vectors; writes the returns, the front "
                        "they trace, its hypervolume and, where the env knows its front, the regret per preference")
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("demos", help="record expert demonstrations to a file, or describe one",
                       description="Record demonstrations of the env's exact optimal experts (DST maps and cdst), "
                                   "or of trained SAC experts (--experts), or convert IQ-Learn pickles "
                                   "(--import-iq-learn), in the Demonstrations format, printing each expert's return.")
    p.add_argument("--env", default="cdst", help="registered env name; default: cdst")
    p.add_argument("--preferences", nargs="+", type=_parse_vector, metavar="W1,W2",
                   help="one comma-separated preference per expert (default: 0.9,0.1 0.5,0.5 0.1,0.9)")
    p.add_argument("--num-demos", type=int, default=10, help="demonstrations per expert; default: 10")
    p.add_argument("--seed", type=int, default=0, help="random seed (stochastic experts); default: 0")
    p.add_argument("--out", default="demos.npz", help="file to write; default: demos.npz")
    p.add_argument("--info", metavar="FILE", help="describe an existing demos file instead")
    p.add_argument("--experts", metavar="FILE",
                   help="record the SAC experts of FILE (env and preferences from it), e.g. "
                        "experiments/demos/mo-hopper-experts.npz written by experiments/train_experts.py")
    p.add_argument("--import-iq-learn", nargs="+", metavar="PKL",
                   help="convert IQ-Learn expert pickles (one per --preferences entry, same order) for --env, "
                        "with the absorbing state MOIQ trains in")
    p.set_defaults(func=_cmd_demos)

    p = sub.add_parser("plot", help="learning curves and transfer plots of runs",
                       description="Learning curves (mean and min-max over the given runs, e.g. seeds) and, for "
                                   "runs evaluated with `moiq eval`, the preference transfer against the true front.")
    p.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run directories of `moiq train`")
    p.add_argument("--out", help="folder for the PNG files (default: the first run directory)")
    p.add_argument("--metric", help="the metrics.csv column to draw (default: the scalarised evaluation return)")
    p.set_defaults(func=_cmd_plot)
    return parser


def main(argv: list[str] | None = None) -> int:
    from moiq_jax.runner import TrainingDiverged
    from moiq_jax.runtime import use_compilation_cache

    args = build_parser().parse_args(argv)
    use_compilation_cache()  # reruns load their programs instead of compiling them
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except TrainingDiverged as err:
        print(f"error: training diverged: {err}", file=sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
