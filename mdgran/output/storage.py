"""Output files on shared storage: one writer per output name, and storage faults as one line.

* :class:`OutputLock`: a run holds ``NAME.lock`` (an advisory ``flock``, which works where
  HDF5's own file locking is switched off, e.g. ``HDF5_USE_FILE_LOCKING=FALSE`` on clusters)
  from before it creates its temporary until its file is in place; a second run on the same
  name is refused at once, naming the holder.  The kernel drops the lock when its process
  dies, so a killed run never leaves a stale lock behind.  A process forked while a lock is
  held (a sweep's worker) closes its copy of the descriptor at once: the lock belongs to the
  process that took it alone, and ends with it.
* :class:`StorageError`: the file system refused a write (full disk, quota, file size limit,
  read-only remount).  :func:`abandon` then closes the HDF5 file without letting the HDF5
  library write to the failing disk again (it would fail again at exit and crash the
  interpreter: exit 139) and removes the temporary, checkpoint or not.
"""
from __future__ import annotations

import errno
import os
import re
import socket
from pathlib import Path


class StorageError(OSError):
    """Writing the output failed: one line (exit status 1)."""


class OutputLocked(ValueError):
    """Another run is writing the same output name: one line (exit status 2)."""


def temporary_path(path) -> Path:
    """``NAME.tmp-PID`` beside the file ``NAME``: where this process writes it before renaming it
    onto ``NAME`` (a sweep removes the ``*.tmp-*`` a killed writer left)."""
    path = Path(path)
    return path.with_name(f"{path.name}.tmp-{os.getpid()}")


def write_atomic(path, text: str):
    """Write ``text`` to ``path`` through :func:`temporary_path` and a rename: a reader sees the
    old file or the whole new one, never a part."""
    tmp = temporary_path(path)
    tmp.write_text(text)
    os.replace(tmp, path)


def lock_path(path) -> Path:
    path = Path(path)
    return path.with_name(f"{path.name}.lock")


#: descriptors of the locks this process holds (a forked child closes its copies)
_HELD: set = set()


def _close_inherited_locks():
    for fd in list(_HELD):
        try:
            os.close(fd)
        except OSError:
            pass
    _HELD.clear()


os.register_at_fork(after_in_child=_close_inherited_locks)


class OutputLock:
    """An exclusive, non-blocking lock on ``NAME.lock`` beside the output file ``NAME``."""

    def __init__(self, path):
        import fcntl

        self.path = lock_path(path)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown"
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputLocked(f"{Path(path)} is being written by another run "
                                       f"({holder}); wait for it to end or choose another "
                                       "output name") from None
                raise StorageError(f"cannot lock {self.path}: {exc.strerror}") from None
            try:  # the file we locked may have been removed by its last holder meanwhile
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}".encode(), 0)
        self.fd = fd
        _HELD.add(fd)

    def release(self):
        if self.fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            _HELD.discard(self.fd)
            os.close(self.fd)  # closing drops the flock
            self.fd = None


def reason(exc: BaseException) -> str:
    """One line for a failed write: the operating system's words where HDF5 quotes an errno
    (``errno = 28``: No space left on device), else the exception's first line."""
    text = str(exc)
    m = re.search(r"errno = (\d+)", text)
    if m:
        return os.strerror(int(m.group(1)))
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return (text.splitlines() or [type(exc).__name__])[0][:200]


def _discard_writes(h5file):
    """Point the file descriptor HDF5 writes ``h5file`` through at ``/dev/null``: its last
    writes (at close, and again at interpreter exit) then succeed wherever they fall.  Emptying
    the file frees the space of a full disk, but not a write past a file size limit, which
    failed again and crashed the process (exit 139)."""
    try:
        fd = h5file.id.get_vfd_handle()
        null = os.open(os.devnull, os.O_RDWR)
    except Exception:  # noqa: BLE001 - not a POSIX file driver: emptying the file must do
        return
    try:
        os.dup2(null, fd)
    except OSError:
        pass
    finally:
        os.close(null)


