"""ribreg: skeleton-graph US–CT rib-cartilage registration, from Python.

The numpy API is the ``ribreg`` CLI's ``register`` with arrays::

    import ribreg
    template, labels = ribreg.read_cloud("template.ply")
    target, _ = ribreg.read_cloud("target.ply")
    reg = ribreg.register(template, target, labels)
    mapped = reg.transform(waypoints)      # (N, 3) float64, mm
    reg.report["metrics"]["ed_mean_mm"], reg.rigid  # report dict, 4 x 4 rigid part

A template prepared once (``ribreg.Template``, or ``ribreg template --prepared``) is
reused for every target. Bad input raises ``ValueError`` with the core's message; a file
the system cannot read raises ``OSError``. The robot PC's side of the controller's wire
protocol is ``ribreg.link`` (its failures raise ``ribreg.LinkError``, an ``OSError``); the
simulated robot, phantom and emulator of ``ribreg hil`` are ``ribreg.sim``.
"""

from ._ribreg import (
    LinkError,
    Registration,
    Template,
    __version__,
    read_cloud,
    read_waypoints,
    register,
)

__all__ = [
    "LinkError",
    "Registration",
    "Template",
    "__version__",
    "read_cloud",
    "read_waypoints",
    "register",
]
