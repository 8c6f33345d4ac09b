"""Orbax checkpoints of a run: the latest training states (to resume) and the best parameters by evaluation.

A checkpoint holds the whole training state (parameters, optimiser states, replay buffers, RNG keys) and
a JSON ``meta`` entry (chunk index, metrics history); orbax writes each one to a temporary directory and
renames it when complete, so a killed run never leaves a half-written checkpoint behind.
"""

from __future__ import annotations

import os

import jax
import numpy as np
import orbax.checkpoint as ocp


def _abstract(tree):
    return jax.tree.map(ocp.utils.to_shape_dtype_struct, _without_empty(tree))


def _without_empty(tree):
    """``tree`` with its zero-size arrays (such as MJX's ``act`` of a model without activations) as None:
    orbax cannot save them, and they hold nothing."""
    return jax.tree.map(lambda x: None if np.size(x) == 0 else x, tree)


def _with_empty(like, restored):
    """``restored`` with the zero-size arrays of ``like`` put back."""
    return jax.tree.map(lambda x, r: x if np.size(x) == 0 else r, like, restored, is_leaf=lambda x: x is None)


class Checkpoints:
    """``directory/latest/<step>`` keeps the ``keep`` newest training states; ``directory/best/<step>`` the
    parameters of the best evaluation so far."""

    def __init__(self, directory: str | os.PathLike, keep: int = 2):
        directory = os.path.abspath(os.fspath(directory))
        # Synchronous saves: every save is waited for anyway, and orbax's background threads of an async save
        # time out (printing errors) when a long compile holds the process between two saves.
        self.latest = ocp.CheckpointManager(os.path.join(directory, "latest"), options=ocp.CheckpointManagerOptions(
            max_to_keep=keep, create=True, enable_async_checkpointing=False))
        self.best = ocp.CheckpointManager(os.path.join(directory, "best"), options=ocp.CheckpointManagerOptions(
            max_to_keep=1, create=True, enable_async_checkpointing=False))

    def save(self, step: int, state, meta: dict) -> None:
        """Save the training state after ``step`` env steps, with JSON-serialisable ``meta``."""
        self.latest.save(step, args=ocp.args.Composite(state=ocp.args.StandardSave(_without_empty(state)),
                                                       meta=ocp.args.JsonSave(meta)))
        self.latest.wait_until_finished()

    def save_best(self, step: int, params, meta: dict) -> None:
        self.best.save(step, args=ocp.args.Composite(params=ocp.args.StandardSave(_without_empty(params)),
                                                     meta=ocp.args.JsonSave(meta)))
        self.best.wait_until_finished()

    def latest_step(self) -> int | None:
        return self.latest.latest_step()

    def restore(self, like_state, step: int | None = None):
        """``(state, meta)`` of the newest (or given) checkpoint, shaped like ``like_state``."""
        step = self.latest.latest_step() if step is None else step
        if step is None:
            raise FileNotFoundError(f"no checkpoint to resume in {self.latest.directory}")
        out = self.latest.restore(
            step, args=ocp.args.Composite(state=ocp.args.StandardRestore(_abstract(like_state)), meta=ocp.args.JsonRestore())
        )
        return _with_empty(like_state, out.state), out.meta

    def restore_best(self, like_params):
        """``(params, meta)`` of the best evaluation, shaped like ``like_params``."""
        step = self.best.latest_step()
        if step is None:
            raise FileNotFoundError(f"no best checkpoint in {self.best.directory}")
        out = self.best.restore(
            step, args=ocp.args.Composite(params=ocp.args.StandardRestore(_abstract(like_params)), meta=ocp.args.JsonRestore())
        )
        return _with_empty(like_params, out.params), out.meta

    def close(self) -> None:
        self.latest.close()
        self.best.close()
