"""The MuJoCo envs on both backends against MO-Gymnasium's v5 MuJoCo envs (and, natively, mo-halfcheetah-v4).

Native backend ("mujoco"): from MO-Gymnasium's own resets (its qpos/qvel, started with ``state_at``)
and the same random actions, whole episodes (to termination or the 1000-step limit) equal
MO-Gymnasium's at every step: observation, every reward component, terminated and truncated, within
``EXACT`` (float32 rounding of float64 values; the physics itself is bit for bit MuJoCo's). Steps are
bit-deterministic under jit + nested vmap + scan, and a run cut in two through host memory (as a
checkpoint does) continues bit for bit.

MJX backend ("mjx", at MuJoCo's solver settings): MJX 3.17 runs in float32 and its contact forces differ
from MuJoCo 4.0's by a few per cent (same contact points, constraint forces apart: the Ant with its 0.01
contact margin, and the HalfCheetah), and rollouts are chaotic, so it matches MO-Gymnasium (to ``ATOL +
RTOL * |theirs|``) for the first ``parity_steps`` steps of each episode only: hopper and walker2d 30, the
HalfCheetah 7 (its 8th step was 0.011 apart in one episode already before the native backend), the Ant its
first step from a reset, in the air (a step is compared only while neither side's observation shows a
contact force). Over ``EPISODES`` random-action episodes of at most
``HORIZON`` steps, the mean return vector and mean episode length agree with MO-Gymnasium's to four
standard errors (plus 1e-3). One batched rollout per task, from MO-Gymnasium's resets, serves both MJX tests.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from moiq_jax import envs
from moiq_jax.envs.mujoco import TASKS, native

mo_gym = pytest.importorskip("mo_gymnasium")

EXACT = 1e-5  # native vs MO-Gymnasium, absolute, every step of whole episodes
NATIVE_EPISODES = 20
EPISODES = 32  # MJX: envs per batch, on both sides
HORIZON = 100  # MJX: steps per rollout and time limit on both sides
ATOL = RTOL = 2e-3

# name -> (MO-Gymnasium id, columns of its reward that are ours, MJX parity steps, contact forces in the obs)
CASES = {
    "mo-hopper": ("mo-hopper-v5", [0, 1, 2], 30, None),
    "mo-walker2d": ("mo-walker2d-v5", [0, 1], 30, None),
    "mo-halfcheetah": ("mo-halfcheetah-v5", [0, 1], 7, None),
    "mo-ant": ("mo-ant-v5", [0, 2], 1, slice(27, None)),
}
# the native backend is also checked on mo-halfcheetah-v4 (v5's dynamics, a tenth of its cost objective)
NATIVE_CASES = {**CASES, "mo-halfcheetah-v4": ("mo-halfcheetah-v4", [0, 1], 7, None)}


def gym_start(gym_env, seed):
    obs, _ = gym_env.reset(seed=seed)
    data = gym_env.unwrapped.data
    return obs, data.qpos.copy(), data.qvel.copy()


def started(env, key, base_state):
    """``env``'s reset state (wrapper bookkeeping) with the unwrapped env's ``base_state`` in it."""
    return env.reset(key).replace(env_state=base_state.env_state, obs=base_state.obs)


def to_host(tree):
    """numpy copies of a pytree's arrays (keys as their data), as a checkpoint saves them."""
    def leaf(x):
        return np.array(jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x)

    return jax.tree_util.tree_map(leaf, tree)


def from_host(tree, like):
    """``to_host``'s inverse, as a checkpoint loads it into ``like``'s structure."""
    def leaf(x, ref):
        is_key = jax.dtypes.issubdtype(ref.dtype, jax.dtypes.prng_key)
        return jax.random.wrap_key_data(jnp.asarray(x)) if is_key else jnp.asarray(x)

    return jax.tree_util.tree_map(leaf, tree, like)


def stack(states):
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *states)


# --- registry ---------------------------------------------------------------------------------------


def test_backends_and_make():
    assert envs.default_backend() == ("mujoco" if jax.default_backend() == "cpu" else "mjx")
    for name in CASES:
        assert set(envs.backends(name)) == {"mujoco", "mjx"} and envs.backends(name)[0] == envs.default_backend()
        assert envs.make(name).unwrapped.backend == envs.default_backend()
        assert envs.make(name, backend="mjx").unwrapped.backend == "mjx"
    assert envs.backends("dst") == ()
    with pytest.raises(ValueError, match="has backends"):
        envs.make("mo-hopper", backend="brax")
    with pytest.raises(ValueError, match="no backend choice"):
        envs.make("dst", backend="mujoco")
    with pytest.raises(ValueError, match="nthread"):
        envs.make("mo-hopper", backend="mujoco", nthread=0)
    with pytest.raises(ValueError, match="mjx_solver"):
        envs.make("mo-hopper", backend="mjx", mjx_solver="slow")
    with pytest.raises(ValueError, match="shape"):
        envs.make("mo-hopper", backend="mujoco").unwrapped.state_at(np.zeros(5), np.zeros(6))


