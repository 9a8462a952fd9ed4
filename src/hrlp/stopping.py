"""How a run stops when something outside it ends it: SIGINT (Ctrl-C), SIGTERM (a scheduler's preemption) and SIGHUP
(a closed terminal) all end it the same way (docs/reliability.md, "How a run stops").

* :func:`install_stop_handlers` -- the ``hrlp`` command installs it first thing, before it imports anything heavy:
  from then on each of the three signals raises :class:`Stopped` in the main thread, wherever it is (importing torch,
  sampling, the policy step, the baseline fit, an evaluation). The exception unwinds the run (the iteration that was
  mid-way is dropped, worker processes are stopped) and the command prints one line, :meth:`Stopped.line`, and exits
  with ``128 + signal`` (130, 143, 129). :func:`handling_stop_signals` does the same for a block and puts the previous
  handlers back after it (for tests and for programs that call hrlp's commands in-process).
* :func:`shielded` -- a block that a signal does not cut in two (a checkpoint save with its log row): the signal is
  acted on as the block ends. A signal that comes while a module is being imported waits for the import to end too
  (an exception raised inside the import of a compiled module can abort the interpreter, as torch's does): it is acted
  on within :data:`_RETRY_S` seconds of the import's end.
* A second signal while the first is being acted on ends the process at once (``os._exit``) with one line; what is on
  disk is what a kill at that moment leaves, and checkpoints are written so that any kill leaves a whole one
  (:mod:`hrlp.checkpoint`).
* Worker processes do not act on these signals (a Ctrl-C in a terminal reaches the whole process group): they are
  started inside :func:`children_ignore_stop_signals`, so that they begin with the signals held back (a worker still
  importing torch does nothing), and call :func:`ignore_stop_signals` first; the main process stops them.

Only the standard library is imported here: the ``hrlp`` command installs the handlers before anything else.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a run: Ctrl-C, a scheduler's or a container's stop, the terminal closing."""


class Stopped(BaseException):
    """A stop signal arrived (:data:`STOP_SIGNALS`). A ``BaseException``, as ``KeyboardInterrupt`` is, so that no
    ``except Exception`` swallows it on its way out.

    ``detail`` says where the run stood and how to continue it (``at iteration 41 (2,050,000 steps); hrlp train ...
    --resume continues it``); the layer that knows sets it (:func:`describing`)."""

    def __init__(self, signum: int, detail: str = "") -> None:
        super().__init__(signum, detail)
        self.signum = int(signum)
        self.detail = detail

    @property
    def name(self) -> str:
        """The signal's name, e.g. ``SIGTERM``."""
        return signal_name(self.signum)

    @property
    def exit_code(self) -> int:
        """The shell's convention for a process ended by a signal: 128 + its number (SIGINT 130, SIGTERM 143, SIGHUP 129)."""
        return 128 + self.signum

    def line(self, default: str = "") -> str:
        """The one line a command ends with: ``stopped by SIGTERM at iteration 41 (...); hrlp train ... --resume
        continues it`` (``default`` where no detail was set)."""
        detail = self.detail or default
        return f"stopped by {self.name}" + ("" if not detail or detail[0] in ";,:" else " ") + detail

    def __str__(self) -> str:
        return self.line()


def signal_name(signum: int) -> str:
    """``SIGINT`` for 2, and so on."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class _State:
    """What the handler knows (main thread only)."""

    installed: int = 0
    """Nesting depth of :func:`handling_stop_signals` (and 1 for good after :func:`install_stop_handlers`)."""
    stopping: int | None = None
    """The signal being acted on; another one now ends the process at once."""
    shield: int = 0
    """Nesting depth of :func:`shielded` blocks."""
    deferred: int | None = None
    """A signal that came inside a shielded block, raised as it ends."""
    describe: list[Callable[[], str]] = []  # noqa: RUF012 - one list, the stack of :func:`describing` blocks


def _on_signal(signum: int, frame: FrameType | None) -> None:
    if _State.stopping is not None:  # a second signal while stopping: end now, without unwinding anything
        _exit_now(signum)
    _State.stopping = signum
    if _State.shield:
        _State.deferred = signum
        return
    if _importing(frame):  # an exception inside a compiled module's import can abort the interpreter (torch's does)
        _State.deferred = signum
        _retry_soon()
        return
    raise Stopped(signum)


def _importing(frame: FrameType | None) -> bool:
    """Whether ``frame`` runs inside an ``import`` (importlib's frames are on the stack)."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


_RETRY_S = 0.05
"""How often a stop deferred by an import looks again whether the import has ended."""


def _retry_soon() -> None:
    """Act on the deferred stop as soon as the import has ended: SIGALRM, every :data:`_RETRY_S` seconds, until then."""
    signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, _RETRY_S)


