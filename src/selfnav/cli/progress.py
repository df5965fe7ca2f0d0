"""What the command line shows while it works: progress bars and the first-run compile line.

* :func:`bar`: a rich progress bar on stderr, only on a terminal (never with ``--json`` on
  stdout's behalf, never in a pipe or a log), removed when done;
* :func:`compile_notice`: one line ``selfnav: compiling (first run only)…`` on stderr the
  first time numba compiles one of the package's kernels in this process (a cache miss:
  numba's on-disk cache then serves every later run, so the line appears on a first run, after
  an upgrade, or where the cache cannot be written). Printed above a live bar, not through it.
"""
from __future__ import annotations

import contextlib
import sys

#: the commands whose work runs numba kernels (the notice is installed only for them, so that
#: ``evaluate`` and ``--help`` do not import numba)
NUMBA_COMMANDS = ("allan", "demo", "latitude", "match", "montecarlo", "moving", "navigate",
                  "simulate")
COMPILE_LINE = "selfnav: compiling (first run only)…"

_console = None     # the console of the live bar, if any


def _print(line: str) -> None:
    if _console is not None:
        _console.print(line, markup=False, highlight=False)
    else:
        print(line, file=sys.stderr, flush=True)


@contextlib.contextmanager
def bar(description: str, enabled: bool = True):
    """A transient rich progress bar on stderr while the block runs; yields
    ``update(fraction, description=None)`` (a no-op when stderr is not a terminal)."""
    global _console
    if not (enabled and sys.stderr.isatty()):
        yield lambda fraction, description=None: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn(
            "{task.percentage:>3.0f} %"), TimeElapsedColumn(), transient=True,
            console=console) as prog:
        task = prog.add_task(description, total=1.0)
        old, _console = _console, console

        def update(fraction, description=None):
            kw = {} if description is None else {"description": description}
            prog.update(task, completed=float(fraction), **kw)

        try:
            yield update
        finally:
            _console = old


class _FirstCompile:
    """numba event listener: one line at the first compilation of a selfnav kernel whose
    results numba caches on disk (``cache=True``)."""

    def __init__(self):
        self.shown = False

    def __call__(self, event) -> None:
        if self.shown or not event.is_start:
            return
        disp = (event.data or {}).get("dispatcher")
        func = getattr(disp, "py_func", None)
        if func is None or not str(getattr(func, "__module__", "")).startswith("selfnav"):
            return
        if type(getattr(disp, "_cache", None)).__name__ == "NullCache":
            return          # not cached: compiling again next time is no "first run"
        self.shown = True
        _print(COMPILE_LINE)


@contextlib.contextmanager
def compile_notice(command: str | None):
    """Print :data:`COMPILE_LINE` once if numba compiles a package kernel during the block
    (for the commands of :data:`NUMBA_COMMANDS`)."""
    if command not in NUMBA_COMMANDS:
        yield
        return
    try:
        from numba.core import event
    except ImportError:     # pragma: no cover - numba is a dependency
        yield
        return

    class Listener(event.Listener):
        def __init__(self):
            self.first = _FirstCompile()

        def on_start(self, ev):
            self.first(ev)

        def on_end(self, ev):
            pass

    listener = Listener()
    event.register("numba:compile", listener)
    try:
        yield listener.first
    finally:
        event.unregister("numba:compile", listener)


def command_of(argv) -> str | None:
    """The sub-command named in ``argv`` (its first word that is not an option)."""
    for a in (sys.argv[1:] if argv is None else argv):
        a = str(a)
        if not a.startswith("-"):
            return a
    return None
