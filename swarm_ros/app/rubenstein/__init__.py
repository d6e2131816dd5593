"""The rubenstein algorithm at the command line: the summary a run prints, and its row in the study's
results.csv."""
