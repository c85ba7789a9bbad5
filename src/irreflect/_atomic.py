"""Output that appears whole or not at all, and that one run owns.

A run *claims* its output path before it computes anything (:func:`claim_output`): the
path is checked (:func:`irreflect.validation.check_output_path`), a lock is taken so that a
second run into the same path at the same time refuses with one line, and what killed runs
left behind (hidden temporary folders and files beside the path) is removed. Files are
written into a temporary sibling and renamed into place (:func:`atomic_path`). An output
folder is written whole into a temporary sibling folder and swapped into place
(:func:`atomic_directory`); the folder carries a manifest (:data:`MANIFEST`) listing what
the run wrote, so a rerun replaces everything the previous run wrote (no stale figures or
run folders survive) and keeps only files that no irreflect run wrote there (for example
another command's output folder nested inside it). A non-empty folder without a manifest
is refused: irreflect never deletes files it did not write.

Locks are ``fcntl.flock`` locks on a hidden file beside the path
(``.<name>.irreflect-lock``): the system releases them when a process dies, so a killed run
never blocks the next one, and the lock file is removed when the run ends.

An output path that is a symlink is followed only within the folder it lies in (``latest ->
run3``); its target is what is written, checked and locked, so two runs through a link and
its target are locked out of each other. A link out of that folder, a device, a FIFO or
anything else that is not a regular file (or a folder, for folder outputs) is refused
(:func:`irreflect.validation.check_output_path`). While a run holds its outputs, every
input it reads is checked against them (:func:`check_not_output`): an output never replaces
an input of the same run.
"""

from __future__ import annotations

import contextlib
import contextvars
import ctypes
import ctypes.util
import json
import os
import re
import shutil
import stat
import tempfile
import threading
import time
from pathlib import Path

from .errors import IrreflectError
from .validation import check_output_path, short_list

try:  # POSIX; elsewhere runs are not locked against each other
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None

#: The manifest every output folder carries (hidden), listing the entries the run wrote.
MANIFEST = ".irreflect-manifest.json"
#: The irreflect command this process runs (set by the command line; None from Python): an
#: output folder another command wrote is not replaced by it (:func:`_check_owned`).
RUNNING_COMMAND: contextvars.ContextVar[str | None] = contextvars.ContextVar(
    "irreflect_running_command", default=None)
_TMP = "irreflect-tmp"
_OLD = "irreflect-old"
_LOCK = "irreflect-lock"
#: Leftovers of runs killed before this module had its own names: ``tempfile`` names with
#: the output's name as prefix (``.out.k2j4_x9a`` folders, ``.run.ckpt.k2j4_x9a.tmp`` files).
_LEGACY = r"\.{name}\.[a-z0-9_]{{8}}(\.tmp)?"

_held: dict[Path, _Claim] = {}
_held_lock = threading.Lock()


def _key(path: Path) -> Path:
    return Path(os.path.realpath(path))


class _Claim:
    """A locked output path (one per path and process; re-entrant)."""

    def __init__(self, path: Path, kind: str, option: str):
        self.path = path
        self.kind = kind
        self.option = option
        self.depth = 0
        self.fd: int | None = None
        self.lock_path = path.parent / f".{path.name}.{_LOCK}"
        self.created: list[Path] = []  # folders made for the lock, deepest first

    # -- lock
    def acquire(self) -> None:
        folder = self.path.absolute().parent
        while not folder.exists():
            self.created.append(folder)
            folder = folder.parent
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if fcntl is None:  # pragma: no cover
            return
        for _attempt in range(20):
            fd = self._open_lock()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                pid = _read_pid(fd)
                os.close(fd)
                raise IrreflectError(
                    f"{self.option} {self.path}: another irreflect run"
                    f"{f' (pid {pid})' if pid else ''} is writing there now: wait for it to "
                    "finish or choose another path"
                ) from None
            # the previous holder may have removed the file between our open and flock:
            # then we hold a lock on a deleted file; try again on the new one
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.lock_path))
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self.fd = fd
                return
            os.close(fd)
        raise IrreflectError(f"{self.option} {self.path}: could not take the lock "  # pragma: no cover
                             f"{self.lock_path}: try again")

    def _open_lock(self) -> int:
        """The lock file, never through a link (a link planted there must not make the
        run truncate its target) and only a regular file."""
        try:
            fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
                         | getattr(os, "O_NONBLOCK", 0), 0o644)
        except OSError as exc:
            raise IrreflectError(f"{self.option} {self.path}: cannot take the lock "
                                 f"{self.lock_path} ({exc.strerror or exc}; a link or a "
                                 "special file there?): remove it or choose another path"
                                 ) from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise IrreflectError(f"{self.option} {self.path}: {self.lock_path} is not a "
                                 "regular file: remove it or choose another path")
        return fd

    def release(self) -> None:
        if self.fd is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.lock_path)
            os.close(self.fd)
            self.fd = None
        for folder in self.created:  # a run that wrote nothing leaves no empty folders
            with contextlib.suppress(OSError):
                folder.rmdir()

    # -- leftovers of killed runs
    def clean_leftovers(self) -> None:
        """Remove the hidden temporary entries that runs into this path left when killed
        (safe: we hold the lock, so no live run uses them)."""
        name = self.path.name
        pattern = re.compile(rf"\.{re.escape(name)}\.({_TMP}|{_OLD})-.*|"
                             + _LEGACY.format(name=re.escape(name)))
        with contextlib.suppress(OSError):
            for entry in self.path.parent.iterdir():
                if pattern.fullmatch(entry.name):
                    _remove(entry)
        if self.kind == "checkpoint-dir" and self.path.is_dir():
            # per-run checkpoint files are written atomically inside the folder
            inner = re.compile(rf"\..+\.({_TMP}|{_OLD})-.*|\..+\.ckpt\.[a-z0-9_]{{8}}\.tmp")
            for entry in self.path.iterdir():
                if inner.fullmatch(entry.name):
                    _remove(entry)


