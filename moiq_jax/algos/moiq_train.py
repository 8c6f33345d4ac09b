"""Algorithm 1 as pure JAX (PureJaxRL style): ``make_train(config)`` builds ``train(key, beta)``, which
runs vectorised rollouts for all experts, MOIQ updates vmapped over experts, and an evaluation after each
chunk of ``eval_interval`` env steps, all in ``lax.scan``. ``train(config)`` drives the same chunks from
the host (logging between them); ``sweep`` vmaps the whole of ``train(key, beta)`` over a grid.

The "iq_learn" baseline is the same program with one expert per model and beta = 0, vmapped over the
experts: n separate models, each with its own networks, buffer and envs. "sac" trains the experts
themselves the same way, one model per preference, on the env's true reward (``algos.sac``) instead of
from demonstrations. "gail" is the adversarial baseline, also one model per expert: each update first
trains that model's discriminator on the expert and policy samples, then SAC on the policy samples with
the discriminator's reward (``algos.gail``).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from moiq_jax import envs, replay
from moiq_jax.algos import gail, moiq, sac
from moiq_jax.config import Config
from moiq_jax.envs.wrappers import AutoReset, VmapWrapper
from moiq_jax.evaluate import pearson, preference_returns
from moiq_jax.experts import Demonstrations, oracle_demonstrations
from moiq_jax.preferences import check_preferences
from moiq_jax.runner import run_chunks


@struct.dataclass
class RunnerState:
    """Everything one training run carries between steps (for ``E`` experts of one model)."""

    learner: moiq.Learner
    buffers: replay.ReplayBuffer  # leading expert axis
    env_state: Any  # [E, num_envs, ...]
    key: jax.Array
    env_steps: jax.Array  # per expert
    best_params: moiq.Params
    best_return: jax.Array  # mean scalarised evaluation return of best_params
    discriminator: gail.DiscriminatorState | None = None  # gail only: one per expert (leading expert axis)


class Trainer(NamedTuple):
    """Pure pieces of one configured training: ``init(key)``, ``run_chunk(state, beta)`` (eval_interval
    env steps then an evaluation), ``train(key, beta)`` (all chunks); ``num_chunks``."""

    init: Any
    run_chunk: Any
    train: Any
    num_chunks: int


def load_demonstrations(config: Config) -> Demonstrations:
    """The first ``num_demos`` episodes per expert of the configured demos file (its preferences must be the
    config's), or fresh oracle demonstrations; experts sorted by preference."""
    env = envs.make(config.env, absorbing=True)
    if config.demos is not None:
        demos = Demonstrations.load(config.demos, env)
        given = sorted(config.preferences)
        recorded = sorted(map(tuple, np.round(np.asarray(demos.preferences), 6).tolist()))
        if len(given) != len(recorded) or not np.allclose(given, recorded, atol=1e-5):
            raise ValueError(f"the demos in {config.demos!r} are of preferences {recorded}, not the configured "
                             f"{given}; set --preferences to match the file")
        if demos.num_episodes < config.num_demos:
            raise ValueError(f"the demos in {config.demos!r} hold {demos.num_episodes} episodes per expert, fewer "
                             f"than num_demos = {config.num_demos}")
        demos = demos.replace(**{name: np.asarray(getattr(demos, name))[:, : config.num_demos]
                                 for name in ("obs", "actions", "next_obs", "rewards", "dones", "lengths")})
    else:
        demos = oracle_demonstrations(config.env, config.preferences, config.num_demos, config.seed)
    order = np.lexsort(np.asarray(demos.preferences).T[::-1])[::-1]  # descending, first objective first
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[order], demos)


def _expert_transitions(demos: Demonstrations) -> dict:
    """Real (unpadded) demo steps as ``[E, M, ...]`` arrays; every expert must have the same count M."""
    mask = demos.mask()
    counts = mask.reshape(mask.shape[0], -1).sum(1)
    if np.any(counts != counts[0]):
        raise ValueError(f"MOIQ needs equally many demo steps per expert (use the absorbing-state env), got {counts}")
    take = lambda x: np.stack([np.asarray(x)[e][mask[e]] for e in range(mask.shape[0])])
    return {
        "obs": take(demos.obs), "action": take(demos.actions), "next_obs": take(demos.next_obs),
        "done": take(demos.dones).astype(np.float32), "true_reward": take(demos.rewards),
    }


