"""The simulation: ray casting against a world's compiled scene (``raycast``) and the sonar simulator
that turns a world into a log with its truth (``sonar``), with a real robot's errors."""
