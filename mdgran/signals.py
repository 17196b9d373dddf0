"""Signals: SIGINT (Ctrl-C) and SIGTERM (what batch schedulers send at the time limit).

Both end a run the same way: :class:`Interrupted` (a :class:`KeyboardInterrupt`) is raised in
the driver, which closes every reporter as ``"interrupted"`` (the H5MD writer keeps a valid
checkpoint if checkpointing is on, else removes its temporary) and re-raises; the command
line then says how to resume and exits with ``128 + signal number`` (130, 143).

* :func:`terminate_as_interrupt` makes SIGTERM raise :class:`Interrupted` like Ctrl-C does
  (the command line installs it; a library caller keeps its own handlers); :func:`interrupting`
  does the same inside a block (a sweep's main process), where the handlers are still Python's
  defaults.
* :func:`deferred` holds both signals while C code that calls back into Python runs (LAMMPS's
  ``fix external`` callback): an exception raised inside a ctypes callback cannot cross the C
  frames and is dropped ("Exception ignored on calling ctypes callback"), so the run would go
  on as if nothing happened.  The held signal is delivered when the C call returns.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

HELD = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """A run stopped by a signal; ``signum`` says which (exit status ``128 + signum``)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def terminate_as_interrupt():
    """SIGINT and SIGTERM raise :class:`Interrupted` from now on (main thread only)."""
    if _main_thread():
        for s in HELD:
            signal.signal(s, _raise_interrupted)


@contextmanager
def interrupting():
    """Inside the block, SIGINT and SIGTERM raise :class:`Interrupted` where they are still
    Python's defaults (main thread only); the handlers in place before are restored after."""
    saved = {}
    if _main_thread():
        for s in HELD:
            if signal.getsignal(s) in (signal.SIG_DFL, signal.default_int_handler):
                saved[s] = signal.signal(s, _raise_interrupted)
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


def _deliver(signum: int, handler):
    """Act on a held signal as ``handler`` (the one in place before holding) would have."""
    if handler is signal.SIG_IGN:
        return
    if callable(handler) and handler is not signal.default_int_handler:
        handler(signum, None)  # the caller's handler decides (ours raises Interrupted)
        return
    raise Interrupted(signum)  # Python's default for SIGINT raises; SIGTERM's would kill


@contextmanager
def deferred():
    """Hold SIGINT and SIGTERM inside the block; the first one that arrived is delivered
    (raised as :class:`Interrupted`, or passed to the caller's handler) when it ends."""
    if not _main_thread():
        yield
        return
    got = []
    before = {s: signal.getsignal(s) for s in HELD}
    for s in HELD:
        signal.signal(s, lambda signum, frame: got.append(signum))
    try:
        yield
    finally:
        for s, h in before.items():
            signal.signal(s, h)
    if got:
        _deliver(got[0], before[got[0]])


class FrameSections:
    """Hold SIGINT and SIGTERM while the driver hands a frame to its reporters, or while numba
    compiles (:func:`in_compiler`).

    A signal that arrives between the backend yielding a frame and the last reporter taking it
    would stop the run with the backend one frame ahead of the writer, whose checkpoint (the
    backend's state at *its* last frame) would then not match the frames on disk.  Inside
    ``with FrameSections() as sections:`` the driver sets ``sections.inside = True`` before it
    computes a frame's ledger and calls ``sections.leave()`` once every reporter has the frame:
    a signal in between is delivered there, as the handler in place before would have acted on
    it.  A signal that arrives while numba compiles is held likewise, to the end of the next
    section (or of the run).  Elsewhere (while the backend integrates) signals act at once.  Installed once per run
    (a handler swap costs ~25 us; entering and leaving a section, an attribute each); a signal
    still at its default action (SIGTERM outside the command line: the process ends) is left
    alone.
    """

    def __init__(self):
        self.inside = False
        self.held = None
        self.before = {}

    def __enter__(self):
        if _main_thread():
            for s in HELD:
                h = signal.getsignal(s)
                if h not in (signal.SIG_DFL, signal.SIG_IGN, None):
                    self.before[s] = signal.signal(s, self._on_signal)
        return self

    def _on_signal(self, signum, frame):
        if self.inside or in_compiler(frame):
            if self.held is None:
                self.held = signum
            return
        _deliver(signum, self.before[signum])

    def leave(self):
        """End of a section: deliver a signal held inside it."""
        self.inside = False
        if self.held is not None:
            signum, self.held = self.held, None
            _deliver(signum, self.before[signum])

    def __exit__(self, *exc):
        self.inside = False
        for s, h in self.before.items():
            signal.signal(s, h)
        before, self.before = self.before, {}
        if self.held is not None and exc[0] is None:  # held in the compiler, the run ended
            signum, self.held = self.held, None
            _deliver(signum, before[signum])
        return False


#: modules whose code a signal must not interrupt: numba compiles through LLVM, which calls
#: back into Python through ctypes (an exception raised there is dropped: "Exception ignored
#: on calling ctypes callback function", and the run went on to exit 0 after a SIGTERM)
COMPILER_MODULES = ("numba", "llvmlite")


def in_compiler(frame) -> bool:
    """Whether ``frame`` (where a signal arrived) or a caller runs code of
    :data:`COMPILER_MODULES` (numba compiling a variant on its first use: 15-25 s)."""
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if name.split(".", 1)[0] in COMPILER_MODULES:
            return True
        frame = frame.f_back
    return False
