"""`python -m graphloc` and the `graphloc` console script; a Ctrl-C while loading exits 130."""

import sys

from graphloc.exitcodes import INTERRUPTED


def run() -> int:
    try:
        from graphloc.cli import main
    except KeyboardInterrupt:
        print("graphloc: error: interrupted (Ctrl-C) while starting", file=sys.stderr)
        return INTERRUPTED
    return main()


if __name__ == "__main__":
    sys.exit(run())
