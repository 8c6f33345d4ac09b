"""Two training jobs on a 2-core CPU: how to place them. One update program (the library's SAC update of three
experts, as the expert trainer runs it; or MOIQ's) timed in three layouts, in one run:

1. one job with every core (JAX's default threading);
2. two jobs at once, both with default threading, sharing the cores;
3. two jobs at once, each pinned to its own core with XLA's CPU threading off (``runtime.pin_to_cores``, as
   ``--cpu-cores`` of the training scripts does).

    python benchmarks/parallel_jobs.py [--algorithm sac] [--hidden 256] [--batch 256] [--updates 20] [--repeats 5]
        [--against peer peervec]

Each job is a child process that compiles its program, waits until every job of its layout has compiled, then
times ``--repeats`` programs of ``--updates`` updates; the mean counts (the jobs run at the same time throughout,
so a best-of would favour moments when the other job idles). Printed per layout: ms per update of each job and
the updates per second of all jobs together, against layout 1. ``--against`` then times the update side by side
with ``update_speed.py``'s peer step (``peer``: CleanRL-style SAC, scalar Q; ``peervec``: the same with the vector
critic Q(s, a, w)), each job on its own core, single-threaded, at the same time, once on each core: a comparison
under the same load, free of how XLA splits a program over threads. Run it on quiet cores.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time


def child(args) -> None:
    """One job: (pinned to its core,) compile, meet the other jobs at the barrier, time, print one JSON line."""
    if args.core is not None:
        from moiq_jax.runtime import pin_to_cores

        pin_to_cores([args.core])
    import jax
    import update_speed

    if args.program.startswith("peer"):
        case = update_speed.peer(args.experts, args.hidden, args.batch, args.updates, True,
                                 vector=args.program == "peervec")
    else:
        case = update_speed.ours(args.program, args.experts, args.hidden, args.batch, args.updates, True)
    key = jax.random.PRNGKey(2)
    jax.block_until_ready(case.program(case.state, key))  # warm
    barrier = pathlib.Path(args.barrier)
    (barrier / f"ready{args.index}").touch()
    while len(list(barrier.glob("ready*"))) < args.jobs:
        time.sleep(0.01)
    seconds = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        jax.block_until_ready(case.program(case.state, key))
        seconds.append(time.perf_counter() - start)
    print(json.dumps({"ms_per_update": 1e3 * sum(seconds) / len(seconds) / args.updates}), flush=True)


def layout(args, programs: list[str], pinned: bool) -> list[float]:
    """ms per update of each of ``programs``, run as concurrent child jobs."""
    jobs, cores = len(programs), sorted(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory() as barrier:
        processes = []
        for index, program in enumerate(programs):
            command = [sys.executable, __file__, "--child", "--barrier", barrier, "--index", str(index),
                       "--jobs", str(jobs), "--program", program, "--experts", str(args.experts),
                       "--hidden", str(args.hidden), "--batch", str(args.batch), "--updates", str(args.updates),
                       "--repeats", str(args.repeats)]
            if pinned:
                command += ["--core", str(cores[index % len(cores)])]
            processes.append(subprocess.Popen(command, stdout=subprocess.PIPE, text=True))
        outputs = [p.communicate()[0] for p in processes]
        if any(p.returncode for p in processes):
            raise SystemExit(f"a job failed: {outputs}")
    return [json.loads(out.strip().splitlines()[-1])["ms_per_update"] for out in outputs]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algorithm", default="sac", choices=("sac", "moiq", "iq"))
    parser.add_argument("--experts", type=int, default=3)
    parser.add_argument("--hidden", type=int, default=256)
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--updates", type=int, default=20, help="updates per timed program")
    parser.add_argument("--repeats", type=int, default=5, help="timed programs per job; the mean counts")
    parser.add_argument("--against", nargs="*", default=[], choices=("peer", "peervec"),
                        help="also time the update side by side with these peer steps (SAC only)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--program", help=argparse.SUPPRESS)
    parser.add_argument("--barrier", help=argparse.SUPPRESS)
    parser.add_argument("--index", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--jobs", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--core", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args)
    if args.against and args.algorithm != "sac":
        parser.error("--against compares the SAC update only")
    cores = os.cpu_count()
    if cores != 2:
        print(f"note: this machine has {cores} cores; layouts 2 and 3 still run two jobs")
    print(f"{cores} cores; load average at start {' '.join(f'{x:.1f}' for x in os.getloadavg())}; "
          f"{args.algorithm} x{args.experts}, hidden {args.hidden}x{args.hidden}, batch {args.batch}; "
          f"{args.updates} updates per program, mean of {args.repeats}")
    print(f"{'layout':<40}{'ms/update per job':>22}{'updates/s, all jobs':>22}{'vs one job':>12}")
    base = None
    one = [args.algorithm]
    for name, programs, pinned in (("one job, all cores", one, False), ("two jobs, shared cores", one * 2, False),
                                   ("two jobs, one core each, single-thread", one * 2, True)):
        ms = layout(args, programs, pinned)
        rate = sum(1e3 / m for m in ms)
        base = base or rate
        print(f"{name:<40}{' / '.join(f'{m:.2f}' for m in ms):>22}{rate:>22.1f}{rate / base:>11.2f}x", flush=True)
    for peer in args.against:
        ratios = []
        for programs in ([args.algorithm, peer], [peer, args.algorithm]):
            ms = dict(zip(programs, layout(args, programs, True)))
            ratios.append(ms[peer] / ms[args.algorithm])
            print(f"side by side, one core each: {' / '.join(f'{p} {ms[p]:.2f} ms (core {i})' for i, p in enumerate(programs))}"
                  f"; {args.algorithm} at {ratios[-1]:.2f}x the {peer}'s speed", flush=True)
        print(f"{args.algorithm} x{args.experts} vs {peer}, both cores' placements: "
              f"{' and '.join(f'{r:.2f}x' for r in ratios)} the {peer}'s speed")
    print(f"load average at end {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    main()
