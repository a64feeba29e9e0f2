"""Training the cluster detector: labels from simulation truth (``labels``), the MLP fit with
scikit-learn (``fit``) and its configuration (``config``). May import mapping; mapping never
imports training.
"""
