"""Tests of the controllers room (agents/controllers): the scripted baselines, mpc and residual policies."""
