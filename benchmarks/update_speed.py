"""One update of SAC, MOIQ and IQ-Learn on these CPU cores, in one run: ms per update, GFLOP/s (XLA's count of
the compiled update), its share of a large float32 matrix product's rate measured in the same run, and SAC
against the same step written as a peer would (CleanRL-style JAX: flax MLPs, optax adam, twin Q): "peer" with
SAC's usual scalar Q(s, a), "peer-vec" with the vector critic Q(s, a, w) in R^d that the library's SAC learns
(the preference as an input, one output per objective), the same computation as ours.

    python benchmarks/update_speed.py [--updates 50] [--repeats 3] [--sizes 256:256 128:128] [--only moiq3 iq3]

Networks and batches are built from mo-hopper's sizes (obs 11, action 3, reward 3) without stepping an env.
Each program runs ``--updates`` updates in one ``lax.scan`` (as training does, so dispatch is amortised) on
batches drawn from full replay buffers (and demonstrations) with offpolicy.py's own samplers; the best of
``--repeats`` timings counts, and the matrix product is timed between the algorithms so that its rate
reflects the same load. With ``--no-sampling`` the update on one fixed batch is timed too (last column).
SAC xE and IQ-Learn xE are E single-expert models vmapped (as ``offpolicy`` trains them); MOIQ xE is one
model for E experts.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
from moiq_speed import compiled, matmul_gflops

from moiq_jax import replay
from moiq_jax.algos import actor_critic, moiq, sac
from moiq_jax.algos.offpolicy import expert_and_policy_batch, policy_batch
from moiq_jax.networks import networks_of_sizes

OBS, ACTION, REWARD = 11, 3, 3  # mo-hopper-v5
PREFERENCES = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]], np.float32)
GAMMA, TAU, ALPHA_REG, LR = 0.99, 0.005, 0.5, 3e-4
CAPACITY, DEMO_ROWS = 100_000, 10_000


def transitions(key, rows, experts=None):
    """Random transitions of mo-hopper's sizes (leading axes ``experts, rows``, or ``rows``)."""
    lead = (rows,) if experts is None else (experts, rows)
    k = jax.random.split(key, 4)
    return {"obs": jax.random.normal(k[0], (*lead, OBS)), "action": jax.random.uniform(k[1], (*lead, ACTION), minval=-1),
            "next_obs": jax.random.normal(k[2], (*lead, OBS)), "reward": jax.random.normal(k[3], (*lead, REWARD)),
            "done": (jax.random.uniform(k[3], lead) < 0.01).astype(jnp.float32)}


def full_buffers(key, experts):
    """``experts`` replay buffers of ``CAPACITY`` rows, full."""
    data = transitions(key, CAPACITY, experts)
    full = jnp.full((experts,), CAPACITY, jnp.int32)
    return replay.ReplayBuffer(data, jnp.zeros((experts,), jnp.int32), full)


class Case(NamedTuple):
    name: str
    program: object  # compiled (state, key) -> state running ``updates`` updates
    state: object
    flops: float  # one update, XLA's count


def ours(algorithm: str, experts: int, hidden: int, batch: int, updates: int, sample: bool) -> Case:
    """The library's update for ``algorithm`` ('sac', 'moiq', 'iq') with ``experts`` experts."""
    nets = networks_of_sizes((hidden, hidden), REWARD, ACTION)
    optimisers = actor_critic.Optimisers(optax.adam(LR), optax.adam(LR), optax.adam(LR))
    settings = actor_critic.Settings(-float(ACTION), TAU, True)
    prefs = jnp.asarray(PREFERENCES[:experts])
    beta = 1.0 if algorithm == "moiq" else 0.0

    def objective(critic, params, b, p, k):
        if algorithm == "sac":
            return sac.critic_loss(critic, nets, params, b, p, k, GAMMA)
        return moiq.critic_loss(critic, nets, params, b, p, beta, k, GAMMA, ALPHA_REG, True)

    per_model = algorithm != "moiq"  # SAC and IQ-Learn: one single-expert model per preference, vmapped
    sampler = policy_batch if algorithm == "sac" else expert_and_policy_batch
    key = jax.random.PRNGKey(0)
    buffers, demos = full_buffers(key, experts), transitions(jax.random.PRNGKey(1), DEMO_ROWS, experts)

    def one(learner, buffers, demos, prefs, key):
        batch_key, step_key = jax.random.split(key)
        batches = sampler(buffers, demos, batch_key if sample else jax.random.PRNGKey(3), batch)
        return actor_critic.update(learner, nets, optimisers, batches, prefs, step_key, settings, objective)[0]

    def scanned(n):
        def run(state, key):
            learner, buffers, demos = state

            def body(learner, k):
                if not per_model:
                    return one(learner, buffers, demos, prefs, k), None
                split = lambda x: x[:, None]
                return jax.vmap(one)(learner, jax.tree_util.tree_map(split, buffers),
                                     jax.tree_util.tree_map(split, demos), prefs[:, None],
                                     jax.random.split(k, experts)), None

            learner, _ = jax.lax.scan(body, learner, jax.random.split(key, n))
            return learner, buffers, demos
        return run

    if per_model:
        learner = jax.vmap(lambda k, p: actor_critic.init_learner(nets, optimisers, k, OBS, ACTION, p, 0.2))(
            jax.random.split(key, experts), prefs[:, None])
    else:
        learner = actor_critic.init_learner(nets, optimisers, key, OBS, ACTION, prefs, 0.2)
    state = (learner, buffers, demos)
    program, _ = compiled(scanned(updates), state, key)
    label = {"sac": "SAC", "moiq": "MOIQ", "iq": "IQ-Learn"}[algorithm]
    return Case(f"{label} x{experts}", program, state, flops(scanned(1), state, key))