TRANSITION_FIELDS = ("obs", "action", "next_obs", "done")  # what the inverse-RL losses see of a transition


def update_settings(config: Config, action_size: int) -> tuple[moiq.Optimisers, moiq.Hyper]:
    """The optimisers and hyperparameters of ``moiq.update`` that ``config`` sets (the target entropy is
    minus the action size, as in SAC)."""
    optimisers = moiq.Optimisers(optax.adam(config.critic_lr), optax.adam(config.actor_lr), optax.adam(config.alpha_lr))
    return optimisers, moiq.Hyper(config.gamma, config.alpha_reg, -float(action_size), config.use_target)


def make_train(config: Config, demos: Demonstrations | None = None) -> Trainer:
    """Build the pure training functions for ``config`` (``algo`` "moiq", "iq_learn", "sac" or "gail")."""
    config.validate()
    experts = config.algo == "sac"  # training experts: the true reward, no demonstrations
    adversarial = config.algo == "gail"  # SAC on a discriminator's reward
    separate = config.algo in ("iq_learn", "sac", "gail")
    if experts:
        # Experts learn the task itself: termination ends the episode (no absorbing state to imitate).
        env = envs.make(config.env)
        data = None
        preferences = jnp.asarray(check_preferences(config.preferences, env.reward_dim))
    else:
        demos = load_demonstrations(config) if demos is None else demos
        data = jax.tree_util.tree_map(jnp.asarray, _expert_transitions(demos))
        preferences = jnp.asarray(demos.preferences)
        env = envs.make(config.env, absorbing=True)
    critic_objective = sac.critic_loss if experts or adversarial else moiq.critic_loss
    rollout_env = VmapWrapper(AutoReset(env), config.num_envs)
    nets = moiq.networks_of_sizes(config.hidden_sizes, env.reward_dim, env.action_size, config.action_scale)
    optimisers, hyper = update_settings(config, env.action_size)
    discriminator = gail.Discriminator(config.hidden_sizes)
    disc_optimiser = optax.adam(config.disc_lr)
    iterations_per_chunk = config.eval_interval // config.num_envs
    num_chunks = config.total_steps // config.eval_interval

    def init(key, prefs):
        num_experts = prefs.shape[0]
        learner_key, env_key, key = jax.random.split(key, 3)
        learner = moiq.init_learner(nets, optimisers, learner_key, env.observation_size, env.action_size,
                                    prefs, config.init_alpha)
        example = {"obs": jnp.zeros(env.observation_size), "action": jnp.zeros(env.action_size),
                   "next_obs": jnp.zeros(env.observation_size), "done": jnp.zeros(()),
                   "reward": jnp.zeros(env.reward_dim)}
        buffers = jax.vmap(lambda _: replay.init(example, config.buffer_size))(jnp.arange(num_experts))
        env_state = jax.vmap(rollout_env.reset)(jax.random.split(env_key, num_experts))
        disc_state = None
        if adversarial:
            key, disc_key = jax.random.split(key)
            disc_state = jax.vmap(lambda k: gail.init(discriminator, disc_optimiser, k, env.observation_size,
                                                      env.action_size))(jax.random.split(disc_key, num_experts))
        return RunnerState(learner, buffers, env_state, key, jnp.zeros((), jnp.int32),
                           learner.params, jnp.full((), -jnp.inf), disc_state)

    def sample_batches(buffers, expert_data, key):
        """Per expert: its replay batch alone when training experts; else expert rows, then policy rows."""
        num_experts = buffers.size.shape[0]
        policy_key, expert_key = jax.random.split(key)
        policy = jax.vmap(replay.sample, in_axes=(0, 0, None))(
            buffers, jax.random.split(policy_key, num_experts), config.batch_size)
        if expert_data is None:
            return policy
        policy = {k: policy[k] for k in TRANSITION_FIELDS}
        rows = jax.random.randint(expert_key, (num_experts, config.batch_size), 0, expert_data["obs"].shape[1])
        expert = jax.tree_util.tree_map(
            lambda x: jnp.take_along_axis(x, rows.reshape(*rows.shape, *([1] * (x.ndim - 2))), axis=1),
            {k: expert_data[k] for k in TRANSITION_FIELDS})
        batches = jax.tree_util.tree_map(lambda e, p: jnp.concatenate([e, p], axis=1), expert, policy)
        is_expert = jnp.arange(2 * config.batch_size) < config.batch_size
        return {**batches, "is_expert": jnp.broadcast_to(is_expert, (num_experts, 2 * config.batch_size))}

    def env_iteration(state: RunnerState, beta, expert_data, prefs):
        key, act_key, random_key, update_key = jax.random.split(state.key, 4)
        num_experts = prefs.shape[0]
        obs = state.env_state.obs  # [E, num_envs, obs]
        learned, _ = jax.vmap(nets.sample, in_axes=(None, 0, 0, 0))(
            state.learner.params.actor, obs, prefs, jax.random.split(act_key, num_experts))
        random = jax.random.uniform(random_key, learned.shape, minval=-1.0, maxval=1.0)
        action = jnp.where(state.env_steps < config.learning_starts, random, learned)
        nxt = jax.vmap(rollout_env.step)(state.env_state, action)
        transitions = {"obs": obs, "action": action, "next_obs": nxt.info["final_obs"],
                       "done": nxt.done.astype(jnp.float32), "reward": nxt.reward}
        buffers = jax.vmap(replay.add)(state.buffers, transitions)

        def learn(models):
            def one_update(models, k):
                learner, disc_state = models
                batch_key, step_key = jax.random.split(k)
                batches = sample_batches(buffers, expert_data, batch_key)
                disc_metrics = {}
                if adversarial:
                    disc_state, disc_metrics = jax.vmap(
                        lambda d, b: gail.update(d, discriminator, disc_optimiser, b))(disc_state, batches)
                    policy = {name: batches[name][:, config.batch_size:] for name in TRANSITION_FIELDS}
                    batches = jax.vmap(lambda p, b: gail.with_reward(discriminator, p, b, env.reward_dim))(
                        disc_state.params, policy)
                learner, metrics = moiq.update(learner, nets, optimisers, batches, prefs, beta, step_key, hyper,
                                               config.tau, config.learn_alpha, critic_objective)
                return (learner, disc_state), {**metrics, **disc_metrics}

            models, metrics = jax.lax.scan(one_update, models, jax.random.split(update_key, config.updates_per_step))
            return models, jax.tree_util.tree_map(lambda m: m[-1], metrics)

        ready = state.env_steps + config.num_envs > config.learning_starts
        (learner, disc_state), metrics = jax.lax.cond(
            ready, learn, lambda models: (models, jax.tree_util.tree_map(
                lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(learn, models)[1])),
            (state.learner, state.discriminator))
        metrics = {**metrics, "updated": ready}
        return state.replace(learner=learner, discriminator=disc_state, buffers=buffers, env_state=nxt, key=key,
                             env_steps=state.env_steps + config.num_envs), metrics

    def evaluate_params(params, prefs, expert_data, disc_state, key):
        """Deterministic-policy vector returns per preference and the recovered reward's Pearson correlations
        with the true one on the demonstrations, as a dict of metrics: scalarised by the expert's preference
        (``reward_correlation``) and, for moiq and iq_learn, per objective
        (``reward_correlation_objectives``, ``[E, d]``). None for experts, which recover no reward; for gail,
        the discriminator's (scalar) reward against the true scalarised one."""
        keys = jax.random.split(key)
        returns = preference_returns(nets, params.actor, env, prefs, keys[1], config.eval_episodes).mean(axis=1)
        if expert_data is None:
            return returns, None
        if adversarial:
            def disc_correlation(disc_params, data_i, preference):
                rewards = gail.generator_reward(discriminator.apply(disc_params, data_i["obs"], data_i["action"]))
                return pearson(rewards, data_i["true_reward"] @ preference)

            return returns, {"reward_correlation": jax.vmap(disc_correlation)(disc_state.params, expert_data, prefs)}
        alphas = jnp.exp(params.log_alpha)

        def correlation(data_i, preference, alpha, k):
            rewards, _ = moiq.recovered_rewards(nets, params.critic, params, alpha, data_i, preference, k, config.gamma)
            rewards = jnp.mean(rewards, 0)  # over the twins
            per_objective = jax.vmap(pearson, in_axes=(1, 1))(rewards, data_i["true_reward"])
            return pearson(rewards @ preference, data_i["true_reward"] @ preference), per_objective

        scalar, per_objective = jax.vmap(correlation)(expert_data, prefs, alphas, jax.random.split(keys[0], prefs.shape[0]))
        return returns, {"reward_correlation": scalar, "reward_correlation_objectives": per_objective}

    def run_chunk(state: RunnerState, beta, expert_data, prefs):
        state, metrics = jax.lax.scan(lambda s, _: env_iteration(s, beta, expert_data, prefs), state, None,
                                      length=iterations_per_chunk)
        updated = jnp.maximum(jnp.sum(metrics.pop("updated")), 1)
        metrics = jax.tree_util.tree_map(lambda m: jnp.sum(m, axis=0) / updated, metrics)  # mean over updates
        key, eval_key = jax.random.split(state.key)
        returns, correlations = evaluate_params(state.learner.params, prefs, expert_data, state.discriminator, eval_key)
        scalar = jnp.sum(returns * prefs, axis=-1)
        score = jnp.mean(scalar)
        better = score > state.best_return
        best = jax.tree_util.tree_map(lambda new, old: jnp.where(better, new, old),
                                      state.learner.params, state.best_params)
        state = state.replace(key=key, best_params=best, best_return=jnp.maximum(score, state.best_return))
        metrics = {**metrics, "eval_return": returns, "eval_scalar_return": scalar, "env_steps": state.env_steps}
        if correlations is not None:
            metrics.update(correlations)
        return state, metrics

    if separate:  # n single-expert models, vmapped; beta is irrelevant (no neighbours) and set to 0
        per_model = None if data is None else jax.tree_util.tree_map(lambda x: x[:, None], data)
        model_prefs = preferences[:, None]
        num_models = preferences.shape[0]

        def init_all(key):
            return jax.vmap(init)(jax.random.split(key, num_models), model_prefs)

        def chunk_all(state, beta):
            state, metrics = jax.vmap(run_chunk, in_axes=(0, None, 0, 0))(state, 0.0 * beta, per_model, model_prefs)
            return state, _merge_models(metrics)
    else:
        def init_all(key):
            return init(key, preferences)

        def chunk_all(state, beta):
            return run_chunk(state, beta, data, preferences)

    def train(key, beta):
        state = init_all(key)
        return jax.lax.scan(lambda s, _: chunk_all(s, beta), state, None, length=num_chunks)

    return Trainer(init_all, chunk_all, train, num_chunks)


