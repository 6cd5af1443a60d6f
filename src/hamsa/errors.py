"""The one small error hierarchy of hamsa, and its warnings.

Every error a user can cause with bad input is a :class:`HamsaError` (a ``ValueError``), so a
script can catch them all at once, and the command-line tool turns them into one line on stderr
and exit code 2.
"""

from __future__ import annotations


class HamsaError(ValueError):
    """Base class of every error hamsa raises for bad input or an impossible request."""


class MeshError(HamsaError):
    """A mesh is malformed (bad shapes, indices, degenerate or non-manifold faces) or unreadable."""


class PotentialError(HamsaError):
    """A potential has the wrong length, is not finite, or does not fit the mesh."""


class SolverError(HamsaError):
    """An eigenproblem request is impossible (k out of range) or the solver did not converge."""


class CompressionError(HamsaError):
    """A compressed file is corrupted, truncated, of another version, or does not fit the faces."""


class MissingDependencyError(HamsaError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


class RepairWarning(UserWarning):
    """A mesh was changed by an explicit ``repair=True`` request; the message says what changed."""


class ResourceError(HamsaError, MemoryError):
    """A request would not fit in this machine's memory; the message says how much it needs."""


class ConvergenceWarning(UserWarning):
    """An iterative method stopped at its iteration cap before reaching its tolerance."""


class PerformanceNotice(UserWarning):
    """A faster optional backend is not installed; results are the same, only slower."""