@pytest.mark.parametrize("name", list(NATIVE_CASES))
def test_sizes_match_gymnasium(name):
    gym_env = mo_gym.make(NATIVE_CASES[name][0])
    for backend in envs.backends(name):
        env = envs.make(name, backend=backend)
        assert env.observation_size == gym_env.observation_space.shape[0]
        assert env.action_size == gym_env.action_space.shape[0]
        assert env.reward_dim == len(NATIVE_CASES[name][1])
        assert env.unwrapped.dt == pytest.approx(gym_env.unwrapped.dt)
        assert not env.deterministic_reset


# --- native backend ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(CASES))
def test_state_at_is_gymnasium_set_state(name):
    """``state_at`` holds exactly what mj_resetData + set_state (mj_forward) leave: state, warm start, xpos."""
    base = envs.make(name, backend="mujoco").unwrapped
    model, sim = base.mj_model, base.sim
    rng = np.random.default_rng(0)
    qpos = model.qpos0 + rng.uniform(-0.1, 0.1, model.nq)
    qvel = rng.normal(0, 0.1, model.nv)
    data = mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    expected = np.zeros(sim.nstate)
    mujoco.mj_getState(model, data, expected, native.STATE_SPEC)
    values = base.values(base.state_at(qpos, qvel))
    np.testing.assert_array_equal(values[:sim.nstate], expected)
    if sim.body is not None:
        np.testing.assert_array_equal(values[sim.nstate:], data.xpos[sim.body])


@pytest.mark.parametrize("name", ["mo-hopper", "mo-ant"])
def test_native_pending_starts_step_as_exact_starts(name):
    """A reset (qpos0 + float32 noise, added at the next step) and a traced float32 ``state_at`` step
    bit for bit as ``state_at`` of the same float64 values."""
    base = envs.make(name, backend="mujoco").unwrapped
    action = jnp.full((base.action_size,), 0.3)
    step = jax.jit(base.step)
    reset = jax.jit(base.reset)(jax.random.key(5))
    qpos32 = jnp.linspace(-0.1, 0.1, base.mj_model.nq) + jnp.asarray(base.mj_model.qpos0, jnp.float32)
    traced = jax.jit(base.state_at)(qpos32, jnp.full((base.mj_model.nv,), 0.05))
    for start in (reset, traced):
        qpos, qvel = base.qpos_qvel(start)
        exact = base.state_at(qpos, qvel)
        np.testing.assert_array_equal(np.asarray(start.obs), np.asarray(exact.obs))
        np.testing.assert_array_equal(np.asarray(step(start, action).env_state.bits),
                                      np.asarray(step(exact, action).env_state.bits))
        np.testing.assert_array_equal(np.asarray(step(start, action).obs), np.asarray(step(exact, action).obs))


@pytest.mark.parametrize("name", list(CASES))
def test_reset_noise_matches_gymnasium(name):
    """Reset noise (shared by both backends): uniform on qpos, uniform or Gaussian on qvel, of the task's scale."""
    base = envs.make(name, backend="mujoco").unwrapped
    qpos, qvel = base.qpos_qvel(jax.jit(jax.vmap(base.reset))(jax.random.split(jax.random.key(0), 2000)))
    qpos = qpos - base.mj_model.qpos0
    task = base.task
    scale = task.reset_noise_scale
    assert np.abs(qpos).max() <= scale + 1e-6
    np.testing.assert_allclose(qpos.std(0), scale / np.sqrt(3), rtol=0.1)
    if task.qvel_noise_normal:
        np.testing.assert_allclose(qvel.std(0), scale, rtol=0.1)
    else:
        assert np.abs(qvel).max() <= scale + 1e-6
        np.testing.assert_allclose(qvel.std(0), scale / np.sqrt(3), rtol=0.1)
    assert np.abs(qpos.mean(0)).max() < 0.1 * scale and np.abs(qvel.mean(0)).max() < 0.1 * scale


