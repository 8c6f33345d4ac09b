"""Expert policies and their demonstrations."""

import jax

from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.dst_oracle import optimal_treasure, oracle_policy, record_demonstrations
from moiq_jax.experts.iq_learn_format import load_iq_learn, save_iq_learn


def oracle_demonstrations(env_name: str, preferences, num_demos: int, seed: int = 0) -> Demonstrations:
    """``num_demos`` episodes per preference from the env's exact optimal experts, in the absorbing-state env:
    the paper's stochastic oracle on discrete DST maps, the deterministic shortest-path policy on cdst."""
    from moiq_jax import envs

    envs.spec(env_name)  # unknown names raise, listing the known ones
    if env_name.startswith("dst"):
        return record_demonstrations(env_name, preferences, num_demos, jax.random.key(seed))
    if env_name == "cdst":
        from moiq_jax.experts import cdst_oracle

        return cdst_oracle.record_demonstrations(preferences, num_demos)
    raise ValueError(f"no oracle experts for env {env_name!r}; record demonstrations with trained experts and "
                     f"pass the file with --demos")


__all__ = [
    "Demonstrations",
    "load_iq_learn",
    "optimal_treasure",
    "oracle_demonstrations",
    "oracle_policy",
    "record_demonstrations",
    "save_iq_learn",
]