def _on_alarm(signum: int, frame: FrameType | None) -> None:
    if _State.deferred is None:  # acted on already (a shielded block ended, or a safe point's check)
        return
    if _State.shield or _importing(frame):
        signal.setitimer(signal.ITIMER_REAL, _RETRY_S)
        return
    deferred, _State.deferred = _State.deferred, None
    raise Stopped(deferred)


def _disarm() -> None:
    """Cancel a pending retry (Python restores SIGALRM's default, which ends the process, as it exits)."""
    if _State.deferred is not None or signal.getsignal(signal.SIGALRM) is _on_alarm:
        signal.setitimer(signal.ITIMER_REAL, 0)
    _State.deferred = None


def _exit_now(signum: int) -> None:
    """End the process at once with one line on stderr (a second signal, or one while the process exits)."""
    detail = ""
    if _State.describe:
        with contextlib.suppress(Exception):
            detail = _State.describe[-1]()
    if _State.stopping == -1:  # the command had finished: only its exit was left
        line = f"stopped by {signal_name(signum)} while exiting"
    else:
        line = f"stopped at once by a second signal ({signal_name(signum)})"
        line += ("" if not detail or detail[0] in ";,:" else " ") + detail
    with contextlib.suppress(OSError):
        os.write(2, (line + "\n").encode())
    os._exit(128 + signum)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def install_stop_handlers() -> None:
    """Make :data:`STOP_SIGNALS` raise :class:`Stopped` for the rest of the process's life (the ``hrlp`` command's
    entry point); a signal the process ignores already (SIGHUP under ``nohup``) stays ignored. Outside the main thread:
    nothing (Python runs signal handlers in the main thread only)."""
    if not _main_thread():
        return
    _install()
    _State.installed += 1


def _install() -> None:
    """Our handler for each stop signal, except one this process was told to ignore (``nohup`` ignores SIGHUP: a
    closed terminal must then not stop the run)."""
    for s in STOP_SIGNALS:
        if signal.getsignal(s) is not signal.SIG_IGN:
            signal.signal(s, _on_signal)


def exit_at_once_on_stop_signals() -> None:
    """From now on a stop signal ends the process at once (a command that has finished and only exits: its
    interpreter shutdown, with its ``atexit`` handlers, is no place for an exception)."""
    _State.stopping = -1 if _State.stopping is None else _State.stopping
    if _main_thread():
        _disarm()


@contextlib.contextmanager
def handling_stop_signals() -> Iterator[None]:
    """:func:`install_stop_handlers` for the block; the previous handlers come back after it (a no-op outside the
    main thread)."""
    if not _main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    _install()
    _State.installed += 1
    try:
        yield
    finally:
        _State.installed -= 1
        if _State.installed == 0:
            _disarm()
            _State.stopping = None
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)


def stop_signal() -> int | None:
    """The stop signal being acted on (one has arrived and the process is stopping), or None."""
    return None if _State.stopping in (None, -1) else _State.stopping


def raise_if_stopping() -> None:
    """Raise :class:`Stopped` if a stop signal has arrived but its exception went astray: swallowed by code that
    catches everything, or turned by a compiled module's interrupted import into an error that someone caught. Called
    at safe points (before each training iteration, as a :func:`describing` block ends); a no-op inside a
    :func:`shielded` block, which raises it as it ends."""
    if (signum := stop_signal()) is not None and not _State.shield:
        _disarm()
        raise Stopped(signum)


