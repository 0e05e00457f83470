"""All-or-nothing output sets: every output of a run appears, or none does.

A run reserves one temporary file beside each target (:meth:`OutputSet.path`), writes its
outputs there, and renames them onto their targets together (:meth:`OutputSet.commit`). A
failure anywhere before or during the commit leaves every target exactly as it was: files of
earlier runs are kept as hard-linked (or copied) backups until the whole set has been
renamed, and put back if one rename fails.

Temporary names are ``.<stem>~<hash>.pde2cad-<pid>-<n>.tmp<suffix>`` (backups ``.bak``), cut
to fit the file-system name limit even for a 250-character target. The suffix of the target
is kept so writers that choose the format by suffix (matplotlib, ezdxf) still work.

Cleaning up
    SIGTERM and SIGINT (what ``timeout``, CI runners and ``docker stop`` send, and Ctrl-C)
    remove the temporary files of every open set before the process ends with the usual
    status; a signal that arrives during a commit waits until the commit is done. Normal
    interpreter exit removes them too. ``kill -9`` cannot be caught: its leftovers carry the
    dead process id in their name, and the next run that writes the same target removes the
    ones whose process no longer exists.

:func:`check_paths` refuses, before any work, an output that is an input or another output.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import re
import shutil
import signal
from collections.abc import Iterable
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any

from pde2cad.errors import ExportError, InputError

__all__ = ["OutputSet", "check_paths", "TEMP_MARK"]

#: Every temporary or backup name holds this mark (what a user can search for).
TEMP_MARK = ".pde2cad-"
_SIGNALS = (signal.SIGTERM, signal.SIGINT)
_MAX_SUFFIX = 16  # bytes of the target suffix kept in temporary names

_active: list[OutputSet] = []
_previous: dict[int, Any] = {}
_state: dict[str, Any] = {"committing": 0, "deferred": None}


# --------------------------------------------------------------------------- path checks
def _same(a: Path, b: Path) -> bool:
    """Whether two paths name one file: equal after resolving, or the same inode."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_paths(inputs: Iterable[str | Path], outputs: Iterable[str | Path | None]) -> None:
    """Refuse outputs that would overwrite an input or another output of the same run.

    Parameters
    ----------
    inputs : iterable of str or Path
        Files the run reads.
    outputs : iterable of str or Path or None
        Files the run writes (``None`` entries, options not given, are skipped).

    Raises
    ------
    InputError
        An output is an input (same resolved path, or a hard/symbolic link to it), or two
        outputs are one file.
    """
    ins = [Path(p) for p in inputs]
    outs = [Path(p) for p in outputs if p is not None]
    for out in outs:
        for src in ins:
            if _same(out, src):
                raise InputError(
                    f"output {out} would overwrite the input {src}; give the output another name"
                )
    for i, a in enumerate(outs):
        for b in outs[i + 1 :]:
            if _same(a, b):
                raise InputError(
                    f"outputs {a} and {b} are the same file; give each output its own name"
                )


# --------------------------------------------------------------------------- names
def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _cut(text: str, limit: int) -> str:
    """``text`` cut to at most ``limit`` bytes of UTF-8 (never inside a character)."""
    return text.encode("utf-8", errors="surrogateescape")[: max(limit, 0)].decode(
        "utf-8", errors="ignore"
    )


def _stem_key(target: Path) -> str:
    """The fixed head of every temporary name of ``target``: ``.<stem>~<hash>``."""
    digest = hashlib.sha1(target.name.encode("utf-8", errors="surrogateescape")).hexdigest()[:8]
    # Room for "." + "~hash" + ".pde2cad-<pid>-<n>.bak" + suffix within the name limit.
    room = _name_max(target.parent) - 1 - 9 - len(".pde2cad-4294967295-999999.bak") - _MAX_SUFFIX
    return f".{_cut(target.stem, room)}~{digest}"


def _suffix(target: Path) -> str:
    s = target.suffix
    return s if len(s.encode("utf-8", errors="surrogateescape")) <= _MAX_SUFFIX else ""


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):  # another user's live process
        return True
    return True


def _remove_stale(target: Path) -> None:
    """Remove temporary/backup files of ``target`` left by processes that no longer exist."""
    pattern = re.compile(
        re.escape(_stem_key(target) + TEMP_MARK)
        + r"(\d+)-\d+\.(?:tmp|bak)"
        + re.escape(_suffix(target))
        + "$"
    )
    try:
        entries = list(os.scandir(target.parent))
    except OSError:
        return
    for entry in entries:
        m = pattern.match(entry.name)
        if m and not _pid_alive(int(m.group(1))):
            try:
                os.unlink(entry.path)
            except OSError:
                pass


# --------------------------------------------------------------------------- signals
def _on_signal(signum: int, frame: FrameType | None) -> None:
    if _state["committing"]:
        _state["deferred"] = signum  # finish the renames first; then end as asked
        return
    for out in list(_active):
        out.discard()
    previous = _previous.get(signum, signal.SIG_DFL)
    _restore_handlers()
    if callable(previous):
        previous(signum, frame)  # e.g. Python's SIGINT handler raises KeyboardInterrupt
    elif previous != signal.SIG_IGN:
        os.kill(os.getpid(), signum)  # default action: end with the signal's status


def _install_handlers() -> None:
    if _previous:
        return
    for sig in _SIGNALS:
        try:
            old = signal.getsignal(sig)
            if old == signal.SIG_IGN:  # e.g. nohup: the user asked not to be stopped by it
                continue
            signal.signal(sig, _on_signal)
            _previous[sig] = old
        except (ValueError, OSError):  # not the main thread: rely on atexit/finally
            continue


