"""The ``"mujoco"`` backend: a task stepped by MuJoCo's C engine, pure and jittable, for CPUs.

``env_state`` is a ``NativeState``: MuJoCo's state as float64 values carried bit for bit as uint32
pairs (JAX runs without x64, and rounding the state to float32 between steps makes rollouts drift
apart): ``mj_getState`` for ``STATE_SPEC`` (time, qpos, qvel, act and the solver's warm start
``qacc_warmstart``), then the main body's ``xpos`` where the task reads it. A step is one host
callback with ``vmap_method="broadcast_all"``, so a whole (nested) ``vmap`` batch is one call (on a
CPU ``buffer_callback``, which fills XLA's output buffers in place; elsewhere ``pure_callback``); it
sets each env's state into an ``MjData``, runs ``mj_step`` ``frame_skip`` times (and
``mj_rnePostConstraint`` where the task reads contact forces, as Gymnasium), reads the state back and
applies the task's rules in float64 numpy, as Gymnasium does. Outputs depend only on inputs (every input
of ``mj_step`` is set from the state), so steps are bit-reproducible and the step is pure: it runs under
``jit``, ``vmap`` and ``lax.scan``.

MuJoCo's work: ``mujoco.batch.Batch`` (MuJoCo's own batched stepping on its C thread pool; its state
rows are ``mjSTATE_INTEGRATION``, warm start included, so a step continues exactly from its output)
steps the batch, unless the task reads contact forces: Gymnasium computes ``cfrc_ext`` with
``mj_rnePostConstraint`` after the step, which a ``Batch`` cannot run (nor ``mujoco.rollout``, which also
drops the warm start). Those tasks (the Ant) step in a loop of ``mj_setState`` (state and controls),
``mj_step``, ``mj_rnePostConstraint`` and ``mj_getState`` on the calling thread and ``nthread - 1`` workers
of a persistent pool (one ``MjData`` each; MuJoCo's bindings release the GIL in these calls), which claim
small chunks of envs from a shared counter until none is left, so no thread waits on another's fixed share.
The two engines step bit for bit alike (tested).

Reset and ``state_at`` need no physics and no callback: Gymnasium's ``mj_resetData`` + ``set_state``
leaves time and warm start zero, the free root body's ``xpos`` equal to its ``qpos[:3]`` and ``cfrc_ext``
zero. So a reset holds ``qpos0`` as float64 bits and its float32 noise as ``pending``, which the next
step adds in float64 (as Gymnasium adds its noise) before stepping; ``state_at`` of float64 numpy arrays
holds them exactly. (Tests check both against ``mj_forward``.) This keeps resets cheap: ``AutoReset``
computes one at every step.
"""

from __future__ import annotations

import functools
import itertools
import os
import queue
import threading
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from jax.experimental.buffer_callback import buffer_callback
from mujoco.batch import Batch

from moiq_jax.envs.base import is_concrete
from moiq_jax.envs.mujoco.base import MujocoEnv, Physics, Task

STATE_SPEC = int(mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_WARMSTART)
INPUT_SPEC = STATE_SPEC | int(mujoco.mjtState.mjSTATE_CTRL)  # the state, then the controls: one mj_setState per env
BATCH_ROW_SPEC = int(mujoco.mjtState.mjSTATE_INTEGRATION)  # what a mujoco.batch.Batch's state rows hold
ENGINES = ("batch", "loop")
MIN_ENVS_TO_SPLIT = 4  # smaller batches are stepped on the calling thread
CHUNKS_PER_THREAD = 16


@struct.dataclass
class NativeState:
    """``bits``: float64 values as little-endian uint32 pairs, ``[width, 2]`` (see the module docstring).
    ``pending``: float32 ``(qpos, qvel)`` offsets not yet added (reset noise; zero after a step): the next
    step adds them in float64 first, as Gymnasium's reset adds its noise to ``init_qpos``."""

    bits: jax.Array
    pending: jax.Array


def to_bits(x: np.ndarray) -> np.ndarray:
    """float64 ``[..., n]`` -> its bits as uint32 ``[..., n, 2]`` (exact)."""
    x = np.ascontiguousarray(x, np.float64)
    return x.view(np.uint32).reshape(*x.shape, 2)


def from_bits(bits: np.ndarray) -> np.ndarray:
    """uint32 ``[..., n, 2]`` -> the float64 ``[..., n]`` they hold (exact)."""
    bits = np.ascontiguousarray(bits, np.uint32)
    return bits.view(np.float64).reshape(bits.shape[:-1])


