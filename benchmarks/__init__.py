"""Benchmark scripts (importable as a package for benchmarks.concealed)."""
