"""Demonstration generators, one module per domain."""
