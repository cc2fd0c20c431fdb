"""Simulated OpenEL devices (placeholder until the core lands)."""
