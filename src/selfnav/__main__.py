"""``python -m selfnav`` and the ``selfnav`` command.

The command-line stack takes a second or more to import on a loaded machine; a Ctrl-C in that
second is the same one line and exit code 130 as later (not a traceback, not a death by
SIGINT).
"""
import sys


def run():
    try:
        from selfnav.cli import main

        return main()
    except KeyboardInterrupt:
        print("selfnav: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(run())
