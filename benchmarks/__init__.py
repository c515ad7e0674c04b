"""Benchmarks: python -m benchmarks (docs/performance.md)."""
