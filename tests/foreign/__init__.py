"""An outside user's team logs for graphloc, written from ``docs/log_format.md`` alone.

Nothing in this package imports graphloc or reads its source: ``team_generator`` writes log
directories as a new user would from the documentation, and ``score`` judges graphloc's TUM
outputs against the generator's ground truth (issue 48).
"""
