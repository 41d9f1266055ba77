"""The one route from a source to its outputs (`team_run.run_team`), above the datasets and the
pipelines it joins; the command line and the API call it."""
