"""What an experiment script's smoke run spends compiling, at this checkout and at a baseline commit, in one run.

    python benchmarks/script_compiles.py --baseline COMMIT [--script table1.py] [--suite [--tests PATH ...]]

For this checkout and for ``COMMIT`` (checked out in a temporary git worktree): ``experiments/<script> --quick
--envs mo-halfcheetah`` in a new process with an empty compilation cache (as on a fresh CI machine) and
``JAX_LOG_COMPILES``: wall seconds, the number of programs XLA compiled and their compile seconds, the training
chunks among them, and the ratios to the baseline. ``--suite`` also runs the README's test command (on
``--tests``) in both trees, each from an empty compilation cache. The two trees run one after the other on the
same machine: run it on quiet cores, or read the ratios with the load the script prints. Results:
``results/suite_time/``.
"""

from __future__ import annotations

import argparse
import collections
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time

from suite_time import suite_seconds

ROOT = pathlib.Path(__file__).resolve().parents[1]
COMPILED = re.compile(r"Finished XLA compilation of (.+?) in ([0-9.e+-]+) sec")


def environment(tree: pathlib.Path, cache: str) -> dict:
    return {**os.environ, "PYTHONPATH": str(tree), "MOIQ_COMPILATION_CACHE": cache, "JAX_LOG_COMPILES": "1"}


def script_run(tree: pathlib.Path, script: str) -> dict:
    """Wall seconds and XLA's compiles of one smoke run of ``script`` in ``tree``."""
    with tempfile.TemporaryDirectory() as scratch:
        start = time.perf_counter()
        out = subprocess.run([sys.executable, str(tree / "experiments" / script), "--quick", "--envs", "mo-halfcheetah",
                              "--cache", f"{scratch}/cache", "--out", f"{scratch}/out"], cwd=tree,
                             env=environment(tree, f"{scratch}/xla"), capture_output=True, text=True, check=False)
        seconds = time.perf_counter() - start
    if out.returncode != 0:
        raise SystemExit(f"{script} failed in {tree}:\n{out.stderr[-3000:]}")
    compiles = [(name, float(s)) for name, s in COMPILED.findall(out.stderr)]
    per_name = collections.Counter(name for name, _ in compiles)
    return {"seconds": seconds, "compiles": len(compiles), "compile_seconds": sum(s for _, s in compiles),
            "chunks": per_name["jit(chunk_all)"], "top": per_name.most_common(3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", required=True, help="the commit to compare with (e.g. main before a change)")
    parser.add_argument("--script", default="table1.py", help="an experiment script with --quick (default table1.py)")
    parser.add_argument("--suite", action="store_true", help="also the README's test command in both trees (long)")
    parser.add_argument("--tests", nargs="+", default=["tests"], help="what --suite runs (default: the whole suite)")
    args = parser.parse_args()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    print(f"load before: {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as parent:
        baseline = pathlib.Path(parent) / "baseline"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(baseline), args.baseline],
                       capture_output=True, check=True)
        try:
            trees = {f"baseline {args.baseline}": baseline, f"this checkout ({head})": ROOT}
            runs = {label: script_run(tree, args.script) for label, tree in trees.items()}
            for label, run in runs.items():
                print(f"{args.script} --quick, {label}: {run['seconds']:.0f} s wall, {run['compiles']} programs compiled "
                      f"in {run['compile_seconds']:.0f} s, {run['chunks']} of them training chunks; most compiled: "
                      + ", ".join(f"{name} x{count}" for name, count in run["top"]))
            base, this = runs.values()
            print(f"  this / baseline: wall {this['seconds'] / base['seconds']:.2f}, "
                  f"compile seconds {this['compile_seconds'] / base['compile_seconds']:.2f}")
            if args.suite:
                suite = {label: suite_seconds(lambda cache, tree=tree: environment(tree, cache) | {"JAX_LOG_COMPILES": "0"},
                                             args.tests, tree) for label, tree in trees.items()}
                for label, (seconds, summary) in suite.items():
                    print(f"pytest {' '.join(args.tests)}, {label}, empty compilation cache: {seconds:.0f} s ({summary})")
                (base_s, _), (this_s, _) = suite.values()
                print(f"  this / baseline: {this_s / base_s:.2f}")
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(baseline)], check=False)
    print(f"load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
