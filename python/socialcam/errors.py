"""Exceptions raised by socialcam.

- ``ValueError``: malformed input (shape, NaN, non-unit vector, ...), naming the argument.
- :class:`DegenerateError` (a ``ValueError``): well-formed input that is geometrically
  degenerate — rank deficiency (thesis Theorem 2), parallel rays, too few observations.
- :class:`ConvergenceError` (a ``RuntimeError``): only raised when a caller asks for
  strictness; otherwise results carry ``converged=False``.
"""

from socialcam._core import ConvergenceError, DegenerateError

__all__ = ["ConvergenceError", "DegenerateError"]
