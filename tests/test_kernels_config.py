"""The options every hand-written kernel is compiled with (mcchain.kernels.config)."""

from __future__ import annotations


def test_njit__a_kernel_called_with_constants_compiles_once_per_type() -> None:
    """A helper called from a kernel with the constants 0, 1 and 2 and with a variable compiles
    one ``int64`` version (numba alone would compile four: one per literal value), and gives
    the values of each call."""
    from mcchain.kernels.config import JIT, njit

    @njit(**dict(JIT, cache=False))
    def scaled(x, k):
        return x * k + (1.0 if k == 0 else 0.0)

    @njit(**dict(JIT, cache=False))
    def caller(x, n):
        return scaled(x, 0), scaled(x, 1), scaled(x, 2), scaled(x, n)

    assert caller(1.5, 3) == (1.0, 1.5, 3.0, 4.5)
    assert [str(s) for s in scaled.signatures] == ["(float64, int64)"]
