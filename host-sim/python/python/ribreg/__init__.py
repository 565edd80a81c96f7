"""ribreg: skeleton-graph US–CT rib-cartilage registration."""
from ._ribreg import __version__

__all__ = ["__version__"]
