"""Reports over finished maps: ``compare`` (map, evaluate, JSON), ``gates`` (--require
expressions), ``figure`` (the paper-style comparison PNG).
"""
