"""User-facing errors: one line, naming the file, the row or column and the likely cause."""
from __future__ import annotations

import threading


class SelfnavError(Exception):
    """An error the command line reports as one line (no traceback) with a non-zero exit."""

    exit_code = 2


class InputError(SelfnavError):
    """Bad input data.

    Parameters
    ----------
    path : str
        The file (or a description of the input).
    message : str
        What is wrong and the likely cause.
    row : int, optional
        1-based line number in the file.
    column : str, optional
        Column name.
    """

    def __init__(self, path, message: str, *, row: int | None = None, column: str | None = None):
        self.path = str(path)
        self.row = row
        self.column = column
        where = [self.path]
        if row is not None:
            where.append(f"line {row}")
        if column is not None:
            where.append(f"column '{column}'")
        super().__init__(", ".join(where) + ": " + message)


class NotAtRestError(SelfnavError):
    """Data that a static method cannot use because the unit was moving."""


class OutputError(SelfnavError):
    """An output path selfnav cannot or will not write (a folder named as a file, a special
    file, a file in the way of a folder, no permission): one line naming the path."""

    def __init__(self, path, message: str):
        self.path = str(path)
        super().__init__(f"{self.path}: {message}")


class Interrupted(BaseException):
    """Ctrl-C inside the command line (a ``BaseException`` like ``KeyboardInterrupt``, so that
    no ``except Exception`` swallows it and no library turns it into something else)."""


#: Set by the command line's Ctrl-C handler. The exception it raises can still be lost when the
#: handler happens to run inside a finalizer or a library callback ("Exception ignored in ...");
#: long waiting loops (the Monte Carlo's) check this too.
interrupt_requested = threading.Event()


def check_interrupt() -> None:
    """Raise :class:`Interrupted` if Ctrl-C was pressed (see :data:`interrupt_requested`)."""
    if interrupt_requested.is_set():
        raise Interrupted()


class SelfnavWarning(UserWarning):
    """Something the user should know, said in one line: the command line prints each as
    ``selfnav: warning: <message>`` on stderr; in Python it is an ordinary warning."""


def warn(message: str, *, stacklevel: int = 2) -> None:
    """Issue ``message`` as a :class:`SelfnavWarning` (one line, no newlines)."""
    import warnings

    warnings.warn(str(message).replace("\n", " "), SelfnavWarning, stacklevel=stacklevel + 1)
