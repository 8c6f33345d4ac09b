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

    # --- moiq --- (also its baselines: "iq_learn" trains one model per expert with beta = 0)
    beta: float = 5.0  # consensus penalty weight; 0 is the paper's ablation
    total_steps: int = 100_000  # env steps per expert
    num_envs: int = 1  # parallel envs per expert
    learning_starts: int = 1_000  # env steps per expert of random actions before updates begin
    updates_per_step: int = 1  # gradient updates per vectorised env step
    batch_size: int = 256  # expert samples per expert and update, and as many policy samples
    buffer_size: int = 100_000  # replay capacity per expert
    hidden_sizes: tuple[int, ...] = (256, 256)
    critic_lr: float = 3e-4
    actor_lr: float = 3e-5
    alpha_lr: float = 3e-4
    tau: float = 0.005  # Polyak rate of the target critics
    init_alpha: float = 0.01  # initial entropy temperature
    learn_alpha: bool = True
    alpha_reg: float = 0.5  # IQ-Learn's chi^2 regulariser: phi(x) = x - x^2 / (4 alpha_reg)
    eval_interval: int = 5_000  # env steps per expert between evaluations (and best-model checks)
    eval_episodes: int = 1  # cdst and its experts are deterministic: one episode measures the return

    def __post_init__(self):
        # Lists from JSON/YAML or the CLI become tuples, so configs stay hashable.
        object.__setattr__(self, "preferences", tuple(tuple(float(w) for w in p) for p in self.preferences))
        object.__setattr__(self, "hidden_sizes", tuple(int(h) for h in self.hidden_sizes))

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
        self._validate_moiq()
        reward_dim = env.reward_dim if env is not None else len(self.preferences[0])
        check_preferences(self.preferences, reward_dim)
        return self

    def _validate_moiq(self) -> None:
        if self.beta < 0:
            raise ValueError(f"beta must be non-negative, got {self.beta}")
        positive = ("total_steps", "num_envs", "updates_per_step", "batch_size", "buffer_size", "eval_interval",
                    "eval_episodes", "critic_lr", "actor_lr", "alpha_lr", "init_alpha", "alpha_reg")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise ValueError(f"hidden_sizes must be positive layer widths, got {self.hidden_sizes}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"tau must be in (0, 1], got {self.tau}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must be non-negative, got {self.learning_starts}")
        for name in ("total_steps", "eval_interval"):
            if getattr(self, name) % self.num_envs:
                raise ValueError(f"{name} ({getattr(self, name)}) must be a multiple of num_envs ({self.num_envs})")
        if self.total_steps % self.eval_interval:
            raise ValueError(f"total_steps ({self.total_steps}) must be a multiple of eval_interval ({self.eval_interval})")
