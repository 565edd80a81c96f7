"""Type stubs of the ``ribreg._ribreg`` extension module (see ``host-sim/python/src``)."""

from os import PathLike
from typing import Any, Optional, Sequence, Union, final

import numpy as np
import numpy.typing as npt

__version__: str
__all__ = ["__version__", "Template", "Registration", "register", "read_cloud", "read_waypoints"]

_Points = npt.ArrayLike  # (N, 3), any real dtype, any memory order
_Path = Union[str, PathLike[str]]

@final
class Template:
    """A template prepared once and reused; the format of ``ribreg template --prepared``."""

    def __new__(cls, points: _Points, labels: npt.ArrayLike) -> "Template":
        """Prepares a template from a labelled cloud (1 = sternum, 2..5 = rib)."""
    @staticmethod
    def load(path: _Path) -> "Template":
        """A prepared template file as it is, or a labelled cloud prepared now."""
    def save(self, path: _Path) -> None:
        """Writes the prepared template (binary PLY)."""
    @property
    def points(self) -> npt.NDArray[np.float64]:
        """The template cloud, (N, 3), mm."""
    @property
    def labels(self) -> npt.NDArray[np.int32]:
        """Its labels, (N,)."""
    @property
    def skeleton(self) -> npt.NDArray[np.float64]:
        """The 30 skeleton points, (30, 3), mm."""
    def __len__(self) -> int: ...

@final
class Registration:
    """The non-rigid mapping template -> target found by ``register``."""

    def transform(self, points: _Points) -> npt.NDArray[np.float64]:
        """Maps (N, 3) points from the template into the target."""
    @property
    def registered(self) -> npt.NDArray[np.float64]:
        """The template's points mapped into the target, (N, 3)."""
    @property
    def report(self) -> dict[str, Any]:
        """The report of ``ribreg register --report`` (skeleton, rigid part, ED/HD, timings)."""
    @property
    def rigid(self) -> npt.NDArray[np.float64]:
        """The rigid part, template -> target, 4 x 4."""

def register(
    template: Union[_Points, Template],
    target: _Points,
    labels: Optional[npt.ArrayLike] = None,
    *,
    method: str = "improved",
    prepared: Optional[Template] = None,
) -> Registration:
    """Registers the template onto the target (``method``: "improved" or "paper")."""

def read_cloud(
    path: _Path,
) -> tuple[npt.NDArray[np.float64], Optional[npt.NDArray[np.int32]]]:
    """(points, labels or None) of a PLY, PCD, XYZ or CSV cloud."""

def read_waypoints(path: _Path) -> tuple[npt.NDArray[np.float64], Sequence[str]]:
    """(points, labels) of a CSV, ``.mrk.json`` or ``.fcsv`` waypoint file."""