def as_stop(error: BaseException) -> Stopped | None:
    """``error`` as a :class:`Stopped`: itself if it is one, a new one if a stop signal has arrived (an error raised
    while the stop unwinds, or one that C code made of it: an interrupted ``import`` of a compiled module raises
    ``ImportError: initialization failed``), else None."""
    if isinstance(error, Stopped):
        return error
    signum = stop_signal()
    return None if signum is None or isinstance(error, SystemExit) else Stopped(signum)


def handling() -> bool:
    """Whether stop signals raise :class:`Stopped` now (inside :func:`handling_stop_signals` or after
    :func:`install_stop_handlers`)."""
    return _State.installed > 0 and _main_thread()


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """A block that a stop signal does not cut in two (a checkpoint save with its log row): a signal that arrives inside
    it raises :class:`Stopped` as the block ends, unless the block raises an error of its own. A second signal inside it
    still ends the process at once."""
    _State.shield += 1
    try:
        yield
    finally:
        _State.shield -= 1
    if _State.shield == 0 and _State.deferred is not None:
        signum = _State.deferred
        _disarm()
        raise Stopped(signum)


@contextlib.contextmanager
def describing(detail: Callable[[], str]) -> Iterator[None]:
    """Inside the block, a :class:`Stopped` leaving it without a detail gets ``detail()`` (where the run stands and
    how to continue it, read when the signal comes); the line of a second signal, which ends the process at once,
    ends with it too."""
    _State.describe.append(detail)
    try:
        yield
        raise_if_stopping()
    except Exception as error:
        if (stop := as_stop(error)) is None:
            raise
        with contextlib.suppress(Exception):
            stop.detail = detail()
        raise stop from None
    except Stopped as e:
        if not e.detail:
            with contextlib.suppress(Exception):
                e.detail = detail()
        raise
    finally:
        _State.describe.remove(detail)


def ignore_stop_signals() -> None:
    """In a worker process: ignore :data:`STOP_SIGNALS` (the main process stops the worker), then stop holding them back
    (a process started inside :func:`children_ignore_stop_signals` begins with them held back; those pending are
    dropped)."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


@contextlib.contextmanager
def children_ignore_stop_signals() -> Iterator[None]:
    """Processes started inside the block (fork and exec, as multiprocessing's ``spawn`` does) begin with
    :data:`STOP_SIGNALS` held back (blocked), so a Ctrl-C to the process group while one starts up (it imports torch
    for seconds) does nothing there; the worker then ignores them and lets them through (:func:`ignore_stop_signals`).

    A blocked set survives ``exec`` (a handler does not, and "ignore" set here would be this process's too, where
    another thread could take a signal and drop it). This thread blocks them for the block; a signal meanwhile stays
    pending, or reaches another thread, whose handler defers it (the block is :func:`shielded`): either way it is
    acted on as the block ends."""
    if not _main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    with shielded():
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
        try:
            _start_resource_tracker()
            signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now, with the stop signals blocked (it ignores SIGINT and SIGTERM
    itself; SIGHUP stays blocked there, so a closed terminal does not end it either). Left to the first ``spawn``, it
    would start inside :func:`children_ignore_stop_signals` and unblock SIGINT and SIGTERM in this thread as it does,
    so that the worker spawned next would begin with them unblocked."""
    try:
        from multiprocessing import resource_tracker
    except ImportError:  # pragma: no cover - a platform without it
        return
    resource_tracker.ensure_running()


__all__ = [
    "STOP_SIGNALS",
    "Stopped",
    "as_stop",
    "children_ignore_stop_signals",
    "describing",
    "exit_at_once_on_stop_signals",
    "handling",
    "handling_stop_signals",
    "ignore_stop_signals",
    "install_stop_handlers",
    "raise_if_stopping",
    "shielded",
    "signal_name",
    "stop_signal",
]