def _merge_models(metrics):
    """Per-model metrics ``[n, 1, ...]`` (or ``[n]`` for scalars) as per-expert ``[n, ...]``."""
    return {k: (v[:, 0] if v.ndim >= 2 and v.shape[1] == 1 else v) for k, v in metrics.items()}


@dataclasses.dataclass
class TrainResult:
    """final_params, best_params (by mean scalarised evaluation return), best_return, history: per
    evaluation a dict of arrays (per-expert entries have an expert axis), and wall-clock seconds."""

    config: Config
    final_params: Any
    best_params: Any
    best_return: float
    history: dict[str, np.ndarray]
    seconds: float


def train(config: Config, demos: Demonstrations | None = None, log=print, run_dir: str | None = None,
          resume: bool = False, progress: bool = False, until=None, on_chunk=None) -> TrainResult:
    """Run Algorithm 1 for ``config``: jitted chunks of ``eval_interval`` env steps, logged in between;
    with ``run_dir``, also checkpointed after every chunk and resumable (see ``moiq_jax.runner``); with
    ``until``, stopped after the first evaluation whose metrics (a dict of arrays) it holds true for;
    ``on_chunk(state, history)`` is called after every evaluation."""
    trainer = make_train(config, demos)
    state, history, seconds = run_chunks(trainer, config, run_dir=run_dir, resume=resume, log=log, progress=progress,
                                         until=until, on_chunk=on_chunk)
    stacked = {k: np.stack([h[k] for h in history]) for k in history[0]}
    return TrainResult(config, state.learner.params, state.best_params, np.asarray(state.best_return), stacked, seconds)


