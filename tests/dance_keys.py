"""The keys of `play.metrics.dance_metrics`'s result and of each front paw's entry in it,
which `dance`'s ``metrics.json`` and `eval`'s report items carry too: one list for the tests
that check them."""

DANCE_METRIC_KEYS = frozenset(
    {
        "duration_s",
        "falls_s",
        "front",
        "rear_lift_mean_m",
        "rear_lift_max_m",
        "bas",
        "realtime_factor_sim",
        "realtime_factor_render",
    }
)

DANCE_FOOT_KEYS = frozenset({"mae_m", "mae_feasible_m", "corr", "corr_feasible"})
"""The keys of each front paw's entry under ``front``."""
