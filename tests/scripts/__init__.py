"""The examples and benchmarks, run end to end."""
