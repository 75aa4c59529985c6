"""The CUDA side of :mod:`tether_gym.portable`, imported only when a GPU run is asked for.

A module of its own because numba's CUDA simulator swaps the ``cuda`` module a kernel reaches
through its globals for its own: the kernel must name ``cuda`` as a module-level global.
"""

from __future__ import annotations

from numba import cuda

from tether_gym.portable import build_kernels

_advance_cluster = build_kernels(cuda.jit(device=True))


@cuda.jit
def advance(  # type: ignore[no-untyped-def]
    duration, safety_factor, max_step, topology, x, v, f_int, f_applied, f_previous, mass, damping,
    rest, stiffness, pretension, inverse_mass_sum, last_step, omega2, substeps,
):  # fmt: skip
    """One thread per cluster: :func:`tether_gym.portable.build_kernels`'s advance."""
    b = cuda.grid(1)
    if b < x.shape[2]:
        _advance_cluster(
            b, duration, safety_factor, max_step, topology, x, v, f_int, f_applied, f_previous, mass, damping,
            rest, stiffness, pretension, inverse_mass_sum, last_step, omega2, substeps,
        )  # fmt: skip
