"""Compatibility: writing FRF sets by suffix is :func:`guidefit.io.write_frfs`."""

from guidefit.io.registry import write_frfs

__all__ = ["write_frfs"]
