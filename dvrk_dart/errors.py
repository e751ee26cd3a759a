"""The one error type users see: a one-line message naming the file or parameter."""

import threading


class DvrkDartError(Exception):
    """A user-facing error; the CLI prints `dvrk-dart: <message>` and exits with 2."""

    exit_code = 2


class SimulationDiverged(DvrkDartError):
    """The simulation left its physical envelope (NaN, open loop, joint out of range)."""


#: set by the CLI's Ctrl-C handler: an interrupt that a library swallowed
#: (raised inside a weakref callback or a compiled kernel) is still seen here
interrupted = threading.Event()


def raise_if_interrupted() -> None:
    """Before an output is committed: a Ctrl-C that did not stop the work stops the commit."""
    if interrupted.is_set():
        raise KeyboardInterrupt
