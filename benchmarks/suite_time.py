"""Whether compiling the tests at XLA's backend (LLVM) optimisation level 0 would shorten the test suite: the tests'
programs are small and short, so compiling is much of their time, but some (MJX rollouts) run long.

    python benchmarks/suite_time.py [--tests tests/test_admm.py ...] [--skip-suite]

1. One MuJoCo training chunk and its ``init`` (the quick protocol's MOIQ on mo-halfcheetah, as the experiment
   scripts' smoke runs compile them): seconds to compile at level 3 (XLA's default, as users run) and at level 0,
   each in a new process, and whether ``init`` makes the same state bit for bit at both levels.
2. The README's test command (or ``--tests``) at level 3 and at level 0, each with an empty compilation cache of
   its own (as on a fresh CI machine): wall seconds and the ratio.

Run it on quiet cores: the two suite runs are minutes apart and share the machine with nothing else only then.
Results: ``results/suite_time/``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
LEVELS = (3, 0)

CHUNK_COMPILE = """
import hashlib, sys, time
sys.path.insert(0, {experiments!r})
import jax, jax.numpy as jnp, numpy as np
import paper_mujoco as paper
from moiq_jax.algos import offpolicy
from moiq_jax.train import algorithm_of
config, _ = paper.sweep_of("mo-halfcheetah", "quick", "moiq")
trainer = offpolicy.make_trainer(config, algorithm_of(config))
hyper = {{name: jnp.float32(value) for name, value in trainer.hyper.items()}}
lowered = jax.jit(trainer.init).lower(jax.random.PRNGKey(0))
start = time.perf_counter()
init = lowered.compile()
print("init", time.perf_counter() - start)
state = init(jax.random.PRNGKey(0))
digest = hashlib.sha256()
for leaf in jax.tree_util.tree_leaves(state):
    leaf = jax.random.key_data(leaf) if jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key) else leaf
    digest.update(np.ascontiguousarray(leaf).tobytes())
print("state", digest.hexdigest())
lowered = jax.jit(trainer.run_chunk).lower(state, hyper, trainer.setup)
start = time.perf_counter()
lowered.compile()
print("chunk", time.perf_counter() - start)
"""


def environment(level: int, cache: str) -> dict:
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if "optimization_level" not in f]
    return {**os.environ, "PYTHONPATH": str(ROOT), "MOIQ_COMPILATION_CACHE": cache,
            "XLA_FLAGS": " ".join([*flags, f"--xla_backend_optimization_level={level}"])}


def program_compiles(level: int) -> dict:
    """Compile seconds of the quick chunk's ``init`` and ``chunk`` programs at ``level``, and a digest of the
    state ``init`` makes (the same at every level only if the level leaves the numbers alone)."""
    script = CHUNK_COMPILE.format(experiments=str(ROOT / "experiments"))
    out = subprocess.run([sys.executable, "-c", script], env=environment(level, ""), capture_output=True, text=True,
                         check=True)
    fields = dict(line.split(" ", 1) for line in out.stdout.strip().splitlines() if line.split(" ")[0] in
                  ("init", "state", "chunk"))
    return {"init": float(fields["init"]), "chunk": float(fields["chunk"]), "state": fields["state"]}


def suite_seconds(env_of, tests: list[str], tree: pathlib.Path = ROOT) -> tuple[float, str]:
    """Wall seconds and pytest's summary line of the README's test command on ``tests`` in ``tree``, with the
    environment ``env_of(cache)`` for an empty compilation cache ``cache`` of its own."""
    with tempfile.TemporaryDirectory() as cache:
        start = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile",
                              "-p", "no:cacheprovider", *tests], cwd=tree, env=env_of(cache),
                             capture_output=True, text=True, check=False)
        seconds = time.perf_counter() - start
    summary = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else out.stderr[-500:]
    return seconds, summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tests", nargs="+", default=["tests"], help="what pytest runs (default: the whole suite)")
    parser.add_argument("--skip-suite", action="store_true", help="only the chunk's compile times")
    args = parser.parse_args()
    print(f"uptime before: {os.getloadavg()}")
    compiles = {level: program_compiles(level) for level in LEVELS}
    for program in ("chunk", "init"):
        for level, times in compiles.items():
            print(f"quick MOIQ {program} on mo-halfcheetah, compiled at level {level}: {times[program]:.1f} s")
        print(f"  level 0 / level 3: {compiles[0][program] / compiles[3][program]:.2f}")
    same = compiles[0]["state"] == compiles[3]["state"]
    print(f"init's state at level 0 {'is' if same else 'is not'} bit-identical to level 3's")
    if not args.skip_suite:
        suite = {}
        for level in LEVELS:
            suite[level], summary = suite_seconds(lambda cache, level=level: environment(level, cache), args.tests)
            print(f"pytest {' '.join(args.tests)} at level {level}, cold compilation cache: {suite[level]:.0f} s ({summary})")
        print(f"  level 0 / level 3: {suite[0] / suite[3]:.2f}")
    print(f"uptime after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