def _read_pid(fd: int) -> int | None:
    with contextlib.suppress(OSError, ValueError):
        os.lseek(fd, 0, os.SEEK_SET)
        return int(os.read(fd, 32).decode().strip() or "0") or None
    return None


def _remove(entry: Path) -> None:
    if entry.is_dir() and not entry.is_symlink():
        shutil.rmtree(entry, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            entry.unlink()


@contextlib.contextmanager
def claim_output(path, kind: str = "dir", option: str = "--out", suffixes=None):
    """Check ``path`` and lock it for this run, before any work (see the module docstring).

    ``kind``: ``"file"``, ``"dir"`` (a folder the run owns and replaces) or
    ``"checkpoint-dir"`` (a folder of per-run checkpoint files, kept between runs).
    Re-entrant within a process: :func:`atomic_path` and :func:`atomic_directory` reuse a
    claim the caller holds. Yields the path.
    """

    if (path is None or not isinstance(path, str | os.PathLike) or str(path).strip() == ""
            or kind == "file" and str(path).endswith(("/", os.sep))):  # Path() drops the '/'
        check_output_path(path, "file" if kind == "file" else "dir", option, suffixes)
    path = Path(path)
    key = _key(path)
    with _held_lock:
        claim = _held.get(key)
        new = claim is None
        if not new and (claim.kind == "file") != (kind == "file"):  # two outputs, one path
            word = {True: "file", False: "folder"}
            raise IrreflectError(
                f"{option} {path}: is the {claim.option} {word[claim.kind == 'file']} of this "
                f"run ({claim.option} {claim.path}); expected a {word[kind == 'file']} of its "
                f"own: give {option} another path")
        if new:
            path = check_output_path(path, "file" if kind == "file" else "dir", option,
                                     suffixes)
            if kind == "dir":
                _check_owned(path, option)
            claim = _Claim(path, kind, option)
            try:
                claim.acquire()
                claim.clean_leftovers()
            except BaseException:
                claim.release()
                raise
            _held[key] = claim
        claim.depth += 1
    try:
        yield claim.path
    finally:
        with _held_lock:
            claim.depth -= 1
            if claim.depth == 0:
                _held.pop(key, None)
                claim.release()


@contextlib.contextmanager
def claim_outputs(*claims):
    """:func:`claim_output` for several outputs at once, each ``(path, kind, option[,
    suffixes])``; a claim whose path is None is skipped (an option not given)."""
    with contextlib.ExitStack() as stack:
        for path, kind, option, *rest in claims:
            if path is not None:
                stack.enter_context(claim_output(path, kind, option, *rest))
        yield


def _check_owned(path: Path, option: str) -> None:
    """A folder a run may replace: absent, empty, written by irreflect (manifest) through
    the same command as the one running (:data:`RUNNING_COMMAND`; another command's output
    is not this run's to replace), or holding only other irreflect output folders (e.g.
    ``out/select`` before ``reproduce --out out``), which the run keeps."""
    if not path.is_dir():
        return
    if (path / MANIFEST).exists():
        other, running = _manifest_command(path), RUNNING_COMMAND.get()
        if other and running and other != running and other != "irreflect":
            raise IrreflectError(
                f"{option} {path}: the folder holds the output of 'irreflect {other}' (its "
                f"{MANIFEST}), which this 'irreflect {running}' run would replace: choose "
                "another folder, or delete it")
        return
    entries = [e.name for e in path.iterdir()
               if not (e.is_dir() and (e / MANIFEST).exists())
               and not re.fullmatch(rf"\..+\.({_TMP}|{_OLD}|{_LOCK}).*", e.name)]
    if entries:

        raise IrreflectError(
            f"{option} {path}: the folder exists and holds files irreflect did not write "
            f"({short_list(sorted(entries), 3)}; no {MANIFEST}): choose a new or empty folder, "
            "or delete it"
        )


def check_not_output(path, expected: str = "an input", reading: str | None = None) -> None:
    """Refuse to read ``path`` as an input when an output this process holds would replace
    it: the same file (also through a link or a hard link), or a file of an output folder
    that the previous run wrote (its manifest lists it). ``reading``: the option of a claim
    that may be read back (``--checkpoint``: a run resumes from its own checkpoint)."""
    path = Path(path)
    real = _key(path)
    try:
        st = os.stat(path)
    except OSError:
        st = None
    with _held_lock:
        claims = list(_held.values())
    for claim in claims:
        if reading is not None and claim.option == reading:
            continue
        target = _key(claim.path)
        if claim.kind == "file":
            same = real == target
            if not same and st is not None:
                with contextlib.suppress(OSError):
                    same = os.path.samestat(st, os.stat(target))
        else:
            same = (claim.kind == "dir" and target in real.parents
                    and real.relative_to(target).parts[0] in _manifest_entries(target))
        if same:
            raise IrreflectError(
                f"{path}: is read as {expected} and would be replaced by this run's output "
                f"{claim.option} {claim.path}: write the output elsewhere (an output never "
                "replaces an input of the same run)")


# ----------------------------------------------------------------------------- files
def _permissions(path: Path) -> None:
    """``mkstemp``/``mkdtemp`` make owner-only entries; give the usual ones (umask)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, (0o777 if path.is_dir() else 0o666) & ~umask)


@contextlib.contextmanager
def atomic_path(path, option: str = "output"):
    """Yield a temporary path beside ``path``; move it into place only if the block
    succeeds. The path is claimed (locked) for the duration unless the caller holds it."""

    with claim_output(path, "file", option) as path:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{_TMP}-", dir=path.parent)
        os.close(fd)
        tmp = Path(tmp)
        try:
            yield tmp
            _permissions(tmp)
            os.replace(tmp, path)
        finally:
            if tmp.exists():
                tmp.unlink()


# ----------------------------------------------------------------------------- folders
@contextlib.contextmanager
def atomic_directory(path, option: str = "--out", command: str = "irreflect"):
    """Yield a fresh temporary folder beside ``path``; on success it replaces ``path``
    whole (with a manifest of what was written), keeping only entries of the old folder
    that no irreflect run wrote. On failure nothing at ``path`` changes."""

    with claim_output(path, "dir", option) as path:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.{_TMP}-", dir=path.parent))
        try:
            yield tmp
            written = sorted(p.relative_to(tmp).as_posix() for p in tmp.rglob("*")
                             if p.is_file())
            manifest = {"written_by": "irreflect", "command": command,
                        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "files": written}
            (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
            _permissions(tmp)
            _swap_in(tmp, path)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def _swap_in(new: Path, path: Path) -> None:
    """Put folder ``new`` at ``path``. An existing folder is exchanged with it atomically
    where the system allows (Linux ``renameat2``), after its foreign entries (not in its
    manifest) have been moved into ``new``; the old folder is then deleted."""
    if not path.exists():
        os.rename(new, path)
        return
    owned = _manifest_entries(path)
    for entry in path.iterdir():
        if entry.name == MANIFEST or entry.name in owned:
            continue
        target = new / entry.name
        if not target.exists():  # this run's output of the same name wins
            os.rename(entry, target)
    old = path.parent / f".{path.name}.{_OLD}-{os.getpid()}"
    if _exchange(new, path):
        _remove(new)  # now holds the previous run's output
        return
    os.rename(path, old)  # pragma: no cover - systems without renameat2
    os.rename(new, path)  # pragma: no cover
    _remove(old)  # pragma: no cover


def _read_manifest(path: Path) -> dict:
    """The manifest a previous run left in folder ``path`` ({} when absent or unreadable;
    read only when it is a regular file of reasonable size: a FIFO planted there must not
    hang)."""
    manifest = path / MANIFEST
    try:
        st = os.lstat(manifest)
        if not stat.S_ISREG(st.st_mode) or st.st_size > 16 * 2**20:
            return {}
        with open(manifest, "rb") as fh:
            doc = json.loads(fh.read(16 * 2**20).decode("utf-8"))
        return doc if isinstance(doc, dict) else {}
    except (OSError, ValueError, TypeError, RecursionError):
        return {}


def _manifest_command(path: Path) -> str:
    """The command a previous run recorded in its manifest ('' when unreadable)."""
    return str(_read_manifest(path).get("command") or "")


def _manifest_entries(path: Path) -> set[str]:
    """Top-level names of the entries a previous run recorded in its manifest."""
    files = _read_manifest(path).get("files", [])
    return {str(f).split("/")[0] for f in files} if isinstance(files, list) else set()


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Atomically exchange two paths (Linux ``renameat2(RENAME_EXCHANGE)``); False when
    the system or file system cannot."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_uint]
    rc = renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    return rc == 0
