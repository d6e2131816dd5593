"""The study's model's (darr-niazi) files: its run directory and its pictures."""