@pytest.mark.parametrize("name", list(NATIVE_CASES))
def test_native_whole_episodes_equal_mo_gymnasium(name):
    """From MO-Gymnasium's resets, same random actions: every step of whole episodes equal within EXACT."""
    gym_id, columns = NATIVE_CASES[name][:2]
    env = envs.make(name, backend="mujoco")
    base = env.unwrapped
    gym_env = mo_gym.make(gym_id)  # its default 1000-step limit, as ours
    actions = np.random.default_rng(1).uniform(-1, 1, (NATIVE_EPISODES, 1000, env.action_size)).astype(np.float32)
    starts, theirs = [], []
    for i in range(NATIVE_EPISODES):
        first_obs, qpos, qvel = gym_start(gym_env, seed=i)
        state = base.state_at(qpos, qvel)
        np.testing.assert_allclose(np.asarray(state.obs), first_obs, rtol=0, atol=EXACT)
        starts.append(started(env, jax.random.key(i), state))
        episode = []
        for action in actions[i]:
            obs, reward, terminated, truncated, _ = gym_env.step(action)
            episode.append((obs, reward[columns], terminated, truncated))
            if terminated or truncated:
                break
        theirs.append(episode)
    horizon = max(len(episode) for episode in theirs)

    def rollout(state, actions):
        def body(state, action):
            state = env.step(state, action)
            return state, (state.obs, state.reward, state.done, state.truncated)

        return jax.lax.scan(body, state, actions)[1]

    ours = jax.jit(jax.vmap(rollout))(stack(starts), jnp.asarray(actions[:, :horizon]))
    obs, reward, done, truncated = map(np.asarray, ours)
    for i, episode in enumerate(theirs):
        for t, (their_obs, their_reward, terminated, their_truncated) in enumerate(episode):
            where = f"{name} episode {i} step {t}"
            np.testing.assert_allclose(obs[i, t], their_obs, rtol=0, atol=EXACT, err_msg=where)
            np.testing.assert_allclose(reward[i, t], their_reward, rtol=0, atol=EXACT, err_msg=where)
            assert (done[i, t], truncated[i, t]) == (terminated, their_truncated), where
    assert sum(map(len, theirs)) >= NATIVE_EPISODES * 10


def test_native_steps_are_deterministic_under_jit_vmap_scan(name="mo-ant"):
    """Nested vmap (2 x 3 envs) in scan: twice the same bits, equal to stepping each env alone, and a run
    cut in two through host memory continues bit for bit."""
    env = envs.AutoReset(envs.make(name, backend="mujoco", episode_length=20))
    keys = jax.random.split(jax.random.key(0), 6).reshape(2, 3)
    actions = jax.random.uniform(jax.random.key(1), (30, 2, 3, env.action_size), minval=-1, maxval=1)

    @jax.jit
    def run(state, actions):
        def body(state, action):
            state = jax.vmap(jax.vmap(env.step))(state, action)
            return state, (state.obs, state.reward, state.done | state.truncated)

        return jax.lax.scan(body, state, actions)

    start = jax.vmap(jax.vmap(env.reset))(keys)
    first = to_host(run(start, actions))
    jax.tree_util.tree_map(np.testing.assert_array_equal, first, to_host(run(start, actions)))
    half, _ = run(start, actions[:15])
    resumed = from_host(to_host(half), half)
    jax.tree_util.tree_map(np.testing.assert_array_equal, first[0], to_host(run(resumed, actions[15:])[0]))

    state = env.reset(keys[1, 2])
    step = jax.jit(env.step)
    for t in range(actions.shape[0]):  # the same env stepped alone
        state = step(state, actions[t, 1, 2])
        np.testing.assert_array_equal(np.asarray(state.obs), first[1][0][t, 1, 2])
        np.testing.assert_array_equal(np.asarray(state.reward), first[1][1][t, 1, 2])
    np.testing.assert_array_equal(np.asarray(state.env_state.bits), first[0].env_state.bits[1, 2])
    assert first[1][2].any(), "no episode ended: the auto-reset path went untested"


class AntWithoutContactForces(TASKS["mo-ant"]):
    """The Ant's model and main body, for the ``"batch"`` engine (which cannot compute contact forces)."""

    contact_forces = False


