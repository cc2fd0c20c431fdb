"""Tests that keep the documentation and its examples true."""