def flops(fn, *args) -> float:
    """XLA's floating-point operation count of ``fn`` compiled for ``args``."""
    cost = jax.jit(fn).lower(*args).compile().cost_analysis()
    return (cost[0] if isinstance(cost, list) else cost)["flops"]


# ---- the peer: a CleanRL-style JAX SAC step (scalar reward, no preference input) ----

class QNetwork(nn.Module):
    """Q(s, a), or with ``outputs`` > 0 a vector Q(s, a, w) of that many objectives taking the preference w."""

    hidden: int
    outputs: int = 0

    @nn.compact
    def __call__(self, obs, action, preference=None):
        x = jnp.concatenate([obs, action] if preference is None else [obs, action, preference], -1)
        x = nn.relu(nn.Dense(self.hidden)(x))
        x = nn.relu(nn.Dense(self.hidden)(x))
        return nn.Dense(self.outputs)(x) if self.outputs else nn.Dense(1)(x)[..., 0]


class Actor(nn.Module):
    hidden: int

    @nn.compact
    def __call__(self, obs):
        x = nn.relu(nn.Dense(self.hidden)(obs))
        x = nn.relu(nn.Dense(self.hidden)(x))
        mean, log_std = nn.Dense(ACTION)(x), nn.Dense(ACTION)(x)
        log_std = jnp.tanh(log_std)
        return mean, -5.0 + 0.5 * 7.0 * (log_std + 1)


def peer(experts: int, hidden: int, batch: int, updates: int, sample: bool, vector: bool = False) -> Case:
    """CleanRL's SAC (sac_continuous_action, in JAX as its td3_jax/sbx write it): two Q TrainStates, their targets,
    an actor, a learnt log alpha; one jitted step does critic, actor, alpha and Polyak. ``experts`` copies vmapped.
    With ``vector``, the same step on the computation the library's SAC does: each Q takes the expert's preference
    w and returns one value per objective, fitted to the vector reward; the twins are compared on w . Q."""
    qf, actor = QNetwork(hidden, REWARD if vector else 0), Actor(hidden)
    tx = optax.adam(LR)
    obs0, act0 = jnp.zeros((1, OBS)), jnp.zeros((1, ACTION))
    prefs = jnp.asarray(PREFERENCES[:experts])

    def q_of(q, obs, action, w):
        return qf.apply(q, obs, action, jnp.broadcast_to(w, (obs.shape[0], REWARD))) if vector else qf.apply(q, obs, action)

    def scalar(q, w):
        return q @ w if vector else q

    def init(key):
        k1, k2, k3 = jax.random.split(key, 3)
        w0 = (jnp.zeros((1, REWARD)),) if vector else ()
        q1, q2, pi = qf.init(k1, obs0, act0, *w0), qf.init(k2, obs0, act0, *w0), actor.init(k3, obs0)
        log_alpha = jnp.log(0.2)
        return {"q1": q1, "q2": q2, "t1": q1, "t2": q2, "pi": pi, "log_alpha": log_alpha, "q_opt": tx.init((q1, q2)),
                    "pi_opt": tx.init(pi), "a_opt": tx.init(log_alpha)}

    def sample_action(pi, obs, key):
        mean, log_std = actor.apply(pi, obs)
        std = jnp.exp(log_std)
        u = mean + std * jax.random.normal(key, mean.shape)
        a = jnp.tanh(u)
        log_prob = jnp.sum(-0.5 * ((u - mean) / std) ** 2 - log_std - 0.5 * jnp.log(2 * jnp.pi)
                           - jnp.log(1 - a**2 + 1e-6), -1)
        return a, log_prob

    def step(s, b, w, key):
        k1, k2 = jax.random.split(key)
        alpha = jnp.exp(s["log_alpha"])
        next_a, next_lp = sample_action(s["pi"], b["next_obs"], k1)
        next_q1, next_q2 = q_of(s["t1"], b["next_obs"], next_a, w), q_of(s["t2"], b["next_obs"], next_a, w)
        if vector:
            next_q = jnp.where((scalar(next_q1, w) <= scalar(next_q2, w))[:, None], next_q1, next_q2)
            target = b["reward"] + ((1 - b["done"]) * GAMMA)[:, None] * (next_q - (alpha * next_lp)[:, None])
        else:
            target = b["reward"][:, 0] + (1 - b["done"]) * GAMMA * (jnp.minimum(next_q1, next_q2) - alpha * next_lp)

        def q_loss(qs):
            errors = [(q_of(q, b["obs"], b["action"], w) - target) ** 2 for q in qs]
            return sum(jnp.mean(jnp.sum(e, -1) if vector else e) for e in errors)

        grads = jax.grad(q_loss)((s["q1"], s["q2"]))
        upd, q_opt = tx.update(grads, s["q_opt"])
        q1, q2 = optax.apply_updates((s["q1"], s["q2"]), upd)

        def pi_loss(pi):
            a, lp = sample_action(pi, b["obs"], k2)
            q = jnp.minimum(scalar(q_of(q1, b["obs"], a, w), w), scalar(q_of(q2, b["obs"], a, w), w))
            return jnp.mean(alpha * lp - q), lp

        grads, lp = jax.grad(pi_loss, has_aux=True)(s["pi"])
        upd, pi_opt = tx.update(grads, s["pi_opt"])
        pi = optax.apply_updates(s["pi"], upd)
        a_grad = jax.grad(lambda la: -jnp.mean(la * (lp + -ACTION)))(s["log_alpha"])
        upd, a_opt = tx.update(a_grad, s["a_opt"])
        return {"q1": q1, "q2": q2, "t1": optax.incremental_update(q1, s["t1"], TAU),
                    "t2": optax.incremental_update(q2, s["t2"], TAU), "pi": pi, "log_alpha": s["log_alpha"] + upd,
                    "q_opt": q_opt, "pi_opt": pi_opt, "a_opt": a_opt}

    key = jax.random.PRNGKey(0)
    buffers = full_buffers(key, experts)

    def scanned(n):
        def run(state, key):
            models, buffers = state

            def body(models, k):
                batch_key, step_key = jax.random.split(k)
                b = policy_batch(buffers, None, batch_key if sample else jax.random.PRNGKey(3), batch)
                return jax.vmap(step)(models, b, prefs, jax.random.split(step_key, experts)), None

            models, _ = jax.lax.scan(body, models, jax.random.split(key, n))
            return models, buffers
        return run

    state = (jax.vmap(init)(jax.random.split(key, experts)), buffers)
    program, _ = compiled(scanned(updates), state, key)
    return Case(f"peer{'-vec' if vector else ''} SAC x{experts}", program, state, flops(scanned(1), state, key))