def abandon(h5file, tmp: Path, forget=lambda: None):
    """Close ``h5file`` after a failed write and remove its temporary ``tmp``.

    HDF5 keeps unwritten data in its caches and retries at close and again at interpreter
    exit, where a second failure crashes the process (exit 139).  Emptying the file first
    frees the space, so those last writes succeed into a file that is then removed.  A
    checkpoint file is removed too: after a failed write it cannot be trusted to be whole.
    ``forget()`` drops the caller's references to the file's datasets, once their last
    writes can succeed."""
    try:
        os.truncate(tmp, 0)
    except OSError:
        pass
    _discard_writes(h5file)
    forget()
    for finish in (h5file.flush, h5file.close):
        try:
            finish()
        except Exception:  # noqa: BLE001 - the file is being thrown away
            pass
    try:
        tmp.unlink(missing_ok=True)
    except OSError:
        pass


# ---- output names, checked before a run starts ----------------------------------------------
#: longest suffix the HDF5 writer puts after the output file's name (".tmp-" + a pid; ".partial")
TMP_SUFFIX = len(".tmp-") + 10


def _refuse(key: str, message: str):
    """Bad input naming the parameter ``key``: :class:`~mdgran.model.scene.SceneError` (exit status
    2 on the command line, which names the flag instead)."""
    from ..model.scene import SceneError

    return SceneError(key, message)


def _existing_ancestor(path) -> Path:
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _name_max(folder) -> int:
    """Longest file name (bytes) the file system of ``folder`` allows (255 if it does not say)."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def _check_creatable(out: str, key: str) -> int:
    """The first existing folder on ``out``'s way is a writable folder; no name is too long.
    Returns the file system's longest name."""
    anc = _existing_ancestor(Path(out).absolute().parent)
    if not anc.is_dir():
        raise _refuse(key, f"{str(anc)!r} is a file, so {out!r} cannot be created in it")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise _refuse(key, f"cannot create {out!r}: folder {str(anc)!r} is not writable")
    limit = _name_max(anc)
    for part in Path(out).parts:
        if len(os.fsencode(part)) > limit:
            raise _refuse(key, f"the name {part[:20]!r}... is {len(os.fsencode(part))} bytes, "
                          f"the file system allows {limit}")
    return limit


def check_out_file(out: str, scene_spec: str | None = None, key: str = "out"):
    """Refuse up front an output file that the run could not write at its end: empty, a folder
    (or a name ending in ``/``), in a folder that cannot be created or written, a name too long
    for its temporary, or the scene file ``scene_spec`` itself."""
    if not out:
        raise _refuse(key, "must name an output file, e.g. run.h5")
    p = Path(out)
    if out.endswith(("/", os.sep)) or p.name in ("", ".", "..") or p.is_dir():
        raise _refuse(key, f"{out!r} is a folder; give a file name, e.g. "
                      f"{os.path.join(out, 'run.h5')}")
    limit = _check_creatable(out, key)
    if len(os.fsencode(p.name)) + TMP_SUFFIX > limit:
        raise _refuse(key, f"the file name is {len(os.fsencode(p.name))} bytes; at most "
                      f"{limit - TMP_SUFFIX} (room for the temporary .tmp-PID or .partial "
                      f"suffix in the file system's {limit})")
    if scene_spec and p.exists() and Path(scene_spec).is_file() and \
            os.path.samefile(scene_spec, p):
        raise _refuse(key, f"{out!r} is the scene file; give another name")


def check_out_dir(out: str, key: str = "out"):
    """Refuse up front an output folder that cannot be made (empty, an existing file, in a
    folder that cannot be written)."""
    if not out:
        raise _refuse(key, "must name a folder")
    if Path(out).exists() and not Path(out).is_dir():
        raise _refuse(key, f"{out!r} is a file; give a folder")
    _check_creatable(out, key)
