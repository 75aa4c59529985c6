"""Tests of the task, the single and vector envs and the SB3 adapter."""
