"""The ``aquarom`` command: scene files in, results, plots and pictures out.

Bad input ends in one line on stderr and exit code 2; a solver that stops early keeps what it
computed, says when it stopped and exits with code 3. The parser is in ``parser.py``, the
commands in ``commands.py`` and ``runs.py``, the output folders in ``outputs.py``.
"""
from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
import traceback

from mpi4py import MPI

from aquarom_fenics import set_log_level
from aquarom_fenics.cli.commands import COMMANDS
from aquarom_fenics.cli.outputs import os_error_text, settle_output
from aquarom_fenics.cli.parser import build_parser
from aquarom_fenics.errors import InputError, Interrupted, SolverError
from aquarom_fenics.io.output_lock import release_output_locks
from aquarom_fenics.io.stop_signals import sigterm_as_interrupt, stop_between_steps, stop_for


AGREEMENT_SECONDS = 10.0   # how long a failing rank waits for the others to fail too before aborting all


def main(argv=None) -> int:
    keep_signals_in_python()
    args = build_parser().parse_args(argv)
    comm = MPI.COMM_WORLD
    agreement = comm.Dup() if comm.size > 1 else None
    set_log_level("info" if args.verbose else "warning")      # the console shows details only with --verbose
    logging.getLogger("aquarom").setLevel(logging.INFO if comm.rank == 0 else logging.ERROR)  # records for any handler
    # the toolkit's console handler is the one that prints: importing dolfinx puts a plain stderr
    # handler on the root logger, which would print every record again ("INFO:aquarom:…")
    import dolfinx  # noqa: F401  (its import adds that handler: silence it before any command imports it)

    silenced = [(handler, handler.level) for handler in logging.getLogger().handlers
                if type(handler) is logging.StreamHandler and handler.stream is sys.stderr]
    for handler, _ in silenced:
        handler.setLevel(logging.CRITICAL + 1)
    try:
        with sigterm_as_interrupt():
            code, line = run_and_settle(args)
    finally:
        release_output_locks()
        for handler, level in silenced:
            handler.setLevel(level)
    if line is None:
        return code
    return end_in_agreement(agreement, code, f"aquarom {args.command}: {line}")


def keep_signals_in_python() -> None:
    """PETSc (initialised when dolfinx is first imported) must not take over SIGTERM and SIGPIPE:
    it would abort the run with a dump instead of the handling here (SIGTERM like Ctrl-C; a closed
    stdout, as in ``aquarom … | head``, only ends the printing)."""
    options = os.environ.get("PETSC_OPTIONS", "")
    if "-no_signal_handler" not in options.split():
        os.environ["PETSC_OPTIONS"] = f"{options} -no_signal_handler".strip()


def run_and_settle(args) -> tuple[int, str | None]:
    """Run the command, then finish its outputs (manifest, swap) with Ctrl-C and SIGTERM held
    back; the exit code and the line for the user (None: nothing to say)."""
    started = time.perf_counter()
    line = None
    try:
        with progress_shown(not getattr(args, "no_progress", False)):
            code = COMMANDS[args.command](args)          # a dry run too: each command makes its checks first
    except (Exception, KeyboardInterrupt) as error:
        code, line = describe_failure(args, error)
    with stop_between_steps() as stop_requested:
        try:
            settle_output(args, code, time.perf_counter() - started)
        except (OSError, InputError) as problem:
            text = os_error_text(problem) if isinstance(problem, OSError) else str(problem)
            code, line = InputError.exit_code, f"{line + '; ' if line else ''}error: the outputs could not be finished ({text})"
        stop = stop_requested()
    if stop is not None and line is None:
        code = stop_for(stop, "").exit_code
        line = f"{stop_for(stop, 'after the run had finished')}; its outputs are complete"
    return code, line


def progress_shown(shown: bool):
    """``--no-progress``: no FOM progress bar in the command's run (and its FOM checks)."""
    if shown:
        return contextlib.nullcontext()
    from aquarom_fenics.dynamics.simulate import progress_bars

    return progress_bars(False)


def describe_failure(args, error: BaseException) -> tuple[int, str]:
    """Exit code and the one line for the user: 2 bad input or OS error, 3 solver stop, 130 Ctrl-C,
    143 SIGTERM.

    Anything else is a bug: its traceback is printed and the exit code is 1.
    """
    if isinstance(error, KeyboardInterrupt):
        location = getattr(args, "output", None)
        written = location is not None and location.working.is_dir() and any(location.working.iterdir())
        where = f"; partial results in {location.target}/" if written else "; nothing written"
        return getattr(error, "exit_code", Interrupted.exit_code), f"{str(error) or 'interrupted (Ctrl-C)'}{where}"
    if isinstance(error, InputError):
        return InputError.exit_code, f"error: {error}"
    if isinstance(error, SolverError):
        return SolverError.exit_code, f"solver stopped: {error}"
    if isinstance(error, OSError):          # a write that failed (full disk, quota, permissions): a failure
        location = getattr(args, "output", None)
        unnamed = f"writing in {location.working}/" if location is not None else "a file"
        written = location is not None and location.working.is_dir() and any(location.working.iterdir())
        args.failed_write = True
        kept = f"; what was written before is kept in {location.working}/" if written else ""
        return InputError.exit_code, f"error: {os_error_text(error, unnamed)}{kept}"
    if MPI.COMM_WORLD.size == 1:
        raise error
    traceback.print_exc()
    return 1, f"internal error on rank {MPI.COMM_WORLD.rank}: {type(error).__name__}: {error}"


def end_in_agreement(agreement, code: int, line: str) -> int:
    """Print the one line and return the exit code, on every rank alike.

    Under MPI the failing ranks wait (on their own communicator) for the others: when every rank
    failed, rank 0 prints its line and all return its code; when some rank is still busy (a
    failure on one rank only), this rank prints its line and aborts every rank with its code.
    """
    if agreement is None:
        print(line, file=sys.stderr, flush=True)
        return code
    request = agreement.Ibarrier()
    deadline = time.monotonic() + AGREEMENT_SECONDS
    while not request.Test():
        if time.monotonic() > deadline:
            print(line, file=sys.stderr, flush=True)
            MPI.COMM_WORLD.Abort(code)
        time.sleep(0.01)
    code, line = agreement.bcast((code, line))
    if agreement.rank == 0:
        print(line, file=sys.stderr, flush=True)
    return code
