"""The `moiq` console script, run as a real subprocess."""

import shutil
import subprocess

import pytest

MOIQ = shutil.which("moiq")
pytestmark = pytest.mark.skipif(MOIQ is None, reason="the package is not installed (pip install -e .)")


def moiq(*args):
    return subprocess.run([MOIQ, *args], check=False, capture_output=True, text=True, timeout=300)


def test_envs_lists_every_registered_env_with_sizes():
    out = moiq("envs")
    assert out.returncode == 0, out.stderr
    rows = {line.split()[0]: line.split() for line in out.stdout.splitlines()[1:]}
    assert rows["dst"][1:6] == ["2", "4", "discrete", "2", "100"]
    assert rows["cdst"][1:6] == ["2", "2-D", "box", "2", "100"]
    assert {"dst-concave", "dst-mini"} <= set(rows)


def test_optimal_rollout_prints_the_exact_front():
    out = moiq("rollout", "--env", "cdst", "--policy", "optimal")
    assert out.returncode == 0, out.stderr
    assert "treasure at (10, 9): return (   23.70,   -23.00)  on the front" in out.stdout
    assert "treasure at (4, 3): return (   14.00,    -7.00)  dominated" in out.stdout
    assert out.stdout.count("on the front") == 8


def test_random_rollout_prints_vector_returns_consistent_with_lengths():
    out = moiq("rollout", "--env", "dst", "--episodes", "5", "--seed", "3")
    assert out.returncode == 0, out.stderr
    episodes = [line for line in out.stdout.splitlines() if line.strip().startswith("episode")]
    assert len(episodes) == 5
    for line in episodes:
        step_cost = float(line.split("return (")[1].split(")")[0].split(",")[1])
        length = int(line.split("length")[1])
        assert step_cost == -length  # each step costs exactly 1


def test_unknown_env_is_a_clear_error():
    out = moiq("rollout", "--env", "nope")
    assert out.returncode == 2
    assert "unknown env 'nope'; known envs: cdst, dst, dst-concave, dst-mini, mo-ant, mo-halfcheetah, mo-hopper, mo-walker2d" in out.stderr
