"""The run configuration: one flat frozen dataclass, every field settable from the command line.

Sections hold the fields of each algorithm; values a sweep varies (beta, seed) are passed to the
jitted programs as arrays, never baked in as constants.
"""

from __future__ import annotations

import dataclasses

from moiq_jax.preferences import check_preferences

ALGORITHMS = ("admm", "moiq", "iq_learn")


@dataclasses.dataclass(frozen=True)
class Config:
    # --- common ---
    env: str = "cdst"
    algo: str = "moiq"
    preferences: tuple[tuple[float, ...], ...] = ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))
    num_demos: int = 10  # demonstrations per expert
    demos: str | None = None  # a Demonstrations file; None: record them from the env's oracle experts
    seed: int = 0
    gamma: float = 0.99

    def __post_init__(self):
        # Lists from JSON/YAML or the CLI become tuples, so configs stay hashable.
        object.__setattr__(self, "preferences", tuple(tuple(float(w) for w in p) for p in self.preferences))

    def replace(self, **changes) -> Config:
        return dataclasses.replace(self, **changes)

    def validate(self, env=None) -> Config:
        """Raise ValueError naming the bad field; with ``env``, also check preferences fit its reward_dim."""
        from moiq_jax import envs

        envs.spec(self.env)  # unknown env names raise, listing the known ones
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algo {self.algo!r}; known algorithms: {', '.join(ALGORITHMS)}")
        if self.num_demos < 1:
            raise ValueError(f"num_demos must be at least 1, got {self.num_demos}")
        if not 0.0 <= self.gamma < 1.0:
            raise ValueError(f"gamma must be in [0, 1), got {self.gamma}")
        reward_dim = env.reward_dim if env is not None else len(self.preferences[0])
        check_preferences(self.preferences, reward_dim)
        return self