def split_cpu_into_devices(count: int | None = None) -> None:
    """Split the host CPU into ``count`` XLA devices (default: one per core), so that a sweep's runs,
    sharded over them (``shard_runs``), run as concurrent programs instead of one program whose small
    operations leave the cores idle between them (``benchmarks/moiq_speed.py`` measures the gain).

    Takes effect only before JAX's first computation in the process; an ``XLA_FLAGS`` that already sets
    the host device count is left as it is. Other platforms (GPU) are unaffected."""
    flag = "--xla_force_host_platform_device_count"
    flags = os.environ.get("XLA_FLAGS", "")
    if flag not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {flag}={count or os.cpu_count() or 1}".strip()


def use_compilation_cache(path: str | None = None) -> str | None:
    """Keep compiled programs on disk (JAX's persistent compilation cache), so that the same program run
    again, in this process or a later one, is loaded instead of compiled (a cdst ``train``: about 11 s to
    compile, 3 s to load). ``path`` defaults to ``$MOIQ_COMPILATION_CACHE``, else ``~/.cache/moiq_jax/xla``;
    an empty ``MOIQ_COMPILATION_CACHE`` turns the cache off. A folder JAX already has
    (``JAX_COMPILATION_CACHE_DIR``) is kept. Call before the first compilation; returns the folder in use."""
    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    if path is None:
        default = os.path.join(os.path.expanduser("~"), ".cache", "moiq_jax", "xla")
        path = os.environ.get("MOIQ_COMPILATION_CACHE", default)
    if not path:
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    return path


