"""The rubenstein algorithm's rows between its graph's nodes, their checks, its lockstep and its checkpoint."""
