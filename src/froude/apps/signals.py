"""The one signal-handling helper of the long-running apps (the batch driver, the studio server).

Ctrl-C and SIGTERM become KeyboardInterrupt, so a run stops the same way for both (files closed, workers
cancelled, the server shut down) even when started from a shell that ignores SIGINT in background jobs;
the previous handlers come back afterwards. Python sets handlers from the main thread only: elsewhere
(tests that run an app in a thread) nothing is changed.
"""
from __future__ import annotations

import contextlib
import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def interrupt_on_signals(before_raise=None) -> dict:
    """SIGINT and SIGTERM raise KeyboardInterrupt from now on (``before_raise()`` runs first when given).

    Returns the previous handlers, for ``restore_signals`` ({} off the main thread: nothing was changed).
    """
    if not _main_thread():
        return {}

    def stop(signum, frame):
        if before_raise is not None:
            before_raise()
        raise KeyboardInterrupt

    return {sig: signal.signal(sig, stop) for sig in STOP_SIGNALS}


def restore_signals(previous: dict) -> None:
    """Put back the handlers ``interrupt_on_signals`` or ``ignoring`` replaced."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)


@contextlib.contextmanager
def ignoring(*signals):
    """Within the block the given signals are ignored (main thread only): processes spawned there inherit
    SIG_IGN, so a Ctrl-C to the process group reaches the driver alone."""
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in signals} if _main_thread() else {}
    try:
        yield
    finally:
        restore_signals(previous)
