"""Atomic file writing: a failed run never leaves a half-written output file."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pde2cad.io.staging import OutputSet


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    A one-file :class:`~pde2cad.io.staging.OutputSet`: the temporary file keeps the suffix
    of ``path`` (libraries that pick a format by suffix still work), gets the permissions a
    plain ``open()`` would give, and is removed on any exception or SIGTERM/SIGINT, leaving
    ``path`` untouched.
    """
    with OutputSet() as out:
        yield out.path(path)
