"""Errors that reach the user as one line (what, where, what would be valid)."""


def one_line(text: str) -> str:
    """``text`` as one printable line: line breaks and other control characters (from a file or an
    option quoted in a message) written as escapes such as ``\\n``."""
    return "".join(character if character.isprintable() else repr(character)[1:-1] for character in text)


class InputError(Exception):
    """Bad input from the user (scene, mesh file, design, PROM file): exit code 2, no traceback.

    Its message is always one line (:func:`one_line`), whatever user text it quotes."""

    exit_code = 2

    def __str__(self) -> str:
        return one_line(super().__str__())


class SolverError(Exception):
    """A solver that stopped (divergence, non-finite values): exit code 3, results kept so far."""

    exit_code = 3


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, after the partial results and their summary were written: exit code 130."""

    exit_code = 130


class Terminated(Interrupted):
    """SIGTERM (a batch system's stop), handled like Ctrl-C: partial results kept, exit code 143 (128 + 15)."""

    exit_code = 143
