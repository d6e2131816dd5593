"""The rubenstein algorithm's files: its recording and its run directory."""
