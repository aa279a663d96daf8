"""Exceptions raised by socialcam.

- ``ValueError``: malformed input (shape, NaN, non-unit vector, ...), naming the argument.
- :class:`DegenerateError` (a ``ValueError``): well-formed input that is geometrically
  degenerate — rank deficiency (thesis Theorem 2), parallel rays, too few observations.
- :class:`ConvergenceError` (a ``RuntimeError``): an iterative solver hit its iteration
  cap. Only raised when the caller passes ``strict=True`` (:func:`socialcam.triangulate`,
  :func:`socialcam.reconstruct_trajectory`, :func:`socialcam.reconstruct_trajectories`,
  :meth:`socialcam.GazeField.fit`); otherwise results carry ``converged=False``.
"""

from socialcam._core import ConvergenceError, DegenerateError

__all__ = ["ConvergenceError", "DegenerateError"]
