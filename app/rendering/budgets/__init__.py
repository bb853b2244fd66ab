"""Time budgets: per dispatch, per frame, sample bands, per-device defaults, the measured ceiling."""
