"""User-facing errors: one line, naming the file, the row or column and the likely cause."""
from __future__ import annotations


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


class SelfnavWarning(UserWarning):
    """A condition the user should know about; the CLI prints it as one line."""
