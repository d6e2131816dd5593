"""The study's model (the darr-niazi algorithm) at the command line: the summary a run prints."""
