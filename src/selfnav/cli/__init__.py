"""The ``selfnav`` command: parses, calls the library, formats (DESIGN §6).

Each sub-command lives in a module ``selfnav/cli/cmd_<name>.py`` with a ``register(app)``
function; they are discovered here so that adding a command touches no shared file.
"""
from __future__ import annotations

import importlib
import pkgutil
import sys

import typer

from selfnav.errors import SelfnavError

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

    for mod in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if mod.name.startswith("cmd_"):
            importlib.import_module(f"selfnav.cli.{mod.name}").register(app)


_register_all()


def main(argv=None) -> int:
    """Entry point: user errors become one line on stderr and exit code 2, no traceback."""
    try:
        rv = app(args=argv, standalone_mode=False)
        return int(rv or 0)
    except SelfnavError as e:
        print(f"selfnav: error: {e}", file=sys.stderr)
        code = e.exit_code
    except KeyboardInterrupt:
        print("selfnav: interrupted", file=sys.stderr)
        code = 130
    except Exception as e:
        # typer's (vendored or not) click exceptions, recognised by what they offer
        kind = type(e).__name__
        if kind == "Exit":
            code = e.exit_code
        elif kind == "Abort":
            print("selfnav: aborted", file=sys.stderr)
            code = 130
        elif hasattr(e, "show") and hasattr(e, "exit_code"):  # usage errors, bad parameters
            e.show()
            code = e.exit_code
        else:
            raise
    if argv is None:
        sys.exit(code)
    return code
