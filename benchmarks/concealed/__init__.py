"""Concealed-effect benchmark generator (see README.md)."""
