"""Reports over logs and finished maps: ``compare`` (map, evaluate, JSON), ``gates`` (--require
expressions), ``figure`` and ``picture`` (PNGs), ``log_check`` (what a log holds before mapping)."""
