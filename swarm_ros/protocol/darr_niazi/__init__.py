"""The study's model's (darr-niazi) parts of the graph's protocol that have a counterpart in another algorithm's."""
