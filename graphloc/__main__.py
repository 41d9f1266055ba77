"""`python -m graphloc` and the `graphloc` console script (`run`): the command line of
`graphloc.cli`, imported inside `run` so that a Ctrl-C while it loads ends with exit code 130
and one line rather than Python's traceback."""

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
