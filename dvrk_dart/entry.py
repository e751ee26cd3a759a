"""The `dvrk-dart` console command: a light module, so that Ctrl-C while the
heavy modules load (numpy, pandas, DART) ends in one line, and an exit that
does not wait on worker pools an interrupt ended (a worker killed while it
handed back a result leaves the pool's thread waiting forever)."""

import os
import signal
import sys

#: exit codes of an interrupted (Ctrl-C) or terminated (SIGTERM) command
INTERRUPTED, TERMINATED = 130, 143


def run() -> None:
    try:
        from dvrk_dart.cli import main
    except KeyboardInterrupt:
        print("dvrk-dart: interrupted", file=sys.stderr)
        os._exit(INTERRUPTED)
    code = main()
    # the command is over (its outputs are in place or removed): a Ctrl-C while
    # the interpreter shuts down must not turn its exit code into "interrupted"
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if code in (INTERRUPTED, TERMINATED):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
