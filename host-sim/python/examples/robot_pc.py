#!/usr/bin/env python3
"""The robot PC's whole procedure against the ribreg controller, in Python: the twin of
``ribreg hil`` (``host-sim/src/hil/procedure.rs``), with the same result.

Handshake, configure, upload the prepared template and the waypoints, stream a
simulated sweep's poses and frames, register, follow the setpoints with the simulated
robot, and report the probe error per waypoint (the probe's aim point when the
controller moved on, against the phantom's truth)::

    python robot_pc.py --in-process --quick --seed 0
    python robot_pc.py --port 127.0.0.1:4321 --quick     # the emulator's UART, a board
    python robot_pc.py --port /dev/ttyUSB0 --baud 115200
    python robot_pc.py --in-process --quick --faults      # link faults injected

``--in-process`` runs the core's controller in this process on a simulated clock: the
run is deterministic and equals ``ribreg hil --in-process`` with the same options bit
for bit. Exit status 0 when every waypoint is within tolerance and every message was
applied exactly once, 1 otherwise, 2 on a link failure.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from ribreg import error_summary
from ribreg.link import (
    Command,
    CommandKind,
    Cost,
    Fault,
    FaultKind,
    LinkError,
    Pose,
    Session,
    Setpoint,
    State,
    Status,
    Waypoint,
)
from ribreg.sim import TOLERANCE_MM, Scenario

#: How long each stage may take, s (as ``ribreg hil``).
TIMEOUT_S = 120.0


def run(session: Session, scenario: Scenario, progress: Callable[[str], None]) -> Dict[str, Any]:
    """Runs the whole procedure on ``scenario`` through ``session``; returns the report
    (the fields of ``ribreg hil --json`` but the controller's costs and wall time in
    their own keys). Raises :class:`LinkError` when a stage does not complete."""
    t0 = time.monotonic()
    progress(f"temporal calibration: lag {scenario.lag_ms:.1f} ms")

    # Handshake and upload.
    ack = session.handshake(TIMEOUT_S)
    progress(f"controller: protocol {ack.version}, frames up to {ack.max_frame} bytes")
    for upload in scenario.upload():
        session.send(upload)
    session.flush(TIMEOUT_S)
    progress(f"template uploaded: {scenario.nodes} nodes, {scenario.waypoints} waypoints")

    # Sweep: the controller's clock follows the poses' time stamps, 10 ms at a time.
    session.send(Command(CommandKind.START_SWEEP))
    msgs = scenario.sweep_messages()
    n_poses = sum(1 for s in msgs if isinstance(s, Pose))
    n_frames = len(msgs) - n_poses
    last_t = 0
    for i, sent in enumerate(msgs):
        if isinstance(sent, Pose) and sent.t_us >= last_t + 10_000:
            session.advance(min(max(sent.t_us - last_t, 0), 10_000))
            last_t = sent.t_us
        session.send(sent)
        session.pump(0.0)
        if i % 20_000 == 0:
            progress(f"sweep: {i} of {len(msgs)} messages")
    session.send(Command(CommandKind.END_SWEEP))
    session.flush(TIMEOUT_S)

    # Register: the robot stands still and keeps reporting its pose at 100 Hz.
    robot = scenario.robot()
    robot_t_us = int(scenario.sweep_end_s * 1e6) + 10_000
    poses_sent = n_poses
    session.send(Command(CommandKind.REGISTER))
    mapped: List[Waypoint] = []
    start = time.monotonic()
    while len(mapped) < scenario.waypoints:
        if time.monotonic() - start > TIMEOUT_S:
            raise LinkError("registration did not finish in time")
        session.send(robot.pose(robot_t_us))
        poses_sent += 1
        robot_t_us += 10_000
        session.advance(10_000)
        session.pump(0.002)
        while (m := session.next_message()) is not None:
            if isinstance(m, Waypoint):
                mapped.append(m)
            elif isinstance(m, Fault):
                raise LinkError(f"controller fault: {m}")
    mapped.sort(key=lambda w: w.index)
    progress(f"registered: {len(mapped)} waypoints mapped")

    # Execute: the robot answers every setpoint (moves 10 ms toward it, then reports);
    # where it aims when the controller moves on to the next waypoint is the outcome.
    session.send(Command(CommandKind.EXECUTE))
    robot.start_executing()
    current: Optional[int] = None
    reached: List[Optional[Tuple[float, float, float]]] = [None] * scenario.waypoints
    start = time.monotonic()
    last_report = time.monotonic()
    done = False
    quiet_ticks = 0
    pose_timeouts = 0
    tick_us = 10_000 if session.simulated_clock else 2_000
    # A refused pose report stops the setpoints for good: say which, as `ribreg hil` does.
    refused_before = len(session.refused)
    while not done:
        refused = session.refused
        if len(refused) > refused_before:
            seq, code, detail = refused[refused_before]
            what = (
                code.value
                if detail is None
                else f"content refused: {error_summary(detail)} (error code {detail})"
            )
            raise LinkError(f"the controller refused message {seq} while executing: {what}")
        if time.monotonic() - start > TIMEOUT_S:
            raise LinkError("execution did not finish in time")
        session.advance(tick_us)
        session.pump(0.002)
        setpoints: List[Setpoint] = []
        while (m := session.next_message()) is not None:
            if isinstance(m, Setpoint):
                setpoints.append(m)
            elif isinstance(m, Status) and m.state == State.DONE:
                done = True
            elif isinstance(m, Fault) and m.kind == FaultKind.POSE_TIMEOUT:
                pose_timeouts += 1
                progress("controller: robot poses stopped, setpoints stopped")
            elif isinstance(m, Fault):
                progress(f"controller fault: {m}")
        for sp in setpoints:
            if current is not None and current != sp.waypoint:
                reached[current] = robot.aim_point()
            current = sp.waypoint
            robot.follow(sp)
        # Besides answering setpoints, a real robot reports at 100 Hz of its own clock.
        due = session.simulated_clock or time.monotonic() - last_report >= 0.010
        if setpoints or due:
            robot.update_flange()
            session.send(robot.pose(robot_t_us))
            poses_sent += 1
            last_report = time.monotonic()
            robot_t_us += 10_000
        quiet_ticks = 0 if setpoints else quiet_ticks + 1
        if quiet_ticks > 50:
            session.send(Command(CommandKind.STATUS))
            quiet_ticks = 0
    if current is not None and reached[current] is None:
        reached[current] = robot.aim_point()

    # Final status and costs.
    session.send(Command(CommandKind.STATUS))
    session.send(Command(CommandKind.COST))
    session.flush(TIMEOUT_S)
    status: Optional[Status] = None
    cost: Optional[Cost] = None
    for _ in range(400):
        session.advance(1000)
        session.pump(0.005)
        while (m := session.next_message()) is not None:
            if isinstance(m, Status):
                status = m
            elif isinstance(m, Cost):
                cost = m
        if status is not None and cost is not None:
            break
    if status is None:
        raise LinkError("no final status")

    waypoints = []
    for w, aim, truth in zip(mapped, reached, scenario.true_waypoints):
        aim = aim if aim is not None else (math.nan,) * 3
        d = [a - t for a, t in zip(aim, truth)]
        waypoints.append({
            "mapped": list(w.position),
            "quality_mm": w.quality_mm,
            "supported": w.supported,
            "reached": list(aim),
            "truth": list(truth),
            "error_mm": math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]),
        })
    stats = session.stats
    return {
        "waypoints": waypoints,
        "link": vars(stats),
        "applied": [status.poses, status.frames_placed + status.frames_refused,
                    poses_sent, n_frames],
        "refused": [f"{seq}: {code.value}" + ("" if d is None else f"({d})")
                    for seq, code, d in session.refused],
        "lag_ms": scenario.lag_ms,
        "points": status.points,
        "wall_s": time.monotonic() - t0,
        "cost": vars(cost) if cost is not None else None,
        "pose_timeouts": pose_timeouts,
    }


def print_report(r: Dict[str, Any]) -> None:
    """The per-waypoint table and the summary line, as ``ribreg hil`` prints them."""
    print("waypoint  mapped (x, y, z) mm               quality  probe error")
    for i, w in enumerate(r["waypoints"]):
        x, y, z = w["mapped"]
        print(f"{i:>8}  ({x:8.2f}, {y:8.2f}, {z:8.2f})  {w['quality_mm']:6.2f} mm  "
              f"{w['error_mm']:6.2f} mm")
    errors = [w["error_mm"] for w in r["waypoints"]]
    link = r["link"]
    a = r["applied"]
    print(f"robot_pc: {len(errors)} waypoints, probe error mean "
          f"{sum(errors) / max(len(errors), 1):.2f} mm, max {max(errors, default=0):.2f} mm "
          f"(tolerance {TOLERANCE_MM} mm); lag {r['lag_ms']:.1f} ms; {r['points']} points "
          f"compounded; applied poses {a[0]}/{a[2]}, frames {a[1]}/{a[3]}; link: "
          f"{link['sent']} frames sent, {link['resent']} re-sent, {link['nacks']} NACKs, "
          f"{link['timeouts']} timeouts, faults injected {link['injected']}; "
          f"{r['wall_s']:.1f} s")


def main(argv: Optional[List[str]] = None) -> int:
    """Command line: see the module's docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    where = ap.add_mutually_exclusive_group(required=True)
    where.add_argument("--in-process", action="store_true",
                       help="the core's controller in this process (simulated clock)")
    where.add_argument("--port", help="a serial device, or HOST:PORT over TCP")
    ap.add_argument("--baud", type=int, default=115_200, help="baud rate of a serial device")
    ap.add_argument("--seed", type=int, default=0, help="seed of the phantom")
    ap.add_argument("--variant", choices=["aligned", "misaligned"], default="aligned",
                    help="pose of the US target")
    ap.add_argument("--quick", action="store_true",
                    help="the lighter sweep of ribreg hil --quick")
    ap.add_argument("--faults", action="store_true",
                    help="inject link faults (corrupted, dropped, duplicated, reordered "
                         "frames, garbage), as ribreg hil --faults")
    ap.add_argument("--fault-seed", type=int, default=1, help="seed of the fault injection")
    ap.add_argument("--json", help="also write the report as JSON here")
    ap.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = ap.parse_args(argv)

    def progress(line: str) -> None:
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    try:
        faults = args.fault_seed if args.faults else None
        if args.in_process:
            session = Session.in_process(faults)
        elif ":" not in args.port or args.port.startswith("COM"):
            session = Session.serial(args.port, args.baud, faults)
        else:
            session = Session.connect(args.port, faults)
        scenario = Scenario(args.seed, quick=args.quick, variant=args.variant)
        report = run(session, scenario, progress)
    except LinkError as e:
        print(f"robot_pc: link: {e}", file=sys.stderr)
        return 2
    print_report(report)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)
    worst = max((w["error_mm"] for w in report["waypoints"]), default=0.0)
    a = report["applied"]
    return 0 if worst <= TOLERANCE_MM and a[0] == a[2] and a[1] == a[3] else 1


if __name__ == "__main__":
    sys.exit(main())
