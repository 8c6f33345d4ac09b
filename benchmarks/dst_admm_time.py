"""Wall time of the whole Figure 1 experiment (both DST maps, 5 seeds each, 10 rounds), compile included."""

import argparse
import time

from experiments.dst_admm import run

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--inner-rl", default="soft_vi", choices=("soft_vi", "ppo"))
args = parser.parse_args()
start = time.perf_counter()
run(args.inner_rl)  # returns numpy arrays, so all work has finished
print(f"Figure 1 experiment ({args.inner_rl}, both maps, 5 seeds): {time.perf_counter() - start:.1f} s wall")
