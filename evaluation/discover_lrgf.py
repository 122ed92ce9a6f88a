"""Deprecated location, kept for one release: use :mod:`evaluation.discover.lrgf`."""

from evaluation.discover.lrgf import LRGFModel

__all__ = ["LRGFModel"]
