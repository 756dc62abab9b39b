"""Pipeline: papermill runs, outputs, tolerances, book build."""
