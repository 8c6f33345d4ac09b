"""Fixtures shared by the test modules."""

import contextlib

import jax
import pytest


@contextlib.contextmanager
def _compiled_programs():
    names = []

    def listener(event, seconds, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            names.append(kwargs.get("fun_name"))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield names
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


@pytest.fixture
def compiled_programs():
    """``with compiled_programs() as names:`` the names of the programs XLA compiles inside the block
    (persistent-cache hits included), in order: how a test sees that work reuses a compiled program."""
    return _compiled_programs
