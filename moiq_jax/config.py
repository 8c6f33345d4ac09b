"""The run configuration: common fields plus one section per algorithm family, each validating itself.

``Config`` holds what every run needs (env, preferences, demonstrations, seed, discount) and the
sections ``offpolicy`` (the loop of moiq, iq_learn, sac and gail), ``moiq`` (the inverse soft-Q critic
of moiq and iq_learn), ``gail`` (its discriminator) and ``admm`` (the tabular consensus ADMM, with its
``ppo`` inner RL). Every field has one flat name (``beta``, ``total_steps``, ``ppo_iterations``) that is
its command-line flag, its key in config files and config.json, and a keyword of ``Config(...)`` and
``Config.replace(...)``. Each field's help text is its ``metadata["help"]``. Why the tuned values are
what they are is recorded beside the evidence, in the results READMEs (results/cdst_moiq/README.md,
results/dst_admm/README.md).
"""

from __future__ import annotations

import dataclasses

from moiq_jax.preferences import check_preferences


def _field(default, help: str):
    return dataclasses.field(default=default, metadata={"help": help})


def _positive(section, names) -> None:
    for name in names:
        if not getattr(section, name) > 0:
            raise ValueError(f"{name} must be positive, got {getattr(section, name)}")


@dataclasses.dataclass(frozen=True)
class OffPolicyConfig:
    """The off-policy loop (moiq, iq_learn, sac, gail): rollouts, replay, SAC-style updates, evaluation."""

    total_steps: int = _field(100_000, "env steps per expert")
    num_envs: int = _field(1, "parallel envs per expert")
    learning_starts: int = _field(1_000, "env steps per expert of random actions before updates begin")
    updates_per_step: int = _field(1, "gradient updates per vectorised env step")
    batch_size: int = _field(256, "expert samples per expert and update, and as many policy samples")
    buffer_size: int = _field(100_000, "replay capacity per expert")
    hidden_sizes: tuple[int, ...] = _field((256, 256), "hidden layer widths of the actor and critics")
    num_critics: int = _field(2, "critics: 2, SAC's clipped double Q; 1, IQ-Learn's single critic for MuJoCo")
    action_scale: float = _field(1.0, "policy actions clip(action_scale * tanh(u), -1, 1); see networks.sample_action")
    critic_lr: float = _field(3e-4, "Adam learning rate of the critics")
    actor_lr: float = _field(3e-5, "Adam learning rate of the actor")
    alpha_lr: float = _field(3e-4, "Adam learning rate of the entropy temperature")
    tau: float = _field(0.005, "Polyak rate of the target critics")
    init_alpha: float = _field(0.01, "initial entropy temperature")
    learn_alpha: bool = _field(True, "learn the entropy temperature (SAC's loss); else keep init_alpha")
    eval_interval: int = _field(5_000, "env steps per expert between evaluations (and best-model checks)")
    eval_episodes: int = _field(1, "episodes per evaluation (cdst and its experts are deterministic: one suffices)")
    adopt_margin: float | None = _field(
        None, "sac's experts (one model per preference): after each evaluation, a model that another beats under its own "
              "preference by more than this fraction of its best return continues from that model's learner and replay "
              "(algos/adoption.py); None: never")
    absorbing_rollouts: bool = _field(
        True, "learners from demonstrations: after a termination, rollouts go on in the absorbing state to the time "
              "limit (its reward learnt; paper sec. 4.1.1); else the episode ends there, V(s') = 0 (IQ-Learn's code)")

    def __post_init__(self):
        object.__setattr__(self, "hidden_sizes", tuple(int(h) for h in self.hidden_sizes))

    def validate(self) -> None:
        if self.num_critics not in (1, 2):
            raise ValueError(f"num_critics must be 1 or 2, got {self.num_critics}")
        _positive(self, ("total_steps", "num_envs", "updates_per_step", "batch_size", "buffer_size", "eval_interval",
                         "eval_episodes", "critic_lr", "actor_lr", "alpha_lr", "init_alpha", "action_scale"))
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise ValueError(f"hidden_sizes must be positive layer widths, got {self.hidden_sizes}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"tau must be in (0, 1], got {self.tau}")
        if self.adopt_margin is not None and not self.adopt_margin >= 0.0:
            raise ValueError(f"adopt_margin must be >= 0 (or None: never adopt), got {self.adopt_margin}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must be non-negative, got {self.learning_starts}")
        for name in ("total_steps", "eval_interval"):
            if getattr(self, name) % self.num_envs:
                raise ValueError(f"{name} ({getattr(self, name)}) must be a multiple of num_envs ({self.num_envs})")
        if self.total_steps % self.eval_interval:
            raise ValueError(f"total_steps ({self.total_steps}) must be a multiple of eval_interval ({self.eval_interval})")


VALUE_TERMS = ("value", "v0")
REGULARISERS = ("replay", "policy", "both")


@dataclasses.dataclass(frozen=True)
class MOIQConfig:
    """The inverse soft-Q critic of moiq (and of iq_learn, which has no consensus penalty)."""

    beta: float = _field(5.0, "consensus penalty weight (moiq); 0 is the paper's ablation")
    alpha_reg: float = _field(0.5, "IQ-Learn's chi^2 regulariser: phi(x) = x - x^2 / (4 alpha_reg)")
    use_target: bool = _field(True, "V(s') from the target critic (no gradient); False: online critic, as IQ-Learn")
    value_term: str = _field("value", "IQ-Learn's second loss term: 'value', E_mix[V(s) - gamma V(s')] over expert and "
                                      "policy rows; 'v0', (1 - gamma) E_expert[V(s)] (IQ-Learn's hopper and walker)")
    regulariser: str = _field("replay", "where the chi^2 regulariser reads the policy rows' rewards: 'replay', at their "
                                        "stored actions; 'policy', at actions of the current policy (IQ-Learn's "
                                        "code for MuJoCo); 'both', every row at its own and at the policy's action")
    penalty_online: bool = _field(False, "moiq with use_target: the consensus penalty's rewards take V(s') from the "
                                         "online critic, with gradient, not from the lagging target")
    preference_warmup_steps: int = _field(50_000, "moiq with infer_preferences: env steps per expert under the "
                                                  "initial spread preferences before the first preference step")
    preference_interval: int = _field(10_000, "moiq with infer_preferences: env steps per expert between "
                                              "preference steps")

    def validate(self) -> None:
        if self.beta < 0:
            raise ValueError(f"beta must be non-negative, got {self.beta}")
        _positive(self, ("alpha_reg", "preference_interval"))
        if self.value_term not in VALUE_TERMS:
            raise ValueError(f"value_term must be one of {', '.join(VALUE_TERMS)}, got {self.value_term!r}")
        if self.regulariser not in REGULARISERS:
            raise ValueError(f"regulariser must be one of {', '.join(REGULARISERS)}, got {self.regulariser!r}")
        if self.preference_warmup_steps < 0:
            raise ValueError(f"preference_warmup_steps must be >= 0, got {self.preference_warmup_steps}")


@dataclasses.dataclass(frozen=True)
class GAILConfig:
    """GAIL's discriminator (its generator is the off-policy loop's SAC; the discriminator has hidden_sizes)."""

    disc_lr: float = _field(3e-4, "Adam learning rate of the gail discriminator")

    def validate(self) -> None:
        _positive(self, ("disc_lr",))


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """PPO as ADMM's inner RL (flat names ``ppo_<field>``)."""

    iterations: int = _field(20, "PPO updates (rollout + epochs) per ADMM round")
    num_envs: int = _field(64, "parallel episodes per PPO rollout (each runs the full time limit)")
    epochs: int = _field(4, "PPO epochs per rollout")
    minibatches: int = _field(4, "PPO minibatches per epoch")
    learning_rate: float = _field(3e-3, "PPO Adam learning rate")
    clip: float = _field(0.2, "PPO ratio clip")
    gae_lambda: float = _field(1.0, "PPO GAE lambda (1: Monte-Carlo advantages)")
    hidden: int = _field(64, "PPO hidden layer width")

    def validate(self) -> None:
        _positive(self, ("iterations", "num_envs", "epochs", "minibatches", "learning_rate", "clip", "hidden"))
        if not 0 <= self.gae_lambda <= 1:
            raise ValueError(f"ppo_gae_lambda must be in [0, 1], got {self.gae_lambda}")


INNER_RL = ("soft_vi", "ppo")
INFER_PREFERENCES = ("admm", "moiq")  # the algorithms that can infer the experts' preferences
PREFERENCE_RULES = ("closest", "likelihood")


@dataclasses.dataclass(frozen=True)
class ADMMConfig:
    """Discrete MOIRL with consensus ADMM (paper sec. 4.1) and its inner RL."""

    rounds: int = _field(10, "ADMM rounds: one reward update, then inner RL for every expert")
    admm_iterations: int = _field(10, "consensus ADMM iterations per round (eq. 7)")
    rho: float = _field(3.0, "ADMM penalty: 1/rho is the step size of the common reward per iteration")
    visit_metric: bool = _field(True, "scale the ADMM penalty per state-action by its visit count (see admm.py)")
    reward_l2: float = _field(0.0, "lambda of the reward regulariser -(lambda/2)||r_i||^2 in the x-update")
    reward_bound: float = _field(5.0, "box bound |r_i| <= reward_bound, keeps the x-update finite")
    inner_rl: str = _field("soft_vi", "ADMM's inner RL: soft_vi (exact, fast) or ppo (as in the paper)")
    temperature: float = _field(1.0, "entropy temperature of the max-ent inner RL (soft VI, and PPO's soft reward)")
    preference_warmup: int = _field(10, "with infer_preferences: rounds under the initial spread preferences before "
                                        "the preference step starts (run before the `rounds` rounds)")
    preference_resolution: int = _field(50, "with infer_preferences: candidate preferences on a simplex grid of this "
                                            "many steps per unit weight")
    preference_rule: str = _field("closest", "with infer_preferences: among the candidates that repeat an expert's "
                                             "behaviour, the closest to its current preference or the most likely "
                                             "(closest or likelihood)")
    ppo: PPOConfig = dataclasses.field(default_factory=PPOConfig)

    def validate(self) -> None:
        _positive(self, ("rounds", "admm_iterations", "rho", "reward_bound", "temperature", "preference_resolution"))
        if self.preference_warmup < 0:
            raise ValueError(f"preference_warmup must be >= 0, got {self.preference_warmup}")
        if self.preference_rule not in PREFERENCE_RULES:
            raise ValueError(f"unknown preference_rule {self.preference_rule!r}; choose one of "
                             f"{', '.join(PREFERENCE_RULES)}")
        if self.reward_l2 < 0:
            raise ValueError(f"reward_l2 must be >= 0, got {self.reward_l2}")
        if self.inner_rl not in INNER_RL:
            raise ValueError(f"unknown inner_rl {self.inner_rl!r}; choose one of {', '.join(INNER_RL)}")
        self.ppo.validate()


SECTIONS = {"offpolicy": OffPolicyConfig, "moiq": MOIQConfig, "gail": GAILConfig, "admm": ADMMConfig}


def _flat_fields() -> dict[str, tuple[tuple[str, ...], dataclasses.Field]]:
    """Flat name -> (path of section attributes, field) of every sectioned field."""
    found = {}
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            if f.name == "ppo":
                for g in dataclasses.fields(PPOConfig):
                    found[f"ppo_{g.name}"] = ((section, "ppo"), g)
            else:
                found[f.name] = ((section,), f)
    return found


@dataclasses.dataclass(frozen=True, init=False)
class Config:
    """Common fields and the sections; ``Config(beta=0.5, total_steps=2000)`` takes flat names, or whole
    sections (``Config(moiq=MOIQConfig(beta=0.5))``)."""

    env: str = _field("cdst", "a registered env (see `moiq envs`)")
    env_backend: str | None = _field(None, "the env's simulation backend (MuJoCo tasks: mujoco, MuJoCo's C engine, or mjx); "
                                           "None: the env's default")
    algo: str = _field("moiq", "moiq, iq_learn or gail (one model per expert), admm (discrete DST), sac (train experts)")
    preferences: tuple[tuple[float, ...], ...] = _field(((0.9, 0.1), (0.5, 0.5), (0.1, 0.9)),
                                                        "one preference per expert, in any order")
    num_demos: int = _field(10, "demonstrations per expert (the first ones of a --demos file)")
    demos: str | None = _field(None, "a Demonstrations file; None: record them from the env's oracle experts")
    seed: int = _field(0, "random seed of the whole run")
    infer_preferences: bool = _field(False, "infer every expert's preference from its demonstrations (their labels "
                                            "ignored) jointly with the reward (algo admm: algos/preference_inference.py; "
                                            "moiq: algos/moiq_preference_inference.py)")
    gamma: float = _field(0.99, "discount factor")
    offpolicy: OffPolicyConfig = dataclasses.field(default_factory=OffPolicyConfig)
    moiq: MOIQConfig = dataclasses.field(default_factory=MOIQConfig)
    gail: GAILConfig = dataclasses.field(default_factory=GAILConfig)
    admm: ADMMConfig = dataclasses.field(default_factory=ADMMConfig)

    def __init__(self, **values):
        common = {f.name: f for f in dataclasses.fields(Config) if f.name not in SECTIONS}
        flat = _flat_fields()
        unknown = sorted(set(values) - set(common) - set(flat) - set(SECTIONS))
        if unknown:
            raise TypeError(f"Config got unknown fields {unknown}")
        for name, f in common.items():
            object.__setattr__(self, name, values.get(name, f.default))
        sections = {}
        for name, cls in SECTIONS.items():
            given = values.get(name, cls())
            sections[name] = cls(**given) if isinstance(given, dict) else given
        for name, (path, _) in flat.items():
            if name in values:
                sections[path[0]] = _replace_in(sections[path[0]], path[1:], name.removeprefix("ppo_")
                                                if len(path) > 1 else name, values[name])
        for name, section in sections.items():
            object.__setattr__(self, name, section)
        # Lists from JSON/YAML or the CLI become tuples, so configs stay hashable.
        object.__setattr__(self, "preferences", tuple(tuple(float(w) for w in p) for p in self.preferences))

    def replace(self, **changes) -> Config:
        """A copy with ``changes`` (flat names or whole sections)."""
        return Config(**{**self.sections(), **changes})

    def sections(self) -> dict:
        """The common fields and the section objects, as keywords of ``Config``."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(Config)}

    def to_dict(self) -> dict:
        """Every field by its flat name (config.json, config files, the CLI)."""
        out = {name: getattr(self, name) for name in self.sections() if name not in SECTIONS}
        for name, (path, f) in _flat_fields().items():
            section = getattr(self, path[0])
            for attr in path[1:]:
                section = getattr(section, attr)
            out[name] = getattr(section, f.name)
        return out

    def validate(self, env=None, sections=()) -> Config:
        """Raise ValueError naming the bad field: the common fields and the named ``sections``; with
        ``env``, also check the preferences fit its reward_dim."""
        from moiq_jax import envs

        envs.spec(self.env)  # unknown env names raise, listing the known ones
        if self.num_demos < 1:
            raise ValueError(f"num_demos must be at least 1, got {self.num_demos}")
        if self.infer_preferences and self.algo not in INFER_PREFERENCES:
            raise ValueError(f"infer_preferences runs with algo {' or '.join(INFER_PREFERENCES)}, got {self.algo!r}")
        if not 0.0 <= self.gamma < 1.0:
            raise ValueError(f"gamma must be in [0, 1), got {self.gamma}")
        if self.env_backend is not None and self.env_backend not in envs.backends(self.env):
            offered = ", ".join(envs.backends(self.env)) or "none: it is pure JAX"
            raise ValueError(f"env_backend {self.env_backend!r} is not a backend of {self.env!r} ({offered})")
        for name in sections:
            getattr(self, name).validate()
        reward_dim = env.reward_dim if env is not None else len(self.preferences[0])
        check_preferences(self.preferences, reward_dim)
        if len(set(self.preferences)) != len(self.preferences):
            raise ValueError(f"preferences must differ (each labels one expert), got {list(self.preferences)}")
        return self

    def make_env(self, absorbing: bool = False):
        """The configured env; ``backend`` is passed only when ``env_backend`` is set."""
        from moiq_jax import envs

        backend = {} if self.env_backend is None else {"backend": self.env_backend}
        return envs.make(self.env, absorbing=absorbing, **backend) if absorbing else envs.make(self.env, **backend)


def _replace_in(section, path, name, value):
    if not path:
        return dataclasses.replace(section, **{name: value})
    inner = getattr(section, path[0])
    return dataclasses.replace(section, **{path[0]: _replace_in(inner, path[1:], name, value)})


def _all_fields() -> dict[str, dataclasses.Field]:
    """Every field (common and sectioned) by its flat name."""
    return {**{f.name: f for f in dataclasses.fields(Config) if f.name not in SECTIONS},
            **{name: f for name, (_, f) in _flat_fields().items()}}


def field_help() -> dict[str, str]:
    """Each field's flat name -> its help text."""
    return {name: f.metadata.get("help", "") for name, f in _all_fields().items()}


def field_types() -> dict[str, str]:
    """Each field's flat name -> its annotation as written (e.g. ``"float | None"``), for the CLI's parsers."""
    return {name: str(f.type) for name, f in _all_fields().items()}


# Settings tuned per env over the (paper-sized) defaults; the evidence for each is in the results READMEs
# (cdst: results/cdst_moiq/README.md, "Tuned settings"). mo-hopper: the paper's three expert preferences
# (sec. 5.1); the other MuJoCo tasks use the default three.
TUNED: dict[str, dict] = {
    "cdst": {"hidden_sizes": (64, 64), "batch_size": 64, "num_envs": 4, "actor_lr": 3e-4, "action_scale": 2.5,
             "learn_alpha": False, "init_alpha": 0.01, "use_target": False, "eval_interval": 5_000, "beta": 0.5,
             "updates_per_step": 2},
    "mo-hopper": {"preferences": ((0.8, 0.1, 0.1), (0.1, 0.8, 0.1), (0.1, 0.1, 0.8))},
}


def tuned(env: str, **changes) -> Config:
    """The config for ``env`` with its tuned settings (``TUNED``; the defaults where none), then ``changes``."""
    return Config(env=env, **{**TUNED.get(env, {}), **changes})
