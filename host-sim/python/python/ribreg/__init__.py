"""ribreg: skeleton-graph US–CT rib-cartilage registration, from Python.

The numpy API is the ``ribreg`` CLI's ``register`` with arrays::

    import ribreg
    template, labels = ribreg.read_cloud("template.ply")
    target, _ = ribreg.read_cloud("target.ply")
    planned, _ = ribreg.read_waypoints("plan.mrk.json")
    reg = ribreg.register(template, target, labels, waypoints=planned)
    reg.waypoints                          # (M, 3) float64, mm: where to drive the probe
    reg.report["metrics"]["ed_mean_mm"], reg.rigid  # report dict, 4 x 4 rigid part

Waypoints given to ``register`` are checked against what the sweep shows, as the CLI
checks them: a registration that cannot support every one raises
``ribreg.RegistrationError`` (a ``ValueError``; ``code`` is the core's error code,
``ribreg.error_summary(code)`` says what it means), and so does any other registration
the core refuses (a rib side not seen, an ambiguous pose). With ``partial=True`` the
waypoints the sweep does not reach are marked ``False`` in ``reg.supported`` instead;
never drive to those. ``reg.transform(points)`` maps any other points and checks none.

A template prepared once (``ribreg.Template``, or ``ribreg template --prepared``) is
reused for every target. Bad input raises ``ValueError`` with the core's message; a file
the system cannot read raises ``OSError``. The robot PC's side of the controller's wire
protocol is ``ribreg.link`` (its failures raise ``ribreg.LinkError``, an ``OSError``); the
simulated robot, phantom and emulator of ``ribreg hil`` are ``ribreg.sim``.
"""

from ._ribreg import (
    LinkError,
    Registration,
    RegistrationError,
    Template,
    __version__,
    error_summary,
    read_cloud,
    read_waypoints,
    register,
)

__all__ = [
    "LinkError",
    "Registration",
    "RegistrationError",
    "Template",
    "__version__",
    "error_summary",
    "read_cloud",
    "read_waypoints",
    "register",
]
