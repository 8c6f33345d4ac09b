"""A checkpointed sweep (``moiq_jax.sweep(..., run_dir=...)``: one jitted, vmapped chunk program called once
per ``eval_interval`` env steps, the state saved after each, so that it can resume) against a sweep without a
run directory (the whole training as one jitted program: ``lax.scan`` over the chunks inside one
``jit(vmap(...))``), in one run and on the same inputs, the CPU split into one device per run as ``moiq
sweep`` does.

    python benchmarks/sweep_chunks.py [--betas 0 5] [--seeds 2] [--total-steps 6000] [--eval-interval 600]

Each way is timed twice in this process: first compiling its programs, then again with the programs
loaded from JAX's persistent compilation cache (a fresh temporary folder), as the ``moiq`` command keeps it.
Also prints the largest difference between the two ways' final evaluation returns.
"""

from __future__ import annotations

import argparse
import tempfile
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--betas", nargs="+", type=float, default=[0.0, 5.0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--total-steps", type=int, default=6000)
    parser.add_argument("--eval-interval", type=int, default=600)
    args = parser.parse_args()
    runs = len(args.betas) * args.seeds

    from moiq_jax.runtime import split_cpu_into_devices

    split_cpu_into_devices(runs)
    import jax
    import numpy as np

    import moiq_jax
    from moiq_jax.config import tuned

    jax.config.update("jax_compilation_cache_dir", tempfile.mkdtemp(prefix="sweep_chunks_xla"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    config = tuned("cdst", total_steps=args.total_steps, eval_interval=args.eval_interval)
    seeds = list(range(args.seeds))

    def whole_program():
        """A sweep without a run directory: every chunk of every run in one jitted program."""
        return moiq_jax.sweep(config, beta=args.betas, seed=seeds, log=None).history["eval_return"]

    def chunked():
        """A checkpointed sweep: one chunk program per ``eval_interval``, the state saved after each."""
        return moiq_jax.sweep(config, run_dir=tempfile.mkdtemp(prefix="sweep_chunks_run"), beta=args.betas,
                              seed=seeds, log=None).history["eval_return"]

    times, returns = {}, {}
    for name, run in (("whole program", whole_program), ("chunk by chunk", chunked)):
        for attempt in ("compiling", "cached"):
            start = time.perf_counter()
            returns[name] = run()
            times[name, attempt] = time.perf_counter() - start
    print(f"cdst sweep of {runs} runs ({len(args.betas)} betas x {args.seeds} seeds), {args.total_steps} env steps per "
          f"expert in chunks of {args.eval_interval}, {jax.device_count()} CPU devices:")
    for attempt in ("compiling", "cached"):
        whole, chunks = times["whole program", attempt], times["chunk by chunk", attempt]
        print(f"  {attempt:>9}: whole program {whole:6.1f} s, chunk by chunk {chunks:6.1f} s "
              f"({chunks / whole:.2f}x the whole program's time)")
    difference = np.max(np.abs(returns["whole program"] - returns["chunk by chunk"]))
    print(f"  largest difference of the evaluation returns between the two: {difference:.3g}")


if __name__ == "__main__":
    main()