@pytest.mark.parametrize("task_class", [TASKS["mo-hopper"], AntWithoutContactForces])
def test_native_engines_step_alike(task_class):
    """``mujoco.batch.Batch`` and the per-env loop, at 1 and 2 threads, give the same bits for states
    (warm start included) and the main body's xpos, over 40 chained steps from varied starts."""
    engines = [native.Simulator(task_class(), nthread, engine) for engine in native.ENGINES for nthread in (1, 2)]
    sim, rng, n = engines[0], np.random.default_rng(0), 12
    model = sim.model
    inputs = np.zeros((n, sim.nstate + model.nu))
    for i in range(n):
        qpos = model.qpos0 + rng.uniform(-0.1, 0.1, model.nq)
        inputs[i, :sim.nstate] = sim.start_values(qpos, rng.uniform(-0.5, 0.5, model.nv))[:sim.nstate]
    chained = [inputs.copy() for _ in engines]
    for _ in range(40):
        controls = rng.uniform(-1, 1, (n, model.nu))
        outs = []
        for engine, x in zip(engines, chained):
            x[:, sim.nstate:] = controls
            out = np.full((n, sim.width), np.nan)
            engine.advance(n, x, out, None)
            x[:, :sim.nstate] = out[:, :sim.nstate]
            outs.append(out)
        for engine, out in zip(engines[1:], outs[1:]):
            np.testing.assert_array_equal(out, outs[0], err_msg=f"{engine.engine}, {engine.nthread} threads")
    assert np.any(outs[0][:, sim.nstate - model.nv:sim.nstate] != 0), "the warm start went untested"
    with pytest.raises(ValueError, match="contact forces"):
        native.Simulator(TASKS["mo-ant"](), 1, "batch")


def test_native_host_function_is_the_jitted_step(name="mo-ant"):
    """``Simulator.step``, the host function off a CPU (numpy in, new arrays out), gives what the jitted step
    writes in place on a CPU, bit for bit, over a nested batch: from resets (pending noise) and after a step."""
    base = envs.make(name, backend="mujoco").unwrapped
    step = jax.jit(jax.vmap(jax.vmap(base.step)))
    state = jax.vmap(jax.vmap(base.reset))(jax.random.split(jax.random.key(3), 6).reshape(2, 3))
    for t in range(2):
        action = jax.random.uniform(jax.random.key(t), (2, 3, base.action_size), minval=-1, maxval=1)
        nxt = step(state, action)
        host = base.sim.step(*(np.asarray(x) for x in (state.env_state.bits, state.env_state.pending, action)))
        for got, want in zip(host, (nxt.env_state.bits, nxt.obs, nxt.reward, nxt.done)):
            assert got.shape == want.shape and got.dtype == want.dtype
            np.testing.assert_array_equal(got, np.asarray(want))
        state = nxt
    inputs = (np.asarray(x) for x in (state.env_state.bits, state.env_state.pending, action))
    strided = np.empty((2, 3, 2 * base.observation_size), np.float32)[..., ::2]  # not C-contiguous: a reshape would copy it
    with pytest.raises(ValueError, match="C-contiguous"):
        base.sim.step_into((host[0].copy(), strided, host[2].copy(), host[3].copy()), *inputs)


# --- MJX backend ------------------------------------------------------------------------------------


class Rollouts:
    """One task's batched MJX rollout (MuJoCo's solver settings, one compiled ``jit(vmap(scan(step)))``) of
    ``EPISODES`` random-action episodes from MO-Gymnasium's own resets (seeds 0, 1, ...), which both MJX tests
    read: step by step against MO-Gymnasium from the same starts, and in distribution against its own."""

    def __init__(self, name: str):
        self.name = name
        self.gym_id, self.columns, self.parity_steps, self.contact_forces = CASES[name]
        self.env = envs.make(name, episode_length=HORIZON, backend="mjx", mjx_solver="mujoco")
        base = self.env.unwrapped

        def start(key, qpos, qvel):
            return started(self.env, key, base.state_at(qpos, qvel))

        def rollout(state, actions):
            def body(state, action):
                state = self.env.step(state, action)
                return state, (state.obs, state.reward, state.done, state.truncated)

            return jax.lax.scan(body, state, actions)[1]

        self.reset = jax.jit(jax.vmap(self.env.reset))
        gym_env = self.gym()
        qpos, qvel, first_obs = [], [], []
        for seed in range(EPISODES):
            obs, q, v = gym_start(gym_env, seed)
            qpos.append(q)
            qvel.append(v)
            first_obs.append(obs)
        self.first_obs = np.array(first_obs)
        keys = jax.random.split(jax.random.key(0), EPISODES)
        self.start = jax.jit(jax.vmap(start))(keys, jnp.asarray(np.array(qpos), jnp.float32),
                                              jnp.asarray(np.array(qvel), jnp.float32))
        rng = np.random.default_rng(1)
        self.actions = rng.uniform(-1, 1, (EPISODES, HORIZON, self.env.action_size)).astype(np.float32)
        self.obs, self.reward, self.done, self.truncated = map(
            np.asarray, jax.jit(jax.vmap(rollout))(self.start, jnp.asarray(self.actions)))

    def gym(self):
        return mo_gym.make(self.gym_id, max_episode_steps=HORIZON)


