"""Memory checks before large allocations: a clear error instead of swapping or the OOM killer."""

from __future__ import annotations

from hamsa.errors import ResourceError


def available_memory() -> int | None:
    """Bytes of memory available to new allocations (Linux ``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def require_memory(nbytes: float, what: str, fraction: float = 0.9) -> None:
    """Raise ResourceError if ``nbytes`` exceed ``fraction`` of the available memory (no-op when unknown)."""
    available = available_memory()
    if available is not None and nbytes > fraction * available:
        raise ResourceError(
            f"{what} needs about {nbytes / 1e9:.1f} GB but only {available / 1e9:.1f} GB of memory are available"
        )
