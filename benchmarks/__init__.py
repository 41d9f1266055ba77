"""Experiment drivers behind scripts/ and `graphloc reproduce`: each module holds the trials,
summaries and plots of one benchmark or seed reproduction, so the script in scripts/ and the
CLI verb are thin callers of the same code (works from an installed package, not only a
source checkout)."""

# the seed tables `graphloc reproduce` knows (benchmarks.reproduce computes them);
# kept here, free of imports, so that the CLI lists them without loading the experiments
TABLES = ("seed000-table1", "seed000-table2", "seed000-table3", "seed004-table1", "seed001-exp1")
