"""Pipeline: papermill runs, outputs, progress, claims and ledger, tolerances and bands, book
build, sweeps."""