def best_seconds(case: Case, repeats: int) -> float:
    key, best = jax.random.PRNGKey(2), float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(case.program(case.state, key))
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=50, help="updates per timed program (one lax.scan)")
    parser.add_argument("--repeats", type=int, default=3, help="timings per program; the best counts")
    parser.add_argument("--sizes", nargs="+", default=["256:256", "128:128"], help="hidden:batch pairs")
    parser.add_argument("--only", nargs="+", default=None, help="a subset of: sac1 sac3 moiq3 iq3 peer1 peer3 peervec1 peervec3")
    parser.add_argument("--no-sampling", action="store_true", help="also time the update on a fixed batch")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores, jax {jax.__version__} {jax.default_backend()}; load average at start "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}; mo-hopper sizes obs {OBS} action {ACTION} reward {REWARD}; "
          f"{args.updates} updates per program, best of {args.repeats}")
    for size in args.sizes:
        hidden, batch = map(int, size.split(":"))
        print(f"\n== hidden {hidden}x{hidden}, batch {batch} per expert (IQ/MOIQ: {batch} expert + {batch} policy rows)")
        print(f"{'update':<16}{'ms/update':>10}{'MFLOP':>9}{'GFLOP/s':>9}{'% matmul':>10}{'matmul GF/s':>12}"
              f"{'ms no-sampling':>16}")
        rows = {}
        specs = [("sac", 1), ("sac", 3), ("moiq", 3), ("iq", 3)]
        for algorithm, experts in [*specs, ("peer", 1), ("peer", 3), ("peervec", 1), ("peervec", 3)]:
            if args.only and f"{algorithm}{experts}" not in args.only:
                continue
            figures = []
            for sample in (True, False) if args.no_sampling else (True,):
                case = (peer(experts, hidden, batch, args.updates, sample, vector=algorithm == "peervec")
                        if algorithm.startswith("peer") else ours(algorithm, experts, hidden, batch, args.updates, sample))
                figures.append((case, best_seconds(case, args.repeats) / args.updates))
            case, seconds = figures[0]
            peak = matmul_gflops()
            rate = case.flops / seconds / 1e9
            rows[case.name] = seconds
            extra = f"{1e3 * figures[1][1]:>16.2f}" if len(figures) > 1 else ""
            print(f"{case.name:<16}{1e3 * seconds:>10.2f}{case.flops / 1e6:>9.1f}{rate:>9.1f}{100 * rate / peak:>9.0f}%"
                  f"{peak:>12.0f}{extra}", flush=True)
        for experts in (1, 3):
            for peer_name in ("peer", "peer-vec"):
                theirs, mine = rows.get(f"{peer_name} SAC x{experts}"), rows.get(f"SAC x{experts}")
                if theirs and mine:
                    print(f"SAC x{experts} vs {peer_name}: {theirs / mine:.2f}x the {peer_name}'s speed")
    print(f"\nload average at end {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
