"""Whether compiling the tests at XLA's backend (LLVM) optimisation level 0 would shorten the test suite: the tests'
programs are small and short, so compiling is much of their time, but some (MJX rollouts) run long.

    python benchmarks/suite_time.py [--tests tests/test_admm.py ...] [--skip-suite]

1. One MuJoCo training chunk (the quick protocol's MOIQ on mo-halfcheetah, as the experiment scripts' smoke runs
   compile it): seconds to compile at level 3 (XLA's default, as users run) and at level 0, each in a new process.
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
import sys, time
sys.path.insert(0, {experiments!r})
import jax, jax.numpy as jnp
import paper_mujoco as paper
from moiq_jax.algos import offpolicy
from moiq_jax.train import algorithm_of
config, _ = paper.sweep_of("mo-halfcheetah", "quick", "moiq")
trainer = offpolicy.make_trainer(config, algorithm_of(config))
hyper = {{name: jnp.float32(value) for name, value in trainer.hyper.items()}}
state = jax.jit(trainer.init)(jax.random.PRNGKey(0))
lowered = jax.jit(trainer.run_chunk).lower(state, hyper, trainer.setup)
start = time.perf_counter()
lowered.compile()
print(time.perf_counter() - start)
"""


def environment(level: int, cache: str) -> dict:
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if "optimization_level" not in f]
    return {**os.environ, "PYTHONPATH": str(ROOT), "MOIQ_COMPILATION_CACHE": cache,
            "XLA_FLAGS": " ".join([*flags, f"--xla_backend_optimization_level={level}"])}


def chunk_compile_seconds(level: int) -> float:
    script = CHUNK_COMPILE.format(experiments=str(ROOT / "experiments"))
    out = subprocess.run([sys.executable, "-c", script], env=environment(level, ""), capture_output=True, text=True,
                         check=True)
    return float(out.stdout.strip().splitlines()[-1])


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
    compile_times = {level: chunk_compile_seconds(level) for level in LEVELS}
    for level, seconds in compile_times.items():
        print(f"quick MOIQ chunk on mo-halfcheetah, compiled at level {level}: {seconds:.1f} s")
    print(f"  level 0 / level 3: {compile_times[0] / compile_times[3]:.2f}")
    if not args.skip_suite:
        suite = {}
        for level in LEVELS:
            suite[level], summary = suite_seconds(lambda cache, level=level: environment(level, cache), args.tests)
            print(f"pytest {' '.join(args.tests)} at level {level}, cold compilation cache: {suite[level]:.0f} s ({summary})")
        print(f"  level 0 / level 3: {suite[0] / suite[3]:.2f}")
    print(f"uptime after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
