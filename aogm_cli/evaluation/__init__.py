"""Map quality, running no mapper: ``metrics`` against simulated truth, ``consistency`` of a map with its
own log, ``holdout`` scores on scans held out of its making, and what a ``planner`` sees in it."""
