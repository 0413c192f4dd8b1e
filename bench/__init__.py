"""Benchmarks: `make bench` runs bench/run_bench.py."""
