"""Training the cluster detector: labels from simulation truth (``labels``), the MLP fit with
scikit-learn (``fit``) and its configuration (``config``). Runs no mapper (the standard map its
labels need is passed in); mapping never imports training."""
