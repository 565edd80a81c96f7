"""ribreg.link and ribreg.sim: the frames against the golden vectors the Rust tests use,
a damaged byte stream, bad messages, the session against the in-process controller,
and the example procedure (examples/robot_pc.py) against ``ribreg hil`` in-process and
against the emulated firmware.

Environment: ``RIBREG_BIN`` names the ``ribreg`` binary (default
``target/release/ribreg``, built if missing); ``RIBREG_REQUIRE_QEMU=1`` makes a missing
``qemu-system-arm`` a failure instead of a skip.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from ribreg.link import (
    Ack,
    Command,
    CommandKind,
    FrameError,
    Hello,
    HelloAck,
    LinkError,
    MAX_FRAME,
    Nack,
    NackCode,
    Node,
    Pose,
    Receiver,
    Session,
    TemplateNodes,
    Waypoint,
    Waypoints,
    decode_frame,
    encode_frame,
    from_wire,
)
from ribreg.sim import TOLERANCE_MM, Emulator, Scenario, emulator_available

REPO = Path(__file__).resolve().parents[3]
EXAMPLE = REPO / "host-sim" / "python" / "examples" / "robot_pc.py"
GOLDEN = REPO / "tests" / "fixtures" / "golden" / "wire.json"
SEED = 0


def golden_cases():
    return json.loads(GOLDEN.read_text())["cases"]


def test_every_golden_frame_encodes_and_decodes_as_the_rust_encoder():
    cases = golden_cases()
    assert len(cases) >= 40
    for c in cases:
        to = c["direction"] == "to_controller"
        msg = from_wire(c["message"], to)
        frame = encode_frame(c["seq"], msg)
        assert frame.hex() == c["frame"], c["name"]
        assert decode_frame(frame, to) == (c["seq"], msg), c["name"]


def test_a_damaged_frame_is_a_frame_error():
    frame = bytearray(encode_frame(7, Pose(123, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])))
    with pytest.raises(FrameError, match="CRC|COBS|message"):
        decode_frame(bytes(frame[:-3]), to_controller=True)  # truncated
    frame[5] ^= 0x40
    with pytest.raises(FrameError):
        decode_frame(bytes(frame), to_controller=True)  # garbled
    assert issubclass(FrameError, ValueError)
    with pytest.raises(FrameError, match="more than one frame"):
        decode_frame(encode_frame(0, Ack(0)) * 2)


@pytest.mark.parametrize("chunk", [1, 3, 7, 1000])
def test_the_receiver_loses_no_message_around_bad_bytes(chunk):
    good = [(1, Ack(1)), (2, Nack(2, NackCode.INVALID, 9)), (3, HelloAck(1, 2, 604))]
    garbled = bytearray(encode_frame(9, Ack(9)))
    garbled[-3] ^= 0x40  # a CRC byte; never a zero (that would cut the frame in two)
    assert 0 not in garbled[:-1]
    stream = (encode_frame(*good[0]) + bytes(garbled) + encode_frame(*good[1])
              + b"\x13\x37" * (MAX_FRAME) + b"\x00"  # over-long garbage
              + encode_frame(*good[2]) + encode_frame(4, Ack(4))[:-4])  # cut short
    rx = Receiver()
    out = []
    for i in range(0, len(stream), chunk):
        out += rx.feed(stream[i:i + chunk])
    assert [x if isinstance(x, tuple) else type(x) for x in out] == [
        good[0], FrameError, good[1], FrameError, good[2]]
    assert "CRC" in str(out[1]) or "COBS" in str(out[1])
    assert "longer" in str(out[3])
    # The frame cut short completes when its rest arrives.
    assert rx.feed(encode_frame(4, Ack(4))[-4:]) == [(4, Ack(4))]


def test_messages_the_protocol_cannot_carry_are_value_errors():
    with pytest.raises(ValueError, match="u16"):
        encode_frame(0, Hello(version=70_000))
    with pytest.raises(ValueError):
        encode_frame(0, Waypoints(0, 9, [[0.0, 0.0, 0.0]] * 9))  # 8 a chunk at most
    with pytest.raises(ValueError):
        encode_frame(0, TemplateNodes(0, 33, [Node([0.0, 0.0, 0.0], 1)] * 33))
    with pytest.raises(ValueError):
        encode_frame(0, Pose(-1, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError):
        encode_frame(0, Pose(0, [float("nan"), 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError):
        Session.in_process().send(Waypoints(0, 300, []))


def test_the_in_process_session_handshakes_and_records_refusals():
    s = Session.in_process()
    ack = s.handshake()
    assert ack == HelloAck(0x47524252, 2, MAX_FRAME)
    assert s.simulated_clock
    # Registering without a template is refused by the application, not re-sent.
    seq = s.send(Command(CommandKind.REGISTER))
    s.flush(5.0)
    assert seq == 1
    assert s.refused == [(1, NackCode.BAD_STATE, None)]
    assert s.stats.sent == 2 and s.stats.resent == 0
    s.send(Command(CommandKind.STATUS))
    msg = s.next_message(timeout=1.0)
    assert msg is not None and msg.state.value == "Idle" and msg.expected_seq == 3


def test_a_link_that_cannot_open_is_a_link_error():
    with pytest.raises(LinkError, match="cannot connect") as e:
        Session.connect("127.0.0.1:1")
    assert isinstance(e.value, OSError)
    with pytest.raises(LinkError, match="serial"):
        Session.serial("/nonexistent/tty")


def test_the_scenario_is_what_ribreg_hil_uploads():
    sc = Scenario(SEED, quick=True)
    up = sc.upload()
    assert type(up[0]).__name__ == "Configure"
    assert sum(len(m.nodes) for m in up if isinstance(m, TemplateNodes)) == sc.nodes
    assert sum(len(m.points) for m in up if isinstance(m, Waypoints)) == sc.waypoints == 10
    assert len(sc.true_waypoints) == sc.waypoints
    with pytest.raises(ValueError, match="variant"):
        Scenario(0, variant="sideways")


def ribreg_bin() -> Path:
    path = Path(os.environ.get("RIBREG_BIN", REPO / "target" / "release" / "ribreg"))
    if not path.exists():
        subprocess.run(["cargo", "build", "--release", "-p", "ribreg-sim"], cwd=REPO,
                       check=True, timeout=1800)
    return path


def run_example(tmp_path: Path, *args: str) -> dict:
    out = tmp_path / "robot_pc.json"
    proc = subprocess.run([sys.executable, str(EXAMPLE), *args, "--quick", "--seed",
                           str(SEED), "--quiet", "--json", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(out.read_text())


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


@pytest.mark.parametrize("faults", [[], ["--faults"]], ids=["clean", "faults"])
def test_the_example_in_process_equals_ribreg_hil(tmp_path, faults):
    py = run_example(tmp_path, "--in-process", *faults)
    ref_path = tmp_path / "hil.json"
    subprocess.run([str(ribreg_bin()), "hil", "--in-process", "--quick", "--seed",
                    str(SEED), *faults, "--json", str(ref_path)], check=True,
                   capture_output=True, timeout=600)
    ref = json.loads(ref_path.read_text())
    assert len(py["waypoints"]) == len(ref["waypoints"]) == 10
    for a, b in zip(py["waypoints"], ref["waypoints"]):
        # f32 fields: the Rust JSON writes the shortest decimal of the f32.
        assert a["mapped"] == [f32(v) for v in b["mapped"]]
        assert a["quality_mm"] == f32(b["quality_mm"])
        # f64 fields round-trip exactly: bit-equal.
        assert a["reached"] == b["reached"]
        assert a["truth"] == b["truth"]
        assert a["error_mm"] == b["error_mm"]
    assert py["applied"] == ref["applied"]
    a = py["applied"]
    assert a[0] == a[2] and a[1] == a[3]  # every pose and frame applied exactly once
    assert py["points"] == ref["points"]
    assert py["lag_ms"] == ref["lag_ms"]
    assert py["refused"] == ref["refused"] == []
    if faults:
        assert py["link"]["nacks"] > 0 and py["link"]["resent"] > 0
        assert min(py["link"]["injected"]) > 0
    # The same seeded faults, the same re-sends (unless a silence timed out: wall time).
    if py["link"]["timeouts"] == ref["link"]["timeouts"] == 0:
        assert py["link"] == ref["link"]
    assert max(w["error_mm"] for w in py["waypoints"]) <= TOLERANCE_MM


def test_the_example_against_the_emulated_firmware(tmp_path):
    if not emulator_available():
        if os.environ.get("RIBREG_REQUIRE_QEMU") == "1":
            pytest.fail("qemu-system-arm is required (RIBREG_REQUIRE_QEMU=1) but absent")
        pytest.skip("qemu-system-arm is not installed")
    with Emulator() as emu:
        emu.release_uart()
        emulated = run_example(tmp_path, "--port", emu.address)
    reference = run_example(tmp_path, "--in-process")
    # As ribreg hil: the emulated controller maps the same waypoints within 1e-2 mm.
    worst = max(abs(a - b) for wa, wb in zip(emulated["waypoints"], reference["waypoints"])
                for a, b in zip(wa["mapped"], wb["mapped"]))
    assert worst <= 1e-2
    assert emulated["points"] == reference["points"]
    a = emulated["applied"]
    assert a[0] == a[2] and a[1] == a[3]
    assert max(w["error_mm"] for w in emulated["waypoints"]) <= TOLERANCE_MM
    assert emulated["cost"]["registration_calls"] > 0


def test_a_session_shared_by_threads_does_not_deadlock():
    import threading

    s = Session.in_process()
    s.handshake()
    got = []
    t = threading.Thread(target=lambda: got.append(s.next_message(timeout=5.0)))
    t.start()
    for _ in range(50):
        s.pump(0.001)  # contends for the session while the thread waits in it
    s.send(Command(CommandKind.STATUS))
    t.join(10.0)
    assert not t.is_alive()
    assert got and got[0] is not None and got[0].expected_seq == 2