def shard_runs(*arrays):
    """``arrays`` (leading axis: runs) placed sharded over the run axis on all devices, when there are
    several and they divide the number of runs; else unchanged."""
    devices, runs = jax.devices(), arrays[0].shape[0]
    if len(devices) == 1 or runs % len(devices):
        return arrays
    sharding = jax.sharding.NamedSharding(jax.sharding.Mesh(np.array(devices), ("runs",)),
                                          jax.sharding.PartitionSpec("runs"))
    return jax.device_put(arrays, sharding)


def run_grid(betas, seeds) -> tuple[np.ndarray, np.ndarray]:
    """The runs of a sweep, every (beta, seed) of the product, betas outermost: their betas (float32) and
    seeds, one entry per run."""
    grid = list(itertools.product(betas, seeds))
    return np.asarray([b for b, _ in grid], np.float32), np.asarray([s for _, s in grid])


def sweep(config: Config, beta=None, seed=None, demos: Demonstrations | None = None) -> dict:
    """Train every (beta, seed) of the product of the given values as one vmapped, compiled program,
    sharded over the run axis when several devices are present and they divide the number of runs
    (on CPU, ``split_cpu_into_devices`` makes the devices: `moiq sweep` makes one per run).

    Returns ``betas``, ``seeds`` (one entry per run), ``history`` (arrays with a leading run axis,
    then the evaluation axis), ``best_return`` and ``best_params`` (leading run axis).
    """
    run_betas, run_seeds = run_grid([config.beta] if beta is None else beta, [config.seed] if seed is None else seed)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(run_seeds, jnp.uint32))
    trainer = make_train(config, demos)
    keys, run_betas = shard_runs(keys, jnp.asarray(run_betas))
    state, history = jax.jit(jax.vmap(trainer.train))(keys, run_betas)
    return {"betas": np.asarray(run_betas), "seeds": run_seeds,
            "history": jax.device_get(history), "best_return": np.asarray(state.best_return),
            "best_params": state.best_params}
