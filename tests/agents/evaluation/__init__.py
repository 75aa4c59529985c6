"""Tests of the evaluation room (agents/evaluation): rollouts, statistics, the benchmark and scoring."""
