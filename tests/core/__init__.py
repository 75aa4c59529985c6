"""Tests of the physics core: clusters, the integrator, the critical step, frames, snapshots."""
