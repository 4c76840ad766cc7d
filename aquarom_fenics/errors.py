"""Errors that reach the user as one line (what, where, what would be valid)."""


class InputError(Exception):
    """Bad input from the user (scene, mesh file, design, PROM file): exit code 2, no traceback."""

    exit_code = 2


class SolverError(Exception):
    """A solver that stopped (divergence, non-finite values): exit code 3, results kept so far."""

    exit_code = 3


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, after the partial results and their summary were written: exit code 130."""

    exit_code = 130


class Terminated(Interrupted):
    """SIGTERM (a batch system's stop), handled like Ctrl-C: partial results kept, exit code 143 (128 + 15)."""

    exit_code = 143