class Simulator:
    """One task's model, its engine (``"batch"`` or ``"loop"``, see the module docstring; by default the loop
    only for tasks that read contact forces) with ``nthread`` threads, and the batched host functions."""

    def __init__(self, task: Task, nthread: int, engine: str | None = None):
        self.task = task
        self.model = model = task.mj_model
        self.nthread = nthread
        self.nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        if model.na or mujoco.mj_stateSize(model, STATE_SPEC) != 1 + model.nq + 2 * model.nv:
            raise ValueError(f"{task.xml_file}: the native backend supports models with time, qpos, qvel and "
                             "warm start only (no actuator activations, history or plugin state)")
        self.qpos = slice(1, 1 + model.nq)
        self.qvel = slice(1 + model.nq, 1 + model.nq + model.nv)
        self.body = task.main_body_id
        if self.body is not None:
            joint = model.body_jntadr[self.body]
            if model.body_jntnum[self.body] != 1 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
                raise ValueError(f"{task.xml_file}: the main body {task.main_body!r} must have one free joint")
            self.body_qpos = slice(model.jnt_qposadr[joint], model.jnt_qposadr[joint] + 3)
        self.width = self.nstate + (3 if self.body is not None else 0)
        probe, data = np.arange(self.nstate + model.nu, dtype=np.float64), mujoco.MjData(model)
        mujoco.mj_setState(model, data, probe, INPUT_SPEC)
        if mujoco.mj_stateSize(model, INPUT_SPEC) != probe.size or not np.array_equal(data.ctrl, probe[self.nstate:]):
            raise ValueError(f"{task.xml_file}: mj_setState does not lay out the controls after the state")
        self.engine = engine or ("loop" if task.contact_forces else "batch")
        if self.engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
        if self.engine == "batch":
            if task.contact_forces:
                raise ValueError(f"{type(task).__name__} reads contact forces, which only the 'loop' engine computes")
            self.batches: dict[int, Batch] = {}  # one per batch size
            self.lock = threading.Lock()  # a Batch must not be used from two threads at once
            self.input_rows = component_columns(model, INPUT_SPEC, BATCH_ROW_SPEC)
            self.state_rows = self.input_rows[:self.nstate]
        else:
            self.datas: queue.SimpleQueue = queue.SimpleQueue()  # one MjData per thread stepping at a time
            for _ in range(nthread):
                self.datas.put(mujoco.MjData(model))
            # the calling thread steps a chunk too, so nthread - 1 workers
            self.pool = ThreadPoolExecutor(nthread - 1, thread_name_prefix="moiq-mujoco") if nthread > 1 else None

    def physics(self, values: np.ndarray, cfrc_ext: np.ndarray | None = None) -> Physics:
        """The rules' view of float64 states ``[n, width]``."""
        xpos = values[:, self.nstate:self.nstate + 3] if self.body is not None else None
        return Physics(values[:, self.qpos], values[:, self.qvel], xpos, cfrc_ext)

    # --- host functions (numpy in, numpy out; any leading batch shape) ---------------------------

    def start_values(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """float64 values ``[width]`` after ``mj_resetData`` + ``set_state(qpos, qvel)``."""
        values = np.zeros(self.width)
        values[self.qpos], values[self.qvel] = qpos, qvel
        if self.body is not None:
            values[self.nstate:] = values[self.qpos][self.body_qpos]
        return values

    def with_pending(self, values: np.ndarray, pending: np.ndarray) -> np.ndarray:
        """``values`` ``[n, width]`` with the pending offsets ``[n, nq + nv]`` added (float64), in place."""
        nq = self.model.nq
        pending = pending.astype(np.float64)
        for target, offset in ((self.qpos, pending[:, :nq]), (self.qvel, pending[:, nq:])):
            np.add(values[:, target], offset, out=values[:, target], where=offset != 0)
        if self.body is not None:
            offset = pending[:, self.body_qpos]
            np.add(values[:, self.nstate:], offset, out=values[:, self.nstate:], where=offset != 0)
        return values

    def step(self, bits, pending, action):
        """One env step of every state in (``bits``, ``pending``) under ``action``: new arrays (bits, obs, reward,
        done), each with ``action``'s batch shape."""
        batch = np.shape(action)[:-1]
        out = (np.empty((*batch, self.width, 2), np.uint32), np.empty((*batch, self.task.observation_size), np.float32),
               np.empty((*batch, self.task.reward_dim), np.float32), np.empty(batch, bool))
        self.step_into(out, bits, pending, action)
        return out

    def inputs_of(self, bits, pending, action):
        """What a step of (``bits``, ``pending``) under ``action`` starts from, flat over the batch: the float64
        values ``[n, width]`` (pending offsets added), the float32 actions ``[n, nu]``, and MuJoCo's input rows
        ``[n, nstate + nu]`` (the state, then the controls as ``MjData`` holds them: float64 of the float32)."""
        bits, pending, action = (np.asarray(x) for x in (bits, pending, action))
        nq, nv, nu, ns = self.model.nq, self.model.nv, self.model.nu, self.nstate
        values = self.with_pending(from_bits(bits).reshape(-1, self.width).copy(), pending.reshape(-1, nq + nv))
        action = action.astype(np.float32, copy=False).reshape(-1, nu)
        inputs = np.empty((values.shape[0], ns + nu))
        inputs[:, :ns], inputs[:, ns:] = values[:, :ns], action
        return values, action, inputs

    def step_into(self, out, bits, pending, action):
        """``step`` writing into ``out`` = (bits, obs, reward, done) in place: C-contiguous writable arrays, or
        buffers numpy views as such (``buffer_callback``'s); MuJoCo writes the new states straight into ``bits``."""
        out_bits, out_obs, out_reward, out_done = out = [np.asarray(x) for x in out]
        if not all(x.flags.c_contiguous and x.flags.writeable for x in out):
            raise ValueError("step_into needs C-contiguous writable output arrays")
        values, action, inputs = self.inputs_of(bits, pending, action)
        n = values.shape[0]
        new = out_bits.reshape(n, self.width, 2).view(np.float64)[..., 0]  # float64 [n, width], in place
        cfrc = np.empty((n, self.model.nbody, 6)) if self.task.contact_forces else None
        self.advance(n, inputs, new, cfrc)
        before, after = self.physics(values), self.physics(new, cfrc)
        reward, done = self.task.reward_and_done(before, after, action, np)
        out_obs.reshape(n, -1)[...] = self.task.observe(after, np)
        out_reward.reshape(n, -1)[...] = reward
        out_done.reshape(n)[...] = done

    def advance(self, n, inputs, out, cfrc):
        """MuJoCo's env step of envs ``0..n-1``: ``inputs`` ``[n, nstate + nu]`` (state, ctrl) to ``out``
        ``[n, width]`` (state, main body's xpos) and ``cfrc`` (contact forces, or None), on the engine."""
        if self.engine == "batch":
            self.run_batch(n, inputs, out)
        else:
            self.run_chunks(n, inputs, out, cfrc)

    def run_batch(self, n, inputs, out):
        """``advance`` on a ``mujoco.batch.Batch`` of ``n`` simulations: rows in, ``frame_skip`` substeps, rows out."""
        with self.lock:
            batch = self.batches.get(n)
            if batch is None:
                batch = self.batches[n] = Batch(self.model, n, self.nthread)
                if self.body is not None:
                    batch.bind("xpos")  # a derived field is copied out from the first call after it is bound
            batch.state[:, self.input_rows] = inputs
            batch.step(nstep=self.task.frame_skip)
            out[:, :self.nstate] = batch.state[:, self.state_rows]
            if self.body is not None:
                out[:, self.nstate:] = batch.bind("xpos")[:, self.body]

    def run_chunks(self, n, inputs, out, cfrc):
        """``advance`` in a loop over envs, in chunks of about ``n / (CHUNKS_PER_THREAD * nthread)`` envs that the
        calling thread and ``nthread - 1`` pool workers claim one at a time until none is left, so that a thread
        that starts late or steps slower states takes fewer chunks (no thread waits for another's fixed share)."""
        size = max(1, -(-n // (CHUNKS_PER_THREAD * self.nthread)))
        nchunks = -(-n // size)
        if self.pool is None or nchunks == 1 or n < MIN_ENVS_TO_SPLIT:
            self._step_chunks(iter([0]), 1, n, n, inputs, out, cfrc)
            return
        claim = itertools.count()  # next() on it is one C call, atomic under the GIL
        args = (claim, nchunks, size, n, inputs, out, cfrc)
        futures = [self.pool.submit(self._step_chunks, *args) for _ in range(min(self.nthread, nchunks) - 1)]
        self._step_chunks(*args)  # this thread claims chunks too
        for future in futures:
            future.result()

    def _step_chunks(self, claim, nchunks, size, n, inputs, out, cfrc):
        """Steps the chunks it claims from ``claim`` on one ``MjData``: ``inputs`` ``[n, nstate + nu]`` (state, ctrl)
        to ``out`` ``[n, width]`` (state, main body's xpos) and ``cfrc`` (contact forces, or None)."""
        model, data, frame_skip, body = self.model, self.datas.get(), self.task.frame_skip, self.body
        states = out[:, :self.nstate]
        try:
            for chunk in claim:
                if chunk >= nchunks:
                    break
                for i in range(chunk * size, min(chunk * size + size, n)):
                    mujoco.mj_setState(model, data, inputs[i], INPUT_SPEC)
                    mujoco.mj_step(model, data, frame_skip)
                    if cfrc is not None:
                        mujoco.mj_rnePostConstraint(model, data)
                        cfrc[i] = data.cfrc_ext
                    mujoco.mj_getState(model, data, states[i], STATE_SPEC)
                    if body is not None:
                        out[i, self.nstate:] = data.xpos[body]
        finally:
            self.datas.put(data)


def component_columns(model: mujoco.MjModel, spec: int, within: int) -> np.ndarray:
    """The columns that a state vector of ``spec`` occupies in one of ``within`` (a superset): MuJoCo lays
    state components out in the order of their ``mjtState`` bits."""
    columns = []
    for bit in (1 << i for i in range(within.bit_length())):
        if spec & bit:
            offset = mujoco.mj_stateSize(model, within & (bit - 1))
            columns.extend(range(offset, offset + mujoco.mj_stateSize(model, bit)))
    return np.asarray(columns)


@functools.cache
def simulator(task_class: type[Task], nthread: int, engine: str | None = None) -> Simulator:
    """One ``Simulator`` (and its threads) per task, thread count and engine, shared by every env built."""
    return Simulator(task_class(), nthread, engine)


def default_threads() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


class NativeEnv(MujocoEnv):
    """A task on MuJoCo's C engine; ``nthread`` (default: the CPUs this process may use) steps a batch."""

    backend = "mujoco"

    def __init__(self, task: Task, nthread: int | None = None):
        nthread = default_threads() if nthread is None else int(nthread)
        if nthread < 1:
            raise ValueError(f"nthread must be at least 1, got {nthread}")
        super().__init__(task)
        self.nthread = nthread

    @property
    def sim(self) -> Simulator:
        return simulator(type(self.task), self.nthread)

    def _start(self, qpos, qvel, offset):
        sim, model, nq = self.sim, self.mj_model, self.mj_model.nq
        if offset:  # reset: qpos0 + dq, 0 + dv
            base_q, base_v = self.task.init_qpos, np.zeros(model.nv)
        elif is_concrete((qpos, qvel)) and not isinstance(qpos, jax.Array):  # exact float64 start
            base_q, base_v = np.asarray(qpos, np.float64), np.asarray(qvel, np.float64)
            qpos, qvel = np.zeros(nq, np.float32), np.zeros(model.nv, np.float32)
        else:  # float32 arrays, possibly traced
            base_q, base_v = np.zeros(nq), np.zeros(model.nv)
        pending = jnp.concatenate([jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32)])
        bits = jnp.asarray(to_bits(sim.start_values(base_q, base_v)))
        # The observation in float32 from the same rules (it is float32 anyway): set_state's cfrc_ext is zero.
        cfrc = jnp.zeros((model.nbody, 6), jnp.float32) if self.task.contact_forces else None
        view = Physics(jnp.asarray(base_q, jnp.float32) + pending[:nq], jnp.asarray(base_v, jnp.float32) + pending[nq:],
                       None, cfrc)
        return self.initial_state(NativeState(bits, pending), self.task.observe(view, jnp))

    def step(self, state, action):
        self.check_action(action)
        action = jnp.asarray(action, jnp.float32)
        sim = self.sim
        shapes = (jax.ShapeDtypeStruct((sim.width, 2), jnp.uint32),
                  jax.ShapeDtypeStruct((self.observation_size,), jnp.float32),
                  jax.ShapeDtypeStruct((self.reward_dim,), jnp.float32),
                  jax.ShapeDtypeStruct((), jnp.bool_))
        env_state = state.env_state
        # On a CPU, XLA hands the callback its output buffers to fill in place (no copies, and a far smaller fixed
        # cost per call than pure_callback's); elsewhere the arrays travel to the host and back.
        bits, obs, reward, done = jax.lax.platform_dependent(
            env_state.bits, env_state.pending, action,
            cpu=lambda *args: buffer_callback(lambda ctx, out, *xs: sim.step_into(out, *xs), shapes,
                                              vmap_method="broadcast_all")(*args),
            default=lambda *args: jax.pure_callback(sim.step, shapes, *args, vmap_method="broadcast_all"))
        return state.replace(env_state=NativeState(bits, jnp.zeros_like(env_state.pending)), obs=obs, reward=reward,
                             done=done, truncated=jnp.zeros((), bool))

    def values(self, state) -> np.ndarray:
        """The float64 values a concrete state holds, pending offsets added, ``[..., width]`` (for tests and
        inspection)."""
        env_state = state.env_state if hasattr(state, "env_state") else state
        values = from_bits(np.asarray(env_state.bits))
        pending = np.asarray(env_state.pending)
        flat = self.sim.with_pending(values.reshape(-1, values.shape[-1]).copy(), pending.reshape(-1, pending.shape[-1]))
        return flat.reshape(values.shape)

    def qpos_qvel(self, state) -> tuple[np.ndarray, np.ndarray]:
        """float64 ``qpos`` and ``qvel`` of a concrete state."""
        values = self.values(state)
        return values[..., self.sim.qpos], values[..., self.sim.qvel]
