"""The counter-based random streams of the `uvms.water` plugin, in Python (the C plugin's
``uvms_splitmix64``, waves.c): the Gauss-Markov current's normals (:mod:`uvms_mj.physics.reference`)
and the waves' frequency offsets, phases and directions (:mod:`uvms_mj.physics.waves`)."""

from __future__ import annotations

#: Unsigned 64-bit arithmetic: every result taken modulo 2^64.
MASK = (1 << 64) - 1


def splitmix64(z: int) -> int:
    """SplitMix64 finaliser on unsigned 64-bit integers (Steele, Lea & Flood 2014):

        z += 0x9E3779B97F4A7C15; z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EB; return z ^ (z >> 31)   (mod 2^64)
    """
    z = (z + 0x9E3779B97F4A7C15) & MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)