def _restore_handlers() -> None:
    for sig, old in list(_previous.items()):
        try:
            signal.signal(sig, old if old is not None else signal.SIG_DFL)
        except (ValueError, OSError):
            pass
    _previous.clear()


@atexit.register
def _discard_all() -> None:
    for out in list(_active):
        out.discard()


# --------------------------------------------------------------------------- the set
class OutputSet:
    """Outputs staged beside their targets and renamed onto them together.

    Use as a context manager: leaving the block normally commits what is still pending,
    an exception discards it. ``commit()`` and ``discard()`` may also be called directly.

    Examples
    --------
    >>> with OutputSet() as out:                      # doctest: +SKIP
    ...     write_svg(drawing, out.path(Path("a.svg")))
    ...     write_dxf(drawing, out.path(Path("a.dxf")))
    ...     out.commit()                              # both files, or neither
    """

    def __init__(self) -> None:
        self.pending: dict[Path, Path] = {}
        self._count = 0

    # -- reserving
    def path(self, target: str | Path) -> Path:
        """Reserve an empty temporary file beside ``target`` and return its path.

        Raises
        ------
        ExportError
            The folder does not exist or is not writable, or ``target`` is a folder.
        """
        target = Path(target)
        if target.is_symlink():  # write through the link, as a plain open() would
            target = Path(os.path.realpath(target))
        parent = target.parent
        if not parent.is_dir():
            raise ExportError(f"cannot write {target}: folder {parent} does not exist; create it first")
        if target.is_dir():
            raise ExportError(f"cannot write {target}: it is a folder; give a file name")
        if target in self.pending:
            return self.pending[target]
        _remove_stale(target)
        tmp = self._reserve(target, "tmp")
        self.pending[target] = tmp
        if self not in _active:
            _active.append(self)
            _install_handlers()
        return tmp

    def _reserve(self, target: Path, kind: str) -> Path:
        """Create a new empty file ``.<stem>~<hash>.pde2cad-<pid>-<n>.<kind><suffix>``."""
        while True:
            self._count += 1
            name = f"{_stem_key(target)}{TEMP_MARK}{os.getpid()}-{self._count}.{kind}{_suffix(target)}"
            tmp = target.parent / name
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            except FileExistsError:
                continue
            except OSError as exc:
                raise ExportError(
                    f"cannot write {target}: {exc.strerror or exc} in folder {target.parent}; "
                    "check that it is writable"
                ) from exc
            os.close(fd)
            return tmp

    # -- committing
    def commit(self) -> None:
        """Rename every staged file onto its target: all of them, or none.

        Each staged file is flushed to disk and given the target's permissions (an
        existing target's mode, else 0666 minus the umask). Existing targets are kept as
        backups until every rename succeeded; if one fails, the targets renamed before it
        get their earlier file back (the same file, so contents, mode and times are as
        they were) and targets that did not exist are removed again.

        Raises
        ------
        ExportError
            A staged file is missing or a rename failed; no target has changed.
        """
        _state["committing"] += 1
        try:
            self._commit()
        finally:
            _state["committing"] -= 1
            self.discard()
            deferred, _state["deferred"] = _state["deferred"], None
            if deferred is not None and not _state["committing"]:
                _on_signal(deferred, None)

    def _commit(self) -> None:
        backups: dict[Path, Path | None] = {}
        done: list[Path] = []
        target = Path()
        try:
            for target, tmp in self.pending.items():
                _prepare(tmp, target)
                backups[target] = self._backup(target)
            for target, tmp in self.pending.items():
                os.replace(tmp, target)
                done.append(target)
        except OSError as exc:
            for t in reversed(done):
                _restore(t, backups.get(t))
            raise ExportError(
                f"cannot write {target}: {exc.strerror or exc}; no output of this run was "
                "written and earlier files are unchanged"
            ) from exc
        finally:
            for b in backups.values():
                if b is not None and b.exists():
                    b.unlink()

    def _backup(self, target: Path) -> Path | None:
        """A second name for an existing target (hard link, else a copy); None if none."""
        if not target.exists():
            return None
        backup = self._reserve(target, "bak")
        try:
            backup.unlink()
            os.link(target, backup)
        except OSError:
            shutil.copy2(target, backup)
        return backup

    def discard(self) -> None:
        """Remove every staged file; targets stay as they are."""
        for tmp in self.pending.values():
            try:
                tmp.unlink()
            except OSError:
                pass
        self.pending.clear()
        if self in _active:
            _active.remove(self)
        if not _active:
            _restore_handlers()

    # -- context manager
    def __enter__(self) -> OutputSet:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None and self.pending:
            self.commit()
        else:
            self.discard()


def _prepare(tmp: Path, target: Path) -> None:
    """Flush ``tmp`` to disk and give it the mode ``target`` has (or a new file would get)."""
    if not tmp.is_file():
        raise FileNotFoundError(2, "the staged file vanished", str(tmp))
    try:
        mode = target.stat().st_mode & 0o7777
    except OSError:
        umask = os.umask(0o022)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(tmp, mode)
    with open(tmp, "rb") as handle:
        os.fsync(handle.fileno())


def _restore(target: Path, backup: Path | None) -> None:
    """Undo the rename onto ``target``: its backup back in place, or no file at all."""
    try:
        if backup is None:
            target.unlink()
        else:
            os.replace(backup, target)
    except OSError:
        pass
