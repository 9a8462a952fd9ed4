"""Domain packages: the ``hrlp.domains`` entry point, through which a domain (the arm, Fetch) registers its skill-file
formats, shipped skills and named observation parts without the generic core importing it."""

from __future__ import annotations

import functools
import importlib.metadata

#: The entry-point group of domain packages (``pyproject.toml``).
DOMAINS_GROUP = "hrlp.domains"


@functools.cache
def load_domains() -> None:
    """Import every package registered under :data:`DOMAINS_GROUP` once, so that they register what they declare.
    A domain whose optional dependencies are missing declares facts only (numbers and names), so importing it never
    needs them."""
    for point in importlib.metadata.entry_points(group=DOMAINS_GROUP):
        point.load()
