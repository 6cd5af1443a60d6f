"""The one small error hierarchy of hamsa, and its warnings.

Every error a user can cause with bad input is a :class:`HamsaError` (a ``ValueError``), so a
script can catch them all at once, and the command-line tool turns them into one line on stderr
and exit code 2 — except :class:`ConvergenceError`, a solver failure rather than bad input (exit 3).
"""

from __future__ import annotations


class HamsaError(ValueError):
    """Base class of every error hamsa raises for bad input or an impossible request."""


class MeshError(HamsaError):
    """A mesh is malformed (bad shapes, indices, degenerate or non-manifold faces) or unreadable."""


class PotentialError(HamsaError):
    """A potential has the wrong length, is not finite, or does not fit the mesh."""


class SolverError(HamsaError):
    """An eigenproblem request is impossible (k out of range, a matrix that is not positive definite)."""


class CompressionError(HamsaError):
    """A compressed file is corrupted, truncated, of another version, or does not fit the faces."""


class FileAccessError(HamsaError):
    """A file cannot be read or written safely: missing, not a regular file, beyond the read limit, an
    array whose header does not match what is expected, or an output that would replace an input."""


class ConvergenceError(SolverError, RuntimeError):
    """An iterative solver did not converge within its bounded effort; the message says what was tried.

    Not bad input: the command-line tool reports it with its own exit code (3)."""


class MissingDependencyError(HamsaError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


class RepairWarning(UserWarning):
    """A mesh was changed by an explicit ``repair=True`` request; the message says what changed."""


class InputWarning(UserWarning):
    """An input is valid but likely to give a misleading result (e.g. stray points in a cloud); the message
    says why and what removes the cause."""


class ResourceError(HamsaError, MemoryError):
    """A request would not fit in this machine's memory; the message says how much it needs."""


class ConvergenceWarning(UserWarning):
    """An iterative method stopped at its iteration cap before reaching its tolerance."""


class PerformanceNotice(UserWarning):
    """A faster optional backend is not installed; results are the same, only slower."""
