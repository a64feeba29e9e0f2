"""The names of the scores ``aogm compare`` reports of a map (CONTRACT.md, Metrics): evaluation
computes them, the results file (``io.results``) stores and checks them, the table, the CSV and
the gates (``report``) name them.
"""

METRIC_KEYS = ("accuracy", "occupied_precision", "occupied_recall", "occupied_f1", "brier", "ece")  # against the truth
LATER_METRIC_KEYS = ("ece",)  # of METRIC_KEYS, those a --json file written before ECE lacks
TRUTH_KEYS = ("leak", "block", "surface_recall")  # what a planner sees, against a simulated log's truth
STANDARD_KEYS = ("walls_kept", "leak_vs_standard", "far_leak")  # what a planner sees, against the standard map (no truth)
PLANNER_KEYS = (*TRUTH_KEYS, *STANDARD_KEYS)  # ``evaluation.planner``: with truth the first, without the others
CONSISTENCY_KEYS = ("method", "readings", "endpoint_occupied", "endpoint_occupied_8", "endpoint_free", "free_cells",
                    "free_contradicted")  # ``evaluation.consistency.summarize``: a log without truth
SCORE_KEYS = ("holdout_auc", "holdout_auc_band", "holdout_loglik", "holdout_readings", "holdout_scans")  # ``evaluation.holdout``
# ``mapping.calibration.model_values``: stats["calibration"]["final"]
LEARNED_KEYS = ("sigma", "p_rand", "p_hit", "p_max")
