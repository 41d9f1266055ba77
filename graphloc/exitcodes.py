"""The exit codes of every `graphloc` verb (docs/outputs.md, "Exit codes")."""

from __future__ import annotations

OK = 0  # done: every output written
FAILED = 1  # the input was fine but the work failed: an OS error (disk full, permissions), a
#            solver or Open3D runtime error; one `error:` line names what failed
BAD_INPUT = 2  # bad input or usage (argparse's code too): one `error:` line naming file, line
#               and field, or the option
INCOMPLETE = 3  # no trustworthy full answer, said so: smooth / online stopped by SIGINT /
#                SIGTERM (partial outputs, metrics.json "partial": true), fuse-maps not fused
#                (a report of every candidate and why it lost, no map)
RUNS_FAILED = 4  # smooth / online over many runs: at least one run failed (runs.csv says why)
INCONSISTENT = 5  # smooth / online --strict: every output written, but the solve failed its
#                  consistency test or raised a warning (metrics.json "consistency" says which)
INTERRUPTED = 130  # a second Ctrl-C, or Ctrl-C in a verb that cannot stop cleanly (128 + SIGINT)

CODES = {
    OK: "ok",
    FAILED: "failed",
    BAD_INPUT: "bad input or usage",
    INCOMPLETE: "stopped or not fused",
    RUNS_FAILED: "some runs failed",
    INCONSISTENT: "inconsistent or incomplete solve (--strict)",
    INTERRUPTED: "interrupted",
}


class SolverFailure(ValueError):
    """The input was read but GTSAM could not solve it (an indeterminate or ill-conditioned
    system): FAILED, not BAD_INPUT. A ValueError, so that callers that try another start or
    drop a hypothesis on a failed solve (`team_graph.solve`) still catch it."""


class OutputDropped(BaseException):
    """A stop signal arrived while an output that may be left out was being written (a figure,
    seconds to draw on a long run): the writer drops that output and lists it as skipped
    (`pipelines.report.write_outputs`). A BaseException, as KeyboardInterrupt, so that no
    `except Exception` of the drawing library swallows it."""
