"""Numbers about a built dataset: the audit's checks and statistics, the PnP evaluation, Ultralytics' own view."""
