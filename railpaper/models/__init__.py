"""Models: each paper's vehicle as matrices (single wheelset, 10-DOF vertical, 16-state lateral,
the papers' toys); they build matrices and never estimate."""
