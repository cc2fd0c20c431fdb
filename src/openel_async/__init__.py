"""openel-async."""
