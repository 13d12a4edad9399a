"""Files written whole or not at all: a temporary file beside the target, renamed over it; several
outputs all or none; a file's hash and provenance."""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable, Iterable, Iterator

from ..core.run import Run
from ..errors import DataError, HystError
from .runs import _run_text


def check_not_input(path: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> None:
    """Refuse to write ``path`` when it is one of the command's input files."""
    target = Path(path).resolve()
    for inp in inputs:
        if inp is None:
            continue
        if Path(inp).resolve() == target:
            raise DataError(f"{path}: refusing to overwrite an input file; choose another output path")


def atomic_write_text(path: str | os.PathLike, text: str,
                      inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    atomic_write(path, lambda f: f.write(text.encode("utf-8")), inputs=inputs)


def _file_mode() -> int:
    """Mode of a new file under the process's umask (what ``open(path, "w")`` would give)."""
    # mkstemp makes its file 0600 whatever the umask; reading the umask means setting it, so it is
    # put back at once (read each time: a caller may change its umask between two writes)
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _stage(target: Path) -> str:
    """An empty temporary file beside ``target``, with the mode a new file would get; its name
    keeps the target's suffix, since some writers (matplotlib) choose the format by it."""
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    try:
        os.fchmod(fd, _file_mode())
    finally:
        os.close(fd)
    return tmp


def _check_target(path: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> Path:
    check_not_input(path, inputs)
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{path}: the folder {folder} does not exist")
    if target.is_dir():
        raise DataError(f"{path}: is a directory; give a file name")
    return target


def _cannot_write(path: str | os.PathLike, exc: OSError) -> DataError:
    # the message names the file the user asked for, never the temporary file beside it
    return DataError(f"{path}: cannot write ({exc.strerror or exc})")


def atomic_write(path: str | os.PathLike, writer: Callable, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Call ``writer(binary_file)`` on a temporary file, then rename it onto ``path``.

    On any error the temporary file is removed and ``path`` is left as it was. The file gets
    the mode the umask gives a new file.
    """
    target = _check_target(path, inputs)
    try:
        tmp = _stage(target)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    try:
        with open(tmp, "wb") as f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _cannot_write(path, exc) from None
        raise


class PendingOutputs:
    """The output files of one command, staged beside their targets until all are written.

    Made by :func:`all_or_none`; each ``write_*`` (or a writer given :meth:`path`) fills a
    temporary file, and only when every one succeeded are they renamed onto their targets.
    """

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []

    def path(self, target: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> str:
        """A temporary path (same folder and suffix) for a writer that wants a file name."""
        checked = _check_target(target, inputs)
        if any(t.resolve() == checked.resolve() for _, t in self._staged):
            raise DataError(f"{target}: given as two of the outputs; choose different files")
        try:
            tmp = _stage(checked)
        except OSError as exc:
            raise _cannot_write(target, exc) from None
        self._staged.append((tmp, checked))
        return tmp

    def write_bytes(self, target: str | os.PathLike, data: bytes,
                    inputs: Iterable[str | os.PathLike] = ()) -> None:
        """Stage ``data`` for ``target``."""
        self._write(target, lambda f: f.write(data), inputs)

    def write_text(self, target: str | os.PathLike, text: str, inputs: Iterable[str | os.PathLike] = ()) -> None:
        """Stage ``text`` (UTF-8) for ``target``."""
        self.write_bytes(target, text.encode("utf-8"), inputs)

    def write_run(self, target: str | os.PathLike, run: Run, inputs: Iterable[str | os.PathLike] = ()) -> None:
        """Stage ``run`` as a run CSV for ``target``, piece by piece (:func:`write_run`)."""
        self._write(target, _run_writer(run), inputs)

    def _write(self, target: str | os.PathLike, writer: Callable[[BinaryIO], object],
               inputs: Iterable[str | os.PathLike]) -> None:
        tmp = self.path(target, inputs)
        try:
            with open(tmp, "wb") as f:
                writer(f)
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise _cannot_write(target, exc) from None

    def discard(self) -> None:
        """Remove every staged file; no target is touched."""
        for tmp, _ in self._staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self._staged.clear()

    def commit(self) -> list[Path]:
        """Rename every staged file onto its target; returns the targets."""
        done: list[Path] = []
        try:
            for tmp, target in self._staged:
                os.replace(tmp, target)
                done.append(target)
        except OSError as exc:
            # a rename in the same folder fails only if the folder changed under us: say what
            # was written rather than pretend nothing was
            self._staged = self._staged[len(done):]
            self.discard()
            written = f" ({', '.join(map(str, done))} already written)" if done else ""
            raise DataError(f"{target}: cannot write ({exc.strerror or exc}){written}") from None
        self._staged.clear()
        return done


@contextlib.contextmanager
def all_or_none() -> Iterator[PendingOutputs]:
    """Write several output files all or none.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> with all_or_none() as out:
    ...     out.write_text(folder / "report.json", "{}")
    ...     out.write_text(folder / "model.json", "{}")  # an error here would leave neither file
    >>> sorted(p.name for p in folder.iterdir())
    ['model.json', 'report.json']
    >>> import shutil; shutil.rmtree(folder)
    """
    pending = PendingOutputs()
    try:
        yield pending
    except HystError as exc:
        # a writer that was given a temporary path names it in its error: name the target instead
        message = str(exc)
        for tmp, target in pending._staged:
            message = message.replace(tmp, str(target))
        pending.discard()
        if message != str(exc):
            raise type(exc)(message) from None
        raise
    except BaseException:
        pending.discard()
        raise
    pending.commit()


def write_run(path: str | os.PathLike, run: Run, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Write a run CSV atomically (temporary file + rename), piece by piece.

    Parameters
    ----------
    path : path-like
        Target file.
    run : Run
    inputs : iterable of path-like
        Input files of the command: writing over one of them is refused.
    """
    atomic_write(path, _run_writer(run), inputs=inputs)


def _run_writer(run: Run) -> Callable[[BinaryIO], None]:
    """A writer of ``run``'s CSV text to a binary file, piece by piece; the run is checked when
    this is called, before any file is made."""
    pieces = _run_text(run)
    first = next(pieces)

    def write(f: BinaryIO) -> None:
        f.write(first.encode("utf-8"))
        for piece in pieces:
            f.write(piece.encode("utf-8"))

    return write
