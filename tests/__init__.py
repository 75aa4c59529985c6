"""The test-suite, grouped by package area: core/ (physics core), envs/ (task, envs and the SB3
adapter), agents/ and scripts/ (the examples and benchmarks run end to end). Shared helpers are in
helpers.py, the hypothesis profiles in conftest.py."""
