"""The ``selfnav`` command: parses, calls the library, formats (DESIGN §6).

Each sub-command lives in a module ``selfnav/cli/cmd_<name>.py`` with a ``register(app)``
function; they are discovered here so that adding a command touches no shared file. Options
shared by several commands are defined once in :mod:`selfnav.cli.options`.

What the user sees besides the results, whatever the command:

* a bad input or argument: one line ``selfnav: error: ...`` on stderr, exit 2;
* something worth knowing: one line ``selfnav: warning: ...`` per
  :class:`~selfnav.errors.SelfnavWarning` (other libraries' warnings are not shown);
* Ctrl-C: one line ``selfnav: interrupted``, exit 130, outputs left as they were;
* numba compiling the package's kernels (a first run): one line ``selfnav: compiling (first
  run only)…`` (:mod:`selfnav.cli.progress`), and progress bars on a terminal.
"""
from __future__ import annotations

import contextlib
import importlib
import os
import pkgutil
import signal
import sys
import threading
import warnings

import typer
import typer.core

from selfnav.errors import Interrupted, SelfnavError, SelfnavWarning, interrupt_requested

app = typer.Typer(
    name="selfnav",
    help="Navigation without (or despite) satellite signals.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version(value: bool):
    if value:
        from selfnav import __version__

        print(f"selfnav {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")):
    """Navigation without (or despite) satellite signals."""


def _register_all() -> None:
    import selfnav.cli as pkg
    from selfnav.cli.options import GroupedCommand

    for mod in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if mod.name.startswith("cmd_"):
            importlib.import_module(f"selfnav.cli.{mod.name}").register(app)
    for info in app.registered_commands:   # --help in panels (options.HELP_PANELS)
        if info.cls is None or info.cls is typer.core.TyperCommand:
            info.cls = GroupedCommand


_register_all()


@contextlib.contextmanager
def _one_line_warnings():
    """Show each distinct :class:`SelfnavWarning` once as ``selfnav: warning: <msg>``; hide the
    warnings of other libraries (numpy's RuntimeWarnings are symptoms the one-line errors and
    warnings already explain). ``SELFNAV_DEBUG=1`` shows them, one line each."""
    shown = set()
    debug = bool(os.environ.get("SELFNAV_DEBUG"))

    def show(message, category, filename, lineno, file=None, line=None):
        mine = issubclass(category, SelfnavWarning)
        if not (mine or debug):
            return
        text = " ".join(str(message).split())
        if not mine:
            text = f"{category.__name__} in {os.path.basename(filename)}:{lineno}: {text}"
        if text not in shown:
            shown.add(text)
            print(f"selfnav: warning: {text}", file=sys.stderr, flush=True)

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = show
        yield


@contextlib.contextmanager
def _interrupt_as_error(last: bool = False):
    """Ctrl-C raises :class:`Interrupted` (typer would turn ``KeyboardInterrupt`` into a plain
    exit code, and libraries catch it). ``last``: the process ends after this command, so a
    Ctrl-C that comes after the work is done is ignored rather than left to kill the process
    on its way out (exit by signal, no line)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        interrupt_requested.set()
        raise Interrupted()

    interrupt_requested.clear()
    old = signal.signal(signal.SIGINT, handler)
    try:
        yield
    except Exception as e:
        # a Ctrl-C that lands inside a C extension's module initialisation comes back as
        # "ImportError: initialization failed" (pybind11), or wrapped by a library: it is
        # still the user's Ctrl-C, not a crash
        if interrupt_requested.is_set() and not isinstance(e, (Interrupted, SelfnavError)):
            raise Interrupted() from e
        raise
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN if last else old)
        interrupt_requested.clear()


def _usage_line(e) -> str:
    ctx = getattr(e, "ctx", None)
    hint = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    msg = " ".join(str(e.format_message()).split())
    return f"selfnav: error: {msg}{hint}"


def _run(argv) -> int:
    from selfnav.cli.progress import command_of, compile_notice

    try:
        with _interrupt_as_error(last=argv is None), _one_line_warnings(), \
                compile_notice(command_of(argv)):
            rv = app(args=argv, standalone_mode=False, prog_name="selfnav")
        code = int(rv) if isinstance(rv, int) else 0
        if code == 130:  # typer's answer to a KeyboardInterrupt it caught
            print("selfnav: interrupted", file=sys.stderr)
        return code
    except SelfnavError as e:
        print(f"selfnav: error: {' '.join(str(e).split())}", file=sys.stderr)
        return e.exit_code
    except (Interrupted, KeyboardInterrupt):
        print("selfnav: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `selfnav ... | head`: the reader went away
        with contextlib.suppress(Exception):
            sys.stdout = open(os.devnull, "w")
        return 0
    except Exception as e:
        # typer's (vendored or not) click exceptions, recognised by what they offer
        kind = type(e).__name__
        if kind == "Exit":
            return e.exit_code
        if kind == "Abort":
            print("selfnav: interrupted", file=sys.stderr)
            return 130
        if hasattr(e, "format_message") and hasattr(e, "exit_code"):  # usage errors
            print(_usage_line(e), file=sys.stderr)
            return e.exit_code
        raise


def main(argv=None) -> int:
    """Entry point: user errors become one line on stderr and exit code 2, no traceback."""
    code = _run(argv)
    if argv is None:
        sys.exit(code)
    return code
