"""Reproductions and benchmarks, beside the installed package (not part of it): each module
holds the trials, summaries and plots of one benchmark or seed reproduction, the seeds' own
algorithms are `baselines`; scripts/ are thin callers. Run from the checkout: the scripts put it
on sys.path, the tests get it from pytest's `pythonpath`; nothing installed imports it."""

# the seed tables scripts/reproduce.py knows (benchmarks.reproduce computes them)
TABLES = ("seed000-table1", "seed000-table2", "seed000-table3", "seed004-table1", "seed001-exp1")
