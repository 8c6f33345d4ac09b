"""Host-side runtime helpers: XLA devices on the CPU, the persistent compilation cache, and sharding a
sweep's runs over the devices. They configure JAX itself, so they run before the first computation."""

from __future__ import annotations

import os
import platform

import jax
import numpy as np


def split_cpu_into_devices(count: int | None = None) -> None:
    """Split the host CPU into ``count`` XLA devices (default: one per core), so that a sweep's runs,
    sharded over them (``shard_runs``), run as concurrent programs instead of one program whose small
    operations leave the cores idle between them (``benchmarks/moiq_speed.py`` measures the gain).

    Takes effect only before JAX's first computation in the process; an ``XLA_FLAGS`` that already sets
    the host device count is left as it is. Other platforms (GPU) are unaffected."""
    flag = "--xla_force_host_platform_device_count"
    flags = os.environ.get("XLA_FLAGS", "")
    if flag not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {flag}={count or os.cpu_count() or 1}".strip()


VECTOR_EXTENSIONS = ("avx512f", "avx2", "fma", "avx")  # widest first: which XLA's CPU code may use


def host_description() -> str:
    """The host CPU that XLA compiles for: its model name, family and model and its vector extensions (which set
    how XLA vectorises, so floating-point rounding can differ between hosts of the same name), and its cores.
    Saved runs and experiment outputs record it, so that runs that part between machines can be told apart."""
    fields = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if not line.strip():
                    break  # the first processor's block is enough
                key, _, value = line.partition(":")
                fields[key.strip()] = value.strip()
    except OSError:
        pass
    if "flags" not in fields:  # not Linux: what the standard library knows
        return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"
    flags = set(fields["flags"].split())
    vector = [x for x in VECTOR_EXTENSIONS if x in flags] or ["none of " + "/".join(VECTOR_EXTENSIONS)]
    return (f"{fields.get('model name', platform.machine())} (family {fields.get('cpu family', '?')}, model "
            f"{fields.get('model', '?')}), {' '.join(vector)}, {os.cpu_count()} cores")


SINGLE_THREAD_FLAGS = ("--xla_cpu_multi_thread_eigen=false", "intra_op_parallelism_threads=1")


def pin_to_cores(cores) -> None:
    """Run this process on the CPU cores ``cores`` only; on a single core, also turn XLA's CPU threading
    off. Two training jobs on a 2-core machine, one per core, then do more updates per second together than
    one job with both cores or two jobs sharing them (``benchmarks/parallel_jobs.py`` measures the three).

    The XLA flags take effect only before JAX's first computation in the process (a ``ValueError`` says so
    after it); the MuJoCo backend's default thread count follows the pinned cores."""
    from jax._src import xla_bridge

    if not hasattr(os, "sched_setaffinity"):
        raise ValueError("pinning a process to cores needs os.sched_setaffinity (Linux); use the OS's own tool")
    cores = sorted({int(core) for core in cores})
    available = sorted(os.sched_getaffinity(0))
    if not cores or any(core not in available for core in cores):
        raise ValueError(f"cores {cores} are not all among the cores this process may use: {available}")
    if len(cores) == 1 and xla_bridge.backends_are_initialized():
        raise ValueError("pin_to_cores must run before JAX's first computation (its XLA flags are read then)")
    os.sched_setaffinity(0, cores)
    if len(cores) == 1:
        flags = os.environ.get("XLA_FLAGS", "").split()
        missing = [flag for flag in SINGLE_THREAD_FLAGS if flag.split("=")[0] not in " ".join(flags)]
        os.environ["XLA_FLAGS"] = " ".join([*flags, *missing])


def parse_args_on_cores(parser, argv=None):
    """``parser``'s arguments with a ``--cpu-cores N...`` option added, the process pinned to those cores
    (``pin_to_cores``) when it is given; a core this process may not use is a usage error."""
    parser.add_argument("--cpu-cores", type=int, nargs="+",
                        help="run on these CPU cores only (one: XLA single-threaded; runtime.pin_to_cores)")
    args = parser.parse_args(argv)
    if args.cpu_cores:
        try:
            pin_to_cores(args.cpu_cores)
        except ValueError as error:
            parser.error(str(error))
    return args


def use_compilation_cache(path: str | None = None) -> str | None:
    """Keep compiled programs on disk (JAX's persistent compilation cache), so that the same program run
    again, in this process or a later one, is loaded instead of compiled (a cdst ``train``: about 11 s to
    compile, 3 s to load). ``path`` defaults to ``$MOIQ_COMPILATION_CACHE``, else ``~/.cache/moiq_jax/xla``;
    an empty ``MOIQ_COMPILATION_CACHE`` turns the cache off. A folder JAX already has
    (``JAX_COMPILATION_CACHE_DIR``) is kept. Call before the first compilation; returns the folder in use."""
    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    if path is None:
        default = os.path.join(os.path.expanduser("~"), ".cache", "moiq_jax", "xla")
        path = os.environ.get("MOIQ_COMPILATION_CACHE", default)
    if not path:
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    return path


def shard_runs(*arrays):
    """``arrays`` (pytrees whose leaves have a leading run axis) placed sharded over the run axis on all
    devices, when there are several and they divide the number of runs; else unchanged."""
    devices = jax.devices()
    runs = jax.tree_util.tree_leaves(arrays)[0].shape[0]
    if len(devices) == 1 or runs % len(devices):
        return arrays
    sharding = jax.sharding.NamedSharding(jax.sharding.Mesh(np.array(devices), ("runs",)),
                                          jax.sharding.PartitionSpec("runs"))
    return jax.device_put(arrays, sharding)
