"""Device layer package."""
