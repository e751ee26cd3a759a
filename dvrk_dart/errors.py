"""The one error type users see: a one-line message naming the file or parameter."""


class DvrkDartError(Exception):
    """A user-facing error; the CLI prints `dvrk-dart: <message>` and exits with 2."""

    exit_code = 2


class SimulationDiverged(DvrkDartError):
    """The simulation left its physical envelope (NaN, open loop, joint out of range)."""