@pytest.fixture(scope="module", params=list(CASES))
def rollouts(request):
    return Rollouts(request.param)


def test_mjx_reset_is_the_native_reset(rollouts):
    """Both backends draw the same reset noise from a key (float32 vs float64 sums)."""
    keys = jax.random.split(jax.random.key(3), 4)
    ours = rollouts.reset(keys).env_state
    native_env = envs.make(rollouts.name, backend="mujoco").unwrapped
    qpos, qvel = native_env.qpos_qvel(jax.vmap(native_env.reset)(keys))
    np.testing.assert_allclose(np.asarray(ours.qpos), qpos, atol=1e-6)
    np.testing.assert_allclose(np.asarray(ours.qvel), qvel, atol=1e-6)


def test_mjx_steps_match_mo_gymnasium(rollouts):
    """Same start states and actions: obs, reward vector, terminated and truncated match step by step."""
    np.testing.assert_allclose(np.asarray(rollouts.start.obs), rollouts.first_obs, atol=ATOL, rtol=RTOL)
    gym_env = rollouts.gym()
    compared = 0
    for i in range(EPISODES):
        gym_env.reset(seed=i)
        for t in range(rollouts.parity_steps):
            their_obs, their_reward, terminated, their_truncated, _ = gym_env.step(rollouts.actions[i, t])
            if rollouts.contact_forces is not None and (
                    their_obs[rollouts.contact_forces].any() or rollouts.obs[i, t, rollouts.contact_forces].any()):
                break  # MJX's contact forces differ from MuJoCo 4.0's: compare the flight before contact
            where = f"{rollouts.name} episode {i} step {t}"
            np.testing.assert_allclose(rollouts.obs[i, t], their_obs, atol=ATOL, rtol=RTOL, err_msg=where)
            np.testing.assert_allclose(rollouts.reward[i, t], their_reward[rollouts.columns], atol=ATOL, rtol=RTOL,
                                       err_msg=where)
            assert (rollouts.done[i, t], rollouts.truncated[i, t]) == (terminated, their_truncated), where
            compared += 1
            if terminated:
                break
    assert compared >= EPISODES * (1 if rollouts.contact_forces else min(8, rollouts.parity_steps))


def _episode_statistics(rewards, ends):
    """Per-episode returns up to and including the first end, and lengths, from ``[E, T]`` arrays."""
    steps = np.arange(rewards.shape[1])
    length = np.where(ends.any(1), ends.argmax(1) + 1, rewards.shape[1])
    live = steps[None, :] < length[:, None]
    return (rewards * live[..., None]).sum(1), length


def _agree(ours, theirs, what):
    se = np.sqrt(ours.var(0, ddof=1) / len(ours) + theirs.var(0, ddof=1) / len(theirs))
    gap = np.abs(ours.mean(0) - theirs.mean(0))
    assert np.all(gap <= 4 * se + 1e-3), f"{what}: ours {ours.mean(0)}, MO-Gymnasium {theirs.mean(0)}, se {se}"


def test_mjx_random_rollout_statistics_match_mo_gymnasium(rollouts):
    """Whole random-action episodes, ours against MO-Gymnasium's independent ones (other resets, other actions):
    mean returns and lengths agree. Our starts are MO-Gymnasium's resets; that our own resets draw the same
    noise is ``test_mjx_reset_is_the_native_reset`` and, natively, ``test_reset_noise_matches_gymnasium``."""
    assert rollouts.truncated[:, -1].all() and not rollouts.truncated[:, :-1].any()  # the time limit, on the last step
    our_returns, our_lengths = _episode_statistics(rollouts.reward, rollouts.done | rollouts.truncated)

    gym_env = rollouts.gym()
    gym_env.action_space.seed(3)
    their_returns, their_lengths = [], []
    for seed in range(EPISODES):
        gym_env.reset(seed=1000 + seed)
        total, steps, over = 0.0, 0, False
        while not over:
            _, r, terminated, truncated_, _ = gym_env.step(gym_env.action_space.sample())
            total, steps, over = total + r[rollouts.columns], steps + 1, terminated or truncated_
        their_returns.append(total)
        their_lengths.append(steps)
    assert max(their_lengths) <= HORIZON
    _agree(our_returns, np.array(their_returns), f"{rollouts.name} mean return")
    _agree(our_lengths.astype(float), np.array(their_lengths, float), f"{rollouts.name} mean length")
