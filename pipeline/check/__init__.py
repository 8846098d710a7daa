"""`ridgeloc check`: the flight config resolved against its data, and geometry checks that catch a wrong
convention before it becomes a wrong answer (geometry.py: where the lines of sight meet; conventions.py: the
common alternative conventions and the config lines that select them; flight.py: the checks of one flight)."""
