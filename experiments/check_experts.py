"""The committed SAC experts run in MO-Gymnasium's own envs: each expert's return there beside its
demonstrations' (issue 17: within 10%) and the paper's expert column (its Table 1: at least 90%), and how
distinct the experts are (each expert scored under every preference).

    PYTHONPATH=. python experiments/check_experts.py --env mo-hopper [--episodes 10] [--first-seed 0]
        [--demos experiments/demos] [--out FILE]

Reads ``<demos>/<env>-experts.npz`` and ``<demos>/<env>.npz``; writes ``<demos>/<env>-check.json`` (or ``--out``)
and prints the table. Episodes use MO-Gymnasium's ``reset(seed=first_seed + i)`` for i < episodes (another
``--first-seed`` gives episodes not seen before, to test experts chosen on these), its 1,000-step limit,
and each expert's deterministic (mean) action, as the demonstrations do. ``fell``: episodes ended by a fall before
the time limit, in MO-Gymnasium / in the demonstrations (which reach the absorbing state instead).
"""

from __future__ import annotations

import argparse
import json
import pathlib

import jax
import jax.numpy as jnp
import mo_gymnasium
import numpy as np

from moiq_jax.experts import sac
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.networks import networks_of_sizes

# env -> (MO-Gymnasium id, the columns of its vector reward that are this project's objectives)
MO_GYMNASIUM = {
    "mo-hopper": ("mo-hopper-v5", [0, 1, 2]),
    "mo-walker2d": ("mo-walker2d-v5", [0, 1]),
    "mo-halfcheetah": ("mo-halfcheetah-v5", [0, 1]),
    "mo-halfcheetah-v4": ("mo-halfcheetah-v4", [0, 1]),
    "mo-ant": ("mo-ant-v5", [0, 2]),
}


def gymnasium_returns(env: str, config, actor_params, episodes: int, first_seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``[E, episodes, d]`` vector returns of each expert in MO-Gymnasium's env, and ``[E, episodes]`` whether
    the episode ended by termination (a fall) before the time limit."""
    gym_id, columns = MO_GYMNASIUM[env]
    gym_env = mo_gymnasium.make(gym_id)
    c = config.offpolicy
    nets = networks_of_sizes(c.hidden_sizes, len(columns), gym_env.action_space.shape[0], c.action_scale)
    act = jax.jit(lambda params, obs, w: nets.act(params, obs[None], w)[0])
    returns = np.zeros((len(config.preferences), episodes, len(columns)))
    fell = np.zeros((len(config.preferences), episodes), bool)
    for i, preference in enumerate(jnp.asarray(config.preferences, jnp.float32)):
        params = jax.tree_util.tree_map(lambda x, i=i: x[i], actor_params)
        for episode in range(episodes):
            obs, _ = gym_env.reset(seed=first_seed + episode)
            done = False
            while not done:
                action = np.asarray(act(params, jnp.asarray(obs, jnp.float32), preference), np.float64)
                obs, reward, terminated, truncated, _ = gym_env.step(action)
                returns[i, episode] += np.asarray(reward)[columns]
                done = terminated or truncated
            fell[i, episode] = terminated
    gym_env.close()
    return returns, fell


def check(env: str, demos_dir: pathlib.Path, episodes: int, first_seed: int = 0) -> dict:
    config, actor = sac.load_experts(demos_dir / f"{env}-experts.npz")
    demos = Demonstrations.load(demos_dir / f"{env}.npz")
    preferences = np.asarray(config.preferences, np.float64)
    gym, gym_fell = gymnasium_returns(env, config, actor, episodes, first_seed)
    demo_fell = demos.obs[..., -1].max(axis=-1) > 0  # [E, demos]: reached the absorbing state (the env's flag)
    gym_mean, demo_mean = gym.mean(1), demos.mean_returns().astype(np.float64)
    paper = sac.PAPER_EXPERT_RETURNS[env]
    cross = preferences @ gym_mean.T  # [i, j]: expert j's MO-Gymnasium return scalarised by preference i
    experts = []
    for i, (w, p) in enumerate(zip(preferences, paper)):
        scalar, demo_scalar = float(w @ gym_mean[i]), float(w @ demo_mean[i])
        rivals = [j for j in range(len(preferences)) if j != i and cross[i, j] >= cross[i, i]]
        experts.append({
            "preference": w.tolist(), "gym_vector_return": gym_mean[i].round(1).tolist(),
            "gym_scalar_return": round(scalar, 1), "gym_scalar_std": round(float((gym[i] @ w).std()), 1),
            "gym_scalar_returns": (gym[i] @ w).round(1).tolist(), "gym_episodes_fallen": int(gym_fell[i].sum()),
            "demo_scalar_returns": (demos.rewards[i].sum(1).astype(np.float64) @ w).round(1).tolist(),
            "demo_episodes_fallen": int(demo_fell[i].sum()),
            "demo_vector_return": demo_mean[i].round(1).tolist(), "demo_scalar_return": round(demo_scalar, 1),
            "gym_over_demos": round(scalar / demo_scalar, 3) if demo_scalar else None,
            "within_10pct_of_demos": bool(abs(scalar - demo_scalar) <= 0.1 * abs(demo_scalar)),
            "paper_expert_return": p, "gym_over_paper": round(scalar / p, 3),
            "at_least_90pct_of_paper": bool(scalar >= 0.9 * p),
            "experts_as_good_under_this_preference": [preferences[j].tolist() for j in rivals],
        })
    return {"env": env, "gym_id": MO_GYMNASIUM[env][0], "episodes": episodes, "first_seed": first_seed,
            "scalarised_by_row_preference_of_column_expert": cross.round(1).tolist(), "experts": experts}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, choices=sorted(MO_GYMNASIUM))
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0, help="the first episode's reset seed")
    parser.add_argument("--demos", default="experiments/demos", help="folder of the expert and demonstration files")
    parser.add_argument("--out", help="the report's path (default <demos>/<env>-check.json)")
    args = parser.parse_args()
    demos_dir = pathlib.Path(args.demos)
    report = check(args.env, demos_dir, args.episodes, args.first_seed)
    pathlib.Path(args.out or demos_dir / f"{args.env}-check.json").write_text(json.dumps(report, indent=1))
    print(f"{args.env}: each expert in {report['gym_id']}, {args.episodes} episodes from reset seed {args.first_seed}")
    print(f"  {'preference':<16} {'MO-Gym vector':<26} {'MO-Gym':>8} {'demos':>8} {'ratio':>6} {'paper':>7} "
          f"{'ratio':>6} {'fell':>5}  as good under this preference")
    for e in report["experts"]:
        print(f"  {e['preference']!s:<16} {e['gym_vector_return']!s:<26} {e['gym_scalar_return']:8.1f} "
              f"{e['demo_scalar_return']:8.1f} {e['gym_over_demos'] or float('nan'):6.2f} "
              f"{e['paper_expert_return']:7.0f} {e['gym_over_paper']:6.2f} "
              f"{e['gym_episodes_fallen']:2d}/{e['demo_episodes_fallen']:<2d}  "
              f"{e['experts_as_good_under_this_preference'] or 'none'}")


if __name__ == "__main__":
    main()
