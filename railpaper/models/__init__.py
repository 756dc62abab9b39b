"""Models: build matrices / estimate from matrices (never from vehicles)."""
