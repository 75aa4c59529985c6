"""Tests of the agents: baselines, training, shipping, comparison and the benchmark."""
